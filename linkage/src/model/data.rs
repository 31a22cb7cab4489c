//! The [`Data`] workspace: every buffer the algorithms write, allocated once from a [`Model`].
//!
//! Algorithms take `(&Model, &mut Data)` and leave their results in named fields (`mass_matrix`,
//! `bias`, `closure_jacobian_t`, `qdd`, ...), so callers compose them without temporaries and the hot
//! paths allocate nothing.

use nalgebra::{DMatrix, DVector};

pub use crate::math::kkt_factors::KktWorkspace;
use crate::math::space::{MatOps, Space, VecOps};
use crate::math::trig::AnchoredSinCos;
use crate::model::{Attachment, Model};

/// Body poses, motion subspaces and velocities in the world frame.
#[derive(Clone, Debug)]
pub struct Kinematics<S: Space> {
    /// Orientation of each body frame.
    pub body_rot: Vec<S::Rot>,
    /// Origin of each body frame.
    pub body_pos: Vec<S::Point>,
    /// Centre of mass of each body.
    pub com: Vec<S::Point>,
    /// Motion subspace S_i of joint i (world frame, at the world origin).
    pub motion_subspace: Vec<S::Spatial>,
    /// Spatial inertia of each body about the world origin.
    pub body_inertia: Vec<S::Inertia>,
    /// Spatial velocity v_i of each body (world frame).
    pub body_velocity: Vec<S::Spatial>,
    /// The joint rates q̇ of the last `forward_velocity` (the armatures' kinetic energy needs them).
    pub joint_rate: Vec<f64>,
    /// Velocity-product spatial acceleration of each body: its acceleration when q̈ = 0.
    pub bias_acceleration: Vec<S::Spatial>,
    /// Per joint, sin and cos at the last anchor of its angle (see `trig::AnchoredSinCos`).
    pub(crate) sin_cos: Vec<AnchoredSinCos>,
}

impl<S: Space> Kinematics<S> {
    fn new(n: usize) -> Self {
        Kinematics {
            body_rot: vec![S::rot_identity(); n],
            body_pos: vec![S::Point::zero(); n],
            com: vec![S::Point::zero(); n],
            motion_subspace: vec![S::Spatial::zero(); n],
            body_inertia: vec![S::Inertia::zero(); n],
            body_velocity: vec![S::Spatial::zero(); n],
            joint_rate: vec![0.0; n],
            bias_acceleration: vec![S::Spatial::zero(); n],
            sin_cos: vec![AnchoredSinCos::default(); n],
        }
    }

    /// Orientation of a body (identity for ground).
    pub fn rot(&self, body: Option<usize>) -> S::Rot {
        body.map_or_else(S::rot_identity, |b| self.body_rot[b])
    }

    /// World position of an attached point.
    pub fn point(&self, a: &Attachment<S>) -> S::Point {
        match a.body {
            None => a.point,
            Some(b) => self.body_pos[b] + S::rotate(&self.body_rot[b], &a.point),
        }
    }

    /// A body-fixed direction in world axes.
    pub fn direction(&self, body: Option<usize>, d: &S::Point) -> S::Point {
        match body {
            None => *d,
            Some(b) => S::rotate(&self.body_rot[b], d),
        }
    }

    /// Spatial velocity of a body (zero for ground).
    pub fn velocity(&self, body: Option<usize>) -> S::Spatial {
        body.map_or_else(S::Spatial::zero, |b| self.body_velocity[b])
    }

    /// Velocity-product spatial acceleration of a body (zero for ground).
    pub fn bias_accel(&self, body: Option<usize>) -> S::Spatial {
        body.map_or_else(S::Spatial::zero, |b| self.bias_acceleration[b])
    }

    /// Classical velocity of the body-fixed point currently at world position `p`.
    pub fn point_velocity(&self, body: Option<usize>, p: &S::Point) -> S::Point {
        let v = self.velocity(body);
        S::spatial_lin(&v) + S::ang_cross_point(&S::spatial_ang(&v), p)
    }

    /// Classical acceleration, with q̈ = 0, of the body-fixed point at world position `p`
    /// (this is J̇ q̇ for that point).
    pub fn point_bias_acceleration(&self, body: Option<usize>, p: &S::Point) -> S::Point {
        let a = self.bias_accel(body);
        let w = S::spatial_ang(&self.velocity(body));
        let vp = self.point_velocity(body, p);
        S::spatial_lin(&a) + S::ang_cross_point(&S::spatial_ang(&a), p) + S::ang_cross_point(&w, &vp)
    }
}

