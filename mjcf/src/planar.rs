//! Planar reduction: an imported model whose hinges are all parallel and whose slides are all perpendicular to
//! them moves in one plane, whatever layer along the hinge axis each link sits on, so it becomes a planar
//! scene (operational space (x, y, θ), two equations per pin instead of a connect's three).
//!
//! **Why it is exact.** Every joint turns about the common normal n or slides perpendicular to it, so each
//! body's motion from qpos0 is a turn about n and a shift in the plane: a point's depth along n never changes,
//! and its projection onto the plane moves as a planar body's point does. A body's kinetic energy is then
//! ½ m |v_com|² + ½ (nᵀ I n) φ̇² (its angular velocity is φ̇ n), so the planar inertia nᵀ I n and the
//! projected centre of mass give the same mass matrix; gravity along n and the gyroscopic term
//! ω × I ω ⟂ n do no work on any joint. A connect's row along n is identically zero (both points keep their
//! depth, equal at qpos0), and so are a weld's rows along n and about the two in-plane axes: those equations
//! are redundant and dropped.
//!
//! **The planar scene.** Each body's planar frame sits where its spatial frame's origin projects, at angle
//! zero at qpos0; a hinge keeps its q (negated when its axis is −n) with the joint frame's angle taking up
//! q0, a slide its q along the projected axis. Points (centres of mass, geometry, sites, cut points) are
//! projected; a site's depth is kept in [`PlanarReduction::op_depths`] so its 3-D position can be rebuilt.
//! Anything else (a ball or universal joint, a hinge not parallel to the first, a slide with a component
//! along the hinges, no hinge to fix the plane) keeps the spatial scene, and [`Reduction::Spatial`] says why.

use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::math::space::{Planar, SceneKind, Spatial};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::scene::{
    BodySpec, CutKindSpec, CutSpec, GeometrySpec, JointKindSpec, JointSpec, Numbers, OpSpec, Scene, GROUND,
};
use kinloop_linkage::model::{Attachment, ClosurePrimitive, Model, Shape};
use nalgebra::{Rotation3, Vector3};

/// Largest |sin| between two axes called parallel (or |cos| between a slide and the normal called
/// perpendicular).
const PARALLEL: f64 = 1e-9;

/// The plane of a planar import: a unit normal n along the hinges and in-plane axes e1, e2 with e1 × e2 = n,
/// through the world origin. A world point p is (e1·p, e2·p) in the plane, at depth n·p.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal (the first hinge's axis at qpos0).
    pub normal: Vector3<f64>,
    /// The plane's x axis in world coordinates.
    pub e1: Vector3<f64>,
    /// The plane's y axis in world coordinates (n × e1).
    pub e2: Vector3<f64>,
}

impl Plane {
    /// The plane normal to `normal` (unit), its x axis the projection of world x (of world y when the normal
    /// is near x).
    pub fn normal_to(normal: Vector3<f64>) -> Plane {
        let seed = if normal.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let e1 = (seed - normal * normal.dot(&seed)).normalize();
        Plane { normal, e1, e2: normal.cross(&e1) }
    }

    /// A world vector's in-plane coordinates.
    pub fn project(&self, v: &Vector3<f64>) -> [f64; 2] {
        [self.e1.dot(v), self.e2.dot(v)]
    }

    /// The world point at in-plane coordinates `xy` and `depth` along the normal.
    pub fn to_world(&self, xy: [f64; 2], depth: f64) -> Vector3<f64> {
        self.e1 * xy[0] + self.e2 * xy[1] + self.normal * depth
    }
}

/// What a planar import reduced, and how to map it back to the model.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanarReduction {
    /// The plane.
    pub plane: Plane,
    /// Per scene joint, in order: the planar q is `sign` × MuJoCo's qpos (−1 for a hinge along −n).
    pub signs: Vec<f64>,
    /// Per operational point, in order: its depth along the normal (constant in the motion).
    pub op_depths: Vec<f64>,
    /// The spatial equations dropped as redundant, each named (a connect's row along the normal, ...).
    pub dropped: Vec<String>,
    /// The spatial scene the planar one was reduced from (it compiles).
    pub spatial: Scene,
}

