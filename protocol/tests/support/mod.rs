//! Random valid messages for property tests, and representative fixed ones.
#![allow(dead_code)] // each test binary uses its own part of this module

use kinloop_protocol::*;
use proptest::collection::vec;
use proptest::prelude::*;

/// Any session shape with small n and m.
pub fn shape() -> impl Strategy<Value = SessionShape> {
    (prop_oneof![Just(SceneKind::Planar), Just(SceneKind::Spatial)], 0usize..8, 0usize..6)
        .prop_map(|(kind, n, m)| SessionShape { kind, n, nq: n, m })
}

fn within(bound: f64) -> impl Strategy<Value = f64> {
    -bound..=bound
}

fn values(len: usize, bound: f64) -> impl Strategy<Value = Vec<f64>> {
    vec(within(bound), len)
}

fn unit(len: usize) -> impl Strategy<Value = Vec<f64>> {
    vec(-1.0..=1.0f64, len).prop_filter_map("too short to normalize", |v| {
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        (norm > 0.1).then(|| v.iter().map(|x| x / norm).collect())
    })
}

fn pose(shape: SessionShape) -> BoxedStrategy<Vec<f64>> {
    match shape.kind {
        SceneKind::Planar => values(3, 100.0).boxed(),
        SceneKind::Spatial => (values(3, 100.0), unit(4)).prop_map(|(p, q)| [p, q].concat()).boxed(),
    }
}

fn name() -> impl Strategy<Value = String> {
    "[a-z0-9 _-]{0,24}"
}

fn contact(shape: SessionShape) -> impl Strategy<Value = ContactTerm> {
    let d = shape.point_dim();
    (values(d, 100.0), unit(d), within(0.1), within(10.0), values(shape.op_dim(), 1e3), 0.0..1e3, within(1e3))
        .prop_flat_map(|(point, normal, depth, normal_velocity, op_coupling, mobility, bias_accel)| {
            (0.0..1e6, 0.0..1e3).prop_map(move |(stiffness, damping)| ContactTerm {
                point: point.clone(),
                normal: normal.clone(),
                depth,
                normal_velocity,
                op_coupling: op_coupling.clone(),
                mobility,
                bias_accel,
                stiffness,
                damping,
            })
        })
}

fn config_terms(shape: SessionShape) -> impl Strategy<Value = ConfigTerms> {
    let (n, m, k) = (shape.n, shape.m, shape.op_dim());
    (
        values(n, 10.0),
        values(n, 10.0),
        values(triangle_len(n), 1e3),
        values(m * n, 10.0),
        values(m, 10.0),
        values(n, 1e3),
        values(k * n, 10.0),
        values(k, 10.0),
    )
        .prop_map(
            |(q, qd, mass_matrix, closure_jacobian, closure_bias_stab, generalized_bias, op_jacobian, op_bias)| {
                ConfigTerms {
                    q,
                    qd,
                    mass_matrix,
                    closure_jacobian,
                    closure_bias_stab,
                    generalized_bias,
                    op_jacobian,
                    op_bias,
                }
            },
        )
}

fn decreasing(len: usize) -> impl Strategy<Value = Vec<f64>> {
    vec(0.0..1e3f64, len).prop_map(|mut v| {
        v.sort_by(|a, b| b.total_cmp(a));
        v
    })
}

/// A valid snapshot for `shape`.
pub fn snapshot(shape: SessionShape) -> impl Strategy<Value = Snapshot> {
    let k = shape.op_dim();
    let header = (any::<u64>(), 0.0..1e6, any::<u64>(), any::<u32>());
    let local_model = (
        pose(shape),
        values(k, 100.0),
        values(shape.op_triangle_len(), 1e3),
        values(k, 1e3),
        values(k * k, 1.0),
        decreasing(k),
        0..=k as u8,
    );
    let surroundings = (vec(contact(shape), 0..4), any::<u16>(), proptest::option::of(config_terms(shape)));
    (header, local_model, surroundings).prop_map(
        move |(
            (seq, server_time_s, ve_step, user_id),
            (op_pose, op_twist, inverse_inertia, bias_accel, directions, singular_values, constraint_count),
            (contacts, other_manipulators, config),
        )| Snapshot {
            seq,
            server_time_s,
            ve_step,
            user_id,
            uplink_time_s: server_time_s * 0.5,
            op_pose,
            op_twist,
            inverse_inertia,
            bias_accel,
            directions,
            singular_values,
            constraint_count,
            contacts,
            other_manipulators,
            config,
            energy: PortEnergy { received_j: vec![0.5; k], emitted_j: vec![0.25; k] },
        },
    )
}

