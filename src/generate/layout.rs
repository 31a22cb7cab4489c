//! Planar linkages laid out by their joints' positions: each body is named by the point of the joint to
//! its parent and a point giving its x axis; the tree joints' origins and q0 follow from the points, and
//! every cut pins two bodies where they meet at q0, so a generated loop is closed at q0 by construction
//! (both pin points are written out, so compiling the scene checks that construction).

use kinloop_linkage::model::scene::{
    Baumgarte, BodySpec, ContactParams, CutKindSpec, CutSpec, GeometrySpec, JointKindSpec, JointSpec, Numbers, OpSpec,
    GROUND,
};
use kinloop_linkage::{math::space::SceneKind, model::scene::Scene};

/// A point of the plane, in metres.
pub type P2 = [f64; 2];

/// How a body hangs from its parent.
#[derive(Clone, Copy, Debug)]
pub enum Hinge {
    /// A revolute joint at the body's pivot.
    Revolute,
    /// A prismatic joint along the body's x axis (its axis from `pivot` toward `toward`); the body's
    /// origin slides on the line through `rail` (a point of the parent).
    Prismatic {
        /// Where the rail's coordinate is zero, in world coordinates at q0.
        rail: P2,
    },
}

/// One body of a layout.
#[derive(Clone, Debug)]
pub struct LaidBody {
    /// The body's name.
    pub name: String,
    /// Index of the parent body in the layout, `None` for ground.
    pub parent: Option<usize>,
    /// The body's origin (its joint to the parent) at q0, world coordinates.
    pub pivot: P2,
    /// A point on the body's x axis at q0.
    pub toward: P2,
    /// The joint to the parent.
    pub hinge: Hinge,
    /// Further points of the body (joint sites of cuts, ternary corners), world coordinates at q0.
    pub points: Vec<P2>,
    /// Mass, kg.
    pub mass: f64,
}

/// A pin closing a loop: `body` (a layout index) meets `other` (an index or ground) at `at`.
#[derive(Clone, Debug)]
pub struct LaidPin {
    /// One body.
    pub body: usize,
    /// The other body, `None` for ground.
    pub other: Option<usize>,
    /// Where they meet at q0, world coordinates.
    pub at: P2,
}

/// A planar linkage given by its joints' positions at q0.
#[derive(Clone, Debug, Default)]
pub struct Layout {
    /// The bodies, parents before children.
    pub bodies: Vec<LaidBody>,
    /// The loop closures.
    pub pins: Vec<LaidPin>,
}

fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn norm(a: P2) -> f64 {
    a[0].hypot(a[1])
}

/// `p` in the frame of a body with origin `origin` and x axis at `angle`.
fn local(p: P2, origin: P2, angle: f64) -> Vec<f64> {
    let d = sub(p, origin);
    let (s, c) = angle.sin_cos();
    vec![c * d[0] + s * d[1], -s * d[0] + c * d[1]]
}

impl Layout {
    /// A body's x-axis angle at q0, world axes.
    fn angle(&self, i: usize) -> f64 {
        let b = &self.bodies[i];
        let d = sub(b.toward, b.pivot);
        d[1].atan2(d[0])
    }

    /// The frame (origin, angle) of body `i`, or ground's.
    fn frame(&self, i: Option<usize>) -> (P2, f64) {
        i.map_or(([0.0, 0.0], 0.0), |i| (self.bodies[i].pivot, self.angle(i)))
    }

    /// The planar scene of this layout (no gravity, no OP yet): each body a capsule from its pivot to its
    /// farthest point, its COM at the centroid of its points, its inertia a slender rod's about it.
    pub fn scene(&self, name: &str) -> Scene {
        let mut bodies = Vec::new();
        let mut joints = Vec::new();
        for (i, b) in self.bodies.iter().enumerate() {
            let angle = self.angle(i);
            let mut sites: Vec<P2> = vec![b.pivot, b.toward];
            sites.extend(b.points.iter().copied());
            let count = sites.len() as f64;
            let centroid =
                [sites.iter().map(|p| p[0]).sum::<f64>() / count, sites.iter().map(|p| p[1]).sum::<f64>() / count];
            let reach = sites.iter().map(|p| norm(sub(*p, b.pivot))).fold(0.0, f64::max);
            let spread = sites.iter().map(|p| norm(sub(*p, centroid)).powi(2)).sum::<f64>() / count;
            let radius = 0.04 * reach;
            let geometry = sites[1..]
                .iter()
                .map(|p| GeometrySpec::Capsule { from: vec![0.0, 0.0], to: local(*p, b.pivot, angle), radius })
                .collect();
            bodies.push(BodySpec {
                name: b.name.clone(),
                mass: b.mass,
                com: local(centroid, b.pivot, angle),
                // The sites' second moment about their centroid, at least a slender rod's m l²/12.
                inertia: Numbers::One(b.mass * spread.max(reach * reach / 12.0)),
                geometry,
            });
            let (parent_origin, parent_angle) = self.frame(b.parent);
            let parent = b.parent.map_or(GROUND.to_string(), |p| self.bodies[p].name.clone());
            let (kind, origin, rotation, axis, q0) = match b.hinge {
                Hinge::Revolute => (
                    JointKindSpec::Revolute,
                    local(b.pivot, parent_origin, parent_angle),
                    None,
                    None,
                    angle - parent_angle,
                ),
                Hinge::Prismatic { rail } => {
                    let along = norm(sub(b.pivot, rail));
                    let sign = if (b.pivot[0] - rail[0]) * angle.cos() + (b.pivot[1] - rail[1]) * angle.sin() < 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    (
                        JointKindSpec::Prismatic,
                        local(rail, parent_origin, parent_angle),
                        Some(Numbers::One(angle - parent_angle)),
                        Some(vec![1.0, 0.0]),
                        sign * along,
                    )
                }
            };
            joints.push(JointSpec {
                name: format!("j-{}", b.name),
                kind,
                parent,
                child: b.name.clone(),
                origin,
                rotation,
                axis,
                axes: None,
                q0,
                qd0: 0.0,
                spring: None,
                damping: 0.0,
                armature: 0.0,
                actuator: None,
                range: None,
            });
        }
        let cuts = self
            .pins
            .iter()
            .enumerate()
            .map(|(k, pin)| CutSpec {
                // Written out (not left to be taken from q0), so that compiling checks the layout's geometry.
                point_b: Some(pin.other.map_or(pin.at.to_vec(), |o| self.body_point(o, pin.at))),
                ..CutSpec::between(
                    format!("pin-{k}"),
                    CutKindSpec::Pin,
                    self.bodies[pin.body].name.clone(),
                    local(pin.at, self.bodies[pin.body].pivot, self.angle(pin.body)),
                    pin.other.map_or(GROUND.to_string(), |o| self.bodies[o].name.clone()),
                )
            })
            .collect();
        Scene {
            name: name.to_string(),
            kind: SceneKind::Planar,
            gravity: vec![0.0, 0.0],
            length_scale: None,
            baumgarte: Baumgarte::default(),
            contact: ContactParams::default(),
            closure_tolerance: None,
            bodies,
            joints,
            cuts,
            ops: Vec::<OpSpec>::new(),
            obstacles: Vec::new(),
        }
    }

    /// A point of body `i` given in world coordinates at q0, in the body's frame.
    pub fn body_point(&self, i: usize, p: P2) -> Vec<f64> {
        local(p, self.bodies[i].pivot, self.angle(i))
    }
}
