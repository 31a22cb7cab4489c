//! Rules a decoded message must satisfy before anyone acts on it: finite numbers, lengths that match the
//! session, magnitudes no real linkage or device produces only when something is broken or hostile.

use super::error::{DecodeError, Field};
use super::limits::*;
use crate::messages::{
    uplink_flags, AdminAnswer, AdminCommand, AdminRequest, ConfigTerms, ContactTerm, Control, CouplingGains, Datagram,
    DeviceCaps, Hello, Join, Mapping, MappingRequest, OpSummary, PathShape, PortEnergy, RefusalReason, Refused,
    ResumeAnswer, ResumeRefusal, RoomState, SceneInfo, SceneSummary, Snapshot, Uplink, Welcome, MAX_PATH_POSES,
};
use crate::shape::{triangle_len, SceneKind, SessionShape};
use kinloop_linkage::algorithms::configuration::ConfigLayout;

/// Checks a control message; control messages carry their own dimensions, so no session shape is needed.
pub fn control(msg: &Control) -> Result<(), DecodeError> {
    match msg {
        Control::Hello(hello) => self::hello(hello),
        Control::Welcome(welcome) => self::welcome(welcome),
        Control::Refused(refused) => self::refused(refused),
        Control::Leave { reason } => text(Field::at("leave.reason"), reason),
        Control::Error { message, .. } => text(Field::at("error.message"), message),
        Control::Ping { t_s, .. } => scalar(Field::at("ping.t_s"), *t_s, 0.0, MAX_TIME_S),
        Control::Pong { t_s, .. } => scalar(Field::at("pong.t_s"), *t_s, 0.0, MAX_TIME_S),
        Control::SceneInfo(info) => self::scene_info(info),
        Control::Join(join) => self::join(join),
        Control::RoomState(state) | Control::Resume(state) => self::room_state(state),
        Control::ResumeAnswer(answer) => self::resume_answer(answer),
        Control::Admin(request) => self::admin_request(request),
        Control::AdminAnswer(answer) => self::admin_answer(answer),
    }
}

/// Checks a datagram against the session it arrived on.
pub fn datagram(msg: &Datagram, shape: &SessionShape) -> Result<(), DecodeError> {
    match msg {
        Datagram::Snapshot(s) => snapshot(s, shape),
        Datagram::Uplink(u) => uplink(u, shape),
    }
}

/// Checks a hello. Any version passes, so that the server can answer an old client with a polite refusal.
pub fn hello(h: &Hello) -> Result<(), DecodeError> {
    text(Field::at("hello.token"), &h.token)?;
    text(Field::at("hello.client_name"), &h.client_name)?;
    text(Field::at("hello.room"), &h.room)
}

/// Checks an admin request's texts.
fn admin_request(r: &AdminRequest) -> Result<(), DecodeError> {
    text(Field::at("admin.token"), &r.token)?;
    match &r.command {
        AdminCommand::CreateRoom { name, scene, token_file, .. } => {
            text(Field::at("admin.command.name"), name)?;
            text(Field::at("admin.command.scene"), scene)?;
            text(Field::at("admin.command.token_file"), token_file)
        }
        AdminCommand::RemoveRoom { name } => text(Field::at("admin.command.name"), name),
        AdminCommand::ListRooms => Ok(()),
    }
}

/// Checks an admin answer: texts, a bounded list, finite costs.
fn admin_answer(a: &AdminAnswer) -> Result<(), DecodeError> {
    match a {
        AdminAnswer::Refused { what } => text(Field::at("admin_answer.what"), what),
        AdminAnswer::Done { rooms } => {
            count(Field::at("admin_answer.rooms"), rooms.len(), MAX_LIST_ENTRIES)?;
            for (i, room) in rooms.iter().enumerate() {
                text(Field::in_item("admin_answer.rooms", i, "name"), &room.name)?;
                text(Field::in_item("admin_answer.rooms", i, "scene"), &room.scene)?;
                scalar(Field::in_item("admin_answer.rooms", i, "cost_us"), room.cost_us, 0.0, MAX_TIME_S * 1e6)?;
            }
            Ok(())
        }
    }
}

