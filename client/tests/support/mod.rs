//! Test fixtures: a small VE of the paper's testbed built directly on kinloop-linkage (the real `VeCore`
//! lives in the server crate, which the client must not depend on), and a virtual-time loop wiring it to a
//! `HapticCore` and a simulated device. Deliberately minimal: one user, no contacts, no network.

#![allow(dead_code)]

use std::time::Duration;

use kinloop_client::core::{ConstraintMode, CoreConfig, GainChoice, HapticCore, ModelForm, TickReport};
use kinloop_client::device::{DevicePreset, DeviceState, HapticDevice, SimulatedRig};
use kinloop_client::user::{ConstantWrench, SimulatedUser};
use kinloop_linkage::algorithms::constraint_directions::constraint_directions;
use kinloop_linkage::algorithms::jacobian::{apply_wrench, frame_jacobian_t, frame_velocity};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::model::data::Kinematics;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::Forces, algorithms::integrator::step,
    algorithms::integrator::StepConfig, math::space::Planar, math::space::SceneKind, math::space::Space,
    model::builtin, model::data::Data, model::Model,
};
use kinloop_linkage::{
    algorithms::local_model::{op_space_terms, ConfigSpaceTerms, LocalModelTerms},
    math::space::OpPose,
};
use kinloop_protocol::{
    ConfigTerms, CouplingGains, Mapping, OpSummary, OtherUsers, SceneSummary, Snapshot, Uplink, Welcome,
};
use nalgebra::{DMatrix, DVector, Vector3};

/// The paper's graphics-controller gains (section VI).
pub const K_G: [f64; 3] = [1000.0, 1000.0, 10000.0];
/// The paper's graphics-controller damping.
pub const B_G: [f64; 3] = [100.0, 100.0, 10000.0];

/// The user's coupling in the VE: the hand wrench (force channel) plus the graphics controller's PD toward
/// the client's local-model OP, treated linearly-implicitly so the paper's stiff gains stay stable.
struct Coupling {
    op: usize,
    kg: [f64; 3],
    bg: [f64; 3],
    hand: Vector3<f64>,
    target: Option<(OpPose<Planar>, Vector3<f64>)>,
    /// The applied uplink's client clock.
    target_time_s: f64,
    jacobian_t: DMatrix<f64>,
}

impl Coupling {
    fn point(model: &Model<Planar>, kin: &Kinematics<Planar>, op: usize) -> (usize, nalgebra::Vector2<f64>) {
        let o = &model.ops[op];
        (o.body, kin.body_pos[o.body] + Planar::rotate(&kin.body_rot[o.body], &o.point))
    }

    fn wrench(&self, model: &Model<Planar>, kin: &Kinematics<Planar>) -> Vector3<f64> {
        let Some((target, target_twist)) = &self.target else { return self.hand };
        let (body, p) = Self::point(model, kin, self.op);
        let pose = OpPose::<Planar> { position: p, rotation: kin.body_rot[body] };
        let twist = frame_velocity(kin, body, &p);
        let e = target.difference(&pose);
        let de = target_twist - twist;
        self.hand + Vector3::from_fn(|i, _| self.kg[i] * e[i] + self.bg[i] * de[i])
    }
}

impl Forces<Planar> for Coupling {
    fn add_forces(&mut self, model: &Model<Planar>, kin: &Kinematics<Planar>, tau: &mut DVector<f64>) {
        let (body, p) = Self::point(model, kin, self.op);
        apply_wrench(model, kin, body, &p, &self.wrench(model, kin), tau);
    }

    fn add_implicit(
        &mut self,
        model: &Model<Planar>,
        kin: &Kinematics<Planar>,
        dt: f64,
        qd: &DVector<f64>,
        implicit_mass: &mut DMatrix<f64>,
        tau: &mut DVector<f64>,
    ) -> bool {
        if self.target.is_none() {
            return false;
        }
        let (body, p) = Self::point(model, kin, self.op);
        frame_jacobian_t(model, kin, body, &p, &mut self.jacobian_t);
        let jt = &self.jacobian_t;
        let k = DMatrix::from_diagonal(&DVector::from_row_slice(&self.kg));
        let b = DMatrix::from_diagonal(&DVector::from_row_slice(&self.bg));
        *implicit_mass += jt * (&b * dt + &k * (dt * dt)) * jt.transpose();
        *tau -= jt * (&k * (jt.transpose() * qd)) * dt;
        true
    }
}

/// The testbed VE at 1 kHz with one user on OP `link2`.
pub struct TestbedVe {
    pub model: Model<Planar>,
    data: Data<Planar>,
    pub q: DVector<f64>,
    pub qd: DVector<f64>,
    op: usize,
    coupling: Coupling,
    step_config: StepConfig,
    seq: u64,
    pub time_s: f64,
    send_config: bool,
    config_terms: ConfigSpaceTerms,
}

