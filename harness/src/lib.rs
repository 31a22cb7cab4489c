//! The virtual-time harness: one [`VeCore`] and N [`HapticCore`]s with simulated devices and users, joined by
//! seeded link emulators, stepped as a discrete-event simulation — str0m's test style: whichever party is
//! due next runs, and every datagram goes through the real codec and the emulated link.
//!
//! Nothing here reads a clock (except to measure the VE's compute cost, which is reported but never feeds
//! back), so the same plan and seeds give the same results bit for bit, far faster than real time.

pub mod hooks;
pub mod record;

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use kinloop_client::core::{ConstraintMode, CoreConfig, HapticCore, ModelForm};
use kinloop_client::device::presets::DevicePreset;
use kinloop_client::device::rig::SimulatedRig;
use kinloop_client::device::{HapticDevice, SimulatedDevice};
use kinloop_client::user::{UserContext, UserSpec};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{
    math::space::Planar, math::space::SceneKind, math::space::Space, math::space::Spatial, math::space::VecOps,
    model::scene::Scene, model::Model,
};
use kinloop_protocol::codec::{decode_datagram, encode_datagram_into};
use kinloop_protocol::emulator::{LinkConfig, LinkEmulator};
use kinloop_protocol::{Datagram, LocalModelForm, MappingRequest, Role, SessionShape};
use kinloop_server::core::{JoinRequest, PassivityObserver, UserId, VeConfig, VeCore};

pub use hooks::{CoreHooks, Plain, Probe, TickSample};
pub use record::{ClientSample, Recording, VeSample};

/// One simulated participant.
#[derive(Clone, Debug)]
pub struct ClientPlan {
    /// Name (logs and charts).
    pub name: String,
    /// Operational point to hold.
    pub op: String,
    /// Manipulator or observer.
    pub role: Role,
    /// Simulated device.
    pub device: DevicePreset,
    /// Simulated user.
    pub user: UserSpec,
    /// What the client asks of the mapping (the server chooses what is left `None`).
    pub mapping: MappingRequest,
    /// Stiffness or impedance rendering of the constrained directions.
    pub constraint_mode: ConstraintMode,
    /// Local-model form.
    pub form: ModelForm,
    /// Haptic loop rate, Hz.
    pub rate_hz: f64,
    /// Client → server link.
    pub uplink: LinkConfig,
    /// Server → client link.
    pub downlink: LinkConfig,
    /// When the client joins.
    pub join_at: Duration,
    /// When it leaves (never if `None`).
    pub leave_at: Option<Duration>,
    /// Changes to the client's core configuration (gains, safety, ...), applied after the defaults.
    pub tweak: Option<fn(&mut CoreConfig)>,
    /// Like `tweak`, but a closure that may capture values (the gains of one point of a sweep); applied
    /// after `tweak`.
    pub configure: Option<CoreEdit>,
}

/// A change to a client's [`CoreConfig`] that may capture values; cheap to clone and shareable across the
/// threads of a sweep.
#[derive(Clone)]
pub struct CoreEdit(Arc<dyn Fn(&mut CoreConfig) + Send + Sync>);

impl CoreEdit {
    /// Wraps `edit`.
    pub fn new(edit: impl Fn(&mut CoreConfig) + Send + Sync + 'static) -> Self {
        CoreEdit(Arc::new(edit))
    }

    /// Applies the edit.
    pub fn apply(&self, config: &mut CoreConfig) {
        (self.0)(config)
    }
}

impl std::fmt::Debug for CoreEdit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CoreEdit(..)")
    }
}

impl ClientPlan {
    /// The paper's user: the `paper` device mapped one to one at OP `link2`, the constant wrench
    /// (−0.5 N, 0, −0.0025 N m), stiffness mode, 1 kHz, a perfect network.
    pub fn paper(name: &str) -> Self {
        ClientPlan {
            user: UserSpec::paper(),
            mapping: MappingRequest { position_scale: Some(1.0), force_scale: Some(1.0), gravity_compensation: false },
            ..ClientPlan::new(name, "link2", DevicePreset::Paper)
        }
    }

