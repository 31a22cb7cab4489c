//! The codec refuses what a broken or hostile peer may send, and says what and where.

use crate::support;

use kinloop_protocol::bench::{testbed_shape, testbed_snapshot};
use kinloop_protocol::codec::limits::{MAX_DATAGRAM_MESSAGE_BYTES, MAX_LIST_ENTRIES, MAX_STRING_BYTES};
use kinloop_protocol::codec::{decode_control, decode_datagram, encode_control, encode_datagram, DecodeError};
use kinloop_protocol::*;

fn decode_snapshot(snapshot: Snapshot) -> Result<Datagram, DecodeError> {
    decode_datagram(&encode_datagram(&Datagram::Snapshot(snapshot)).unwrap(), &testbed_shape())
}

fn field_of(error: &DecodeError) -> String {
    error.field().unwrap_or_else(|| panic!("no field in {error:?}")).to_string()
}

#[test]
fn wrong_matrix_length_names_the_field_and_both_lengths() {
    let mut s = testbed_snapshot();
    s.inverse_inertia.pop();
    let error = decode_snapshot(s).unwrap_err();
    assert!(matches!(error, DecodeError::WrongLength { got: 5, expected: 6, .. }), "{error:?}");
    assert_eq!(error.to_string(), "snapshot.inverse_inertia has 5 values, expected 6");
}

#[test]
fn nan_is_refused_with_its_index() {
    let mut s = testbed_snapshot();
    s.bias_accel[2] = f64::NAN;
    let error = decode_snapshot(s).unwrap_err();
    assert!(matches!(error, DecodeError::NonFinite { index: Some(2), .. }), "{error:?}");
    assert_eq!(error.to_string(), "snapshot.bias_accel[2] is not finite");
}

/// Infinities are refused as not finite too, with their index, whatever their sign.
#[test]
fn infinity_is_refused_with_its_index() {
    for (index, value) in [(0, f64::INFINITY), (1, f64::NEG_INFINITY)] {
        let mut s = testbed_snapshot();
        s.op_twist[index] = value;
        let error = decode_snapshot(s).unwrap_err();
        assert!(matches!(error, DecodeError::NonFinite { index: Some(i), .. } if i == index), "{error:?}");
        assert_eq!(error.to_string(), format!("snapshot.op_twist[{index}] is not finite"));
    }
}

/// A scene's wrench may be written in any units of the stated range (2e4 N·m is 2e13 g·mm²/s²), but not past
/// it.
#[test]
fn absurd_wrench_is_out_of_range() {
    use kinloop_protocol::codec::limits::MAX_SCENE_WRENCH;
    let absurd = 2.0 * MAX_SCENE_WRENCH;
    let decode = |wrench: f64| {
        let uplink = Uplink { hand_wrench: vec![0.0, wrench, 0.0], ..Uplink::at_rest(1, 3, 3) };
        decode_datagram(&encode_datagram(&Datagram::Uplink(uplink)).unwrap(), &testbed_shape())
    };
    assert!(decode(2e4).is_ok(), "2e4 in some scene's units");
    let error = decode(absurd).unwrap_err();
    assert!(matches!(error, DecodeError::OutOfRange { value, index: Some(1), .. } if value == absurd), "{error:?}");
    assert_eq!(field_of(&error), "uplink.hand_wrench");
}

#[test]
fn snapshot_for_a_spatial_session_is_refused_on_a_planar_one() {
    let (_, spatial) = support::full_spatial_snapshot();
    let error = decode_snapshot(spatial).unwrap_err();
    assert_eq!(field_of(&error), "snapshot.op_pose");
}

#[test]
fn spatial_pose_needs_a_unit_quaternion() {
    let (shape, mut s) = support::full_spatial_snapshot();
    s.op_pose[3] = 0.9;
    let bytes = encode_datagram(&Datagram::Snapshot(s)).unwrap();
    let error = decode_datagram(&bytes, &shape).unwrap_err();
    assert!(matches!(error, DecodeError::NotUnit { norm, .. } if (norm - 0.9).abs() < 1e-12), "{error:?}");
}