/// Whether an import was reduced to a planar scene.
#[derive(Clone, Debug, PartialEq)]
pub enum Reduction {
    /// Reduced: the scene is planar.
    Planar(Box<PlanarReduction>),
    /// Kept spatial.
    Spatial {
        /// Why the model is not planar.
        why: String,
        /// True when every hinge is parallel (a model that may have been meant as planar): the import's
        /// warning then says why it was kept spatial.
        near_planar: bool,
    },
}

impl Reduction {
    /// One line for `inspect` and `import`: what was reduced, or why nothing was.
    pub fn describe(&self) -> String {
        match self {
            Reduction::Planar(r) => {
                let f = |v: &Vector3<f64>| format!("[{:.4}, {:.4}, {:.4}]", v.x, v.y, v.z);
                let dropped = if r.dropped.is_empty() {
                    "no equation dropped".to_string()
                } else {
                    format!("dropped as redundant: {}", r.dropped.join("; "))
                };
                format!(
                    "reduced to a planar scene: hinges along {}, plane axes x = {}, y = {}; operational space 6 → 3 \
                     (the motion along the normal and the turns about the in-plane axes are idle); {dropped}",
                    f(&r.plane.normal),
                    f(&r.plane.e1),
                    f(&r.plane.e2)
                )
            }
            Reduction::Spatial { why, .. } => format!("kept spatial: {why}"),
        }
    }
}

/// Reduces `scene` (spatial, compiled as `model`) to a planar scene when its motion stays in one plane:
/// returns the scene to use and what was done.
pub fn reduce(scene: Scene, model: &Model<Spatial>, file: &str) -> (Scene, Reduction) {
    match planar_scene(&scene, model) {
        Ok((planar, reduction)) => match Model::<Planar>::compile(&planar, file) {
            Ok(_) => (planar, Reduction::Planar(Box::new(reduction))),
            Err(e) => {
                let why = format!("the planar scene made from it does not compile ({e})");
                (scene, Reduction::Spatial { why, near_planar: true })
            }
        },
        Err(spatial) => (scene, spatial),
    }
}

/// The world pose of each scene body at q0 (by name; `ground` the identity).
struct Poses<'a> {
    model: &'a Model<Spatial>,
    data: Data<Spatial>,
}

impl Poses<'_> {
    /// The model's index of scene body `name` (`None`: ground); a name the model lacks keeps the import
    /// spatial (it cannot happen for a scene the model was compiled from).
    fn index(&self, name: &str) -> Result<Option<usize>, Reduction> {
        if name == GROUND {
            return Ok(None);
        }
        self.model.body_index(name).map(Some).ok_or_else(|| spatial(format!("no compiled body '{name}'"), false))
    }

    fn pose(&self, body: Option<usize>) -> (Rotation3<f64>, Vector3<f64>) {
        body.map_or((Rotation3::identity(), Vector3::zeros()), |b| {
            (self.data.kin.body_rot[b], self.data.kin.body_pos[b])
        })
    }
}

fn spatial(why: String, near_planar: bool) -> Reduction {
    Reduction::Spatial { why, near_planar }
}