    /// A user as `kinloop-client` makes one by default: `device` at `op` with a relaxed hand touring the
    /// OP's reach, the server's mapping and the designed gains, stiffness mode, 1 kHz, a perfect network.
    pub fn new(name: &str, op: &str, device: DevicePreset) -> Self {
        ClientPlan {
            name: name.to_string(),
            op: op.into(),
            role: Role::Manipulator,
            device,
            user: UserSpec::soft_hand(),
            mapping: MappingRequest::default(),
            constraint_mode: ConstraintMode::Stiffness,
            form: ModelForm::Op,
            rate_hz: 1000.0,
            uplink: LinkConfig::default(),
            downlink: LinkConfig::default(),
            join_at: Duration::ZERO,
            leave_at: None,
            tweak: None,
            configure: None,
        }
    }

    /// The core's configuration for this participant's device: mode, form and rate from the plan, then
    /// `tweak` and `configure`.
    pub fn core_config(&self, spec: kinloop_client::device::DeviceSpec) -> CoreConfig {
        let mut config = CoreConfig::new(spec);
        config.constraint_mode = self.constraint_mode;
        config.form = self.form;
        config.period = Duration::from_secs_f64(1.0 / self.rate_hz);
        if let Some(tweak) = self.tweak {
            tweak(&mut config);
        }
        if let Some(edit) = &self.configure {
            edit.apply(&mut config);
        }
        config
    }

    /// The same network conditions both ways (each direction gets its own seed).
    pub fn with_link(mut self, link: LinkConfig) -> Self {
        self.downlink = LinkConfig { seed: link.seed.wrapping_mul(2).wrapping_add(1), ..link.clone() };
        self.uplink = link;
        self
    }
}

/// A whole session.
#[derive(Clone, Debug)]
pub struct SessionPlan {
    /// The scene.
    pub scene: Scene,
    /// The VE's configuration.
    pub ve: VeConfig,
    /// The participants.
    pub clients: Vec<ClientPlan>,
    /// Simulated time.
    pub duration: Duration,
    /// Record every this many haptic ticks of each client (and VE ticks); 0 records nothing.
    pub record_every: u32,
}

impl SessionPlan {
    /// The paper's session: the testbed, the paper's VE, one paper user, 3 s, recording every tick.
    pub fn paper() -> Result<Self> {
        Ok(SessionPlan {
            scene: kinloop_linkage::model::builtin::scene("paper-testbed").context("built in")??,
            ve: VeConfig::paper(),
            clients: vec![ClientPlan::paper("user")],
            duration: Duration::from_secs(3),
            record_every: 1,
        })
    }

    /// [`SessionPlan::paper`] as section VI runs it: the paper's gains, `mode` and `form`, and a short ramp-in
    /// (the paper's user pushes from t = 0; a long ramp would let the device run off first).
    pub fn paper_manipulation(mode: ConstraintMode, form: ModelForm) -> Result<Self> {
        let mut plan = Self::paper()?;
        let client = &mut plan.clients[0];
        client.constraint_mode = mode;
        client.form = form;
        client.tweak = Some(|config| {
            config.gains = kinloop_client::core::GainChoice::Paper;
            config.safety.ramp_in = Duration::from_millis(5);
        });
        Ok(plan)
    }
}

/// What a session measured.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SessionSummary {
    /// Simulated seconds.
    pub duration_s: f64,
    /// VE steps taken.
    pub ve_steps: u64,
    /// Largest closure error (m) over the session.
    pub max_closure_error: f64,
    /// Wall-clock compute of the VE per simulated second (µs/s).
    pub ve_compute_us_per_s: f64,
    /// Wall-clock compute of all haptic cores per simulated second (µs/s).
    pub client_compute_us_per_s: f64,
    /// VE states that went non-finite and were restored.
    pub ve_restores: u64,
    /// The round trips the VE weighted the users' sharing of one another's hands by.
    pub ve_sharing: kinloop_server::core::metrics::SharingMetrics,
    /// Per-client results.
    pub clients: Vec<ClientSummary>,
    /// Wall-clock seconds the whole simulation took.
    pub wall_s: f64,
}