/// Checks a scene info.
pub fn scene_info(info: &SceneInfo) -> Result<(), DecodeError> {
    text(Field::at("scene_info.name"), &info.name)?;
    count(Field::at("scene_info.ops"), info.ops.len(), MAX_LIST_ENTRIES)?;
    for (i, name) in info.ops.iter().enumerate() {
        text(Field::in_item("scene_info.ops", i, "name"), name)?;
    }
    Ok(())
}

/// Checks a join: the device's numbers and the mapping asked for. Whether the device's axes fit the scene
/// is the server's decision (it knows the scene), not the codec's.
pub fn join(j: &Join) -> Result<(), DecodeError> {
    text(Field::at("join.op"), &j.op)?;
    device(&j.device)?;
    mapping_request(&j.mapping)
}

/// Checks a device description's numbers (also for callers that join without the wire).
pub fn device(d: &DeviceCaps) -> Result<(), DecodeError> {
    text(Field::at("join.device.name"), &d.name)?;
    if usize::from(d.dof) > MAX_DEVICE_DOF {
        return Err(DecodeError::TooMany {
            field: Field::at("join.device.dof"),
            got: d.dof.into(),
            max: MAX_DEVICE_DOF,
        });
    }
    let min_field = Field::at("join.device.workspace_min");
    let axes = d.workspace_min.len();
    count(min_field, axes, MAX_OP_DIM)?;
    vector(min_field, &d.workspace_min, axes, MAX_POSITION)?;
    vector(Field::at("join.device.workspace_max"), &d.workspace_max, axes, MAX_POSITION)?;
    if d.workspace_min.iter().zip(&d.workspace_max).any(|(lo, hi)| lo > hi) {
        return Err(DecodeError::Inconsistent { field: min_field, what: "workspace_min exceeds workspace_max" });
    }
    non_negative_vector(Field::at("join.device.damping"), &d.damping, axes, MAX_GAIN)?;
    vector(Field::at("join.device.mass"), &d.mass, axes, MAX_GAIN)?;
    if d.mass.iter().any(|m| m.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
        return Err(DecodeError::Inconsistent {
            field: Field::at("join.device.mass"),
            what: "masses must be positive",
        });
    }
    scalar(Field::at("join.device.max_force_n"), d.max_force_n, 0.0, MAX_WRENCH)?;
    scalar(Field::at("join.device.continuous_force_n"), d.continuous_force_n, 0.0, d.max_force_n)?;
    scalar(Field::at("join.device.max_torque_nm"), d.max_torque_nm, 0.0, MAX_WRENCH)?;
    scalar(Field::at("join.device.max_stiffness_n_per_m"), d.max_stiffness_n_per_m, 0.0, MAX_GAIN)?;
    scalar(Field::at("join.device.max_damping_ns_per_m"), d.max_damping_ns_per_m, 0.0, MAX_GAIN)?;
    scalar(
        Field::at("join.device.max_angular_stiffness_nm_per_rad"),
        d.max_angular_stiffness_nm_per_rad,
        0.0,
        MAX_GAIN,
    )?;
    scalar(Field::at("join.device.max_angular_damping_nms_per_rad"), d.max_angular_damping_nms_per_rad, 0.0, MAX_GAIN)?;
    scalar(Field::at("join.device.native_rate_hz"), d.native_rate_hz, MIN_RATE_HZ, MAX_RATE_HZ)
}

