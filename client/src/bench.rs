//! Measurements `kinloop bench --json` reports for the client, kept here so the numbers come from the code
//! that ships: `client/tick_testbed` (snapshot intake + local model + controllers + safety + uplink, no
//! device plant), the device exchange of a tick (`read` then `command`) on a simulated device and through
//! a DHD library, and the real-time loop's timing against a simulated device.

use std::hint::black_box;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, math::space::Planar, math::space::SceneKind, model::builtin,
    model::data::Data, model::Model,
};
use kinloop_linkage::{
    algorithms::local_model::{op_space_terms, op_twist, LocalModelTerms},
    math::space::OpPose,
};
use kinloop_protocol::{CouplingGains, Mapping, OpSummary, SceneSummary, Snapshot, Welcome};
use nalgebra::{UnitComplex, Vector2, Vector3};

use crate::core::{CoreConfig, GainChoice, HapticCore};
use crate::device::dhd::{DhdLibrary, OpenedDhd};
use crate::device::{DevicePreset, DeviceState, HapticDevice, SimulatedRig};
use crate::driver::rt_loop::{self, LoopRings, LoopSettings, LoopShared};
use crate::driver::timing::LatenessSummary;
use crate::user::UserSpec;

/// Why a measurement could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The testbed did not build or solve.
    #[error("testbed: {0}")]
    Testbed(String),
    /// A thread could not start.
    #[error("thread: {0}")]
    Thread(String),
}

/// The paper's testbed at q0, as a server would describe it: the welcome (one-to-one mapping, the surveyed OP)
/// and a snapshot of the OP `link2` at rest.
pub fn testbed_session() -> Result<(Welcome, Snapshot), BenchError> {
    let err = |e: &dyn std::fmt::Display| BenchError::Testbed(e.to_string());
    let scene = builtin::scene("paper-testbed")
        .ok_or_else(|| BenchError::Testbed("not built in".into()))?
        .map_err(|e| err(&e))?;
    let model: Model<Planar> = Model::compile(&scene, "paper-testbed").map_err(|e| err(&e))?;
    let mut data = Data::new(&model);
    let op = model.op_index("link2").ok_or_else(|| BenchError::Testbed("no op link2".into()))?;
    forward_dynamics(&model, &mut data, &model.q0, &model.qd0, &mut ()).map_err(|e| err(&e))?;
    op_space_inertia(&model, &mut data, op).map_err(|e| err(&e))?;
    let inverse = data.op.inverse_inertia;
    let reach = kinloop_linkage::algorithms::reach::survey_op(&model, op, &Default::default()).map_err(|e| err(&e))?;
    let directions = constraint_directions::<Planar>(&inverse, model.length_scale, DEFAULT_THRESHOLD);
    let terms = op_space_terms(&data, &Vector3::zeros(), LocalModelTerms::full());
    let mut op_pose = vec![0.0; 3];
    OpPose::of_op(&model, &data, op).to_slice(&mut op_pose);
    let triangle = (0..3).flat_map(|r| (r..3).map(move |c| (r, c))).map(|(r, c)| inverse[(r, c)]).collect();
    let welcome = Welcome {
        session_id: 1,
        user_id: 1,
        scene: SceneSummary {
            name: "paper-testbed".into(),
            kind: SceneKind::Planar,
            n: model.nv() as u32,
            m: model.nc() as u32,
            ball_rates: Vec::new(),
            op_dim: 3,
            op_name: "link2".into(),
            length_scale: model.length_scale,
        },
        ve_rate_hz: 1000.0,
        snapshot_rate_hz: 1000.0,
        mapping: Mapping::identity(),
        coupling: CouplingGains { stiffness: vec![1000.0, 1000.0, 1e4], damping: vec![100.0, 100.0, 1e4] },
        op: OpSummary::from_reach(&reach, &OpPose::of_op(&model, &data, op)),
    };
    let snapshot = Snapshot {
        seq: 1,
        server_time_s: 0.0,
        ve_step: 1,
        user_id: 1,
        uplink_time_s: 0.0,
        op_pose,
        op_twist: op_twist(&model, &data, op).as_slice().to_vec(),
        inverse_inertia: triangle,
        bias_accel: terms.bias.as_slice().to_vec(),
        directions: directions.directions.as_slice().to_vec(),
        singular_values: directions.singular_values.as_slice().to_vec(),
        constraint_count: directions.count as u8,
        contacts: Vec::new(),
        other_manipulators: 0,
        config: None,
        energy: kinloop_protocol::PortEnergy::zero(3),
    };
    Ok((welcome, snapshot))
}

