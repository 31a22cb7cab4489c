//! Golden byte vectors: the wire format of [`PROTOCOL_VERSION`], frozen.
//!
//! The bytes below were written by hand from the format (bincode 2 standard config: varint integers and
//! lengths, `u64` ≥ 251 as `fb` + u16 LE, enum variants as varint indices, `Option` as 0/1, `f64` as 8 LE
//! bytes), not produced by the code under test. If one of these tests fails, the wire format changed: undo
//! the change, or write new vectors here and bump [`PROTOCOL_VERSION`] (once per landing, see the module
//! documentation of [`crate::messages`]).

use super::*;
use crate::codec::{self, decode_control, decode_datagram, encode_control, encode_datagram};
use crate::shape::{SceneKind, SessionShape};

fn unhex(parts: &[&str]) -> Vec<u8> {
    let digits: String = parts.concat().chars().filter(|c| !c.is_whitespace()).collect();
    (0..digits.len()).step_by(2).map(|i| u8::from_str_radix(&digits[i..i + 2], 16).expect("hex")).collect()
}

const PLANAR_TESTBED: SessionShape = SessionShape { kind: SceneKind::Planar, n: 4, nq: 4, m: 2 };

fn hello() -> Control {
    Control::Hello(Hello {
        version: 5,
        token: "tok".into(),
        client_name: "c1".into(),
        role: Role::Manipulator,
        room: "lab".into(),
    })
}

const HELLO_BYTES: &[&str] = &[
    "00",        // Control::Hello
    "05",        // version 5
    "03 746f6b", // token "tok"
    "02 6331",   // client_name "c1"
    "00",        // role Manipulator
    "03 6c6162", // room "lab"
];

fn unknown_room() -> Control {
    Control::Refused(Refused {
        reason: RefusalReason::UnknownRoom { requested: "x".into(), available: vec!["a".into()] },
        message: String::new(),
    })
}

const UNKNOWN_ROOM_BYTES: &[&str] = &[
    "02",    // Control::Refused
    "08",    // RefusalReason::UnknownRoom
    "01 78", // requested "x"
    "01",    // available: 1 name
    "01 61", // "a"
    "00",    // message ""
];

fn admin() -> Control {
    Control::Admin(AdminRequest {
        version: 8,
        token: "k".into(),
        command: AdminCommand::CreateRoom {
            name: "r".into(),
            scene: "s".into(),
            token_file: String::new(),
            max_users: 2,
        },
    })
}

const ADMIN_BYTES: &[&str] = &[
    "0c",    // Control::Admin
    "08",    // version 8
    "01 6b", // token "k"
    "00",    // AdminCommand::CreateRoom
    "01 72", // name "r"
    "01 73", // scene "s"
    "00",    // token_file ""
    "02",    // max_users 2
];

fn admin_answer() -> Control {
    let room = RoomSummary { name: "r".into(), scene: "s".into(), users: 1, thread: 0, cost_us: 1.0 };
    Control::AdminAnswer(AdminAnswer::Done { rooms: vec![room] })
}

const ADMIN_ANSWER_BYTES: &[&str] = &[
    "0d",               // Control::AdminAnswer
    "00",               // AdminAnswer::Done
    "01",               // rooms: 1
    "01 72",            // name "r"
    "01 73",            // scene "s"
    "01",               // users 1
    "00",               // thread 0
    "000000000000f03f", // cost_us 1.0
];

fn scene_info() -> Control {
    Control::SceneInfo(SceneInfo { name: "tb".into(), kind: SceneKind::Planar, ops: vec!["ee".into(), "knee".into()] })
}

const SCENE_INFO_BYTES: &[&str] = &[
    "07",          // Control::SceneInfo
    "02 7462",     // name "tb"
    "00",          // kind Planar
    "02",          // ops: 2 names
    "02 6565",     // "ee"
    "04 6b6e6565", // "knee"
];