/// Checks the scales a join asks for (also for callers that join without the wire).
pub fn mapping_request(m: &MappingRequest) -> Result<(), DecodeError> {
    for (field, scale) in [
        (Field::at("join.mapping.position_scale"), m.position_scale),
        (Field::at("join.mapping.force_scale"), m.force_scale),
    ] {
        if let Some(value) = scale {
            scalar(field, value, MIN_MAPPING_SCALE, MAX_MAPPING_SCALE)?;
        }
    }
    Ok(())
}

/// Checks a welcome; its scene summary becomes the session shape, so it must be self-consistent.
pub fn welcome(w: &Welcome) -> Result<(), DecodeError> {
    scene(&w.scene)?;
    scalar(Field::at("welcome.ve_rate_hz"), w.ve_rate_hz, MIN_RATE_HZ, MAX_RATE_HZ)?;
    scalar(Field::at("welcome.snapshot_rate_hz"), w.snapshot_rate_hz, MIN_RATE_HZ, MAX_RATE_HZ)?;
    mapping(&w.mapping)?;
    let k = w.scene.kind.op_dim();
    coupling(&w.coupling, k)?;
    op_summary(&w.op, &w.scene.shape())
}

fn scene(s: &SceneSummary) -> Result<(), DecodeError> {
    text(Field::at("welcome.scene.name"), &s.name)?;
    text(Field::at("welcome.scene.op_name"), &s.op_name)?;
    scalar(Field::at("welcome.scene.length_scale"), s.length_scale, 1e-9, MAX_SCENE_POSITION)?;
    count(Field::at("welcome.scene.n"), s.n as usize, MAX_COORDINATES)?;
    count(Field::at("welcome.scene.m"), s.m as usize, MAX_CLOSURE_ROWS)?;
    let field = Field::at("welcome.scene.ball_rates");
    if s.kind == SceneKind::Planar && !s.ball_rates.is_empty() {
        return Err(DecodeError::Inconsistent { field, what: "a planar scene has no ball joints" });
    }
    let rates = s.ball_rates.iter().map(|&r| r as usize).collect();
    if ConfigLayout::new(s.n as usize, rates).is_err() {
        return Err(DecodeError::Inconsistent {
            field,
            what: "each ball joint's three rates must fit in n, after the previous ball's",
        });
    }
    if usize::from(s.op_dim) != s.kind.op_dim() {
        return Err(DecodeError::Inconsistent {
            field: Field::at("welcome.scene.op_dim"),
            what: "op_dim must be 3 for planar scenes and 6 for spatial ones",
        });
    }
    Ok(())
}

fn mapping(m: &Mapping) -> Result<(), DecodeError> {
    scalar(Field::at("welcome.mapping.position_scale"), m.position_scale, MIN_MAPPING_SCALE, MAX_MAPPING_SCALE)?;
    scalar(Field::at("welcome.mapping.force_scale"), m.force_scale, MIN_MAPPING_SCALE, MAX_MAPPING_SCALE)
}

fn coupling(g: &CouplingGains, k: usize) -> Result<(), DecodeError> {
    non_negative_vector(Field::at("welcome.coupling.stiffness"), &g.stiffness, k, MAX_SCENE_GAIN)?;
    non_negative_vector(Field::at("welcome.coupling.damping"), &g.damping, k, MAX_SCENE_GAIN)
}

