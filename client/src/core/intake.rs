//! Snapshot intake: a wire [`Snapshot`] (vectors) is checked and copied into fixed-size, preallocated terms
//! the tick can use without allocating. The checks are the wire's own (`validate::snapshot`: lengths,
//! finiteness and the protocol's ranges), then the core's stricter ones (its own bound on Λ̂⁻¹, non-negative diagonal, a pose it
//! can read). The codec already ran the wire's checks on network input; the core runs them again because
//! in-process callers hand it snapshots directly, and a corrupt term must never reach the device or the
//! uplink (a pose of 1e300 m accepted here once sent the local model, and the uplinks, off to 1e298 m).

use std::time::Duration;

use kinloop_linkage::math::space::{MatOps, Space, VecOps};
use kinloop_linkage::{
    algorithms::configuration::ConfigLayout,
    algorithms::local_model::{ConfigSpaceTerms, ContactTerm, MAX_LOCAL_CONTACTS},
    math::space::OpPose,
};
use kinloop_protocol::codec::{validate, DecodeError};
use kinloop_protocol::{ConfigTerms, SessionShape, Snapshot};

/// Why a snapshot was refused (no allocation: the wire's checks name fields by static paths).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SnapshotRejection {
    /// The wire's own checks refuse it (a length, a non-finite number, a value outside the protocol's range).
    #[error("snapshot refused by the wire's checks: {0}")]
    Wire(DecodeError),
    /// A field passes the wire's checks but not the core's stricter ones.
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
    /// Client clock of the uplink the VE had used (0: none).
    pub uplink_time_s: f64,
    /// The VE's clock at the state the snapshot describes (s).
    pub server_time_s: f64,
    /// Other manipulators hold the linkage (the snapshot counts them).
    pub shared: bool,
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
    /// Where q's ball joints sit (the welcome's), to check their quaternions.
    layout: ConfigLayout,
}

impl<S: Space> SnapshotTerms<S> {
    /// Empty terms; `config_shape` = `Some((layout, m))` preallocates configuration terms.
    pub fn new(config_shape: Option<&(ConfigLayout, usize)>) -> Self {
        SnapshotTerms {
            seq: 0,
            received_at: Duration::ZERO,
            uplink_time_s: 0.0,
            server_time_s: 0.0,
            shared: false,
            op_pose: OpPose::identity(),
            op_twist: S::OpVec::zero(),
            inverse_inertia: S::OpMat::zero(),
            bias: S::OpVec::zero(),
            directions: S::OpMat::identity(),
            singular_values: S::OpVec::zero(),
            constraint_count: 0,
            contacts: [ContactTerm::<S>::none(); MAX_LOCAL_CONTACTS],
            contact_count: 0,
            config: config_shape.map(|(l, m)| ConfigSpaceTerms::zeros_nq(l.nq(), l.nv(), *m, S::DIM)),
            layout: config_shape.map(|(l, _)| l.clone()).unwrap_or_default(),
            has_config: false,
        }
    }

    /// Checks `snap` and copies it in; on refusal `self` may be partly written and must not be used.
    pub fn fill_from(
        &mut self,
        snap: &Snapshot,
        shape: &SessionShape,
        received_at: Duration,
        max_inverse_inertia: f64,
        pose_memo: &mut S::RotParamsMemo,
    ) -> Result<(), SnapshotRejection> {
        validate::snapshot(snap, shape).map_err(SnapshotRejection::Wire)?;
        let k = S::DIM;
        self.op_pose = OpPose::from_slice_memo(&snap.op_pose, pose_memo)
            .ok_or(SnapshotRejection::Implausible { field: "op_pose" })?;
        self.op_twist = S::OpVec::from_slice(&snap.op_twist);
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
        self.bias = S::OpVec::from_slice(&snap.bias_accel);
        self.server_time_s = snap.server_time_s;
        self.directions.as_mut_slice().copy_from_slice(&snap.directions);
        self.singular_values = S::OpVec::from_slice(&snap.singular_values);
        self.constraint_count = snap.constraint_count;
        self.fill_contacts(snap);
        self.has_config = false;
        if let (Some(terms), Some(wire)) = (self.config.as_mut(), snap.config.as_ref()) {
            if self.layout.first_non_unit(&wire.q).is_some() {
                return Err(SnapshotRejection::Implausible { field: "snapshot.config.q" });
            }
            fill_config(terms, wire);
            self.has_config = true;
        }
        self.seq = snap.seq;
        self.received_at = received_at;
        self.uplink_time_s = snap.uplink_time_s;
        self.shared = snap.other_manipulators > 0;
        Ok(())
    }

    /// The nearest contacts (the server lists them nearest first) in the local model's convention: the gap
    /// is minus the penetration depth, the gap rate the separating normal velocity.
    fn fill_contacts(&mut self, snap: &Snapshot) {
        self.contact_count = snap.contacts.len().min(MAX_LOCAL_CONTACTS);
        for (slot, c) in self.contacts.iter_mut().zip(&snap.contacts) {
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
    }
}

/// Copies wire configuration terms, of the lengths the wire's checks found for the session, into
/// preallocated ones (mass matrix from its packed upper triangle).
fn fill_config(terms: &mut ConfigSpaceTerms, wire: &ConfigTerms) {
    let n = terms.qd.len();
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
}
