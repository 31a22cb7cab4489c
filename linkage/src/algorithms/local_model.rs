//! The local model of interaction (paper section V, Fig 3): a reduced simulation of the linkage that runs at
//! the haptic rate, between updates from the VE.
//!
//! Two forms, fed from the same VE state, give the same operational-point motion:
//! - [`ConfigSpaceLocalModel`], the paper's form (eq 11, 13): D̂, Ŵ, ŵ_stab, the generalized bias and Ĵ are
//!   frozen at the update and the KKT system is solved for q̈ in configuration space. Its cost grows with
//!   the number of links and loops.
//! - [`OpSpaceLocalModel`], the reduced operational-space form `ẍ = Λ̂⁻¹ F + b̂` (plus a coupling per nearby
//!   contact), whose size does not grow with the linkage.
//!
//! With the bias terms switched off ([`LocalModelTerms::paper`]) both reduce to the paper's eq 13,
//! `D̂ q̈ = J_hᵀ F_h - Ŵᵀ λ`.

use nalgebra::{DMatrix, DVector};

use crate::algorithms::configuration::ConfigLayout;
use crate::algorithms::jacobian::frame_velocity;
use crate::algorithms::kkt::RANK_TOLERANCE;
use crate::math::dense;
use crate::math::space::{MatOps, OpPose, Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// Which frozen terms the local model keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LocalModelTerms {
    /// Keep the bias: Coriolis, gravity, springs, joint forces, other users, the closure's velocity
    /// products and Baumgarte terms, J̇q̇ (eq 11 keeps Ĝ and ŵ_stab; eq 13 drops all of them).
    pub bias: bool,
}

impl LocalModelTerms {
    /// Everything the VE knows at the update.
    pub fn full() -> Self {
        LocalModelTerms { bias: true }
    }
    /// The paper's testbed approximation, eq 13: inertia and closure only.
    pub fn paper() -> Self {
        LocalModelTerms { bias: false }
    }
}

/// A nearby contact as the reduced local model sees it: everything along its normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactTerm<S: Space> {
    /// Contact normal (into free space), world frame.
    pub normal: S::Point,
    /// Signed gap along the normal (negative = penetration), m.
    pub gap: f64,
    /// Gap rate, m/s.
    pub gap_rate: f64,
    /// Effect of an OP wrench on the gap acceleration, and of a unit normal contact force on the OP
    /// acceleration: `Λ⁻¹_hc n` (symmetric coupling).
    pub coupling: S::OpVec,
    /// Gap acceleration per unit normal force, `nᵀ Λ⁻¹_cc n`.
    pub mobility: f64,
    /// Gap acceleration with no OP wrench and no contact force.
    pub bias: f64,
    /// Penalty stiffness, N/m.
    pub stiffness: f64,
    /// Penalty damping, N s/m.
    pub damping: f64,
}

impl<S: Space> ContactTerm<S> {
    /// A placeholder that pushes with no force (zero stiffness and damping), for fixed-size contact arrays.
    pub fn none() -> Self {
        ContactTerm {
            normal: S::Point::zero(),
            gap: 0.0,
            gap_rate: 0.0,
            coupling: S::OpVec::zero(),
            mobility: 0.0,
            bias: 0.0,
            stiffness: 0.0,
            damping: 0.0,
        }
    }

    /// The penalty force this contact pushes with now (≥ 0, along the normal).
    pub fn force(&self) -> f64 {
        if self.gap >= 0.0 {
            0.0
        } else {
            (-self.stiffness * self.gap - self.damping * self.gap_rate).max(0.0)
        }
    }
}

/// Most contacts a reduced local model tracks (the nearest ones).
pub const MAX_LOCAL_CONTACTS: usize = 8;

/// The frozen terms of the reduced form: `ẍ = Λ̂⁻¹ F + b̂`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpSpaceTerms<S: Space> {
    /// Λ̂⁻¹ with the loops closed.
    pub inverse_inertia: S::OpMat,
    /// b̂: the OP acceleration with no wrench from this user.
    pub bias: S::OpVec,
}

