//! Snapshot intake: a wire [`Snapshot`] (vectors) is checked and copied into fixed-size, preallocated terms
//! the tick can use without allocating. The wire codec already validated the shape of network input; the
//! core checks again because in-process callers hand it snapshots directly, and a corrupt Λ̂⁻¹ must never
//! reach the device.

use std::time::Duration;

use kinloop_linkage::local_model::{ConfigSpaceTerms, ContactTerm, OpPose, MAX_LOCAL_CONTACTS};
use kinloop_linkage::space::{MatOps, Space, VecOps};
use kinloop_protocol::{ConfigTerms, Snapshot};

/// Why a snapshot was refused (no allocation: the field names are static).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SnapshotRejection {
    /// A field has the wrong length for the session.
    #[error("snapshot field {field} has the wrong length")]
    WrongLength {
        /// Which field.
        field: &'static str,
    },
    /// A field holds NaN or infinity.
    #[error("snapshot field {field} is not finite")]
    NonFinite {
        /// Which field.
        field: &'static str,
    },
    /// A field is finite but physically implausible.
    #[error("snapshot field {field} is implausible")]
    Implausible {
        /// Which field.
        field: &'static str,
    },
}

/// The terms of one snapshot, in the types the tick uses.
#[derive(Clone, Debug)]
pub(crate) struct SnapshotTerms<S: Space> {
    pub seq: u64,
    pub received_at: Duration,
    pub op_pose: OpPose<S>,
    pub op_twist: S::OpVec,
    /// Λ̂⁻¹ (physical units).
    pub inverse_inertia: S::OpMat,
    /// b̂.
    pub bias: S::OpVec,
    /// Û, columns in scaled coordinates, decreasing singular value.
    pub directions: S::OpMat,
    /// Σ̂ of the scaled Λ̃⁻¹.
    pub singular_values: S::OpVec,
    /// The server's count.
    pub constraint_count: u8,
    pub contacts: [ContactTerm<S>; MAX_LOCAL_CONTACTS],
    pub contact_count: usize,
    /// Present only when the session carries configuration terms and this snapshot had them.
    pub config: Option<ConfigSpaceTerms>,
    pub has_config: bool,
}

fn finite_of_len(field: &'static str, v: &[f64], len: usize) -> Result<(), SnapshotRejection> {
    if v.len() != len {
        return Err(SnapshotRejection::WrongLength { field });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(SnapshotRejection::NonFinite { field });
    }
    Ok(())
}

impl<S: Space> SnapshotTerms<S> {
    /// Empty terms; `config_shape` = `Some((n, m))` preallocates configuration terms.
    pub fn new(config_shape: Option<(usize, usize)>) -> Self {
        SnapshotTerms {
            seq: 0,
            received_at: Duration::ZERO,
            op_pose: OpPose::identity(),
            op_twist: S::OpVec::zero(),
            inverse_inertia: S::OpMat::zero(),
            bias: S::OpVec::zero(),
            directions: S::OpMat::identity(),
            singular_values: S::OpVec::zero(),
            constraint_count: 0,
            contacts: [ContactTerm::<S>::none(); MAX_LOCAL_CONTACTS],
            contact_count: 0,
            config: config_shape.map(|(n, m)| ConfigSpaceTerms::zeros(n, m, S::DIM)),
            has_config: false,
        }
    }

    /// Checks `snap` and copies it in; on refusal `self` may be partly written and must not be used.
    pub fn fill_from(
        &mut self,
        snap: &Snapshot,
        received_at: Duration,
        max_inverse_inertia: f64,
        pose_memo: &mut S::RotParamsMemo,
    ) -> Result<(), SnapshotRejection> {
        let k = S::DIM;
        finite_of_len("op_pose", &snap.op_pose, OpPose::<S>::wire_len())?;
        self.op_pose = OpPose::from_slice_memo(&snap.op_pose, pose_memo)
            .ok_or(SnapshotRejection::Implausible { field: "op_pose" })?;
        finite_of_len("op_twist", &snap.op_twist, k)?;
        self.op_twist = S::OpVec::from_slice(&snap.op_twist);
        finite_of_len("inverse_inertia", &snap.inverse_inertia, k * (k + 1) / 2)?;
        let mut index = 0;
        for r in 0..k {
            for c in r..k {
                let v = snap.inverse_inertia[index];
                index += 1;
                if v.abs() > max_inverse_inertia || (r == c && v < 0.0) {
                    return Err(SnapshotRejection::Implausible { field: "inverse_inertia" });
                }
                self.inverse_inertia[(r, c)] = v;
                self.inverse_inertia[(c, r)] = v;
            }
        }
        finite_of_len("bias_accel", &snap.bias_accel, k)?;
        self.bias = S::OpVec::from_slice(&snap.bias_accel);
        finite_of_len("directions", &snap.directions, k * k)?;
        self.directions.as_mut_slice().copy_from_slice(&snap.directions);
        finite_of_len("singular_values", &snap.singular_values, k)?;
        if snap.singular_values.iter().any(|s| *s < 0.0) {
            return Err(SnapshotRejection::Implausible { field: "singular_values" });
        }
        self.singular_values = S::OpVec::from_slice(&snap.singular_values);
        if usize::from(snap.constraint_count) > k {
            return Err(SnapshotRejection::Implausible { field: "constraint_count" });
        }
        self.constraint_count = snap.constraint_count;
        self.fill_contacts(snap)?;
        self.has_config = false;
        if let (Some(terms), Some(wire)) = (self.config.as_mut(), snap.config.as_ref()) {
            fill_config(terms, wire)?;
            self.has_config = true;
        }
        self.seq = snap.seq;
        self.received_at = received_at;
        Ok(())
    }

