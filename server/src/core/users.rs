//! Who is in the VE: identity, role, operational point, liveness and the per-user buffers allocated once at
//! join so that ticks and snapshots allocate nothing.

use std::time::Duration;

use kinloop_linkage::algorithms::local_model::{ConfigSpaceTerms, MAX_LOCAL_CONTACTS};
use kinloop_linkage::{math::space::Space, model::Model};
use kinloop_protocol::{
    ConfigTerms, ContactTerm, Datagram, DeviceCaps, Hello, Join, LocalModelForm, Mapping, MappingRequest, Role,
    Snapshot,
};

use super::fade::Fade;
use super::guards::WrenchLimits;
use super::passivity::PassivityObserver;

/// A user's id in the VE (also in welcomes and snapshots).
pub type UserId = u32;

/// What a client asks for when it joins.
#[derive(Clone, Debug, PartialEq)]
pub struct JoinRequest {
    /// Free-form name, for logs.
    pub name: String,
    /// Manipulator or observer.
    pub role: Role,
    /// Name of an operational point of the scene (several users may hold the same one); empty: the scene's
    /// first.
    pub op: String,
    /// Which local model the user's snapshots carry.
    pub form: LocalModelForm,
    /// The user's device, if it described one (its limits bound hand wrenches; with the OP's reach it sets
    /// the mapping and the coupling gains).
    pub device: Option<DeviceCaps>,
    /// What the user asked of the mapping.
    pub mapping: MappingRequest,
}

impl JoinRequest {
    /// The request a handshake's hello and join make.
    pub fn from_handshake(hello: &Hello, join: &Join) -> Self {
        JoinRequest {
            name: hello.client_name.clone(),
            role: hello.role,
            op: join.op.clone(),
            form: join.form,
            device: Some(join.device.clone()),
            mapping: join.mapping.clone(),
        }
    }
}

/// Whether a user is still in the session.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Presence {
    /// Joined; receives snapshots.
    Present,
    /// Left; its coupling fades out, then the user is removed.
    Leaving,
}

/// Start of a run of rejected uplinks, so it is reported once.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RejectionBurst {
    /// Rejections in the current burst.
    pub count: u64,
    /// Time of the last rejection.
    pub last_at: Option<Duration>,
}

/// Reusable storage of one user's snapshot. The snapshot lives inside a [`Datagram`] so a driver can encode
/// it without copying; the contact terms not in use wait in `spare_contacts` with their vectors allocated.
#[derive(Debug)]
pub struct SnapshotSlot {
    /// Always `Datagram::Snapshot`.
    pub message: Datagram,
    /// Contact terms with allocated vectors, not in the current snapshot.
    pub spare_contacts: Vec<ContactTerm>,
    /// Built and not yet polled.
    pub pending: bool,
    /// Configuration-space terms scratch, for `LocalModelForm::ConfigSpace`.
    pub config_scratch: Option<ConfigSpaceTerms>,
}