/// One client's results.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ClientSummary {
    /// Name.
    pub name: String,
    /// Ticks run.
    pub ticks: u64,
    /// Largest commanded force or torque over the device's limit (≤ 1 always).
    pub max_force_ratio: f64,
    /// RMS distance between the device and the VE's operational point, in the device's space (what the hand
    /// feels: the VE distance times the mapping's position scale), m, over active ticks with a hand on the
    /// handle (a presence sensor's `HAND_OFF` ticks are left out of this and the next two).
    pub device_op_rms_m: f64,
    /// Largest device–OP distance, device space (m).
    pub device_op_max_m: f64,
    /// Largest distance between the VE's OP and the device as the VE has heard of it: the device's position
    /// at the client time of the newest uplink the VE had used (for a VE that leads its target, the later
    /// client time it aims at, `Snapshot::uplink_time_s`), device space (m). The VE follows the device
    /// through the uplink, so under delay it trails the device by the delay's worth of motion
    /// (`device_op_max_m` grows with it); this distance grows only when the VE fails to follow.
    pub device_op_heard_max_m: f64,
    /// RMS distance the device has moved since the pose the VE has heard of (device space, m): the device-OP
    /// distance a VE sitting exactly on the device as heard would show. A VE that only follows what it has
    /// heard cannot do better than this on average; less needs a VE that runs ahead of the hand (predicts it),
    /// with energy the hand has not yet given.
    pub device_unheard_rms_m: f64,
    /// RMS distance between the device and the local model's OP (the client's tracking error), device space, m.
    pub device_model_rms_m: f64,
    /// Fraction of active ticks with the command clamped at the device limit.
    pub saturated_fraction: f64,
    /// Snapshots the client accepted.
    pub snapshots: u64,
    /// Uplinks the client sent.
    pub uplinks: u64,
    /// Fraction of uplinks the deadband saved.
    pub uplink_saving: f64,
    /// Non-finite values refused by the safety layer.
    pub non_finite: u64,
    /// Uplinks the server refused (undecodable or failing its guards).
    pub uplinks_refused: u64,
    /// Snapshots the client could not decode.
    pub snapshots_refused: u64,
    /// Energy the user's coupling absorbed from the VE, as the VE's passivity observer booked it (J; negative:
    /// the coupling generated energy). Zero unless the VE runs with `passivity`.
    pub passivity_absorbed_j: f64,
    /// VE ticks in which the passivity controller scaled this user's PD down.
    pub passivity_activations: u64,
    /// The mapping the server chose (device metres per VE metre, device newtons per VE newton).
    pub position_scale: f64,
    /// See `position_scale`.
    pub force_scale: f64,
    /// The graphics controller's gains the server chose for this user, K_g then B_g per axis.
    pub coupling: Vec<f64>,
    /// The client's gains (device units): k_j, b_j, then K_pc and B_pc per axis.
    pub gains: Vec<f64>,
}

struct Participant<S: Space> {
    plan: ClientPlan,
    /// The device until the participant joins; then it is in the rig, with the user the welcome shaped.
    device: Option<SimulatedDevice<S>>,
    rig: Option<SimulatedRig<S>>,
    core: Option<HapticCore<S>>,
    user_id: Option<UserId>,
    up: LinkEmulator<Vec<u8>>,
    down: LinkEmulator<Vec<u8>>,
    period: Duration,
    next_tick: Duration,
    ticks: u64,
    left: bool,
    op_sum_sq: f64,
    op_max: f64,
    /// The device's pose by tick time since the VE's newest heard uplink, oldest first (`device_op_heard_max_m`).
    heard: VecDeque<(f64, OpPose<S>)>,
    heard_max: f64,
    /// Sum of squares and count of the device's distance from its pose as heard (`device_unheard_rms_m`).
    unheard_sum_sq: f64,
    unheard_ticks: u64,
    model_sum_sq: f64,
    active_ticks: u64,
    /// Active ticks with a hand on the handle (the device-OP figures' count).
    held_ticks: u64,
    saturated: u64,
    compute: Duration,
    uplinks_refused: u64,
    snapshots_refused: u64,
    passivity: PassivityObserver,
    /// Scales, coupling and gains chosen at the join, for the summary.
    chosen: (f64, f64, Vec<f64>, Vec<f64>),
}

/// Device poses kept for `device_op_heard_max_m`: 16 s of a 1 kHz loop.
const HEARD_HISTORY: usize = 16_384;