#[test]
fn increasing_singular_values_and_excess_constraints_are_inconsistent() {
    let mut s = testbed_snapshot();
    s.singular_values = vec![1.0, 2.0, 0.0];
    assert!(matches!(decode_snapshot(s).unwrap_err(), DecodeError::Inconsistent { .. }));
    let mut s = testbed_snapshot();
    s.constraint_count = 4;
    assert!(matches!(decode_snapshot(s).unwrap_err(), DecodeError::TooMany { got: 4, max: 3, .. }));
}

#[test]
fn too_many_contacts_are_refused() {
    let (_, full) = support::full_spatial_snapshot();
    let mut contact = full.contacts[0].clone();
    contact.point.pop();
    contact.normal = vec![0.0, 1.0];
    contact.op_coupling.truncate(3);
    let mut s = testbed_snapshot();
    s.contacts = vec![contact; MAX_LIST_ENTRIES + 1];
    let error = decode_snapshot(s).unwrap_err();
    assert_eq!(error, DecodeError::TooMany { field: codec::Field::at("snapshot.contacts"), got: 65, max: 64 });
}

#[test]
fn unknown_uplink_flags_are_refused() {
    let uplink = Uplink { flags: 1 << 31, ..Uplink::at_rest(1, 3, 3) };
    let bytes = encode_datagram(&Datagram::Uplink(uplink)).unwrap();
    assert_eq!(decode_datagram(&bytes, &testbed_shape()).unwrap_err(), DecodeError::UnknownFlags { bits: 1 << 31 });
}

#[test]
fn trailing_bytes_are_refused() {
    let mut bytes = encode_datagram(&Datagram::Snapshot(testbed_snapshot())).unwrap();
    bytes.extend_from_slice(&[0, 0, 0]);
    assert_eq!(decode_datagram(&bytes, &testbed_shape()).unwrap_err(), DecodeError::Trailing { extra: 3 });
}

#[test]
fn truncated_message_is_malformed() {
    let bytes = encode_datagram(&Datagram::Snapshot(testbed_snapshot())).unwrap();
    let error = decode_datagram(&bytes[..bytes.len() - 1], &testbed_shape()).unwrap_err();
    assert!(matches!(error, DecodeError::Malformed(_)), "{error:?}");
}

#[test]
fn oversize_buffer_is_refused_before_decoding() {
    let bytes = vec![0u8; MAX_DATAGRAM_MESSAGE_BYTES + 1];
    assert_eq!(
        decode_datagram(&bytes, &testbed_shape()).unwrap_err(),
        DecodeError::TooLarge { limit: MAX_DATAGRAM_MESSAGE_BYTES }
    );
}

#[test]
fn long_strings_are_refused() {
    let message = Control::Leave { reason: "x".repeat(MAX_STRING_BYTES + 1) };
    let error = decode_control(&encode_control(&message).unwrap()).unwrap_err();
    assert!(matches!(error, DecodeError::TooLong { bytes: 257, max: 256, .. }), "{error:?}");
    assert_eq!(field_of(&error), "leave.reason");
}

/// A well-formed welcome to a spatial scene.
fn spatial_welcome() -> Welcome {
    Welcome {
        session_id: 1,
        user_id: 1,
        scene: SceneSummary {
            name: "s".into(),
            kind: SceneKind::Spatial,
            n: 6,
            m: 0,
            ball_rates: Vec::new(),
            op_dim: 6,
            op_name: "ee".into(),
            length_scale: 0.05,
        },
        ve_rate_hz: 1000.0,
        snapshot_rate_hz: 1000.0,
        mapping: Mapping::identity(),
        coupling: CouplingGains { stiffness: vec![1.0; 6], damping: vec![1.0; 6] },
        op: OpSummary {
            position: vec![0.0; 3],
            reach_min: vec![0.0; 3],
            reach_max: vec![0.1; 3],
            tour: Vec::new(),
            static_force_n: 0.0,
            static_torque_nm: 0.0,
            inverse_mass_max: 1.0,
            inverse_rotational_inertia_max: 1.0,
            path: Vec::new(),
            path_rest_acceleration: None,
            path_shape: PathShape::Open,
        },
    }
}

#[test]
fn welcome_with_a_wrong_op_dimension_is_refused() {
    let mut welcome = spatial_welcome();
    assert!(decode_control(&encode_control(&Control::Welcome(welcome.clone())).unwrap()).is_ok());
    welcome.scene.op_dim = 3;
    let error = decode_control(&encode_control(&Control::Welcome(welcome)).unwrap()).unwrap_err();
    assert_eq!(field_of(&error), "welcome.scene.op_dim");
}