fn resume() -> Control {
    Control::Resume(RoomState {
        scene_hash: 7,
        taken_unix_ms: 300,
        ve_step: 2,
        q: vec![1.0],
        qd: vec![-0.5],
        tag: vec![0xab, 0xcd],
    })
}

const RESUME_BYTES: &[&str] = &[
    "0a",                  // Control::Resume
    "07",                  // scene_hash 7
    "fb 2c01",             // taken_unix_ms 300 (≥ 251: fb + u16 LE)
    "02",                  // ve_step 2
    "01 000000000000f03f", // q [1.0]
    "01 000000000000e0bf", // qd [-0.5]
    "02 abcd",             // tag, 2 bytes
];

fn resume_answer() -> Control {
    Control::ResumeAnswer(ResumeAnswer::Refused(ResumeRefusal::Stale { age_s: 40.0, max_age_s: 30.0 }))
}

const RESUME_ANSWER_BYTES: &[&str] = &[
    "0b",               // Control::ResumeAnswer
    "01",               // ResumeAnswer::Refused
    "04",               // ResumeRefusal::Stale
    "0000000000004440", // age_s 40.0
    "0000000000003e40", // max_age_s 30.0
];

fn join() -> Control {
    Control::Join(Join {
        op: "ee".into(),
        device: DeviceCaps {
            name: "sim".into(),
            dof: 3,
            workspace_min: vec![-0.5, -0.5, -2.0],
            workspace_max: vec![0.5, 0.5, 2.0],
            max_force_n: 8.0,
            continuous_force_n: 4.0,
            max_torque_nm: 0.5,
            max_stiffness_n_per_m: 2048.0,
            max_damping_ns_per_m: 16.0,
            max_angular_stiffness_nm_per_rad: 2.0,
            max_angular_damping_nms_per_rad: 0.25,
            damping: vec![0.5, 0.5, 0.0],
            mass: vec![1.0, 1.0, 0.0625],
            native_rate_hz: 1024.0,
            has_force_sensor: true,
        },
        form: LocalModelForm::OpSpace,
        mapping: MappingRequest { position_scale: Some(0.5), force_scale: None, gravity_compensation: false },
    })
}

const JOIN_BYTES: &[&str] = &[
    "08",                  // Control::Join
    "02 6565",             // op "ee"
    "03 73696d",           // device.name "sim"
    "03",                  // device.dof 3
    "03",                  // workspace_min: 3 values
    "000000000000e0bf",    // -0.5
    "000000000000e0bf",    // -0.5
    "00000000000000c0",    // -2.0
    "03",                  // workspace_max: 3 values
    "000000000000e03f",    // 0.5
    "000000000000e03f",    // 0.5
    "0000000000000040",    // 2.0
    "0000000000002040",    // max_force_n 8.0
    "0000000000001040",    // continuous_force_n 4.0
    "000000000000e03f",    // max_torque_nm 0.5
    "000000000000a040",    // max_stiffness_n_per_m 2048.0
    "0000000000003040",    // max_damping_ns_per_m 16.0
    "0000000000000040",    // max_angular_stiffness_nm_per_rad 2.0
    "000000000000d03f",    // max_angular_damping_nms_per_rad 0.25
    "03",                  // damping: 3 values
    "000000000000e03f",    // 0.5
    "000000000000e03f",    // 0.5
    "0000000000000000",    // 0.0
    "03",                  // mass: 3 values
    "000000000000f03f",    // 1.0
    "000000000000f03f",    // 1.0
    "000000000000b03f",    // 0.0625
    "0000000000009040",    // native_rate_hz 1024.0
    "01",                  // has_force_sensor true
    "00",                  // form OpSpace
    "01 000000000000e03f", // mapping.position_scale Some(0.5)
    "00",                  // mapping.force_scale None
    "00",                  // mapping.gravity_compensation false
];