/// Runs a session to its end; `progress` is called with the simulated time from time to time.
pub fn run(plan: &SessionPlan, progress: &mut dyn FnMut(Duration)) -> Result<(SessionSummary, Recording)> {
    match plan.scene.kind {
        SceneKind::Planar => Session::<Planar>::new(plan)?.run(progress),
        SceneKind::Spatial => Session::<Spatial>::new(plan)?.run(progress),
    }
}

/// A running session in space `S`.
pub struct Session<S: Space> {
    ve: VeCore<S>,
    shape: SessionShape,
    participants: Vec<Participant<S>>,
    duration: Duration,
    record_every: u32,
    recording: Recording,
    max_closure: f64,
    ve_compute: Duration,
    encode_buf: Vec<u8>,
    ve_ticks_seen: u64,
    now: Duration,
}

impl<S: Space> Session<S> {
    /// Builds the VE and every participant (none has joined yet).
    pub fn new(plan: &SessionPlan) -> Result<Self> {
        let model: Model<S> = Model::compile(&plan.scene, &plan.scene.name)?;
        let ve = VeCore::new(model, plan.ve.clone()).map_err(|e| anyhow!("VE configuration: {e}"))?;
        let shape = ve.session_shape();
        let mut participants = Vec::with_capacity(plan.clients.len());
        for c in &plan.clients {
            let device = c.device.build::<S>().map_err(|e| anyhow!("{}: device: {e}", c.name))?;
            anyhow::ensure!(c.rate_hz > 0.0 && c.rate_hz <= 100_000.0, "{}: haptic rate {} Hz", c.name, c.rate_hz);
            let period = Duration::from_secs_f64(1.0 / c.rate_hz);
            participants.push(Participant {
                device: Some(device),
                rig: None,
                core: None,
                user_id: None,
                up: LinkEmulator::new(c.uplink.clone()).map_err(|e| anyhow!("{}: uplink: {e}", c.name))?,
                down: LinkEmulator::new(c.downlink.clone()).map_err(|e| anyhow!("{}: downlink: {e}", c.name))?,
                period,
                next_tick: c.join_at,
                ticks: 0,
                left: false,
                op_sum_sq: 0.0,
                op_max: 0.0,
                heard: VecDeque::new(),
                heard_max: 0.0,
                unheard_sum_sq: 0.0,
                unheard_ticks: 0,
                model_sum_sq: 0.0,
                active_ticks: 0,
                held_ticks: 0,
                saturated: 0,
                compute: Duration::ZERO,
                uplinks_refused: 0,
                snapshots_refused: 0,
                passivity: PassivityObserver::default(),
                chosen: (1.0, 1.0, Vec::new(), Vec::new()),
                plan: c.clone(),
            });
        }
        let names = plan.clients.iter().map(|c| c.name.clone()).collect();
        Ok(Session {
            ve,
            shape,
            participants,
            duration: plan.duration,
            record_every: plan.record_every,
            recording: Recording::new(names),
            max_closure: 0.0,
            ve_compute: Duration::ZERO,
            encode_buf: Vec::with_capacity(2048),
            ve_ticks_seen: 0,
            now: Duration::ZERO,
        })
    }

    /// The VE core (for tests that inspect it).
    pub fn ve(&self) -> &VeCore<S> {
        &self.ve
    }