    /// The nearest contacts (the server lists them nearest first) in the local model's convention: the gap
    /// is minus the penetration depth, the gap rate the separating normal velocity.
    fn fill_contacts(&mut self, snap: &Snapshot) -> Result<(), SnapshotRejection> {
        let point_dim = <S::Point as VecOps>::LEN;
        self.contact_count = snap.contacts.len().min(MAX_LOCAL_CONTACTS);
        for (slot, c) in self.contacts.iter_mut().zip(&snap.contacts) {
            finite_of_len("contacts.normal", &c.normal, point_dim)?;
            finite_of_len("contacts.op_coupling", &c.op_coupling, S::DIM)?;
            let scalars = [c.depth, c.normal_velocity, c.mobility, c.bias_accel, c.stiffness, c.damping];
            if scalars.iter().any(|x| !x.is_finite()) {
                return Err(SnapshotRejection::NonFinite { field: "contacts" });
            }
            if c.stiffness < 0.0 || c.damping < 0.0 || c.mobility < 0.0 {
                return Err(SnapshotRejection::Implausible { field: "contacts" });
            }
            *slot = ContactTerm {
                normal: S::Point::from_slice(&c.normal),
                gap: -c.depth,
                gap_rate: c.normal_velocity,
                coupling: S::OpVec::from_slice(&c.op_coupling),
                mobility: c.mobility,
                bias: c.bias_accel,
                stiffness: c.stiffness,
                damping: c.damping,
            };
        }
        Ok(())
    }
}

/// Copies wire configuration terms into preallocated ones (mass matrix from its packed upper triangle).
fn fill_config(terms: &mut ConfigSpaceTerms, wire: &ConfigTerms) -> Result<(), SnapshotRejection> {
    let n = terms.q.len();
    let m = terms.closure_bias_stab.len();
    let k = terms.op_bias.len();
    finite_of_len("config.q", &wire.q, n)?;
    finite_of_len("config.qd", &wire.qd, n)?;
    finite_of_len("config.mass_matrix", &wire.mass_matrix, n * (n + 1) / 2)?;
    finite_of_len("config.closure_jacobian", &wire.closure_jacobian, m * n)?;
    finite_of_len("config.closure_bias_stab", &wire.closure_bias_stab, m)?;
    finite_of_len("config.generalized_bias", &wire.generalized_bias, n)?;
    finite_of_len("config.op_jacobian", &wire.op_jacobian, k * n)?;
    finite_of_len("config.op_bias", &wire.op_bias, k)?;
    terms.q.copy_from_slice(&wire.q);
    terms.qd.copy_from_slice(&wire.qd);
    let mut index = 0;
    for r in 0..n {
        for c in r..n {
            let v = wire.mass_matrix[index];
            index += 1;
            terms.mass_matrix[(r, c)] = v;
            terms.mass_matrix[(c, r)] = v;
        }
    }
    // nalgebra's dynamic matrices are column-major, as the wire is.
    terms.closure_jacobian.as_mut_slice().copy_from_slice(&wire.closure_jacobian);
    terms.closure_bias_stab.copy_from_slice(&wire.closure_bias_stab);
    terms.generalized_bias.copy_from_slice(&wire.generalized_bias);
    terms.op_jacobian.as_mut_slice().copy_from_slice(&wire.op_jacobian);
    terms.op_bias.copy_from_slice(&wire.op_bias);
    Ok(())
}
