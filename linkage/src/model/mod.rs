//! The multibody model: what a linkage is, apart from anything computed on it. The scene file as written
//! ([`scene`]) and the built-in scenes ([`builtin`]); the immutable [`Model`], a scene compiled once (by
//! [`Model::compile`], in `algorithms::compile`, since compiling needs the algorithms) into the arrays the
//! algorithms read; and the [`Data`](data::Data) workspace they write. This layer uses only `math` (and
//! `error`).
//!
//! Bodies are stored in topological order (every parent before its children); body `i` is moved by tree
//! joint `i`, so `q̇[i]` is the rate of the joint that carries body `i` and `q[joints[i].q_index]` its
//! position (a ball joint's three entries share a quaternion, see [`JointKind::Ball`]). The order follows the file's
//! `[[joint]]` order wherever that is already topological.

use nalgebra::DVector;

pub mod builtin;
pub mod data;
pub mod revolute_built;
pub mod scene;

use crate::math::space::{SceneKind, Space, VecOps};
use crate::model::scene::{Baumgarte, ContactParams, CutKindSpec};

/// Marks "no parent" (the body hangs from ground).
pub const NO_PARENT: usize = usize::MAX;

/// Kind of a tree joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis.
    Revolute,
    /// Translation along the axis.
    Prismatic,
    /// One of the three rotation rates of a ball (spherical) joint, about body axis `slot` (0, 1, 2). A ball
    /// joint is three consecutive entries sharing one unit quaternion `(w, x, y, z)` at
    /// `q[q_index..q_index + 4]` (nq = 4, nv = 3, as in Pinocchio and MuJoCo: no gimbal singularity). Its
    /// velocity is the body's angular velocity relative to the joint frame, in body axes; slots 0 and 1 carry
    /// massless internal bodies with the pose of slot 2's body, which is the scene's child body.
    Ball {
        /// Body axis of this rate: 0, 1 or 2.
        slot: usize,
    },
}

/// A spring on a joint: `τ = -stiffness (q - rest)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    /// Stiffness.
    pub stiffness: f64,
    /// Rest position.
    pub rest: f64,
}

/// The positions a joint or cut freedom is kept within, by penalty walls (see `algorithms::joint_limits`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// Lower end, rad or m.
    pub lo: f64,
    /// Upper end, rad or m (> `lo`).
    pub hi: f64,
    /// The walls' stiffness, N m/rad or N/m.
    pub stiffness: f64,
    /// The walls' damping, N m s/rad or N s/m.
    pub damping: f64,
}

/// A PD actuator on a joint: `τ = clamp(kp (target - q) - kd q̇, ±max_effort)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Actuator {
    /// Proportional gain.
    pub kp: f64,
    /// Derivative gain.
    pub kd: f64,
    /// Target position.
    pub target: f64,
    /// Effort limit (infinite when unlimited).
    pub max_effort: f64,
}

/// A tree joint, carrying the body of the same index.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint<S: Space> {
    /// Name from the scene.
    pub name: String,
    /// Revolute, prismatic or one rate of a ball joint.
    pub kind: JointKind,
    /// Where this joint's position starts in q: equal to the joint's index (its velocity's) until the first
    /// ball joint, whose quaternion takes one coordinate more than its three rates.
    pub q_index: usize,
    /// Index of the parent body, or [`NO_PARENT`].
    pub parent: usize,
    /// Orientation of the joint frame in the parent frame.
    pub placement_rot: S::Rot,
    /// Origin of the joint frame in the parent frame.
    pub placement_pos: S::Point,
    /// Unit axis in the joint frame.
    pub axis: S::Point,
    /// Optional spring.
    pub spring: Option<Spring>,
    /// Viscous damping coefficient (0 when none).
    pub damping: f64,
    /// Armature added to this rate's diagonal entry of D (0 when none), kg m² or kg.
    pub armature: f64,
    /// Optional PD actuator.
    pub actuator: Option<Actuator>,
    /// Optional range of positions.
    pub range: Option<Range>,
}

/// Geometry attached to a body, in its frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape<S: Space> {
    /// Segment swept by a ball.
    Capsule {
        /// Start.
        from: S::Point,
        /// End.
        to: S::Point,
        /// Radius.
        radius: f64,
    },
    /// Disc or sphere.
    Ball {
        /// Centre.
        center: S::Point,
        /// Radius.
        radius: f64,
    },
}

/// A rigid body.
#[derive(Clone, Debug, PartialEq)]
pub struct Body<S: Space> {
    /// Name from the scene.
    pub name: String,
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in the body frame.
    pub com: S::Point,
    /// Rotational inertia about the COM, body axes.
    pub inertia: S::RotInertia,
    /// Geometry for drawing and contacts.
    pub geometry: Vec<Shape<S>>,
}

/// A point fixed to a body (or to ground when `body` is `None`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attachment<S: Space> {
    /// Body index, or `None` for ground.
    pub body: Option<usize>,
    /// Position in the body frame (world frame for ground).
    pub point: S::Point,
}