/// Reduced operational-space local model. Its state is the OP pose and twist; its step costs O(k²) for a
/// k-dimensional operational space, whatever the linkage.
#[derive(Clone, Debug, PartialEq)]
pub struct OpSpaceLocalModel<S: Space> {
    /// Frozen terms from the last update.
    pub terms: OpSpaceTerms<S>,
    /// Nearby contacts (first `contact_count` entries are live).
    pub contacts: [ContactTerm<S>; MAX_LOCAL_CONTACTS],
    /// Number of live contacts.
    pub contact_count: usize,
    /// OP pose.
    pub pose: OpPose<S>,
    /// OP twist (linear, angular).
    pub twist: S::OpVec,
}

impl<S: Space> OpSpaceLocalModel<S> {
    /// A model at `pose` and rest, with the given terms.
    pub fn new(terms: OpSpaceTerms<S>, pose: OpPose<S>) -> Self {
        let empty = ContactTerm::none();
        OpSpaceLocalModel {
            terms,
            contacts: [empty; MAX_LOCAL_CONTACTS],
            contact_count: 0,
            pose,
            twist: S::OpVec::zero(),
        }
    }

    /// The OP acceleration under `wrench` (and the live contacts' penalty forces) without stepping.
    pub fn acceleration(&self, wrench: &S::OpVec) -> S::OpVec {
        let mut acc = self.terms.inverse_inertia * *wrench + self.terms.bias;
        for c in &self.contacts[..self.contact_count] {
            acc += c.coupling * c.force();
        }
        acc
    }

    /// One semi-implicit Euler step of `dt` under the OP `wrench`; returns the acceleration used.
    pub fn step(&mut self, dt: f64, wrench: &S::OpVec) -> S::OpVec {
        let acc = self.acceleration(wrench);
        for i in 0..self.contact_count {
            let f = self.contacts[i].force();
            let c = &mut self.contacts[i];
            let gap_acc = c.coupling.dot(wrench) + c.mobility * f + c.bias;
            c.gap_rate += gap_acc * dt;
            c.gap += c.gap_rate * dt;
        }
        self.twist += acc * dt;
        self.pose.integrate(&self.twist, dt);
        acc
    }
}

/// Terms of the reduced form at operational point `op` from a solved VE state: `Λ̂⁻¹` from
/// `op_space_inertia`, and `b̂ = J q̈ + J̇q̇ - Λ̂⁻¹ F_user`, the OP acceleration the VE computed minus the part
/// due to this user's own wrench `user_wrench` (which the local model adds back itself).
/// Needs `forward_dynamics` (with the user's wrench applied) and `op_space_inertia(op)`.
pub fn op_space_terms<S: Space>(data: &Data<S>, user_wrench: &S::OpVec, terms: LocalModelTerms) -> OpSpaceTerms<S> {
    let ws = &data.op;
    let bias = if terms.bias { op_acceleration(data) - ws.inverse_inertia * *user_wrench } else { S::OpVec::zero() };
    OpSpaceTerms { inverse_inertia: ws.inverse_inertia, bias }
}

/// `J q̈ + J̇q̇`: the acceleration of the operational point of the last `op_space_inertia` under the solved
/// `q̈`, every applied force included. The part of [`op_space_terms`]' b̂ that does not depend on the user,
/// so users holding the same OP can share it.
pub fn op_acceleration<S: Space>(data: &Data<S>) -> S::OpVec {
    let ws = &data.op;
    let mut acc = ws.jdot_qdot;
    for c in 0..S::DIM {
        acc[c] += ws.jacobian_t.column(c).dot(&data.qdd);
    }
    acc
}

/// The frozen terms of the paper's configuration-space form (eq 11), as sent over the wire.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigSpaceTerms {
    /// q at the update.
    pub q: DVector<f64>,
    /// q̇ at the update.
    pub qd: DVector<f64>,
    /// D̂ (n×n).
    pub mass_matrix: DMatrix<f64>,
    /// Ŵ (m×n).
    pub closure_jacobian: DMatrix<f64>,
    /// ŵ_stab (m).
    pub closure_bias_stab: DVector<f64>,
    /// Everything on the right of eq 1 except this user's wrench, moved left: `B + G - τ_joints - τ_others`.
    pub generalized_bias: DVector<f64>,
    /// Ĵ_h (k×n), operational order.
    pub op_jacobian: DMatrix<f64>,
    /// J̇q̇ at the OP (k).
    pub op_bias: DVector<f64>,
}

