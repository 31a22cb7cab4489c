//! Turns coordinates into what the page draws: world-space capsules and balls of every body, and the
//! operational points, by the view's own [`Model`] and [`Data`] (never the VE's: the hub runs on the
//! network side and computes [`forward_kinematics`] itself).

use kinloop_linkage::algorithms::configuration;
use kinloop_linkage::algorithms::jacobian::frame_jacobian_t;
use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::model::{Obstacle, Shape};
use kinloop_linkage::{
    math::space::SceneKind, math::space::Space, math::space::VecOps, model::data::Data, model::Model,
};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// The static part of a scene, sent once in the welcome.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SceneInfo {
    /// Scene name.
    pub name: String,
    /// `planar` or `spatial`.
    pub kind: &'static str,
    /// Configuration coordinates (nq: a ball joint takes four).
    pub n: usize,
    /// Characteristic length L (m): directions are in `(v, L ω)`.
    pub length_scale: f64,
    /// Operational points a page may grab, by name.
    pub ops: Vec<String>,
    /// Obstacles, world frame.
    pub obstacles: Vec<ObstacleInfo>,
    /// Corners (min, max) of the linkage's drawing at its initial configuration, for the first camera.
    pub bounds: [Vec<f64>; 2],
}

/// An obstacle on the page.
#[derive(Clone, Debug, Serialize, PartialEq)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum ObstacleInfo {
    /// `{x : normal·x ≥ offset}` is free.
    Plane {
        /// Name.
        name: String,
        /// Unit normal into free space.
        normal: Vec<f64>,
        /// Offset (m).
        offset: f64,
    },
    /// A solid disc or sphere.
    Ball {
        /// Name.
        name: String,
        /// Centre.
        center: Vec<f64>,
        /// Radius (m).
        radius: f64,
    },
}

/// The linkage at one configuration, world frame.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Drawn {
    /// Capsules: `from` (2 or 3 numbers), `to`, radius, body index.
    pub capsules: Vec<Vec<f64>>,
    /// Balls: centre, radius, body index.
    pub balls: Vec<Vec<f64>>,
    /// Operational points: pose on the wire (x, y, θ or x, y, z, qw, qx, qy, qz), in the order of
    /// [`SceneInfo::ops`].
    pub ops: Vec<Vec<f64>>,
}

/// A scene the view can draw, whatever its space.
pub trait Geometry: Send {
    /// The static part.
    fn info(&self) -> &SceneInfo;
    /// The linkage at `q` (as many numbers as the scene has coordinates; anything else draws nothing).
    fn draw(&mut self, q: &[f64]) -> Drawn;
    /// Coordinates near `start` (the scene's initial ones when empty) that close the loops and put
    /// operational point `op` at `position` as nearly as the linkage allows (damped least squares): what a
    /// client's recording, which holds the OP but not q, is drawn with. `None` when the solve diverges.
    fn solve_for_op(&mut self, start: &[f64], op: usize, position: &[f64]) -> Option<Vec<f64>>;
}

/// [`Geometry`] of a model of space `S`.
pub struct Drawer<S: Space> {
    model: Model<S>,
    data: Data<S>,
    q: DVector<f64>,
    info: SceneInfo,
}

impl<S: Space> Drawer<S> {
    /// Draws `model`.
    pub fn new(model: Model<S>) -> Self {
        let data = Data::new(&model);
        let q = model.q0.clone();
        let obstacles = model
            .obstacles
            .iter()
            .map(|o| match o {
                Obstacle::HalfSpace { name, normal, offset } => {
                    ObstacleInfo::Plane { name: name.clone(), normal: normal.as_slice().to_vec(), offset: *offset }
                }
                Obstacle::Ball { name, center, radius } => {
                    ObstacleInfo::Ball { name: name.clone(), center: center.as_slice().to_vec(), radius: *radius }
                }
            })
            .collect();
        let info = SceneInfo {
            name: model.name.clone(),
            kind: match S::KIND {
                SceneKind::Planar => "planar",
                SceneKind::Spatial => "spatial",
            },
            n: model.nq(),
            length_scale: model.length_scale,
            ops: model.ops.iter().map(|o| o.name.clone()).collect(),
            obstacles,
            bounds: [Vec::new(), Vec::new()],
        };
        let mut drawer = Drawer { model, data, q, info };
        let q0 = drawer.model.q0.as_slice().to_vec();
        let drawn = drawer.draw(&q0);
        drawer.info.bounds = bounds(&drawn, <S::Point as VecOps>::LEN);
        drawer
    }

    /// Geometry of body `b` in its frame: the scene's, or a line from its origin to the joints it carries
    /// (its centre of mass when it carries none) for a body the scene gave no geometry.
    fn body_shapes(&self, b: usize) -> Vec<Shape<S>> {
        let body = &self.model.bodies[b];
        if !body.geometry.is_empty() {
            return body.geometry.clone();
        }
        let radius = 0.02 * self.model.length_scale;
        let mut ends: Vec<S::Point> =
            self.model.joints.iter().filter(|j| j.parent == b).map(|j| j.placement_pos).collect();
        if ends.is_empty() {
            ends.push(body.com);
        }
        ends.into_iter().map(|to| Shape::Capsule { from: S::Point::zero(), to, radius }).collect()
    }
}