    fn join<H: CoreHooks<S>>(&mut self, i: usize, now: Duration, hooks: &mut H) -> Result<()> {
        let p = &mut self.participants[i];
        let request = JoinRequest {
            name: p.plan.name.clone(),
            role: p.plan.role,
            op: p.plan.op.clone(),
            form: match p.plan.form {
                ModelForm::Op => LocalModelForm::OpSpace,
                ModelForm::Config => LocalModelForm::ConfigSpace,
            },
            device: p.device.as_ref().map(|d| d.spec().caps()),
            mapping: p.plan.mapping.clone(),
        };
        // The server's own view of the link, as the QUIC driver takes it from the connection: the emulated
        // links' mean delays both ways.
        let round_trip = p.plan.uplink.delay + p.plan.downlink.delay;
        let joined = self
            .ve
            .join_measured(now, request, Some(round_trip))
            .map_err(|e| anyhow!("{} refused: {e}", p.plan.name))?;
        // The wire's checks on the welcome, as the network's handshake makes them: what a real client would be
        // refused, a simulated one is too.
        if let Err(error) = kinloop_protocol::codec::validate::welcome(&joined.welcome) {
            let what = format!("its welcome would be invalid: {error}");
            return Err(anyhow!("{} refused: {}", p.plan.name, kinloop_protocol::RefusalReason::Unservable { what }));
        }
        let spec = p.device.take().context("a participant joins once")?.spec().clone();
        let config = p.plan.core_config(spec);
        let mut core = HapticCore::new(config, &joined.welcome).map_err(|e| anyhow!("{}: {e}", p.plan.name))?;
        // The hand grasps the handle where the linkage is: the device starts at the OP's place in its
        // workspace, and the user tours the reach the welcome describes.
        let op_position = S::Point::from_slice(&joined.welcome.op.position);
        let device =
            p.plan.device.build_at::<S>(core.home(&op_position)).map_err(|e| anyhow!("{}: {e}", p.plan.name))?;
        let context = UserContext::from_welcome(&joined.welcome);
        let user = p.plan.user.build::<S>(&context).map_err(|e| anyhow!("{}: user: {e}", p.plan.name))?;
        p.rig = Some(SimulatedRig::new(device, user));
        hooks.joined(i, &joined.welcome);
        let (w, g) = (&joined.welcome, &core.gains().device);
        let mut gains = vec![g.joint_stiffness, g.joint_damping];
        gains.extend(g.position_stiffness.iter().chain(&g.position_damping));
        let coupling = w.coupling.stiffness.iter().chain(&w.coupling.damping).copied().collect();
        p.chosen = (w.mapping.position_scale, w.mapping.force_scale, coupling, gains);
        core.set_one_way_delay(p.plan.downlink.delay);
        p.core = Some(core);
        p.user_id = Some(joined.user_id);
        Ok(())
    }

    /// The time of the next event: a VE tick, a client's tick or a datagram due on a link.
    pub fn next_event(&self) -> Duration {
        let mut next = self.ve.poll_timeout();
        for p in &self.participants {
            if !p.left {
                next = next.min(p.next_tick);
            }
            for t in [p.up.poll_timeout(), p.down.poll_timeout()].into_iter().flatten() {
                next = next.min(t);
            }
        }
        next
    }

    /// Handles everything due at `now`: datagrams first, then the VE's tick (its tick happens "before"
    /// clients read), then every client's tick. `now` never goes back; events not yet due wait.
    pub fn step(&mut self, now: Duration) -> Result<()> {
        self.step_with(now, &mut Plain)
    }

    /// [`Session::step`] with `hooks` around every call on a core.
    pub fn step_with<H: CoreHooks<S>>(&mut self, now: Duration, hooks: &mut H) -> Result<()> {
        self.now = now;
        self.deliver_links(now, hooks)?;
        if self.ve.poll_timeout() <= now {
            let t = Instant::now();
            self.ve.handle_timeout(now);
            self.ve_compute += t.elapsed();
            self.after_ve_tick(now);
            self.send_snapshots(now);
        }
        for i in 0..self.participants.len() {
            if self.participants[i].left || self.participants[i].next_tick > now {
                continue;
            }
            self.client_tick(i, now, hooks)?;
        }
        Ok(())
    }

    /// Steps every event due up to `until` (inclusive) with `hooks`.
    pub fn run_until_with<H: CoreHooks<S>>(&mut self, until: Duration, hooks: &mut H) -> Result<()> {
        while self.next_event() <= until {
            let now = self.next_event().max(self.now);
            self.step_with(now, hooks)?;
        }
        Ok(())
    }

    /// The time of the last step.
    pub fn now(&self) -> Duration {
        self.now
    }

    /// Participant `i`'s haptic core, once it has joined.
    pub fn core(&self, i: usize) -> Option<&HapticCore<S>> {
        self.participants.get(i).and_then(|p| p.core.as_ref())
    }

    /// Participant `i`'s haptic core, for a test that calls it between steps.
    pub fn core_mut(&mut self, i: usize) -> Option<&mut HapticCore<S>> {
        self.participants.get_mut(i).and_then(|p| p.core.as_mut())
    }