impl ConfigSpaceTerms {
    /// Zeroed terms for n joints, m closure rows, k operational dimensions (nq = nv = n: no ball joints).
    pub fn zeros(n: usize, m: usize, k: usize) -> Self {
        Self::zeros_nq(n, n, m, k)
    }

    /// Zeroed terms for nq configuration and n velocity coordinates (ball joints: nq > n).
    pub fn zeros_nq(nq: usize, n: usize, m: usize, k: usize) -> Self {
        ConfigSpaceTerms {
            q: DVector::zeros(nq),
            qd: DVector::zeros(n),
            mass_matrix: DMatrix::zeros(n, n),
            closure_jacobian: DMatrix::zeros(m, n),
            closure_bias_stab: DVector::zeros(m),
            generalized_bias: DVector::zeros(n),
            op_jacobian: DMatrix::zeros(k, n),
            op_bias: DVector::zeros(k),
        }
    }

    /// Fills the terms at operational point `op` from a solved VE state (see [`op_space_terms`]);
    /// `user_wrench` is this user's wrench the VE applied at the OP. Needs `forward_dynamics` and
    /// `op_space_inertia(op)`; forms D when the dynamics have not (`mass_matrix::ensure`). Allocation-free
    /// when the sizes match.
    pub fn fill_from<S: Space>(
        &mut self,
        model: &Model<S>,
        data: &mut Data<S>,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        user_wrench: &S::OpVec,
        terms: LocalModelTerms,
    ) {
        self.q.copy_from(q);
        self.qd.copy_from(qd);
        crate::algorithms::mass_matrix::ensure(model, data);
        self.mass_matrix.copy_from(&data.mass_matrix);
        data.closure_jacobian_t.transpose_to(&mut self.closure_jacobian);
        data.op.jacobian_t.transpose_to(&mut self.op_jacobian);
        if terms.bias {
            self.closure_bias_stab.copy_from(&data.closure_bias_stab);
            for i in 0..model.nv() {
                self.generalized_bias[i] = data.bias[i] + data.gravity[i] - data.joint_force[i] - data.applied[i];
            }
            // The user's own wrench is part of `applied`; give it back (the local model applies it itself).
            self.generalized_bias.gemv(1.0, &data.op.jacobian_t, &as_column(user_wrench), 1.0);
            self.op_bias.copy_from_slice(data.op.jdot_qdot.as_slice());
        } else {
            self.closure_bias_stab.fill(0.0);
            self.generalized_bias.fill(0.0);
            self.op_bias.fill(0.0);
        }
    }
}

/// A small fixed vector seen as a dynamic column (no allocation), for products with dynamic matrices.
fn as_column<V: VecOps>(v: &V) -> nalgebra::DVectorView<'_, f64> {
    nalgebra::DVectorView::from_slice(v.as_slice(), V::LEN)
}

/// The paper's configuration-space local model (eq 11, 13). At each update it factors the frozen KKT
/// system once (dense Cholesky of D̂, rank-revealing Cholesky of Ŵ D̂⁻¹ Ŵᵀ) and precomputes
/// `q̈ = M F + c` with `M = P Ĵᵀ` and c the acceleration under no user wrench; each step is then O(n k).
/// All buffers are allocated at construction; updates and steps allocate nothing.
#[derive(Clone, Debug)]
pub struct ConfigSpaceLocalModel<S: Space> {
    layout: ConfigLayout,
    terms: ConfigSpaceTerms,
    factor: DMatrix<f64>,
    z: DMatrix<f64>,
    schur: DMatrix<f64>,
    schur_factor: DMatrix<f64>,
    schur_inv_diag: DVector<f64>,
    perm: Vec<usize>,
    rank: usize,
    response: DMatrix<f64>,
    free_accel: DVector<f64>,
    tmp_n: DVector<f64>,
    tmp_m: DVector<f64>,
    tmp_m2: DVector<f64>,
    /// Local joint positions (nq).
    pub q: DVector<f64>,
    /// Local joint velocities.
    pub qd: DVector<f64>,
    /// OP pose.
    pub pose: OpPose<S>,
    /// OP twist.
    pub twist: S::OpVec,
}

impl<S: Space> ConfigSpaceLocalModel<S> {
    /// Allocates for n joints and m closure rows.
    pub fn new(n: usize, m: usize) -> Self {
        Self::with_layout(ConfigLayout::flat(n), m)
    }