fn bounds(drawn: &Drawn, d: usize) -> [Vec<f64>; 2] {
    let mut lo = vec![f64::INFINITY; d];
    let mut hi = vec![f64::NEG_INFINITY; d];
    let mut include = |p: &[f64], r: f64| {
        for a in 0..d {
            lo[a] = lo[a].min(p[a] - r);
            hi[a] = hi[a].max(p[a] + r);
        }
    };
    for c in &drawn.capsules {
        include(&c[..d], c[2 * d]);
        include(&c[d..2 * d], c[2 * d]);
    }
    for b in &drawn.balls {
        include(&b[..d], b[d]);
    }
    for o in &drawn.ops {
        include(&o[..d], 0.0);
    }
    if lo.iter().any(|v| !v.is_finite()) {
        return [vec![-1.0; d], vec![1.0; d]];
    }
    [lo, hi]
}

impl<S: Space> Geometry for Drawer<S> {
    fn info(&self) -> &SceneInfo {
        &self.info
    }

    fn draw(&mut self, q: &[f64]) -> Drawn {
        let mut drawn = Drawn::default();
        if q.len() != self.model.nq() || q.iter().any(|v| !v.is_finite()) {
            return drawn;
        }
        self.q.as_mut_slice().copy_from_slice(q);
        forward_kinematics(&self.model, &mut self.data, &self.q);
        let kin = &self.data.kin;
        let world = |b: usize, p: &S::Point| kin.body_pos[b] + S::rotate(&kin.body_rot[b], p);
        for b in 0..self.model.bodies.len() {
            for shape in self.body_shapes(b) {
                match shape {
                    Shape::Capsule { from, to, radius } => {
                        let mut c = world(b, &from).as_slice().to_vec();
                        c.extend_from_slice(world(b, &to).as_slice());
                        c.extend([radius, b as f64]);
                        drawn.capsules.push(c);
                    }
                    Shape::Ball { center, radius } => {
                        let mut c = world(b, &center).as_slice().to_vec();
                        c.extend([radius, b as f64]);
                        drawn.balls.push(c);
                    }
                }
            }
        }
        for op in 0..self.model.ops.len() {
            let mut pose = vec![0.0; OpPose::<S>::wire_len()];
            OpPose::<S>::of_op(&self.model, &self.data, op).to_slice(&mut pose);
            drawn.ops.push(pose);
        }
        drawn
    }

    fn solve_for_op(&mut self, start: &[f64], op: usize, position: &[f64]) -> Option<Vec<f64>> {
        self.solve(start, op, position)
    }
}

/// Gauss-Newton iterations per solve (from the previous row's q, a few suffice).
const SOLVE_ITERATIONS: usize = 20;
/// Damping of the least-squares steps (m²): keeps a singular or unreachable target finite.
const SOLVE_DAMPING: f64 = 1e-8;

impl<S: Space> Drawer<S> {
    fn solve(&mut self, start: &[f64], op: usize, position: &[f64]) -> Option<Vec<f64>> {
        let (n, m, d) = (self.model.nv(), self.model.nc(), <S::Point as VecOps>::LEN);
        let o = self.model.ops.get(op)?;
        let (body, point) = (o.body, o.point);
        if position.len() != d {
            return None;
        }
        let mut q =
            if start.len() == self.model.nq() { DVector::from_column_slice(start) } else { self.model.q0.clone() };
        let mut jt = DMatrix::zeros(n, S::DIM);
        let mut jac = DMatrix::zeros(m + d, n);
        let mut residual = DVector::zeros(m + d);
        for _ in 0..SOLVE_ITERATIONS {
            forward_kinematics(&self.model, &mut self.data, &q);
            closure_residual_and_jacobian(&self.model, &mut self.data);
            let kin = &self.data.kin;
            let at = kin.body_pos[body] + S::rotate(&kin.body_rot[body], &point);
            frame_jacobian_t(&self.model, kin, body, &at, &mut jt);
            for r in 0..m {
                residual[r] = -self.data.closure_residual[r];
                for c in 0..n {
                    jac[(r, c)] = self.data.closure_jacobian_t[(c, r)];
                }
            }
            for a in 0..d {
                residual[m + a] = position[a] - at.as_slice()[a];
                for c in 0..n {
                    jac[(m + a, c)] = jt[(c, a)];
                }
            }
            if residual.norm() < 1e-10 {
                break;
            }
            let mut normal = &jac * jac.transpose();
            for i in 0..m + d {
                normal[(i, i)] += SOLVE_DAMPING;
            }
            let step = jac.transpose() * normal.cholesky()?.solve(&residual);
            configuration::integrate(&self.model, &mut q, &step, 1.0);
        }
        q.iter().all(|v| v.is_finite()).then(|| q.as_slice().to_vec())
    }
}

/// A boxed [`Geometry`] for a model of either space.
pub fn geometry(
    scene: &kinloop_linkage::model::scene::Scene,
    label: &str,
) -> Result<Box<dyn Geometry>, kinloop_linkage::error::SceneError> {
    Ok(match scene.kind {
        SceneKind::Planar => {
            Box::new(Drawer::new(Model::<kinloop_linkage::math::space::Planar>::compile(scene, label)?))
        }
        SceneKind::Spatial => {
            Box::new(Drawer::new(Model::<kinloop_linkage::math::space::Spatial>::compile(scene, label)?))
        }
    })
}