fn planar_scene(scene: &Scene, model: &Model<Spatial>) -> Result<(Scene, PlanarReduction), Reduction> {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &model.q0);
    let poses = Poses { model, data };
    let (normal, axes) = plane_normal(scene, &poses)?;
    let plane = Plane::normal_to(normal);
    let (cuts, dropped) = planar_cuts(scene, &poses, &plane)?;
    let bodies = scene.bodies.iter().map(|spec| planar_body(spec, &poses, &plane)).collect::<Result<_, _>>()?;
    let mut joints = Vec::with_capacity(scene.joints.len());
    let mut signs = Vec::with_capacity(scene.joints.len());
    for (j, axis) in scene.joints.iter().zip(&axes) {
        let (_, at_child) = poses.pose(poses.index(&j.child)?);
        let (_, at_parent) = poses.pose(poses.index(&j.parent)?);
        let offset = |v: Vector3<f64>| plane.project(&v).to_vec();
        joints.push(if j.kind == JointKindSpec::Revolute {
            let sign = axis.dot(&normal).signum();
            signs.push(sign);
            planar_joint(j, sign, offset(at_child - at_parent), -sign * j.q0, None)
        } else {
            signs.push(1.0);
            // The child's frame sits at the joint frame's origin plus q along the axis.
            let origin = at_child - axis * j.q0 - at_parent;
            planar_joint(j, 1.0, offset(origin), 0.0, Some(plane.project(axis).to_vec()))
        });
    }
    let mut ops = Vec::with_capacity(scene.ops.len());
    let mut op_depths = Vec::with_capacity(scene.ops.len());
    for spec in &scene.ops {
        let (r, p) = poses.pose(poses.index(&spec.body)?);
        let point = Vector3::from_iterator(spec.point.iter().copied().chain(std::iter::repeat(0.0)).take(3));
        op_depths.push(normal.dot(&(p + r * point)));
        ops.push(OpSpec { point: plane.project(&(r * point)).to_vec(), ..spec.clone() });
    }
    let gravity = Vector3::from_iterator(scene.gravity.iter().copied().chain(std::iter::repeat(0.0)).take(3));
    let planar = Scene {
        kind: SceneKind::Planar,
        gravity: plane.project(&gravity).to_vec(),
        bodies,
        joints,
        cuts,
        ops,
        ..scene.clone()
    };
    Ok((planar, PlanarReduction { plane, signs, op_depths, dropped, spatial: scene.clone() }))
}

/// The common hinge normal (the first hinge's world axis at q0) and every joint's world axis, or why the
/// model is not planar.
fn plane_normal(scene: &Scene, poses: &Poses<'_>) -> Result<(Vector3<f64>, Vec<Vector3<f64>>), Reduction> {
    let mut axes = Vec::with_capacity(scene.joints.len());
    for j in &scene.joints {
        // A hinge's axis is the same in its joint frame and its child's frame; the model's joint i carries
        // its body i.
        axes.push(match (j.kind, poses.index(&j.child)?) {
            (JointKindSpec::Revolute | JointKindSpec::Prismatic, Some(b)) => {
                Some(poses.data.kin.body_rot[b] * poses.model.joints[b].axis)
            }
            _ => None,
        });
    }
    let hinges: Vec<(usize, Vector3<f64>)> = scene
        .joints
        .iter()
        .zip(&axes)
        .enumerate()
        .filter(|(_, (j, _))| j.kind == JointKindSpec::Revolute)
        .filter_map(|(i, (_, a))| a.map(|a| (i, a)))
        .collect();
    let Some(&(h, normal)) = hinges.first() else {
        return Err(spatial("no hinge fixes a plane".into(), false));
    };
    if let Some(&(i, _)) = hinges.iter().find(|(_, a)| a.cross(&normal).norm() > PARALLEL) {
        let why = format!("hinge '{}' is not parallel to hinge '{}'", scene.joints[i].name, scene.joints[h].name);
        return Err(spatial(why, false));
    }
    let mut out = Vec::with_capacity(axes.len());
    for (j, axis) in scene.joints.iter().zip(axes) {
        let why = match (j.kind, axis) {
            (JointKindSpec::Ball, _) => format!("joint '{}' is a ball joint", j.name),
            (JointKindSpec::Universal, _) => format!("joint '{}' is a universal joint (two hinges)", j.name),
            (JointKindSpec::Prismatic, Some(a)) if a.dot(&normal).abs() > PARALLEL => {
                format!("slide '{}' moves along the hinges' axis, out of their plane", j.name)
            }
            (_, Some(a)) => {
                out.push(a);
                continue;
            }
            (_, None) => format!("joint '{}' has no axis", j.name),
        };
        return Err(spatial(why, true));
    }
    Ok((normal, out))
}