    /// Allocates for the configuration `layout` (ball joints: nq > n) and m closure rows; q moves by the
    /// VE's own configuration update (`ConfigLayout::integrate`).
    pub fn with_layout(layout: ConfigLayout, m: usize) -> Self {
        let (nq, n, k) = (layout.nq(), layout.nv(), S::DIM);
        ConfigSpaceLocalModel {
            layout,
            terms: ConfigSpaceTerms::zeros_nq(nq, n, m, k),
            factor: DMatrix::zeros(n, n),
            z: DMatrix::zeros(n, m),
            schur: DMatrix::zeros(m, m),
            schur_factor: DMatrix::zeros(m, m),
            schur_inv_diag: DVector::zeros(m),
            perm: (0..m).collect(),
            rank: 0,
            response: DMatrix::zeros(n, k),
            free_accel: DVector::zeros(n),
            tmp_n: DVector::zeros(n),
            tmp_m: DVector::zeros(m),
            tmp_m2: DVector::zeros(m),
            q: DVector::zeros(nq),
            qd: DVector::zeros(n),
            pose: OpPose::identity(),
            twist: S::OpVec::zero(),
        }
    }

    /// The frozen terms in use.
    pub fn terms(&self) -> &ConfigSpaceTerms {
        &self.terms
    }

    /// Takes new frozen terms and resets the local state to them (q, q̇ and the OP pose `pose`).
    /// Returns false (keeping the previous terms) if D̂ is not positive definite or sizes differ.
    pub fn update(&mut self, terms: &ConfigSpaceTerms, pose: OpPose<S>) -> bool {
        let (n, m) = (self.qd.len(), self.tmp_m.len());
        if terms.q.len() != self.q.len()
            || terms.qd.len() != n
            || terms.closure_bias_stab.len() != m
            || terms.op_bias.len() != S::DIM
        {
            return false;
        }
        self.factor.copy_from(&terms.mass_matrix);
        if !dense::cholesky_in_place(&mut self.factor) {
            return false;
        }
        self.terms.q.copy_from(&terms.q);
        self.terms.qd.copy_from(&terms.qd);
        self.terms.mass_matrix.copy_from(&terms.mass_matrix);
        self.terms.closure_jacobian.copy_from(&terms.closure_jacobian);
        self.terms.closure_bias_stab.copy_from(&terms.closure_bias_stab);
        self.terms.generalized_bias.copy_from(&terms.generalized_bias);
        self.terms.op_jacobian.copy_from(&terms.op_jacobian);
        self.terms.op_bias.copy_from(&terms.op_bias);
        // Z = L⁻¹ Wᵀ, S = Zᵀ Z.
        if m > 0 {
            self.terms.closure_jacobian.transpose_to(&mut self.z);
            for r in 0..m {
                dense::solve_lower(&self.factor, &mut self.z.as_mut_slice()[r * n..(r + 1) * n]);
            }
            self.z.tr_mul_to(&self.z, &mut self.schur);
            self.rank = dense::pivoted_cholesky(
                &self.schur,
                &mut self.schur_factor,
                &mut self.perm,
                &mut self.tmp_m,
                self.schur_inv_diag.as_mut_slice(),
                RANK_TOLERANCE,
                m,
                None,
            );
        }
        // Response to an OP wrench, column by column: M = P Ĵᵀ.
        for c in 0..S::DIM {
            for i in 0..n {
                self.tmp_n[i] = self.terms.op_jacobian[(c, i)];
            }
            self.constrained_solve(0.0);
            self.response.column_mut(c).copy_from(&self.tmp_n);
        }
        // Free acceleration: P (-bias) - D⁻¹ Wᵀ S⁺ w_stab.
        self.tmp_n.copy_from(&self.terms.generalized_bias);
        self.tmp_n.neg_mut();
        self.constrained_solve(1.0);
        self.free_accel.copy_from(&self.tmp_n);
        self.q.copy_from(&terms.q);
        self.qd.copy_from(&terms.qd);
        self.pose = pose;
        self.twist = self.op_velocity();
        true
    }