fn op_summary(o: &OpSummary, shape: &SessionShape) -> Result<(), DecodeError> {
    let kind = shape.kind;
    let d = kind.point_dim();
    vector(Field::at("welcome.op.position"), &o.position, d, MAX_SCENE_POSITION)?;
    vector(Field::at("welcome.op.reach_min"), &o.reach_min, d, MAX_SCENE_POSITION)?;
    vector(Field::at("welcome.op.reach_max"), &o.reach_max, d, MAX_SCENE_POSITION)?;
    if o.reach_min.iter().zip(&o.reach_max).any(|(lo, hi)| lo > hi) {
        return Err(DecodeError::Inconsistent {
            field: Field::at("welcome.op.reach_min"),
            what: "reach_min exceeds reach_max",
        });
    }
    let k = kind.op_dim();
    let points = o.tour.len() / k;
    count(Field::at("welcome.op.tour"), points, MAX_LIST_ENTRIES)?;
    vector(Field::at("welcome.op.tour"), &o.tour, points * k, MAX_SCENE_POSITION)?;
    scalar(Field::at("welcome.op.static_force_n"), o.static_force_n, 0.0, MAX_SCENE_WRENCH)?;
    scalar(Field::at("welcome.op.static_torque_nm"), o.static_torque_nm, 0.0, MAX_SCENE_WRENCH)?;
    scalar(Field::at("welcome.op.inverse_mass_max"), o.inverse_mass_max, 0.0, MAX_SCENE_INVERSE_INERTIA)?;
    scalar(
        Field::at("welcome.op.inverse_rotational_inertia_max"),
        o.inverse_rotational_inertia_max,
        0.0,
        MAX_SCENE_INVERSE_INERTIA,
    )?;
    let poses = o.path.len() / shape.pose_dim();
    count(Field::at("welcome.op.path"), poses, MAX_PATH_POSES)?;
    length(Field::at("welcome.op.path"), o.path.len(), poses * shape.pose_dim())?;
    for (i, p) in o.path.chunks(shape.pose_dim()).enumerate() {
        pose(Field::in_item("welcome.op.path", i, "pose"), p, shape)?;
    }
    let rest = Field::at("welcome.op.path_rest_acceleration");
    match (&o.path_rest_acceleration, o.path_shape) {
        (None, _) => Ok(()),
        // A swing's pose is two configurations: no acceleration at rest per pose.
        (Some(a), PathShape::Swing) => length(rest, a.len(), 0),
        (Some(a), _) => vector(rest, a, poses, MAX_SCENE_ACCEL),
    }
}

fn refused(r: &Refused) -> Result<(), DecodeError> {
    text(Field::at("refused.message"), &r.message)?;
    match &r.reason {
        RefusalReason::UnknownOp { requested, available } | RefusalReason::UnknownRoom { requested, available } => {
            text(Field::at("refused.reason.requested"), requested)?;
            count(Field::at("refused.reason.available"), available.len(), MAX_LIST_ENTRIES)?;
            for (i, name) in available.iter().enumerate() {
                text(Field::in_item("refused.reason.available", i, "name"), name)?;
            }
            Ok(())
        }
        RefusalReason::Malformed { what } => text(Field::at("refused.reason.what"), what),
        RefusalReason::Device { what } => text(Field::at("refused.reason.what"), what),
        RefusalReason::Unservable { what } | RefusalReason::OverBudget { what } => {
            text(Field::at("refused.reason.what"), what)
        }
        RefusalReason::UnsupportedVersion { .. }
        | RefusalReason::BadToken
        | RefusalReason::ServerFull { .. }
        | RefusalReason::RoleNotAllowed => Ok(()),
    }
}

/// Checks a snapshot against the session shape: [`snapshot_user_terms`] and [`snapshot_op_terms`].
pub fn snapshot(s: &Snapshot, shape: &SessionShape) -> Result<(), DecodeError> {
    snapshot_user_terms(s, shape)?;
    snapshot_op_terms(s, shape)
}

/// The fields of [`snapshot`] that describe the operational point rather than the user: twist,
/// Λ̂⁻¹, directions, singular values and constraint count. A sender that writes the same values into the
/// snapshots of every user holding one OP checks them once, and each snapshot with
/// [`snapshot_user_terms`].
pub fn snapshot_op_terms(s: &Snapshot, shape: &SessionShape) -> Result<(), DecodeError> {
    let k = shape.op_dim();
    vector(Field::at("snapshot.op_twist"), &s.op_twist, k, MAX_SCENE_SPEED)?;
    vector(
        Field::at("snapshot.inverse_inertia"),
        &s.inverse_inertia,
        shape.op_triangle_len(),
        MAX_SCENE_INVERSE_INERTIA,
    )?;
    vector(Field::at("snapshot.directions"), &s.directions, k * k, MAX_ORTHONORMAL_ENTRY)?;
    singular_values(&s.singular_values, k)?;
    if usize::from(s.constraint_count) > k {
        return Err(DecodeError::TooMany {
            field: Field::at("snapshot.constraint_count"),
            got: s.constraint_count.into(),
            max: k,
        });
    }
    Ok(())
}