    /// Participant `i`'s device and user, once it has joined.
    pub fn rig(&self, i: usize) -> Option<&SimulatedRig<S>> {
        self.participants.get(i).and_then(|p| p.rig.as_ref())
    }

    /// Participant `i`'s device and user, for a test that changes the user between steps.
    pub fn rig_mut(&mut self, i: usize) -> Option<&mut SimulatedRig<S>> {
        self.participants.get_mut(i).and_then(|p| p.rig.as_mut())
    }

    /// Runs to the end of the plan: [`Session::step`] at each [`Session::next_event`].
    pub fn run(mut self, progress: &mut dyn FnMut(Duration)) -> Result<(SessionSummary, Recording)> {
        let wall = Instant::now();
        let mut now = Duration::ZERO;
        let mut last_progress = Duration::ZERO;
        loop {
            let next = self.next_event();
            if next > self.duration {
                break;
            }
            now = next.max(now);
            self.step(now)?;
            if now - last_progress >= Duration::from_millis(100) {
                last_progress = now;
                progress(now);
            }
        }
        progress(self.duration);
        Ok(self.finish(wall.elapsed()))
    }

    fn deliver_links<H: CoreHooks<S>>(&mut self, now: Duration, hooks: &mut H) -> Result<()> {
        for i in 0..self.participants.len() {
            // Datagrams that do not decode (a client reporting absurd values, say) are refused and counted,
            // as a real server and client would.
            while let Some(bytes) = self.participants[i].up.poll(now) {
                let Some(user) = self.participants[i].user_id else { continue };
                match decode_datagram(&bytes, &self.shape) {
                    Ok(Datagram::Uplink(u)) => {
                        if self.ve.handle_uplink(now, user, &u).is_err() {
                            self.participants[i].uplinks_refused += 1;
                        }
                    }
                    _ => self.participants[i].uplinks_refused += 1,
                }
            }
            while let Some(bytes) = self.participants[i].down.poll(now) {
                match (decode_datagram(&bytes, &self.shape), self.participants[i].core.as_mut()) {
                    (Ok(Datagram::Snapshot(mut s)), Some(core)) => hooks.snapshot(i, core, now, &mut s),
                    (Ok(_), _) => {}
                    (Err(_), _) => self.participants[i].snapshots_refused += 1,
                }
            }
        }
        Ok(())
    }

    fn after_ve_tick(&mut self, now: Duration) {
        let state = self.ve.state();
        self.max_closure = self.max_closure.max(state.closure_error);
        self.ve_ticks_seen += 1;
        if self.record_every > 0 && self.ve_ticks_seen.is_multiple_of(self.record_every as u64) {
            let mut sample = VeSample::from_state(now, &state);
            (sample.kinetic_energy, sample.potential_energy) = self.ve.mechanical_energy();
            self.recording.push_ve(sample);
        }
    }

    fn send_snapshots(&mut self, now: Duration) {
        while let Some(pending) = self.ve.poll_snapshot() {
            let user = pending.user_id();
            self.encode_buf.clear();
            if encode_datagram_into(pending.datagram(), &mut self.encode_buf).is_err() {
                continue;
            }
            if let Some(p) = self.participants.iter_mut().find(|p| p.user_id == Some(user) && !p.left) {
                p.down.send(now, self.encode_buf.clone());
            }
        }
    }