/// One primitive of a loop closure; a cut joint is a list of them. Each has an analytic residual h,
/// Jacobian W = ∂h/∂q and velocity-product term w = Ẇ q̇ (see `loop_closure`).
#[derive(Clone, Debug, PartialEq)]
pub enum ClosurePrimitive<S: Space> {
    /// `p_a - p_b = 0` (2 or 3 rows).
    Coincident {
        /// Point on body a.
        a: Attachment<S>,
        /// Point on body b.
        b: Attachment<S>,
    },
    /// `n_a · (p_b - p_a) = 0`: point b stays on the plane (line) through point a normal to `normal_a` (1 row).
    OnPlane {
        /// Point on body a.
        a: Attachment<S>,
        /// Unit normal, fixed in body a.
        normal_a: S::Point,
        /// Point on body b.
        b: Attachment<S>,
    },
    /// `d_a · e_b = 0`: a direction fixed in a stays perpendicular to one fixed in b (1 row).
    Perpendicular {
        /// Body a (or ground).
        body_a: Option<usize>,
        /// Unit direction in body a.
        dir_a: S::Point,
        /// Body b (or ground).
        body_b: Option<usize>,
        /// Unit direction in body b.
        dir_b: S::Point,
    },
    /// Planar only: `θ_a - θ_b - offset = 0` (1 row).
    SameAngle {
        /// Body a (or ground).
        body_a: Option<usize>,
        /// Body b (or ground).
        body_b: Option<usize>,
        /// Relative orientation `R_b⁻¹ R_a` at assembly.
        offset: S::Rot,
    },
}

impl<S: Space> ClosurePrimitive<S> {
    /// Whether this primitive's rows are lengths (rather than angles or unit-free products).
    pub fn rows_are_lengths(&self) -> bool {
        matches!(self, ClosurePrimitive::Coincident { .. } | ClosurePrimitive::OnPlane { .. })
    }

    /// Number of closure equations (rows of W) this primitive contributes.
    pub fn rows(&self) -> usize {
        match self {
            ClosurePrimitive::Coincident { .. } => <S::Point as VecOps>::LEN,
            ClosurePrimitive::OnPlane { .. } | ClosurePrimitive::Perpendicular { .. } => 1,
            ClosurePrimitive::SameAngle { .. } => <S::Angular as VecOps>::LEN,
        }
    }
}

/// The relative motion a cut leaves free between its two bodies, which its spring, damper and range act on
/// (see `algorithms::cut_forces`). `relative` is `R_a⁻¹ R_b` at q0, the pose where angles are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CutFreedom<S: Space> {
    /// A weld: nothing moves.
    Locked,
    /// Point b slides along `axis_a` (unit, in body a) from point a: a length, m (planar slider).
    Slide {
        /// Point on body a.
        a: Attachment<S>,
        /// Point on body b.
        b: Attachment<S>,
        /// Unit slide direction in body a.
        axis_a: S::Point,
    },
    /// Body b turns about `axis_a` (unit, in body a; planar: z): an angle from q0, rad (pin, revolute).
    Hinge {
        /// Body a (or ground).
        body_a: Option<usize>,
        /// Body b (or ground).
        body_b: Option<usize>,
        /// Unit hinge axis in body a.
        axis_a: S::Point,
        /// `R_a⁻¹ R_b` at q0.
        relative: S::Rot,
    },
    /// Body b turns freely about point a: a rotation vector from q0, rad (spherical).
    Rotation {
        /// Body a (or ground).
        body_a: Option<usize>,
        /// Body b (or ground).
        body_b: Option<usize>,
        /// `R_a⁻¹ R_b` at q0.
        relative: S::Rot,
    },
}

/// A cut joint: a list of closure primitives occupying rows `row..row + rows` of h, W and w, and the
/// spring, damper and range acting on the freedom it leaves.
#[derive(Clone, Debug, PartialEq)]
pub struct Cut<S: Space> {
    /// Name from the scene.
    pub name: String,
    /// Kind from the scene.
    pub kind: CutKindSpec,
    /// Primitives.
    pub primitives: Vec<ClosurePrimitive<S>>,
    /// First row of this cut in h, W, w.
    pub row: usize,
    /// Number of rows.
    pub rows: usize,
    /// What the cut leaves free.
    pub freedom: CutFreedom<S>,
    /// Optional spring on the freedom.
    pub spring: Option<Spring>,
    /// Viscous damping on the freedom (0 when none).
    pub damping: f64,
    /// Optional range of the freedom (slides and hinges only).
    pub range: Option<Range>,
}

/// A named operational point.
#[derive(Clone, Debug, PartialEq)]
pub struct OpPoint<S: Space> {
    /// Name from the scene.
    pub name: String,
    /// Body index.
    pub body: usize,
    /// Position in the body frame.
    pub point: S::Point,
}

/// An obstacle, in world coordinates.
#[derive(Clone, Debug, PartialEq)]
pub enum Obstacle<S: Space> {
    /// `{x : normal·x ≥ offset}` is free.
    HalfSpace {
        /// Name from the scene.
        name: String,
        /// Unit normal into free space.
        normal: S::Point,
        /// Offset.
        offset: f64,
    },
    /// A solid ball (disc).
    Ball {
        /// Name from the scene.
        name: String,
        /// Centre.
        center: S::Point,
        /// Radius.
        radius: f64,
    },
}