/// The rest of [`snapshot`]: time, pose (each user's wire angle has its own anchor), b̂, contacts, the
/// energy books' shape and the configuration-space terms.
pub fn snapshot_user_terms(s: &Snapshot, shape: &SessionShape) -> Result<(), DecodeError> {
    scalar(Field::at("snapshot.server_time_s"), s.server_time_s, 0.0, MAX_TIME_S)?;
    scalar(Field::at("snapshot.uplink_time_s"), s.uplink_time_s, 0.0, MAX_TIME_S)?;
    pose(Field::at("snapshot.op_pose"), &s.op_pose, shape)?;
    vector(Field::at("snapshot.bias_accel"), &s.bias_accel, shape.op_dim(), MAX_SCENE_ACCEL)?;
    count(Field::at("snapshot.contacts"), s.contacts.len(), MAX_LIST_ENTRIES)?;
    for (i, c) in s.contacts.iter().enumerate() {
        contact(i, c, shape)?;
    }
    port_energy_shape(("snapshot.energy.received_j", "snapshot.energy.emitted_j"), &s.energy, shape.op_dim())?;
    match &s.config {
        Some(config) => config_terms(config, shape),
        None => Ok(()),
    }
}

fn singular_values(values: &[f64], k: usize) -> Result<(), DecodeError> {
    let field = Field::at("snapshot.singular_values");
    non_negative_vector(field, values, k, MAX_SCENE_INVERSE_INERTIA)?;
    if values.windows(2).any(|pair| pair[0] < pair[1]) {
        return Err(DecodeError::Inconsistent { field, what: "singular values must not increase" });
    }
    Ok(())
}

fn contact(i: usize, c: &ContactTerm, shape: &SessionShape) -> Result<(), DecodeError> {
    const LIST: &str = "snapshot.contacts";
    let d = shape.point_dim();
    vector(Field::in_item(LIST, i, "point"), &c.point, d, MAX_SCENE_POSITION)?;
    unit_vector(Field::in_item(LIST, i, "normal"), &c.normal, d)?;
    scalar(Field::in_item(LIST, i, "depth"), c.depth, -MAX_SCENE_POSITION, MAX_SCENE_POSITION)?;
    scalar(Field::in_item(LIST, i, "normal_velocity"), c.normal_velocity, -MAX_SCENE_SPEED, MAX_SCENE_SPEED)?;
    vector(Field::in_item(LIST, i, "op_coupling"), &c.op_coupling, shape.op_dim(), MAX_SCENE_MATRIX_ENTRY)?;
    scalar(Field::in_item(LIST, i, "mobility"), c.mobility, 0.0, MAX_SCENE_INVERSE_INERTIA)?;
    scalar(Field::in_item(LIST, i, "bias_accel"), c.bias_accel, -MAX_SCENE_ACCEL, MAX_SCENE_ACCEL)?;
    scalar(Field::in_item(LIST, i, "stiffness"), c.stiffness, 0.0, MAX_SCENE_GAIN)?;
    scalar(Field::in_item(LIST, i, "damping"), c.damping, 0.0, MAX_SCENE_GAIN)
}