impl SnapshotSlot {
    /// Storage for a user of `model` with the given form.
    pub fn new<S: Space>(model: &Model<S>, user: UserId, form: LocalModelForm) -> Self {
        let (nq, n, m, k) = (model.nq(), model.nv(), model.nc(), S::DIM);
        let pose_len = kinloop_linkage::math::space::OpPose::<S>::wire_len();
        let point = <S::Point as kinloop_linkage::math::space::VecOps>::LEN;
        let config = (form == LocalModelForm::ConfigSpace).then(|| ConfigTerms {
            q: Vec::with_capacity(nq),
            qd: Vec::with_capacity(n),
            mass_matrix: Vec::with_capacity(n * (n + 1) / 2),
            closure_jacobian: Vec::with_capacity(m * n),
            closure_bias_stab: Vec::with_capacity(m),
            generalized_bias: Vec::with_capacity(n),
            op_jacobian: Vec::with_capacity(k * n),
            op_bias: Vec::with_capacity(k),
        });
        let snapshot = Snapshot {
            seq: 0,
            server_time_s: 0.0,
            ve_step: 0,
            user_id: user,
            uplink_time_s: 0.0,
            op_pose: Vec::with_capacity(pose_len),
            op_twist: Vec::with_capacity(k),
            inverse_inertia: Vec::with_capacity(k * (k + 1) / 2),
            bias_accel: Vec::with_capacity(k),
            directions: Vec::with_capacity(k * k),
            singular_values: Vec::with_capacity(k),
            constraint_count: 0,
            contacts: Vec::with_capacity(if model.obstacles.is_empty() { 0 } else { MAX_LOCAL_CONTACTS }),
            other_manipulators: 0,
            config,
            energy: kinloop_protocol::PortEnergy::zero(k),
        };
        let spare_contacts = if model.obstacles.is_empty() {
            Vec::new()
        } else {
            (0..MAX_LOCAL_CONTACTS)
                .map(|_| ContactTerm {
                    point: Vec::with_capacity(point),
                    normal: Vec::with_capacity(point),
                    depth: 0.0,
                    normal_velocity: 0.0,
                    op_coupling: Vec::with_capacity(k),
                    mobility: 0.0,
                    bias_accel: 0.0,
                    stiffness: 0.0,
                    damping: 0.0,
                })
                .collect()
        };
        SnapshotSlot {
            message: Datagram::Snapshot(snapshot),
            spare_contacts,
            pending: false,
            config_scratch: (form == LocalModelForm::ConfigSpace).then(|| ConfigSpaceTerms::zeros_nq(nq, n, m, k)),
        }
    }

    /// The snapshot.
    pub fn snapshot(&self) -> &Snapshot {
        match &self.message {
            Datagram::Snapshot(s) => s,
            // `message` is built as a snapshot and never replaced.
            Datagram::Uplink(_) => unreachable!("a snapshot slot holds a snapshot"),
        }
    }

    /// The snapshot, mutably.
    pub fn snapshot_mut(&mut self) -> &mut Snapshot {
        match &mut self.message {
            Datagram::Snapshot(s) => s,
            Datagram::Uplink(_) => unreachable!("a snapshot slot holds a snapshot"),
        }
    }
}

/// One user.
#[derive(Debug)]
pub struct User {
    /// Id.
    pub id: UserId,
    /// Name, for logs.
    pub name: String,
    /// Role.
    pub role: Role,
    /// Index of the operational point in the model.
    pub op: usize,
    /// Requested local-model form.
    pub form: LocalModelForm,
    /// Limits on the hand wrench (VE units: the device's rating divided by the mapping's scales).
    pub wrench_limits: WrenchLimits,
    /// The VE's per-user thresholds in the VE's units (see `device_side`).
    pub thresholds: super::device_side::UserThresholds,
    /// The mapping between the user's device and the VE.
    pub mapping: Mapping,
    /// Present or leaving.
    pub presence: Presence,
    /// Sequence number of the newest uplink used.
    pub last_seq: Option<u64>,
    /// When the newest uplink was used.
    pub last_uplink_at: Option<Duration>,
    /// Silent at the last tick (for reporting transitions).
    pub silent: bool,
    /// Coupling fade.
    pub fade: Fade,
    /// Passivity account.
    pub passivity: PassivityObserver,
    /// The newest uplink said no hand holds the device (`uplink_flags::HAND_OFF`).
    pub hand_off: bool,
    /// Its coupling fades out because its hand is off while another user's is on (see
    /// `VeCore::update_couplings`).
    pub let_go: bool,
    /// The network's round trip to this user (see `round_trip`).
    pub round_trip: super::round_trip::RoundTrip,
    /// The coupling's frequency as designed for the user's round trip, softened as it grows (see `design`);
    /// `None` when the gains are fixed (`VeConfig::coupling_stiffness`).
    pub coupling_frequency: Option<super::design::CouplingFrequency>,
    /// Current burst of rejected uplinks.
    pub rejections: RejectionBurst,
    /// Constraint count of the last snapshot.
    pub constraint_count: u8,
    /// Snapshot storage.
    pub slot: SnapshotSlot,
}

impl User {
    /// True when the user's newest uplink is older than `timeout` at `now` (or none came yet).
    pub fn is_silent(&self, now: Duration, timeout: Duration) -> bool {
        self.last_uplink_at.is_none_or(|at| now.saturating_sub(at) > timeout)
    }
}