/// Mean nanoseconds of one haptic tick on the testbed: a fresh snapshot taken in (as at 1 kHz snapshots),
/// then the core's tick (local model, controllers, safety, uplink) for the `paper` device in stiffness mode.
pub fn client_tick_testbed(iters: u64) -> Result<f64, BenchError> {
    let (welcome, mut snapshot) = testbed_session()?;
    let spec = DevicePreset::Paper.spec(SceneKind::Planar).map_err(|e| BenchError::Testbed(e.to_string()))?;
    let mut config = CoreConfig::new(spec);
    config.gains = GainChoice::Paper;
    let mut core = HapticCore::<Planar>::new(config, &welcome).map_err(|e| BenchError::Testbed(e.to_string()))?;
    let mut device = DeviceState::<Planar> {
        pose: OpPose { position: Vector2::new(0.0, 0.0), rotation: UnitComplex::identity() },
        twist: Vector3::zeros(),
        hand_wrench: Some(Vector3::from_column_slice(&builtin::PAPER_WRENCH)),
        grasped: None,
    };
    let mut tick = |k: u64| {
        let now = Duration::from_micros(1000 * k);
        snapshot.seq = k + 1;
        let _ = core.handle_snapshot(now, black_box(&snapshot));
        // A handle that moves a little, so no branch sees a constant input.
        device.pose.position.x = 1e-4 * ((k % 64) as f64);
        black_box(core.tick(now, black_box(&device)).command);
    };
    for k in 0..iters / 10 + 1 {
        tick(k);
    }
    let start = Instant::now();
    for k in 0..iters {
        tick(iters / 10 + 1 + k);
    }
    Ok(start.elapsed().as_nanos() as f64 / iters.max(1) as f64)
}

/// Mean nanoseconds of the device exchange a haptic tick makes, `read` then `command` (a 1 N push along x),
/// over `iters` ticks 1 ms apart on the loop's clock.
fn device_exchange(device: &mut dyn HapticDevice<Planar>, iters: u64) -> Result<f64, BenchError> {
    let push = Vector3::new(1.0, 0.0, 0.0);
    let mut tick = |k: u64| -> Result<(), BenchError> {
        let now = Duration::from_millis(k);
        let state = device.read(now).map_err(|e| BenchError::Testbed(e.to_string()))?;
        black_box(state);
        device.command(now, black_box(&push)).map_err(|e| BenchError::Testbed(e.to_string()))
    };
    for k in 0..iters / 10 + 1 {
        tick(k)?;
    }
    let start = Instant::now();
    for k in 0..iters {
        tick(iters / 10 + 1 + k)?;
    }
    Ok(start.elapsed().as_nanos() as f64 / iters.max(1) as f64)
}

/// [`device_exchange`] on a simulated Falcon (its plant integrated over each millisecond) held by a relaxed
/// hand: what `--device sim:falcon` costs the loop.
pub fn device_tick_sim_falcon(iters: u64) -> Result<f64, BenchError> {
    let built = |e: &dyn std::fmt::Display| BenchError::Testbed(e.to_string());
    let device = DevicePreset::Falcon.build::<Planar>().map_err(|e| built(&e))?;
    let user = UserSpec::soft_hand().build::<Planar>(&Default::default()).map_err(|e| built(&e))?;
    device_exchange(&mut SimulatedRig::new(device, user), iters)
}