fn config_terms(c: &ConfigTerms, shape: &SessionShape) -> Result<(), DecodeError> {
    let (n, m, k) = (shape.n, shape.m, shape.op_dim());
    vector(Field::at("snapshot.config.q"), &c.q, shape.nq, MAX_SCENE_POSITION)?;
    vector(Field::at("snapshot.config.qd"), &c.qd, n, MAX_SCENE_SPEED)?;
    vector(Field::at("snapshot.config.mass_matrix"), &c.mass_matrix, triangle_len(n), MAX_SCENE_MATRIX_ENTRY)?;
    vector(Field::at("snapshot.config.closure_jacobian"), &c.closure_jacobian, m * n, MAX_SCENE_MATRIX_ENTRY)?;
    vector(Field::at("snapshot.config.closure_bias_stab"), &c.closure_bias_stab, m, MAX_SCENE_MATRIX_ENTRY)?;
    vector(Field::at("snapshot.config.generalized_bias"), &c.generalized_bias, n, MAX_SCENE_MATRIX_ENTRY)?;
    vector(Field::at("snapshot.config.op_jacobian"), &c.op_jacobian, k * n, MAX_SCENE_MATRIX_ENTRY)?;
    vector(Field::at("snapshot.config.op_bias"), &c.op_bias, k, MAX_SCENE_MATRIX_ENTRY)
}

/// Checks an uplink against the session shape.
pub fn uplink(u: &Uplink, shape: &SessionShape) -> Result<(), DecodeError> {
    let k = shape.op_dim();
    scalar(Field::at("uplink.client_time_s"), u.client_time_s, 0.0, MAX_TIME_S)?;
    scalar(Field::at("uplink.last_snapshot_age_s"), u.last_snapshot_age_s, 0.0, MAX_TIME_S)?;
    vector(Field::at("uplink.hand_wrench"), &u.hand_wrench, k, MAX_SCENE_WRENCH)?;
    pose(Field::at("uplink.device_pose"), &u.device_pose, shape)?;
    vector(Field::at("uplink.device_twist"), &u.device_twist, k, MAX_SCENE_SPEED)?;
    pose(Field::at("uplink.model_pose"), &u.model_pose, shape)?;
    vector(Field::at("uplink.model_twist"), &u.model_twist, k, MAX_SCENE_SPEED)?;
    port_energy_shape(("uplink.energy.received_j", "uplink.energy.emitted_j"), &u.energy, k)?;
    let unknown = u.flags & !uplink_flags::KNOWN;
    if unknown != 0 {
        return Err(DecodeError::UnknownFlags { bits: unknown });
    }
    Ok(())
}

/// A pose: bounded position (and planar angle); spatial poses end in a unit quaternion.
fn pose(field: Field, p: &[f64], shape: &SessionShape) -> Result<(), DecodeError> {
    vector(field, p, shape.pose_dim(), MAX_SCENE_POSITION)?;
    if shape.kind == SceneKind::Spatial {
        let norm = p[3..].iter().map(|x| x * x).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(DecodeError::NotUnit { field, norm });
        }
    }
    Ok(())
}

fn unit_vector(field: Field, v: &[f64], len: usize) -> Result<(), DecodeError> {
    vector(field, v, len, 1.0 + UNIT_TOLERANCE)?;
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > UNIT_TOLERANCE {
        return Err(DecodeError::NotUnit { field, norm });
    }
    Ok(())
}

/// Exact length, every element finite and within `±bound`.
fn vector(field: Field, v: &[f64], expected: usize, bound: f64) -> Result<(), DecodeError> {
    length(field, v.len(), expected)?;
    elements(field, v, -bound, bound)
}

/// Exact length, every element finite and within `[0, bound]`.
fn non_negative_vector(field: Field, v: &[f64], expected: usize, bound: f64) -> Result<(), DecodeError> {
    length(field, v.len(), expected)?;
    elements(field, v, 0.0, bound)
}