fn welcome() -> Control {
    Control::Welcome(Welcome {
        session_id: 300,
        user_id: 7,
        scene: SceneSummary {
            name: "tb".into(),
            kind: SceneKind::Planar,
            n: 4,
            m: 2,
            ball_rates: Vec::new(),
            op_dim: 3,
            op_name: "ee".into(),
            length_scale: 0.0625,
        },
        ve_rate_hz: 1000.0,
        snapshot_rate_hz: 500.0,
        mapping: Mapping { position_scale: 0.5, force_scale: 0.25, gravity_compensation: true, rigid_grasp: false },
        coupling: CouplingGains { stiffness: vec![512.0, 512.0, 4.0], damping: vec![2.0, 2.0, 0.25] },
        op: OpSummary {
            position: vec![0.25, 0.5],
            reach_min: vec![0.0, 0.0],
            reach_max: vec![1.0, 0.5],
            tour: vec![0.25, -0.25, 0.0],
            static_force_n: 2.0,
            static_torque_nm: 0.0,
            inverse_mass_max: 4.0,
            inverse_rotational_inertia_max: 16.0,
            path: vec![0.25, 0.5, 0.0, 0.5, 0.5, 1.0],
            path_rest_acceleration: Some(vec![-2.0, 0.5]),
            path_shape: PathShape::Open,
        },
    })
}

const WELCOME_BYTES: &[&str] = &[
    "01",               // Control::Welcome
    "fb 2c01",          // session_id 300
    "07",               // user_id 7
    "02 7462",          // scene.name "tb"
    "00",               // scene.kind Planar
    "04",               // scene.n 4
    "02",               // scene.m 2
    "00",               // scene.ball_rates: none
    "03",               // scene.op_dim 3
    "02 6565",          // scene.op_name "ee"
    "000000000000b03f", // scene.length_scale 0.0625
    "0000000000408f40", // ve_rate_hz 1000.0
    "0000000000407f40", // snapshot_rate_hz 500.0
    "000000000000e03f", // mapping.position_scale 0.5
    "000000000000d03f", // mapping.force_scale 0.25
    "01",               // mapping.gravity_compensation true
    "00",               // mapping.rigid_grasp false
    "03",               // coupling.stiffness: 3 values
    "0000000000008040", // 512.0
    "0000000000008040", // 512.0
    "0000000000001040", // 4.0
    "03",               // coupling.damping: 3 values
    "0000000000000040", // 2.0
    "0000000000000040", // 2.0
    "000000000000d03f", // 0.25
    "02",               // op.position: 2 values
    "000000000000d03f", // 0.25
    "000000000000e03f", // 0.5
    "02",               // op.reach_min: 2 values
    "0000000000000000 0000000000000000",
    "02",               // op.reach_max: 2 values
    "000000000000f03f", // 1.0
    "000000000000e03f", // 0.5
    "03",               // op.tour: 3 values (one planar displacement)
    "000000000000d03f", // 0.25
    "000000000000d0bf", // -0.25
    "0000000000000000", // 0.0
    "0000000000000040", // op.static_force_n 2.0
    "0000000000000000", // op.static_torque_nm 0.0
    "0000000000001040", // op.inverse_mass_max 4.0
    "0000000000003040", // op.inverse_rotational_inertia_max 16.0
    "06",               // op.path: 6 values (two planar poses)
    "000000000000d03f", // 0.25
    "000000000000e03f", // 0.5
    "0000000000000000", // 0.0
    "000000000000e03f", // 0.5
    "000000000000e03f", // 0.5
    "000000000000f03f", // 1.0
    "01",               // op.path_rest_acceleration: Some
    "02",               // 2 values
    "00000000000000c0", // -2.0
    "000000000000e03f", // 0.5
    "00",               // op.path_shape Open
];