/// A welcome's OP path: whole poses, each finite and bounded, spatial orientations unit quaternions, at most
/// `MAX_PATH_POSES`; each refusal names the pose.
#[test]
fn a_welcomes_path_is_checked_pose_by_pose() {
    let mut welcome = spatial_welcome();
    let check = |w: &Welcome| decode_control(&encode_control(&Control::Welcome(w.clone())).unwrap());
    let pose = [0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0];
    welcome.op.path = [pose, pose].concat();
    welcome.op.path_rest_acceleration = Some(vec![0.5, -9.81]);
    welcome.op.path_shape = PathShape::Closed;
    assert!(check(&welcome).is_ok());
    // One acceleration per pose, finite.
    welcome.op.path_rest_acceleration = Some(vec![0.5, -9.81, 0.0]);
    assert_eq!(field_of(&check(&welcome).unwrap_err()), "welcome.op.path_rest_acceleration");
    welcome.op.path_rest_acceleration = Some(vec![0.5, f64::NAN]);
    assert_eq!(field_of(&check(&welcome).unwrap_err()), "welcome.op.path_rest_acceleration");
    // A swing carries none (each of its poses is two configurations); without them it passes.
    welcome.op.path_shape = PathShape::Swing;
    welcome.op.path_rest_acceleration = Some(vec![0.5, -9.81]);
    assert_eq!(field_of(&check(&welcome).unwrap_err()), "welcome.op.path_rest_acceleration");
    welcome.op.path_rest_acceleration = None;
    assert!(check(&welcome).is_ok());
    welcome.op.path_shape = PathShape::Closed;
    welcome.op.path_rest_acceleration = Some(vec![0.5, -9.81]);
    // A quaternion that is not unit, in the second pose.
    welcome.op.path[10] = 0.5;
    let error = check(&welcome).unwrap_err();
    assert!(matches!(error, DecodeError::NotUnit { .. }), "{error:?}");
    assert_eq!(field_of(&error), "welcome.op.path[1].pose");
    // A non-finite position.
    welcome.op.path = [pose, pose].concat();
    welcome.op.path[8] = f64::NAN;
    assert_eq!(field_of(&check(&welcome).unwrap_err()), "welcome.op.path[1].pose");
    // Half a pose left over.
    welcome.op.path_rest_acceleration = Some(vec![0.0]);
    welcome.op.path = [&pose[..], &pose[..3]].concat();
    let error = check(&welcome).unwrap_err();
    assert!(matches!(error, DecodeError::WrongLength { got: 10, expected: 7, .. }), "{error:?}");
    // Too many poses.
    welcome.op.path = pose.repeat(MAX_PATH_POSES + 1);
    welcome.op.path_rest_acceleration = Some(vec![0.0; MAX_PATH_POSES + 1]);
    assert!(matches!(check(&welcome), Err(DecodeError::TooMany { .. })));
}

#[test]
fn refusals_read_well() {
    let refused = Refused {
        reason: RefusalReason::UnknownOp { requested: "hand".into(), available: vec!["ee".into(), "knee".into()] },
        message: String::new(),
    };
    assert_eq!(refused.to_string(), "refused: the scene has no free operational point \"hand\" (free: ee, knee)");
    let refused = Refused {
        reason: RefusalReason::UnsupportedVersion { server: 1, client: 2 },
        message: "please upgrade".into(),
    };
    assert_eq!(
        refused.to_string(),
        "refused: protocol version 2 is not supported (the server speaks version 1) — please upgrade"
    );
}

/// A sender that checks the OP's terms once per operational point (`snapshot_op_terms`) and each snapshot's
/// own (`snapshot_user_terms`) refuses exactly what the whole check refuses: each half catches its own fields
/// and only those.
#[test]
fn split_snapshot_check_covers_what_the_whole_check_does() {
    use kinloop_protocol::codec::validate;
    let shape = testbed_shape();
    let mut s = testbed_snapshot();
    s.other_manipulators = 3;
    assert!(validate::snapshot(&s, &shape).is_ok());
    s.op_twist[0] = f64::NAN;
    assert!(validate::snapshot(&s, &shape).is_err());
    assert!(validate::snapshot_op_terms(&s, &shape).is_err());
    assert!(validate::snapshot_user_terms(&s, &shape).is_ok());
    s.op_twist[0] = 0.0;
    s.bias_accel[2] = f64::INFINITY;
    assert!(validate::snapshot(&s, &shape).is_err());
    assert!(validate::snapshot_op_terms(&s, &shape).is_ok());
    assert!(validate::snapshot_user_terms(&s, &shape).is_err());
}