/// The energy books' lengths only: their values (finite, non-negative, never decreasing, no faster than a
/// device can push) are judged against the stream's history by the receiver, which refuses a bad report and
/// counts it without dropping the rest of the message (`crate::passivity::EnergyReports`).
fn port_energy_shape(fields: (&'static str, &'static str), e: &PortEnergy, k: usize) -> Result<(), DecodeError> {
    length(Field::at(fields.0), e.received_j.len(), k)?;
    length(Field::at(fields.1), e.emitted_j.len(), k)
}

/// Longest signature a room state may carry (HMAC-SHA256 makes 32 bytes).
const MAX_TAG_BYTES: usize = 64;

/// A room state: coordinates and velocities of one length, within the wire's position and speed bounds, and
/// a signature no longer than an HMAC's. Whether it fits a scene is the receiving server's question.
pub fn room_state(s: &RoomState) -> Result<(), DecodeError> {
    count(Field::at("room_state.q"), s.q.len(), MAX_COORDINATES)?;
    length(Field::at("room_state.qd"), s.qd.len(), s.q.len())?;
    elements(Field::at("room_state.q"), &s.q, -MAX_POSITION, MAX_POSITION)?;
    elements(Field::at("room_state.qd"), &s.qd, -MAX_SPEED, MAX_SPEED)?;
    count(Field::at("room_state.tag"), s.tag.len(), MAX_TAG_BYTES)
}

fn resume_answer(a: &ResumeAnswer) -> Result<(), DecodeError> {
    match a {
        ResumeAnswer::Refused(ResumeRefusal::Shape { what }) => text(Field::at("resume_answer.what"), what),
        ResumeAnswer::Refused(ResumeRefusal::Stale { age_s, max_age_s }) => {
            scalar(Field::at("resume_answer.age_s"), *age_s, f64::MIN, f64::MAX)?;
            scalar(Field::at("resume_answer.max_age_s"), *max_age_s, 0.0, f64::MAX)
        }
        ResumeAnswer::Refused(ResumeRefusal::Loops { residual_m, tolerance_m }) => {
            scalar(Field::at("resume_answer.residual_m"), *residual_m, 0.0, f64::MAX)?;
            scalar(Field::at("resume_answer.tolerance_m"), *tolerance_m, 0.0, f64::MAX)
        }
        _ => Ok(()),
    }
}

fn length(field: Field, got: usize, expected: usize) -> Result<(), DecodeError> {
    if got != expected {
        return Err(DecodeError::WrongLength { field, got, expected });
    }
    Ok(())
}

fn elements(field: Field, v: &[f64], min: f64, max: f64) -> Result<(), DecodeError> {
    // Two comparisons an element when all is well (a NaN fails both, an infinity one: min and max are finite);
    // the element-by-element pass below only finds what is wrong, and where, for the error.
    debug_assert!(min.is_finite() && max.is_finite(), "bounds must be finite for the fast pass");
    if v.iter().all(|&value| value >= min && value <= max) {
        return Ok(());
    }
    for (i, &value) in v.iter().enumerate() {
        in_range(field, Some(i), value, min, max)?;
    }
    Ok(())
}

fn scalar(field: Field, value: f64, min: f64, max: f64) -> Result<(), DecodeError> {
    in_range(field, None, value, min, max)
}

fn in_range(field: Field, index: Option<usize>, value: f64, min: f64, max: f64) -> Result<(), DecodeError> {
    if !value.is_finite() {
        return Err(DecodeError::NonFinite { field, index });
    }
    if value < min || value > max {
        return Err(DecodeError::OutOfRange { field, index, value, min, max });
    }
    Ok(())
}

fn count(field: Field, got: usize, max: usize) -> Result<(), DecodeError> {
    if got > max {
        return Err(DecodeError::TooMany { field, got, max });
    }
    Ok(())
}

fn text(field: Field, s: &str) -> Result<(), DecodeError> {
    if s.len() > MAX_STRING_BYTES {
        return Err(DecodeError::TooLong { field, bytes: s.len(), max: MAX_STRING_BYTES });
    }
    Ok(())
}