fn snapshot() -> Datagram {
    Datagram::Snapshot(Snapshot {
        seq: 1000,
        server_time_s: 1.5,
        ve_step: 2000,
        user_id: 1,
        uplink_time_s: 1.25,
        op_pose: vec![0.25, 0.5, 1.0],
        op_twist: vec![0.5, -0.25, 0.0],
        inverse_inertia: vec![2.0, 0.5, 0.0, 4.0, 0.0, 16.0],
        bias_accel: vec![0.0, -8.0, 0.0],
        directions: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        singular_values: vec![16.0, 4.0, 0.0],
        constraint_count: 1,
        contacts: vec![],
        other_manipulators: 2,
        config: None,
        energy: PortEnergy { received_j: vec![0.5, 0.25, 0.0], emitted_j: vec![2.0, 0.0, 0.0] },
    })
}

const SNAPSHOT_BYTES: &[&str] = &[
    "00",               // Datagram::Snapshot
    "fb e803",          // seq 1000
    "000000000000f83f", // server_time_s 1.5
    "fb d007",          // ve_step 2000
    "01",               // user_id 1
    "000000000000f43f", // uplink_time_s 1.25
    "03",               // op_pose: 3 values
    "000000000000d03f", // x 0.25
    "000000000000e03f", // y 0.5
    "000000000000f03f", // θ 1.0
    "03",               // op_twist: 3 values
    "000000000000e03f", // 0.5
    "000000000000d0bf", // -0.25
    "0000000000000000", // 0.0
    "06",               // inverse_inertia: 6 values (upper triangle)
    "0000000000000040", // (0,0) 2.0
    "000000000000e03f", // (0,1) 0.5
    "0000000000000000", // (0,2) 0.0
    "0000000000001040", // (1,1) 4.0
    "0000000000000000", // (1,2) 0.0
    "0000000000003040", // (2,2) 16.0
    "03",               // bias_accel: 3 values
    "0000000000000000", // 0.0
    "00000000000020c0", // -8.0
    "0000000000000000", // 0.0
    "09",               // directions: 9 values, identity column-major
    "000000000000f03f 0000000000000000 0000000000000000",
    "0000000000000000 000000000000f03f 0000000000000000",
    "0000000000000000 0000000000000000 000000000000f03f",
    "03",                                                 // singular_values: 3 values
    "0000000000003040",                                   // 16.0
    "0000000000001040",                                   // 4.0
    "0000000000000000",                                   // 0.0
    "01",                                                 // constraint_count 1
    "00",                                                 // contacts: none
    "02",                                                 // other_manipulators 2
    "00",                                                 // config: None
    "03",                                                 // energy.received_j: 3 values
    "000000000000e03f 000000000000d03f 0000000000000000", // 0.5 0.25 0.0
    "03",                                                 // energy.emitted_j: 3 values
    "0000000000000040 0000000000000000 0000000000000000", // 2.0 0.0 0.0
];

fn uplink() -> Datagram {
    Datagram::Uplink(Uplink {
        seq: 42,
        client_time_s: 2.0,
        last_snapshot_seq: 1000,
        last_snapshot_age_s: 0.25,
        hand_wrench: vec![1.0, -2.0, 0.0],
        device_pose: vec![0.25, 0.5, 1.0],
        device_twist: vec![0.0, 0.0, 0.0],
        model_pose: vec![0.25, 0.5, 1.0],
        model_twist: vec![0.0, 0.0, 0.0],
        flags: uplink_flags::CLAMPED | uplink_flags::IMPEDANCE_MODE | uplink_flags::HAND_OFF,
        energy: PortEnergy { received_j: vec![1.0, 0.0, 0.0], emitted_j: vec![0.0, 0.5, 0.0] },
    })
}