    /// `tmp_n ← q̈` solving `D̂ q̈ + Ŵᵀ λ = tmp_n`, `Ŵ q̈ = -closure_weight · ŵ_stab`.
    fn constrained_solve(&mut self, closure_weight: f64) {
        let n = self.qd.len();
        dense::solve_lower(&self.factor, self.tmp_n.as_mut_slice());
        if self.tmp_m.is_empty() {
            dense::solve_lower_t(&self.factor, self.tmp_n.as_mut_slice());
            return;
        }
        // With y = L⁻¹ τ: λ = S⁺ (Zᵀ y + w), q̈ = L⁻ᵀ (y - Z λ).
        self.tmp_m.gemv_tr(1.0, &self.z, &self.tmp_n, 0.0);
        self.tmp_m.axpy(closure_weight, &self.terms.closure_bias_stab, 1.0);
        let inv = self.schur_inv_diag.as_slice();
        dense::pivoted_solve(&self.schur_factor, inv, &self.perm, self.rank, &mut self.tmp_m, &mut self.tmp_m2);
        self.tmp_n.gemv(-1.0, &self.z, &self.tmp_m, 1.0);
        dense::solve_lower_t(&self.factor, &mut self.tmp_n.as_mut_slice()[..n]);
    }

    fn op_velocity(&self) -> S::OpVec {
        let mut v = S::OpVec::zero();
        for c in 0..S::DIM {
            v[c] = row_dot(&self.terms.op_jacobian, c, &self.qd);
        }
        v
    }

    /// One semi-implicit Euler step of `dt` under the OP `wrench`; returns the OP acceleration.
    pub fn step(&mut self, dt: f64, wrench: &S::OpVec) -> S::OpVec {
        // q̈ = M F + c; ẍ = Ĵ q̈ + J̇q̇.
        self.tmp_n.copy_from(&self.free_accel);
        self.tmp_n.gemv(1.0, &self.response, &as_column(wrench), 1.0);
        let mut acc = S::OpVec::zero();
        for c in 0..S::DIM {
            acc[c] = row_dot(&self.terms.op_jacobian, c, &self.tmp_n) + self.terms.op_bias[c];
        }
        self.qd.axpy(dt, &self.tmp_n, 1.0);
        // q ⊕ dt q̇: ball joints' quaternions turn on the sphere, exactly as the VE's q does.
        self.layout.integrate(self.q.as_mut_slice(), self.qd.as_slice(), dt);
        // The OP twist is integrated from ẍ (not recomputed as Ĵ q̇) so that the frozen J̇q̇ counts, exactly
        // as in the reduced form.
        self.twist += acc * dt;
        self.pose.integrate(&self.twist, dt);
        acc
    }

    /// The OP acceleration without any wrench, `Ĵ c + J̇q̇`: with [`Self::inverse_inertia`], what a step
    /// under a wrench `F` accelerates the OP by, `Ĵ c + J̇q̇ + Ĵ M F`, without stepping.
    pub fn free_op_acceleration(&self) -> S::OpVec {
        let mut acc = S::OpVec::zero();
        for c in 0..S::DIM {
            acc[c] = row_dot(&self.terms.op_jacobian, c, &self.free_accel) + self.terms.op_bias[c];
        }
        acc
    }

    /// Λ̂⁻¹ implied by the frozen terms (Ĵ M), for comparison with the reduced form.
    pub fn inverse_inertia(&self) -> S::OpMat {
        let mut out = S::OpMat::zero();
        for c in 0..S::DIM {
            for r in 0..S::DIM {
                out[(r, c)] =
                    self.terms.op_jacobian.row(r).iter().zip(self.response.column(c).iter()).map(|(a, b)| a * b).sum();
            }
        }
        out
    }
}

/// `Σ_j a[r, j] x[j]` without materializing the row.
fn row_dot(a: &DMatrix<f64>, r: usize, x: &DVector<f64>) -> f64 {
    a.row(r).iter().zip(x.iter()).map(|(a, b)| a * b).sum()
}

/// Operational velocity of `op` at the last `forward_velocity`.
pub fn op_twist<S: Space>(model: &Model<S>, data: &Data<S>, op: usize) -> S::OpVec {
    let o = &model.ops[op];
    let p = data.kin.body_pos[o.body] + S::rotate(&data.kin.body_rot[o.body], &o.point);
    frame_velocity(&data.kin, o.body, &p)
}