/// A valid uplink for `shape`.
pub fn uplink(shape: SessionShape) -> impl Strategy<Value = Uplink> {
    let k = shape.op_dim();
    (
        (any::<u64>(), 0.0..1e6, any::<u64>(), 0.0..10.0),
        (values(k, 1e3), pose(shape), values(k, 100.0), pose(shape), values(k, 100.0)),
        any::<u32>().prop_map(|bits| bits & uplink_flags::KNOWN),
    )
        .prop_map(
            move |(
                (seq, client_time_s, last_snapshot_seq, last_snapshot_age_s),
                (hand_wrench, device_pose, device_twist, model_pose, model_twist),
                flags,
            )| Uplink {
                seq,
                client_time_s,
                last_snapshot_seq,
                last_snapshot_age_s,
                hand_wrench,
                device_pose,
                device_twist,
                model_pose,
                model_twist,
                flags,
                energy: PortEnergy { received_j: vec![1.5; k], emitted_j: vec![0.75; k] },
            },
        )
}

/// A shape and a valid datagram for it.
pub fn shape_and_datagram() -> impl Strategy<Value = (SessionShape, Datagram)> {
    shape().prop_flat_map(|shape| {
        let datagram =
            prop_oneof![snapshot(shape).prop_map(Datagram::Snapshot), uplink(shape).prop_map(Datagram::Uplink)];
        (Just(shape), datagram)
    })
}

fn device() -> impl Strategy<Value = DeviceCaps> {
    (
        (name(), 0u8..=16, 0usize..=6, 0.0..1e3, 0.0..=1.0, 0.0..1e2, 0.0..1e5, 0.0..1e3),
        (0.0..1e3, 0.0..1e2, 1.0..1e4, any::<bool>()),
    )
        .prop_flat_map(|(scalars, more)| {
            let axes = scalars.2;
            (Just(scalars), Just(more), vec(within(1.0), axes), vec(0.0..1e2, axes), vec(1e-3..1e2, axes))
        })
        .prop_map(
            |(
                (name, dof, _, max_force_n, continuous, max_torque_nm, stiffness, damping),
                (angular_stiffness, angular_damping, native_rate_hz, has_force_sensor),
                half_extent,
                own_damping,
                mass,
            )| DeviceCaps {
                name,
                dof,
                workspace_min: half_extent.iter().map(|h| -h.abs()).collect(),
                workspace_max: half_extent.iter().map(|h| h.abs()).collect(),
                max_force_n,
                continuous_force_n: continuous * max_force_n,
                max_torque_nm,
                max_stiffness_n_per_m: stiffness,
                max_damping_ns_per_m: damping,
                max_angular_stiffness_nm_per_rad: angular_stiffness,
                max_angular_damping_nms_per_rad: angular_damping,
                damping: own_damping,
                mass,
                native_rate_hz,
                has_force_sensor,
            },
        )
}

fn hello() -> impl Strategy<Value = Hello> {
    (any::<u16>(), name(), name(), prop_oneof![Just(Role::Manipulator), Just(Role::Observer)]).prop_map(
        |(version, token, client_name, role)| Hello { version, token, client_name, role, room: String::new() },
    )
}

fn scale() -> impl Strategy<Value = Option<f64>> {
    prop_oneof![Just(None), (1e-4..1e4).prop_map(Some)]
}

fn join() -> impl Strategy<Value = Join> {
    (
        name(),
        device(),
        prop_oneof![Just(LocalModelForm::OpSpace), Just(LocalModelForm::ConfigSpace)],
        scale(),
        scale(),
        any::<bool>(),
    )
        .prop_map(|(op, device, form, position_scale, force_scale, gravity_compensation)| Join {
            op,
            device,
            form,
            mapping: MappingRequest { position_scale, force_scale, gravity_compensation },
        })
}

fn scene_info() -> impl Strategy<Value = SceneInfo> {
    (name(), prop_oneof![Just(SceneKind::Planar), Just(SceneKind::Spatial)], vec(name(), 0..8))
        .prop_map(|(name, kind, ops)| SceneInfo { name, kind, ops })
}

fn welcome() -> impl Strategy<Value = Welcome> {
    let scene = (name(), prop_oneof![Just(SceneKind::Planar), Just(SceneKind::Spatial)], 0u32..64, 0u32..64, name());
    let mapping = (1e-4..1e4, 1e-4..1e4, any::<bool>(), any::<bool>()).prop_map(
        |(position_scale, force_scale, gravity_compensation, rigid_grasp)| Mapping {
            position_scale,
            force_scale,
            gravity_compensation,
            rigid_grasp,
        },
    );
    (any::<u64>(), any::<u32>(), scene, 1.0..1e4, 1.0..1e4, mapping, 0usize..20).prop_flat_map(
        |(session_id, user_id, (name, kind, n, m, op_name), ve_rate_hz, snapshot_rate_hz, mapping, tour)| {
            let (k, d) = (kind.op_dim(), kind.point_dim());
            let op = (
                vec(within(1.0), d),
                vec(0.0..1.0, d),
                vec(within(1.0), tour * k),
                (0.0..1e3, 0.0..1e2, 0.0..1e3, 0.0..1e3),
            )
                .prop_map(
                    move |(position, extent, tour, (force, torque, inverse_mass, inverse_inertia))| OpSummary {
                        // Up to three poses of the OP's path from the tour's numbers: positions (and a planar angle)
                        // within ±1, spatial orientations the identity quaternion.
                        path: tour
                            .chunks(k)
                            .take(3)
                            .flat_map(|c| match kind {
                                SceneKind::Planar => c[..3].to_vec(),
                                SceneKind::Spatial => [&c[..3], &[1.0, 0.0, 0.0, 0.0][..]].concat(),
                            })
                            .collect(),
                        path_rest_acceleration: Some(tour.chunks(k).take(3).map(|c| c[0] * 10.0).collect()),
                        path_shape: if tour.len() % 2 == 1 { PathShape::Closed } else { PathShape::Open },
                        reach_min: position.clone(),
                        reach_max: position.iter().zip(&extent).map(|(p, e)| p + e).collect(),
                        position,
                        tour,
                        static_force_n: force,
                        static_torque_nm: torque,
                        inverse_mass_max: inverse_mass,
                        inverse_rotational_inertia_max: inverse_inertia,
                    },
                );
            (vec(0.0..1e4, k), vec(0.0..1e2, k), op).prop_map(move |(stiffness, damping, op)| Welcome {
                session_id,
                user_id,
                scene: SceneSummary {
                    name: name.clone(),
                    kind,
                    n,
                    m,
                    ball_rates: Vec::new(),
                    op_dim: k as u8,
                    op_name: op_name.clone(),
                    length_scale: 0.05,
                },
                ve_rate_hz,
                snapshot_rate_hz,
                mapping: mapping.clone(),
                coupling: CouplingGains { stiffness, damping },
                op,
            })
        },
    )
}