/// [`device_exchange`] through the DHD library at `library` (device 0, a planar scene's axes): the calls a
/// `--device dhd` tick makes across the FFI. Through the fake library this is the fake's cost (its plant
/// included), not a USB device's.
pub fn device_tick_dhd(library: &std::path::Path, iters: u64) -> Result<f64, BenchError> {
    let failed = |e: &dyn std::fmt::Display| BenchError::Testbed(e.to_string());
    let library = DhdLibrary::load(library).map_err(|e| failed(&e))?;
    let opened = OpenedDhd::open(Arc::new(library), 0).map_err(|e| failed(&e))?;
    device_exchange(&mut opened.into_device::<Planar>(), iters)
}

/// Runs the real-time loop for `duration` at `rate_hz` against a simulated `paper` device held by the
/// paper's user, with fresh testbed snapshots fed from another thread at about 1 kHz (no network), and
/// returns its lateness (`misses` = ticks more than 500 µs late). `realtime_priority` asks for SCHED_FIFO.
pub fn realtime_loop_sim(
    duration: Duration,
    rate_hz: f64,
    realtime_priority: bool,
) -> Result<LatenessSummary, BenchError> {
    let (welcome, snapshot) = testbed_session()?;
    let built = |e: &dyn std::fmt::Display| BenchError::Testbed(e.to_string());
    let device = DevicePreset::Paper.build::<Planar>().map_err(|e| built(&e))?;
    let user = UserSpec::paper().build::<Planar>(&Default::default()).map_err(|e| built(&e))?;
    let spec = DevicePreset::Paper.spec(SceneKind::Planar).map_err(|e| built(&e))?;
    let mut config = CoreConfig::new(spec);
    config.period = Duration::from_secs_f64(1.0 / rate_hz);
    let core = Box::new(HapticCore::<Planar>::new(config, &welcome).map_err(|e| built(&e))?);
    let (mut snapshots_tx, snapshots_rx) = rtrb::RingBuffer::new(16);
    let (spent_tx, mut spent_rx) = rtrb::RingBuffer::new(32);
    let (uplinks_tx, mut uplinks_rx) = rtrb::RingBuffer::new(64);
    let (mut free_tx, free_rx) = rtrb::RingBuffer::new(64);
    let template = kinloop_protocol::Uplink::at_rest(0, 3, 3);
    for _ in 0..64 {
        let _ = free_tx.push(template.clone());
    }
    let (_cores_tx, cores_rx) = rtrb::RingBuffer::new(1);
    let (spent_cores_tx, _spent_cores_rx) = rtrb::RingBuffer::new(1);
    let (reports_tx, _reports_rx) = rtrb::RingBuffer::new(1024);
    let shared = Arc::new(LoopShared::default());
    let feeder_shared = shared.clone();
    let feeder = std::thread::Builder::new()
        .name("bench-feeder".into())
        .spawn(move || {
            let mut seq = 1;
            while !feeder_shared.stop.load(Ordering::Relaxed) {
                seq += 1;
                let mut s = snapshot.clone();
                s.seq = seq;
                let _ = snapshots_tx.push((std::time::Instant::now(), s));
                while spent_rx.pop().is_ok() {}
                while let Ok(u) = uplinks_rx.pop() {
                    let _ = free_tx.push(u);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        })
        .map_err(|e| BenchError::Thread(e.to_string()))?;
    let rings = LoopRings {
        snapshots: snapshots_rx,
        spent_snapshots: spent_tx,
        uplinks: uplinks_tx,
        free_uplinks: free_rx,
        cores: cores_rx,
        spent_cores: spent_cores_tx,
        records: None,
        reports: reports_tx,
        uplink_sender: None,
    };
    let settings =
        LoopSettings { rate_hz, duration: Some(duration), realtime_priority, busy_wait: true, report_every: 1000 };
    let loop_shared = shared.clone();
    let rig = SimulatedRig::new(device, user);
    let haptic = std::thread::Builder::new()
        .name("bench-haptic".into())
        .spawn(move || rt_loop::run(rig, core, rings, loop_shared, settings))
        .map_err(|e| BenchError::Thread(e.to_string()))?;
    let _ = haptic.join();
    shared.stop.store(true, Ordering::Relaxed);
    let _ = feeder.join();
    Ok(shared.lateness.summary())
}