/// A compiled linkage: immutable, shared by every algorithm.
#[derive(Clone, Debug, PartialEq)]
pub struct Model<S: Space> {
    /// Scene name.
    pub name: String,
    /// Bodies in topological order; body `i` is carried by joint `i`.
    pub bodies: Vec<Body<S>>,
    /// Tree joints; `joints[i].parent < i` (or [`NO_PARENT`]).
    pub joints: Vec<Joint<S>>,
    /// `chain_prefix[k]` is true when the ancestors of body k are exactly bodies `0..k` (lets the
    /// factorization use contiguous loops).
    pub chain_prefix: Vec<bool>,
    /// Number of bodies on the chain prefix: `chain_prefix[k]` exactly for `k < chain_prefix_len` (the
    /// ancestors of a chain-prefix body are on the chain prefix too, so these bodies come first).
    pub chain_prefix_len: usize,
    /// Cut joints.
    pub cuts: Vec<Cut<S>>,
    /// Total number of closure equations m.
    pub closure_rows: usize,
    /// Generic rank of the closure Jacobian W on the constraint manifold (m minus the redundant closures).
    pub closure_rank: usize,
    /// Per closure row, the weight that puts its entries of `S = W D⁻¹ Wᵀ` in common units: `1/L²` for a
    /// row in length (a point's coincidence, a point on a plane), 1 for a row in angle (a perpendicularity, a
    /// planar angle). The pivoted factorization of S chooses its rows by these (`dense::pivoted_cholesky`).
    pub closure_row_weights: Vec<f64>,
    /// Operational points.
    pub ops: Vec<OpPoint<S>>,
    /// Obstacles.
    pub obstacles: Vec<Obstacle<S>>,
    /// Gravity, m/s².
    pub gravity: S::Point,
    /// Baumgarte gains.
    pub baumgarte: Baumgarte,
    /// Contact parameters.
    pub contact: ContactParams,
    /// Characteristic length L (m) making rotations and translations commensurate.
    pub length_scale: f64,
    /// Initial configuration.
    pub q0: DVector<f64>,
    /// Initial velocity.
    pub qd0: DVector<f64>,
    /// True when some joint or cut has a spring.
    pub has_springs: bool,
    /// True when some joint has damping, an actuator or a range, or some cut has damping or a range.
    pub has_joint_forces: bool,
    /// True when gravity is non-zero.
    pub has_gravity: bool,
}

impl<S: Space> Model<S> {
    /// Number of configuration coordinates: one per revolute or prismatic joint, four per ball joint.
    pub fn nq(&self) -> usize {
        self.q0.len()
    }
    /// Number of velocity coordinates n (one per tree joint entry; three per ball joint): the size of D, W's
    /// columns, q̇ and q̈.
    pub fn nv(&self) -> usize {
        self.joints.len()
    }
    /// True when some joint is a ball joint (nq > nv: q moves on a manifold, see `integrator::integrate`).
    pub fn has_balls(&self) -> bool {
        self.nq() != self.nv()
    }
    /// True when body `i` is a ball joint's internal body (massless, no geometry, not in the scene file).
    pub fn is_internal_body(&self, i: usize) -> bool {
        matches!(self.joints[i].kind, JointKind::Ball { slot } if slot < 2)
    }
    /// Number of closure equations m.
    pub fn nc(&self) -> usize {
        self.closure_rows
    }
    /// Operational-space dimension (3 planar, 6 spatial).
    pub fn op_dim(&self) -> usize {
        S::DIM
    }
    /// Kind of the scene.
    pub fn kind(&self) -> SceneKind {
        S::KIND
    }
    /// True when the scene has loops (cut joints).
    pub fn has_loops(&self) -> bool {
        self.closure_rows > 0
    }
    /// Parent of body `i`, or `None` for ground.
    pub fn parent(&self, i: usize) -> Option<usize> {
        let p = self.joints[i].parent;
        (p != NO_PARENT).then_some(p)
    }
    /// Index of the operational point called `name`.
    pub fn op_index(&self, name: &str) -> Option<usize> {
        self.ops.iter().position(|o| o.name == name)
    }
    /// Index of the body called `name`.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }
    /// Total mass.
    pub fn total_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass).sum()
    }
    /// True when the tree is a single chain from ground (every body's parent is the previous body).
    pub fn is_chain(&self) -> bool {
        self.chain_prefix_len == self.joints.len()
    }
    /// True when `a` is an ancestor of `b` or `a == b`.
    pub fn supports(&self, a: usize, mut b: usize) -> bool {
        while b != NO_PARENT {
            if b == a {
                return true;
            }
            b = self.joints[b].parent;
        }
        false
    }

    /// Adds an operational point at run time (e.g. a user grabbing an arbitrary point).
    pub fn with_op(mut self, name: &str, body: usize, point: S::Point) -> Self {
        self.ops.push(OpPoint { name: name.to_string(), body, point });
        self
    }
}