    fn client_tick<H: CoreHooks<S>>(&mut self, i: usize, now: Duration, hooks: &mut H) -> Result<()> {
        let p = &mut self.participants[i];
        if p.core.is_none() && now >= p.plan.join_at {
            self.join(i, now, hooks)?;
        }
        let p = &mut self.participants[i];
        if let Some(leave) = p.plan.leave_at {
            if now >= leave {
                if let Some(user) = p.user_id {
                    let _ = self.ve.leave(now, user);
                }
                p.left = true;
                return Ok(());
            }
        }
        let (Some(core), Some(rig)) = (p.core.as_mut(), p.rig.as_mut()) else {
            p.next_tick += p.period;
            return Ok(());
        };
        let state = rig.read(now).map_err(|e| anyhow!("{}: {e}", p.plan.name))?;
        let t = Instant::now();
        let out = hooks.tick(i, core, now, &state);
        p.compute += t.elapsed();
        let command = out.command;
        let report = *out.report;
        let uplink_sent = out.uplink.is_some();
        if let Some(uplink) = out.uplink.filter(|u| hooks.send_uplink(i, u)) {
            self.encode_buf.clear();
            if encode_datagram_into(&Datagram::Uplink(uplink.clone()), &mut self.encode_buf).is_ok() {
                p.up.send(now, self.encode_buf.clone());
            }
        }
        rig.command(now, &command).map_err(|e| anyhow!("{}: {e}", p.plan.name))?;
        p.ticks += 1;
        p.next_tick += p.period;
        // This user in the VE as the VE's last tick left it (for the figures and the recording).
        let ve_user = p.user_id.and_then(|user| self.ve.state().users().find(|u| u.user_id == user));
        if report.active {
            p.active_ticks += 1;
            let scale = core.scales().position;
            let model = S::op_lin(&report.device_pose.difference(&report.model_pose)).norm() * scale;
            p.model_sum_sq += model * model;
            if report.clamp_scale < 1.0 {
                p.saturated += 1;
            }
            // A handle no hand holds is not followed by a VE that others move (see the server's
            // `update_couplings`), and nobody feels it: its distance to the OP is not tracking.
            let held = report.flags & kinloop_protocol::uplink_flags::HAND_OFF == 0;
            if let Some(u) = &ve_user {
                p.passivity = u.passivity;
            }
            if let Some(u) = ve_user.as_ref().filter(|_| held) {
                p.held_ticks += 1;
                let d = S::op_lin(&report.device_pose.difference(&u.op_pose)).norm() * scale;
                p.op_sum_sq += d * d;
                p.op_max = p.op_max.max(d);
                // The device's pose at the client time of the newest uplink the VE used (the harness runs
                // the client on its own clock) is what the VE has heard of.
                if p.heard.len() == HEARD_HISTORY {
                    // A VE that has heard nothing for this long (an observer never is) is judged against
                    // the oldest pose kept.
                    p.heard.pop_front();
                }
                p.heard.push_back((now.as_secs_f64(), report.device_pose));
                while p.heard.len() > 1 && p.heard[1].0 <= u.heard_until_s {
                    p.heard.pop_front();
                }
                if u.heard_until_s > 0.0 && p.heard[0].0 <= u.heard_until_s {
                    let unheard = S::op_lin(&report.device_pose.difference(&p.heard[0].1)).norm() * scale;
                    p.unheard_sum_sq += unheard * unheard;
                    p.unheard_ticks += 1;
                }
                // A VE that leads its target (`VeConfig::coupling_lead_max_s`) aims at the device of a later
                // client time, and is judged against the device then.
                let aimed = (u.answers_s > 0.0).then(|| p.heard.iter().take_while(|(t, _)| *t <= u.answers_s).last());
                if let Some((_, device)) = aimed.flatten() {
                    let heard = S::op_lin(&device.difference(&u.op_pose)).norm() * scale;
                    p.heard_max = p.heard_max.max(heard);
                }
            }
        }
        let ve_op = ve_user.as_ref().map(|u| u.op_pose);
        hooks.ticked(&TickSample { who: i, report, device: state, command, uplink_sent, ve_op });
        if self.record_every > 0 && p.ticks.is_multiple_of(self.record_every as u64) {
            let mut sample = ClientSample::from_report(&report, report.device_pose, ve_op, &command);
            sample.ve_heard_s = ve_user.map(|u| u.answers_s).filter(|&t| t > 0.0);
            // The true hand (a sensorless device's report carries the observer's estimate) and the handle's
            // true twist (the report's is the encoders' filtered difference, whose lag made a hand's work
            // on a spring-like grasp drift by mJ over a tour: the energy criterion must see the plant).
            sample.hand = core.scales().wrench_to_ve::<S>(&rig.hand_wrench()).as_slice().to_vec();
            sample.device_twist = core.scales().twist_to_ve::<S>(&rig.device().true_twist()).as_slice().to_vec();
            self.recording.push_client(i, sample);
        }
        Ok(())
    }