/// Operational-space quantities for one operational point.
#[derive(Clone, Debug)]
pub struct OpSpaceWorkspace<S: Space> {
    /// Jᵀ at the OP, n×k (columns in op order: linear then angular).
    pub jacobian_t: DMatrix<f64>,
    /// Y = U⁻¹ Jᵀ, n×k.
    pub y: DMatrix<f64>,
    /// `Q = Z_r R⁻ᵀ`: an orthonormal basis of the kept closures' directions (see `op_space`), n×m (the
    /// first `schur_rank` columns are valid).
    pub closure_basis: DMatrix<f64>,
    /// Ỹ = Y with the kept closures' directions projected out (see `op_space`), n×k: `Λ⁻¹ = Ỹᵀ Ỹ` and,
    /// for another point on the linkage, the closed-loop coupling `Ỹᵀ Ỹ'`. Equal to Y without loops.
    pub y_closed: DMatrix<f64>,
    /// J̇ q̇ at the OP (op order).
    pub jdot_qdot: S::OpVec,
    /// Λ⁻¹ with the loops closed (eq 9).
    pub inverse_inertia: S::OpMat,
}

/// Scratch for the integrators.
#[derive(Clone, Debug)]
pub struct IntegratorWorkspace {
    /// Saved configuration at the start of a step.
    pub q_start: DVector<f64>,
    /// Saved velocity at the start of a step.
    pub qd_start: DVector<f64>,
    /// RK4 stage rates of q in the tangent space at the step's start (q̇ itself but for ball joints, whose
    /// entries are the rotation vector's rate, see `integrator`), nv each.
    pub k_q: [DVector<f64>; 4],
    /// RK4 stage accelerations.
    pub k_qd: [DVector<f64>; 4],
    /// Scratch configuration.
    pub q_stage: DVector<f64>,
    /// Scratch velocity.
    pub qd_stage: DVector<f64>,
    /// Scratch tangent displacement (nv) for models with ball joints: a correction or step in velocity
    /// coordinates, applied to q by `integrator::integrate`.
    pub dq: DVector<f64>,
}

/// Everything the algorithms compute, preallocated.
#[derive(Clone, Debug)]
pub struct Data<S: Space> {
    /// Poses, subspaces and velocities.
    pub kin: Kinematics<S>,
    /// Composite (subtree) spatial inertias, world frame.
    pub composite_inertia: Vec<S::Inertia>,
    /// Articulated-body inertias, world frame (scratch of `articulated::factor`).
    pub articulated_inertia: Vec<S::Inertia>,
    /// Per-body spatial forces (scratch of the recursive algorithms).
    pub body_force: Vec<S::Spatial>,
    /// D(q), the joint-space mass matrix, n×n symmetric, written by `mass_matrix` (the forward dynamics
    /// factors D without forming it, see `articulated`; `mass_matrix::ensure` fills it when stale).
    pub mass_matrix: DMatrix<f64>,
    /// True when `mass_matrix` belongs to the current kinematics.
    pub(crate) mass_matrix_fresh: bool,
    /// Form D in every dynamics evaluation, and factor it, rather than factor D from the articulated
    /// inertias without forming it: for callers that need D at every state anyway (the VE server adds its
    /// couplings' implicit mass to it, and its snapshot probe and next step share one state). False by default.
    pub keep_mass_matrix: bool,
    /// B(q, q̇), Coriolis and centripetal generalized forces.
    pub bias: DVector<f64>,
    /// G(q), gravity and joint springs (the paper's "joint flexibility and gravitational effects").
    pub gravity: DVector<f64>,
    /// Joint damping and actuator forces (on the right-hand side of eq 1).
    pub joint_force: DVector<f64>,
    /// Applied generalized forces on the right-hand side: Σ Jᵢᵀ Fᵢ + J_hᵀ F_h (filled by the caller).
    pub applied: DVector<f64>,
    /// Extra symmetric matrix added to D in the KKT solve (linearly-implicit couplings), n×n.
    pub implicit_mass: DMatrix<f64>,
    /// True when `implicit_mass` holds something to add.
    pub use_implicit_mass: bool,
    /// h(q), the closure residual, m.
    pub closure_residual: DVector<f64>,
    /// Wᵀ = (∂h/∂q)ᵀ, n×m (stored transposed so each closure row is contiguous).
    pub closure_jacobian_t: DMatrix<f64>,
    /// w = Ẇ q̇, m.
    pub closure_bias: DVector<f64>,
    /// w_stab = w + 2αβ W q̇ + α² h (eq 3), m.
    pub closure_bias_stab: DVector<f64>,
    /// KKT factors.
    pub kkt: KktWorkspace,
    /// q̈ from the last solve.
    pub qdd: DVector<f64>,
    /// λ from the last solve.
    pub lambda: DVector<f64>,
    /// Operational-space workspace (one OP at a time).
    pub op: OpSpaceWorkspace<S>,
    /// Integrator scratch.
    pub integ: IntegratorWorkspace,
    /// The state at which the position- and velocity-dependent terms above were last evaluated.
    pub(crate) terms_at: TermsMemo,
    /// The configuration at which `forward_poses` last evaluated the body poses and motion subspaces in
    /// `kin`: the projection after a step evaluates them at the q it returns, and the next step's kinematics,
    /// at that same q, reuse them.
    pub(crate) poses_at: BitsMemo,
}