/// An offered room state that is truncated (velocities shorter than coordinates), not finite or carries an
/// oversized signature is refused by the codec, naming the field, before any server looks at it.
#[test]
fn a_malformed_room_state_is_refused_naming_the_field() {
    let state =
        RoomState { scene_hash: 1, taken_unix_ms: 2, ve_step: 3, q: vec![0.5; 4], qd: vec![0.0; 4], tag: vec![7; 32] };
    let decode = |state: RoomState| decode_control(&encode_control(&Control::Resume(state)).unwrap());
    assert!(decode(state.clone()).is_ok());
    let mut truncated = state.clone();
    truncated.qd.pop();
    let error = decode(truncated).unwrap_err();
    assert!(matches!(error, DecodeError::WrongLength { got: 3, expected: 4, .. }), "{error:?}");
    assert_eq!(field_of(&error), "room_state.qd");
    let mut nan = state.clone();
    nan.q[2] = f64::NAN;
    let error = decode(nan).unwrap_err();
    assert!(matches!(error, DecodeError::NonFinite { index: Some(2), .. }), "{error:?}");
    let mut long_tag = state;
    long_tag.tag = vec![0; 65];
    assert_eq!(field_of(&decode(long_tag).unwrap_err()), "room_state.tag");
}

/// A scene with ball joints: its welcome says where their rates start, and its configuration terms carry nq
/// positions (one more per ball) against nv rates. A q of nv positions, or rates that do not fit, are typed
/// errors naming the field.
#[test]
fn ball_joints_make_q_longer_than_its_rates_and_both_are_checked() {
    let mut welcome = spatial_welcome();
    let check = |w: &Welcome| decode_control(&encode_control(&Control::Welcome(w.clone())).unwrap());
    (welcome.scene.n, welcome.scene.m) = (3, 1);
    welcome.scene.ball_rates = vec![0];
    assert!(check(&welcome).is_ok());
    let shape = welcome.scene.shape();
    assert_eq!((shape.n, shape.nq), (3, 4));
    let (_, mut snapshot) = support::full_spatial_snapshot();
    let decode = |s: &Snapshot| decode_datagram(&encode_datagram(&Datagram::Snapshot(s.clone())).unwrap(), &shape);
    // One position per rate: the quaternion does not fit.
    let error = decode(&snapshot).unwrap_err();
    assert!(matches!(error, DecodeError::WrongLength { got: 3, expected: 4, .. }), "{error:?}");
    assert_eq!(field_of(&error), "snapshot.config.q");
    snapshot.config.as_mut().unwrap().q = vec![1.0, 0.0, 0.0, 0.0];
    assert!(decode(&snapshot).is_ok());
    // Rates as many as positions: q̇ is checked against nv.
    snapshot.config.as_mut().unwrap().qd = vec![0.0; 4];
    assert_eq!(field_of(&decode(&snapshot).unwrap_err()), "snapshot.config.qd");
    // A ball whose three rates run past n, two that overlap, and a ball in a planar scene.
    for (kind, n, rates) in
        [(SceneKind::Spatial, 3, vec![1]), (SceneKind::Spatial, 6, vec![0, 2]), (SceneKind::Planar, 3, vec![0])]
    {
        let mut bad = spatial_welcome();
        (bad.scene.kind, bad.scene.n, bad.scene.ball_rates) = (kind, n, rates);
        if kind == SceneKind::Planar {
            bad = Welcome { coupling: CouplingGains { stiffness: vec![1.0; 3], damping: vec![1.0; 3] }, ..bad };
            bad.scene.op_dim = 3;
        }
        let error = check(&bad).unwrap_err();
        assert_eq!(field_of(&error), "welcome.scene.ball_rates", "{error:?}");
    }
}