fn refusal() -> impl Strategy<Value = RefusalReason> {
    prop_oneof![
        (any::<u16>(), any::<u16>()).prop_map(|(server, client)| RefusalReason::UnsupportedVersion { server, client }),
        Just(RefusalReason::BadToken),
        any::<u32>().prop_map(|max_users| RefusalReason::ServerFull { max_users }),
        (name(), vec(name(), 0..5))
            .prop_map(|(requested, available)| RefusalReason::UnknownOp { requested, available }),
        Just(RefusalReason::RoleNotAllowed),
        name().prop_map(|what| RefusalReason::Malformed { what }),
        name().prop_map(|what| RefusalReason::Device { what }),
    ]
}

fn error_code() -> impl Strategy<Value = ErrorCode> {
    prop_oneof![
        Just(ErrorCode::Protocol),
        Just(ErrorCode::Decode),
        Just(ErrorCode::Internal),
        Just(ErrorCode::ShuttingDown),
        Just(ErrorCode::Overloaded),
    ]
}

/// Any valid control message.
pub fn control() -> impl Strategy<Value = Control> {
    prop_oneof![
        hello().prop_map(Control::Hello),
        welcome().prop_map(Control::Welcome),
        (refusal(), name()).prop_map(|(reason, message)| Control::Refused(Refused { reason, message })),
        name().prop_map(|reason| Control::Leave { reason }),
        (error_code(), name()).prop_map(|(code, message)| Control::Error { code, message }),
        (any::<u64>(), 0.0..1e6).prop_map(|(nonce, t_s)| Control::Ping { nonce, t_s }),
        (any::<u64>(), 0.0..1e6).prop_map(|(nonce, t_s)| Control::Pong { nonce, t_s }),
        scene_info().prop_map(Control::SceneInfo),
        join().prop_map(Control::Join),
    ]
}

/// A spatial snapshot with a contact, another user and configuration terms: every optional part present.
pub fn full_spatial_snapshot() -> (SessionShape, Snapshot) {
    let shape = SessionShape { kind: SceneKind::Spatial, n: 3, nq: 3, m: 1 };
    let snapshot = Snapshot {
        seq: 9,
        server_time_s: 0.5,
        ve_step: 500,
        user_id: 2,
        uplink_time_s: 0.45,
        op_pose: vec![0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0],
        op_twist: vec![0.0; 6],
        inverse_inertia: vec![1.0; 21],
        bias_accel: vec![0.0; 6],
        directions: (0..36).map(|i| if i % 7 == 0 { 1.0 } else { 0.0 }).collect(),
        singular_values: vec![6.0, 5.0, 4.0, 3.0, 2.0, 1.0],
        constraint_count: 2,
        contacts: vec![ContactTerm {
            point: vec![0.1, 0.2, 0.0],
            normal: vec![0.0, 0.0, 1.0],
            depth: 0.001,
            normal_velocity: -0.01,
            op_coupling: vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            mobility: 2.0,
            bias_accel: -9.81,
            stiffness: 1e4,
            damping: 10.0,
        }],
        other_manipulators: 1,
        config: Some(ConfigTerms {
            q: vec![0.1, 0.2, 0.3],
            qd: vec![0.0; 3],
            mass_matrix: vec![1.0, 0.1, 0.0, 1.0, 0.1, 1.0],
            closure_jacobian: vec![1.0, 0.0, -1.0],
            closure_bias_stab: vec![0.0],
            generalized_bias: vec![0.0, 9.81, 0.0],
            op_jacobian: vec![0.5; 18],
            op_bias: vec![0.0; 6],
        }),
        energy: PortEnergy { received_j: vec![0.25; 6], emitted_j: vec![0.125; 6] },
    };
    (shape, snapshot)
}