impl TestbedVe {
    /// The testbed at rest at q0; `send_config` adds configuration-space terms to snapshots.
    pub fn new(send_config: bool) -> Self {
        let scene = builtin::scene("paper-testbed").expect("built in").expect("parses");
        let model: Model<Planar> = Model::compile(&scene, "paper-testbed").expect("compiles");
        let data = Data::new(&model);
        let op = model.op_index("link2").expect("op link2");
        let (n, m) = (model.nv(), model.nc());
        TestbedVe {
            q: model.q0.clone(),
            qd: model.qd0.clone(),
            coupling: Coupling {
                op,
                kg: K_G,
                bg: B_G,
                hand: Vector3::zeros(),
                target: None,
                target_time_s: 0.0,
                jacobian_t: DMatrix::zeros(n, 3),
            },
            step_config: StepConfig::euler(1e-3),
            seq: 0,
            time_s: 0.0,
            send_config,
            config_terms: ConfigSpaceTerms::zeros(n, m, 3),
            data,
            op,
            model,
        }
    }

    /// The welcome a server would send for this scene: one-to-one mapping, the paper's graphics-controller
    /// gains, the surveyed reach of `link2`.
    pub fn welcome(&self) -> Welcome {
        let reach =
            kinloop_linkage::algorithms::reach::survey_op(&self.model, self.op, &Default::default()).expect("survey");
        let mut data = Data::new(&self.model);
        kinloop_linkage::algorithms::kinematics::forward_kinematics(&self.model, &mut data, &self.q);
        let pose = OpPose::of_op(&self.model, &data, self.op);
        Welcome {
            session_id: 7,
            user_id: 1,
            scene: SceneSummary {
                name: "paper-testbed".into(),
                kind: SceneKind::Planar,
                n: self.model.nv() as u32,
                m: self.model.nc() as u32,
                op_dim: 3,
                op_name: "link2".into(),
                length_scale: self.model.length_scale,
            },
            ve_rate_hz: 1000.0,
            snapshot_rate_hz: 1000.0,
            mapping: Mapping::identity(),
            coupling: CouplingGains { stiffness: K_G.to_vec(), damping: B_G.to_vec() },
            op: OpSummary::from_reach(&reach, &pose),
        }
    }

    /// Applies an uplink: the force channel and the graphics controller's target.
    pub fn apply_uplink(&mut self, uplink: &Uplink) {
        self.coupling.hand = Vector3::from_column_slice(&uplink.hand_wrench);
        let pose = OpPose::from_slice(&uplink.model_pose).expect("valid model pose");
        self.coupling.target = Some((pose, Vector3::from_column_slice(&uplink.model_twist)));
        self.coupling.target_time_s = uplink.client_time_s;
    }

    /// Replaces the graphics controller's gains.
    pub fn set_graphics_gains(&mut self, kg: [f64; 3], bg: [f64; 3]) {
        self.coupling.kg = kg;
        self.coupling.bg = bg;
    }

    /// Drives the VE with a plain wrench (no client): the paper's VE-only reference.
    pub fn set_hand_only(&mut self, wrench: Vector3<f64>) {
        self.coupling.hand = wrench;
        self.coupling.target = None;
    }

    /// One VE step of 1 ms.
    pub fn step(&mut self) {
        step(&self.model, &mut self.data, &mut self.q, &mut self.qd, &mut self.coupling, &self.step_config)
            .expect("the testbed steps");
        self.time_s += 1e-3;
    }

    /// The OP pose now.
    pub fn op_pose(&mut self) -> OpPose<Planar> {
        kinloop_linkage::algorithms::kinematics::forward_kinematics(&self.model, &mut self.data, &self.q);
        OpPose::of_op(&self.model, &self.data, self.op)
    }