const UPLINK_BYTES: &[&str] = &[
    "01",               // Datagram::Uplink
    "2a",               // seq 42
    "0000000000000040", // client_time_s 2.0
    "fb e803",          // last_snapshot_seq 1000
    "000000000000d03f", // last_snapshot_age_s 0.25
    "03",               // hand_wrench: 3 values
    "000000000000f03f", // 1.0
    "00000000000000c0", // -2.0
    "0000000000000000", // 0.0
    "03",               // device_pose
    "000000000000d03f 000000000000e03f 000000000000f03f",
    "03", // device_twist
    "0000000000000000 0000000000000000 0000000000000000",
    "03", // model_pose
    "000000000000d03f 000000000000e03f 000000000000f03f",
    "03", // model_twist
    "0000000000000000 0000000000000000 0000000000000000",
    "4a", // flags CLAMPED | IMPEDANCE_MODE | HAND_OFF
    "03", // energy.received_j
    "000000000000f03f 0000000000000000 0000000000000000",
    "03", // energy.emitted_j
    "0000000000000000 000000000000e03f 0000000000000000",
];

#[test]
fn resume_and_its_answer_match_golden_bytes() {
    for (message, bytes) in [(resume(), RESUME_BYTES), (resume_answer(), RESUME_ANSWER_BYTES)] {
        let golden = unhex(bytes);
        assert_eq!(encode_control(&message).unwrap(), golden);
        assert_eq!(decode_control(&golden).unwrap(), message);
    }
}

#[test]
fn room_messages_match_golden_bytes() {
    for (message, bytes) in
        [(unknown_room(), UNKNOWN_ROOM_BYTES), (admin(), ADMIN_BYTES), (admin_answer(), ADMIN_ANSWER_BYTES)]
    {
        let golden = unhex(bytes);
        assert_eq!(encode_control(&message).unwrap(), golden, "{}", message.kind_name());
        assert_eq!(decode_control(&golden).unwrap(), message);
    }
}

#[test]
fn hello_matches_golden_bytes() {
    let golden = unhex(HELLO_BYTES);
    assert_eq!(encode_control(&hello()).unwrap(), golden);
    assert_eq!(decode_control(&golden).unwrap(), hello());
}

#[test]
fn scene_info_matches_golden_bytes() {
    let golden = unhex(SCENE_INFO_BYTES);
    assert_eq!(encode_control(&scene_info()).unwrap(), golden);
    assert_eq!(decode_control(&golden).unwrap(), scene_info());
}

#[test]
fn join_matches_golden_bytes() {
    let golden = unhex(JOIN_BYTES);
    assert_eq!(encode_control(&join()).unwrap(), golden);
    assert_eq!(decode_control(&golden).unwrap(), join());
}

#[test]
fn welcome_matches_golden_bytes() {
    let golden = unhex(WELCOME_BYTES);
    assert_eq!(encode_control(&welcome()).unwrap(), golden);
    assert_eq!(decode_control(&golden).unwrap(), welcome());
}

#[test]
fn planar_testbed_snapshot_matches_golden_bytes() {
    let golden = unhex(SNAPSHOT_BYTES);
    assert_eq!(
        golden.len(),
        300,
        "a planar snapshot without contacts is 34 doubles (6 of them the energy books) plus small headers and the \
         count of other manipulators"
    );
    assert_eq!(encode_datagram(&snapshot()).unwrap(), golden);
    assert_eq!(decode_datagram(&golden, &PLANAR_TESTBED).unwrap(), snapshot());
}

#[test]
fn uplink_matches_golden_bytes() {
    let golden = unhex(UPLINK_BYTES);
    assert_eq!(encode_datagram(&uplink()).unwrap(), golden);
    assert_eq!(decode_datagram(&golden, &PLANAR_TESTBED).unwrap(), uplink());
}

#[test]
fn hello_variant_and_version_lead_the_frame_so_other_versions_can_be_refused() {
    let mut future = unhex(HELLO_BYTES);
    future[1] = 0x06; // version 6; the rest may be anything a future version sends
    future.truncate(5);
    assert_eq!(codec::peek_hello_version(&future), Some(6));
    assert_eq!(codec::peek_hello_version(&unhex(WELCOME_BYTES)), None);
}