/// Each cut as a planar one (a connect a pin, a weld a planar weld) and the equations dropped.
fn planar_cuts(scene: &Scene, poses: &Poses<'_>, plane: &Plane) -> Result<(Vec<CutSpec>, Vec<String>), Reduction> {
    let mut dropped = Vec::new();
    let mut cuts = Vec::with_capacity(scene.cuts.len());
    for cut in &scene.cuts {
        let kind = match cut.kind {
            CutKindSpec::Spherical => {
                dropped.push(format!("connect '{}': 1 of 3 (along the normal)", cut.name));
                CutKindSpec::Pin
            }
            CutKindSpec::Weld => {
                dropped.push(format!("weld '{}': 3 of 6 (along the normal, turns about the plane's axes)", cut.name));
                CutKindSpec::Weld
            }
            other => return Err(spatial(format!("cut '{}' is a {other:?} cut", cut.name), true)),
        };
        let compiled = poses.model.cuts.iter().find(|c| c.name == cut.name);
        let Some(ClosurePrimitive::Coincident { a, b }) = compiled.and_then(|c| c.primitives.first()) else {
            return Err(spatial(format!("cut '{}' has no point to pin", cut.name), true));
        };
        // A body's planar point is its spatial point turned to world axes at q0 (planar frames start at
        // angle zero) and projected; point b is written out, as the spatial compile completed it.
        let point = |at: &Attachment<Spatial>| plane.project(&(poses.pose(at.body).0 * at.point)).to_vec();
        cuts.push(CutSpec {
            kind,
            point_a: point(a),
            point_b: Some(point(b)),
            axis: None,
            axis_b: None,
            ..cut.clone()
        });
    }
    Ok((cuts, dropped))
}

/// A body with its centre of mass and geometry projected and its inertia about the normal, nᵀ I n.
fn planar_body(spec: &BodySpec, poses: &Poses<'_>, plane: &Plane) -> Result<BodySpec, Reduction> {
    let b = poses.index(&spec.name)?.ok_or_else(|| spatial("a body named 'ground'".into(), false))?;
    let (r, _) = poses.pose(Some(b));
    let body = &poses.model.bodies[b];
    let inertia_world = r.matrix() * body.inertia * r.matrix().transpose();
    let xy = |p: &Vector3<f64>| plane.project(&(r * p)).to_vec();
    let geometry = body
        .geometry
        .iter()
        .map(|g| match g {
            Shape::Capsule { from, to, radius } => {
                GeometrySpec::Capsule { from: xy(from), to: xy(to), radius: *radius }
            }
            Shape::Ball { center, radius } => GeometrySpec::Ball { center: xy(center), radius: *radius },
        })
        .collect();
    Ok(BodySpec {
        name: spec.name.clone(),
        mass: spec.mass,
        com: xy(&body.com),
        inertia: Numbers::One(plane.normal.dot(&(inertia_world * plane.normal))),
        geometry,
    })
}

/// A spatial hinge or slide as a planar joint: q scaled by `sign` (springs, ranges and targets with it), the
/// joint frame at `origin` in the parent's planar frame, turned by `rotation`.
fn planar_joint(j: &JointSpec, sign: f64, origin: Vec<f64>, rotation: f64, axis: Option<Vec<f64>>) -> JointSpec {
    let mut spring = j.spring;
    if let Some(s) = &mut spring {
        s.rest *= sign;
    }
    let mut actuator = j.actuator;
    if let Some(a) = &mut actuator {
        a.target *= sign;
    }
    JointSpec {
        origin,
        rotation: Some(Numbers::One(rotation)),
        axis,
        axes: None,
        q0: sign * j.q0,
        qd0: sign * j.qd0,
        spring,
        actuator,
        range: j.range.map(|[lo, hi]| if sign < 0.0 { [-hi, -lo] } else { [lo, hi] }),
        ..j.clone()
    }
}