    fn finish(self, wall: Duration) -> (SessionSummary, Recording) {
        let seconds = self.duration.as_secs_f64().max(1e-9);
        let metrics = self.ve.metrics();
        let mut client_compute = Duration::ZERO;
        let clients = self
            .participants
            .iter()
            .map(|p| {
                client_compute += p.compute;
                let stats = p.core.as_ref().map(|c| c.stats()).unwrap_or_default();
                let active = p.active_ticks.max(1) as f64;
                ClientSummary {
                    name: p.plan.name.clone(),
                    ticks: p.ticks,
                    max_force_ratio: stats.max_force_ratio,
                    device_op_rms_m: (p.op_sum_sq / p.held_ticks.max(1) as f64).sqrt(),
                    device_op_max_m: p.op_max,
                    device_op_heard_max_m: p.heard_max,
                    device_unheard_rms_m: (p.unheard_sum_sq / p.unheard_ticks.max(1) as f64).sqrt(),
                    device_model_rms_m: (p.model_sum_sq / active).sqrt(),
                    saturated_fraction: p.saturated as f64 / active,
                    snapshots: stats.snapshots_accepted,
                    uplinks: stats.uplinks_sent,
                    uplink_saving: stats.uplink_saving(),
                    non_finite: stats.non_finite_events,
                    uplinks_refused: p.uplinks_refused,
                    snapshots_refused: p.snapshots_refused,
                    passivity_absorbed_j: p.passivity.absorbed_j,
                    passivity_activations: p.passivity.activations,
                    position_scale: p.chosen.0,
                    force_scale: p.chosen.1,
                    coupling: p.chosen.2.clone(),
                    gains: p.chosen.3.clone(),
                }
            })
            .collect();
        let summary = SessionSummary {
            duration_s: seconds,
            ve_steps: self.ve.state().step,
            max_closure_error: self.max_closure,
            ve_compute_us_per_s: self.ve_compute.as_secs_f64() * 1e6 / seconds,
            client_compute_us_per_s: client_compute.as_secs_f64() * 1e6 / seconds,
            ve_restores: metrics.state_restores,
            ve_sharing: metrics.sharing,
            clients,
            wall_s: wall.as_secs_f64(),
        };
        (summary, self.recording)
    }
}

/// What a test needs to drive a core of its own on real terms: participant 0's welcome, the newest snapshot
/// handed to its core and the core's configuration, `until` into `plan`.
pub fn first_terms<S: Space>(
    plan: &SessionPlan,
    until: Duration,
) -> Result<(kinloop_protocol::Welcome, kinloop_protocol::Snapshot, CoreConfig)> {
    let mut session = Session::<S>::new(plan)?;
    let mut probe = Probe::default();
    session.run_until_with(until, &mut probe)?;
    let config = session.core(0).map(|core| core.config().clone());
    match (probe.welcome, probe.last_snapshot, config) {
        (Some(welcome), Some(snapshot), Some(config)) => Ok((welcome, snapshot, config)),
        _ => Err(anyhow!("participant 0 had no snapshot {until:?} into the session")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A session stepped event by event from outside ends where `run` ends: the same VE steps and the same
    /// tracking, so a test that steps it sees the real thing.
    #[test]
    fn a_session_stepped_by_hand_ends_where_run_ends() {
        let mut plan = SessionPlan::paper().unwrap();
        plan.duration = Duration::from_millis(300);
        let (ran, _) = run(&plan, &mut |_| {}).unwrap();
        let mut session = Session::<Planar>::new(&plan).unwrap();
        assert!(session.core(0).is_none(), "nobody has joined before the first step");
        let mut now = Duration::ZERO;
        while session.next_event() <= plan.duration {
            now = session.next_event().max(now);
            session.step(now).unwrap();
        }
        assert!(session.core(0).is_some_and(|core| core.stats().snapshots_accepted > 0));
        let (stepped, _) = session.finish(Duration::ZERO);
        assert!(ran.ve_steps > 0);
        assert_eq!(stepped.ve_steps, ran.ve_steps);
        assert_eq!(stepped.clients[0].ticks, ran.clients[0].ticks);
        assert_eq!(stepped.clients[0].device_op_rms_m, ran.clients[0].device_op_rms_m);
        assert_eq!(stepped.max_closure_error, ran.max_closure_error);
    }
}