    /// A snapshot of the current state, as a server would send it.
    pub fn snapshot(&mut self) -> Snapshot {
        forward_dynamics(&self.model, &mut self.data, &self.q, &self.qd, &mut self.coupling).expect("dynamics");
        let user_wrench = self.coupling.wrench(&self.model, &self.data.kin);
        op_space_inertia(&self.model, &mut self.data, self.op).expect("op inertia");
        let inverse = self.data.op.inverse_inertia;
        let directions = constraint_directions::<Planar>(&inverse, self.model.length_scale, 0.02);
        let terms = op_space_terms(&self.data, &user_wrench, LocalModelTerms::full());
        let pose = OpPose::of_op(&self.model, &self.data, self.op);
        let mut op_pose = vec![0.0; 3];
        pose.to_slice(&mut op_pose);
        let twist = kinloop_linkage::algorithms::local_model::op_twist(&self.model, &self.data, self.op);
        let mut triangle = Vec::new();
        for r in 0..3 {
            for c in r..3 {
                triangle.push(inverse[(r, c)]);
            }
        }
        let config = self.send_config.then(|| {
            self.config_terms.fill_from(
                &self.model,
                &mut self.data,
                &self.q,
                &self.qd,
                &user_wrench,
                LocalModelTerms::full(),
            );
            let t = &self.config_terms;
            let n = t.q.len();
            let mut mass = Vec::new();
            for r in 0..n {
                for c in r..n {
                    mass.push(t.mass_matrix[(r, c)]);
                }
            }
            ConfigTerms {
                q: t.q.as_slice().to_vec(),
                qd: t.qd.as_slice().to_vec(),
                mass_matrix: mass,
                closure_jacobian: t.closure_jacobian.as_slice().to_vec(),
                closure_bias_stab: t.closure_bias_stab.as_slice().to_vec(),
                generalized_bias: t.generalized_bias.as_slice().to_vec(),
                op_jacobian: t.op_jacobian.as_slice().to_vec(),
                op_bias: t.op_bias.as_slice().to_vec(),
            }
        });
        self.seq += 1;
        Snapshot {
            seq: self.seq,
            server_time_s: self.time_s,
            ve_step: self.seq,
            user_id: 1,
            uplink_time_s: self.coupling.target_time_s,
            op_pose,
            op_twist: twist.as_slice().to_vec(),
            inverse_inertia: triangle,
            bias_accel: terms.bias.as_slice().to_vec(),
            directions: directions.directions.as_slice().to_vec(),
            singular_values: directions.singular_values.as_slice().to_vec(),
            constraint_count: directions.count as u8,
            contacts: Vec::new(),
            others: OtherUsers::default(),
            config,
            energy: kinloop_protocol::PortEnergy::zero(3),
        }
    }
}

/// A core configuration for the paper's experiment on the `paper` device: the paper's gains and a short
/// ramp-in (the paper's user pushes from t = 0; a long ramp would let the device run off first).
pub fn paper_config(mode: ConstraintMode, form: ModelForm) -> CoreConfig {
    let mut config = CoreConfig::new(DevicePreset::Paper.spec(SceneKind::Planar).expect("planar"));
    config.constraint_mode = mode;
    config.form = form;
    config.gains = GainChoice::Paper;
    config.safety.ramp_in = Duration::from_millis(5);
    config
}

/// VE, core and simulated device in virtual time, 1 ms per tick, snapshots and uplinks delivered at once.
pub struct ClosedLoop {
    pub ve: TestbedVe,
    pub core: HapticCore<Planar>,
    pub rig: SimulatedRig<Planar>,
    pub now: Duration,
    last_uplink: Option<Uplink>,
    /// Deliver snapshots only while this is true (to test staleness).
    pub link_up: bool,
}

/// What one tick of the closed loop produced.
pub struct LoopSample {
    pub report: TickReport<Planar>,
    pub ve_op: OpPose<Planar>,
    pub device: DeviceState<Planar>,
    pub command: Vector3<f64>,
    /// True when the core sent an uplink this tick.
    pub uplink_sent: bool,
}

impl ClosedLoop {
    /// The paper's experiment: constant wrench at link 2, `paper` device, given mode and form.
    pub fn paper(mode: ConstraintMode, form: ModelForm) -> Self {
        let user: Box<dyn SimulatedUser<Planar>> =
            Box::new(ConstantWrench::<Planar>::from_values(&builtin::PAPER_WRENCH).expect("3 values"));
        Self::with(paper_config(mode, form), user, form == ModelForm::Config)
    }

    /// Any configuration and user on the `paper` device.
    pub fn with(config: CoreConfig, user: Box<dyn SimulatedUser<Planar>>, send_config: bool) -> Self {
        let ve = TestbedVe::new(send_config);
        let core = HapticCore::new(config, &ve.welcome()).expect("core");
        let device = DevicePreset::Paper.build::<Planar>().expect("paper device");
        ClosedLoop {
            ve,
            core,
            rig: SimulatedRig::new(device, user),
            now: Duration::ZERO,
            last_uplink: None,
            link_up: true,
        }
    }

    /// One millisecond: the VE steps under the last uplink and snapshots; the client reads the device,
    /// takes the snapshot, ticks and commands.
    pub fn tick(&mut self) -> LoopSample {
        if let Some(uplink) = self.last_uplink.take() {
            self.ve.apply_uplink(&uplink);
        }
        self.ve.step();
        if self.link_up {
            let snapshot = self.ve.snapshot();
            self.core.handle_snapshot(self.now, &snapshot).expect("valid snapshot");
        }
        let device = self.rig.read(self.now).expect("simulated device reads");
        let out = self.core.tick(self.now, &device);
        let command = out.command;
        let uplink_sent = out.uplink.is_some();
        if let Some(uplink) = out.uplink {
            if self.link_up {
                self.last_uplink = Some(uplink.clone());
            }
        }
        let report = *out.report;
        self.rig.command(self.now, &command).expect("finite command");
        self.now += Duration::from_millis(1);
        let ve_op = self.ve.op_pose();
        LoopSample { report, ve_op, device, command, uplink_sent }
    }
}