/// A vector remembered bit for bit, or nothing: `holds(x)` is true when `x` is exactly what was last
/// recorded and nothing cleared it since.
#[derive(Clone, Debug)]
pub(crate) struct BitsMemo {
    values: DVector<f64>,
    valid: bool,
}

impl BitsMemo {
    fn new(len: usize) -> Self {
        BitsMemo { values: DVector::zeros(len), valid: false }
    }

    /// True when `x` is bit for bit what was recorded, and nothing has cleared it since.
    pub(crate) fn holds(&self, x: &DVector<f64>) -> bool {
        // On slices: nalgebra's element iterators cost several times more per entry. A miss usually differs
        // in the first entry, so it costs one comparison.
        self.valid
            && self.values.len() == x.len()
            && self.values.as_slice().iter().zip(x.as_slice()).all(|(a, b)| a.to_bits() == b.to_bits())
    }

    /// Records `x`.
    pub(crate) fn record(&mut self, x: &DVector<f64>) {
        crate::math::dense::copy(self.values.as_mut_slice(), x.as_slice());
        self.valid = true;
    }

    /// Forgets what was recorded.
    pub(crate) fn clear(&mut self) {
        self.valid = false;
    }
}

/// The state `(q, q̇)` at which `dynamics_terms` last evaluated everything but the applied forces, so that
/// an evaluation at the same state (the VE server's next step, at the state its snapshots just probed)
/// recomputes only the forces. Exact: a hit needs the very same bits, and every call of `forward_poses` (one
/// that keeps the poses of the same q included) or `forward_velocity` clears it.
#[derive(Clone, Debug)]
pub(crate) struct TermsMemo {
    q: BitsMemo,
    qd: BitsMemo,
}

impl TermsMemo {
    fn new(nq: usize, nv: usize) -> Self {
        TermsMemo { q: BitsMemo::new(nq), qd: BitsMemo::new(nv) }
    }

    /// True when the terms were evaluated at exactly `(q, q̇)` and nothing has touched them since.
    pub(crate) fn holds(&self, q: &DVector<f64>, qd: &DVector<f64>) -> bool {
        self.q.holds(q) && self.qd.holds(qd)
    }

    /// Records that the terms now belong to `(q, q̇)`.
    pub(crate) fn record(&mut self, q: &DVector<f64>, qd: &DVector<f64>) {
        self.q.record(q);
        self.qd.record(qd);
    }

    /// Forgets the state: the kinematics are being changed.
    pub(crate) fn clear(&mut self) {
        self.q.clear();
        self.qd.clear();
    }
}

impl<S: Space> Data<S> {
    /// Allocates every buffer for `model`.
    pub fn new(model: &Model<S>) -> Self {
        let n = model.nv();
        let nq = model.nq();
        let m = model.nc();
        let k = S::DIM;
        Data {
            kin: Kinematics::new(n),
            composite_inertia: vec![S::Inertia::zero(); n],
            articulated_inertia: vec![S::Inertia::zero(); n],
            body_force: vec![S::Spatial::zero(); n],
            mass_matrix: DMatrix::zeros(n, n),
            mass_matrix_fresh: false,
            keep_mass_matrix: false,
            bias: DVector::zeros(n),
            gravity: DVector::zeros(n),
            joint_force: DVector::zeros(n),
            applied: DVector::zeros(n),
            implicit_mass: DMatrix::zeros(n, n),
            use_implicit_mass: false,
            terms_at: TermsMemo::new(nq, n),
            poses_at: BitsMemo::new(nq),
            closure_residual: DVector::zeros(m),
            closure_jacobian_t: DMatrix::zeros(n, m),
            closure_bias: DVector::zeros(m),
            closure_bias_stab: DVector::zeros(m),
            kkt: KktWorkspace::new(n, m),
            qdd: DVector::zeros(n),
            lambda: DVector::zeros(m),
            op: OpSpaceWorkspace {
                jacobian_t: DMatrix::zeros(n, k),
                y: DMatrix::zeros(n, k),
                closure_basis: DMatrix::zeros(n, m),
                y_closed: DMatrix::zeros(n, k),
                jdot_qdot: S::OpVec::zero(),
                inverse_inertia: S::OpMat::zero(),
            },
            integ: IntegratorWorkspace {
                q_start: DVector::zeros(nq),
                qd_start: DVector::zeros(n),
                k_q: std::array::from_fn(|_| DVector::zeros(n)),
                k_qd: std::array::from_fn(|_| DVector::zeros(n)),
                q_stage: DVector::zeros(nq),
                qd_stage: DVector::zeros(n),
                dq: DVector::zeros(n),
            },
        }
    }

    /// The closure Jacobian W (m×n); allocates, for inspection and tests.
    pub fn closure_jacobian(&self) -> DMatrix<f64> {
        self.closure_jacobian_t.transpose()
    }
}
