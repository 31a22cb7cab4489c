//! `renderability-dhd` and `renderability-hd`: the renderability matrix ([`super::renderability`])
//! through a vendor's device, in real processes: for every shipped scene × operational point × device ×
//! network {perfect, 50 ms one way with 5 ms jitter} × hand {soft, firm}, a `kinloop-server --scene S` and a
//! `kinloop-client --op OP --device dhd|hd` with default flags, the client loading the vendor's fake library
//! as a vendor's: the fake DHD library (`fakes/fake-dhd`) as an omega.3 and a Falcon (`FAKE_DHD_SYSTEM`),
//! or the fake OpenHaptics library (`fakes/fake-hd`) as a Touch, whose servo thread then runs the client's
//! loop. One runner serves both ([`Vendor`]); what differs is the fake's variables, its frame and units, and
//! where the device's figures come from.
//!
//! The fake's hand stands in for the simulated presets' hands: the same grasp impedances (soft and firm,
//! `shared/haptics-facts.md`) and the same intention, a tour of the OP's reach. That tour is what the
//! server's welcome gives a client (`Welcome::op::tour`), placed where the client's core puts the OP in the
//! device's workspace (`HapticCore::home`) and written in the device's frame and units: this module
//! computes it ahead of the session with the server's and the client's own cores (same scene, same device
//! spec, same defaults, so the same welcome), and hands it to the fake (`FAKE_DHD_TOUR`, `FAKE_HD_TOUR`).
//! The handle starts at the OP's place, as a simulated rig's does.
//!
//! Default flags include the loop's priority: kinloop's own loop (DHD) asks for SCHED_FIFO as a user's does,
//! and the fake OpenHaptics library's servo thread asks for it as the vendor's does. A loop left at normal
//! priority on a loaded host runs its ticks in bursts and gaps, and the client's core then steps its local
//! model over the gaps with gains designed for one period, which the simulated matrices never meet.
//!
//! A pair renders by the matrix's bounds: the client ends well, no VE restore, no withheld snapshot, no
//! non-finite value; loops closed; at most 5 % of ticks clamped; device-OP RMS (the device against the VE's
//! OP at the same instant, in device space, from both programs' `--record` files) within 5 mm on a perfect
//! network and 10 mm at 50 ms. The two records' clocks are matched by the time zero each program reports
//! on the system clock (the server's `ve.epoch_unix_s`, the client's `loop_epoch_unix_s`), which both
//! programs read on this one machine. Matching them by when each printed a line is late by whatever the
//! host delays the reading (and the client's loop starts on its own thread), and a touring hand turns each
//! 10 ms of mismatch into about half a millimetre of RMS.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;
use serde_json::{json, Value};

use kinloop_client::core::{CoreConfig, HapticCore};
use kinloop_client::device::dhd::specs;
use kinloop_client::device::dhd::{frames, library::LIBRARY_VARIABLE as DHD_VARIABLE};
use kinloop_client::device::hd::library::LIBRARY_VARIABLE as HD_VARIABLE;
use kinloop_client::device::hd::{HdLibrary, OpenedHd};
use kinloop_client::device::{DeviceSpec, HdRequest};
use kinloop_client::user::hand::tour_order;
use kinloop_client::user::{HandKind, UserContext};
use kinloop_linkage::math::space::{Planar, SceneKind, Space, Spatial, VecOps};
use kinloop_linkage::model::{builtin, scene::Scene, Model};
use kinloop_protocol::{LocalModelForm, MappingRequest, Role};
use kinloop_server::core::{JoinRequest, VeConfig, VeCore};

use super::common::{sweep, Options, Output};
use super::renderability::{bound_failures, scene_ops, Network};
use crate::rounding::{num, round};

/// The DHD models of the matrix: `dhdGetSystemType`'s omega.3 and Falcon.
pub const SYSTEMS: [i32; 2] = [33, 60];

/// Whose library a matrix goes through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Vendor {
    /// Force Dimension's DHD SDK (`--device dhd`).
    Dhd,
    /// 3D Systems' OpenHaptics HD API (`--device hd`).
    Hd,
}

impl Vendor {
    /// The experiment's name.
    pub fn experiment(self) -> &'static str {
        match self {
            Vendor::Dhd => "renderability-dhd",
            Vendor::Hd => "renderability-hd",
        }
    }

    /// The devices of its matrix.
    pub fn devices(self) -> Vec<FakeDevice> {
        match self {
            Vendor::Dhd => SYSTEMS.iter().map(|&s| FakeDevice::Dhd(s)).collect(),
            Vendor::Hd => vec![FakeDevice::Touch],
        }
    }

    /// The variable naming the library file.
    pub fn library_variable(self) -> &'static str {
        match self {
            Vendor::Dhd => DHD_VARIABLE,
            Vendor::Hd => HD_VARIABLE,
        }
    }

    /// The fake library's crate name (its file is `{DLL_PREFIX}NAME{DLL_SUFFIX}`).
    fn fake_crate(self) -> &'static str {
        match self {
            Vendor::Dhd => "kinloop_fake_dhd",
            Vendor::Hd => "kinloop_fake_hd",
        }
    }
}

/// The device a pair's fake library is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum FakeDevice {
    /// A DHD device of this `dhdGetSystemType`.
    Dhd(i32),
    /// A Touch behind OpenHaptics.
    Touch,
}

impl FakeDevice {
    /// Its vendor.
    pub fn vendor(self) -> Vendor {
        match self {
            FakeDevice::Dhd(_) => Vendor::Dhd,
            FakeDevice::Touch => Vendor::Hd,
        }
    }

    /// The model's name.
    pub fn name(self) -> &'static str {
        match self {
            FakeDevice::Dhd(system) => specs::model(system).map_or("unknown", |m| m.name),
            FakeDevice::Touch => "Touch",
        }
    }

    /// The device spec a client designs for in a scene of `kind`: the DHD model's, or what the fake
    /// OpenHaptics library at `fake` reports (read through kinloop's own HD code, as the client does).
    fn device_spec(self, kind: SceneKind, fake: &Path) -> Result<DeviceSpec> {
        match self {
            FakeDevice::Dhd(system) => {
                Ok(specs::model(system).with_context(|| format!("no DHD model {system}"))?.device_spec(kind))
            }
            FakeDevice::Touch => {
                let library = HdLibrary::load(fake)?;
                let request = HdRequest { name: None, fallback: None, calibrate: false };
                let (opened, _) = OpenedHd::describe(library, &request)?;
                Ok(opened.spec().device_spec(kind))
            }
        }
    }

    /// A point in kinloop's axes (m; `linear` of them used) as the fake's tour takes it: the DHD device's
    /// frame in metres, or HD's (kinloop's axes) in millimetres.
    fn tour_point(self, kinloop: &[f64], linear: usize) -> [f64; 3] {
        match self {
            FakeDevice::Dhd(_) => frames::to_device(kinloop, linear),
            FakeDevice::Touch => {
                let mut out = [0.0; 3];
                for (o, x) in out.iter_mut().zip(kinloop).take(linear.min(3)) {
                    *o = x * 1e3;
                }
                out
            }
        }
    }

    /// The fake's variables for a pair with `hand` touring `tour` (the fake's frame and units).
    fn fake_env(self, hand: HandKind, tour: &[[f64; 3]]) -> Vec<(&'static str, String)> {
        let tour: Vec<String> = tour.iter().map(|p| format!("{:e},{:e},{:e}", p[0], p[1], p[2])).collect();
        match self {
            FakeDevice::Dhd(system) => vec![
                ("FAKE_DHD_SYSTEM", system.to_string()),
                ("FAKE_DHD_HAND", hand.name().to_owned()),
                ("FAKE_DHD_TOUR", tour.join(";")),
            ],
            FakeDevice::Touch => {
                vec![("FAKE_HD_HAND", hand.name().to_owned()), ("FAKE_HD_TOUR", tour.join(";"))]
            }
        }
    }
}
/// The hands of the matrix.
pub const HANDS: [HandKind; 2] = [HandKind::Soft, HandKind::Firm];
/// A pair's session (s), as `renderability-live`'s; `--quick` halves it.
pub const SECONDS: f64 = 4.0;
/// How long the server outlives the client's session: its start-up, the connection and the leave (s).
const SERVER_MARGIN_S: f64 = 2.5;

/// One pair of the matrix.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DevicePoint {
    /// Built-in scene name.
    pub scene: String,
    /// Operational point.
    pub op: String,
    /// The device the fake library is.
    pub device: FakeDevice,
    /// Network.
    pub network: Network,
    /// Hand.
    pub hand: HandKind,
}

impl DevicePoint {
    /// `scene:op model network hand`.
    pub fn label(&self) -> String {
        format!("{}:{} {} {} {}", self.scene, self.op, self.device.name(), self.network.name(), self.hand.name())
    }
}

/// What one pair measured.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceResult {
    /// The pair.
    pub point: DevicePoint,
    /// Renders by every bound.
    pub renders: bool,
    /// Which bounds failed.
    pub failures: Vec<String>,
    /// Fraction of the client's active ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Device-OP RMS against the VE's OP, device space (m).
    pub device_op_rms_m: f64,
    /// The client's own device-to-local-model RMS, device space (m).
    pub device_model_rms_m: f64,
    /// Largest closure error (m).
    pub max_closure_error_m: f64,
    /// VE restores.
    pub ve_restores: u64,
}

/// Every pair of `vendor`'s matrix for `scenes` (all built-in scenes when empty).
pub fn points(vendor: Vendor, scenes: &[&str], hands: &[HandKind]) -> Result<Vec<DevicePoint>> {
    let mut out = Vec::new();
    for (scene, op, _) in scene_ops(scenes)? {
        for device in vendor.devices() {
            for network in Network::ALL {
                for &hand in hands {
                    out.push(DevicePoint { scene: scene.clone(), op: op.clone(), device, network, hand });
                }
            }
        }
    }
    Ok(out)
}

/// How a program is started: its name (`kinloop-server`, `kinloop-client`) and arguments to a command.
pub type Launch = dyn Fn(&str, &[String]) -> Command + Sync;

/// The programs a pair runs: `kinloop-server`, `kinloop-client` and the vendor's fake library.
pub struct Programs {
    launch: Box<Launch>,
    /// The fake library.
    pub fake: PathBuf,
}

impl Programs {
    /// Programs started by `launch` (tests re-execute their own binary as each program), the fake at `fake`.
    pub fn launched_by(launch: Box<Launch>, fake: PathBuf) -> Programs {
        Programs { launch, fake }
    }

    /// The programs beside this executable (cargo puts `kinloop`, `kinloop-server` and `kinloop-client` in
    /// one folder, and the fake library in it or in its `deps`), the library from the vendor's variable
    /// (`KINLOOP_DHD_LIB`, `KINLOOP_HD_LIB`) when set.
    pub fn beside_this_program(vendor: Vendor) -> Result<Programs> {
        let exe = std::env::current_exe().context("this program's path")?;
        let dir = exe.parent().context("this program's folder")?.to_owned();
        for name in ["kinloop-server", "kinloop-client"] {
            let path = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
            if !path.is_file() {
                bail!("{} is missing: build the workspace (cargo build --release --workspace)", path.display());
            }
        }
        let fake = fake_library_beside_this_program(vendor)?;
        let launch = move |program: &str, args: &[String]| {
            let mut command = Command::new(dir.join(format!("{program}{}", std::env::consts::EXE_SUFFIX)));
            command.args(args);
            command
        };
        Ok(Programs { launch: Box::new(launch), fake })
    }

    fn command(&self, program: &str, args: Vec<String>) -> Command {
        (self.launch)(program, &args)
    }
}

/// `vendor`'s fake library: its variable's (`KINLOOP_DHD_LIB`, `KINLOOP_HD_LIB`) when set, else beside this
/// executable or in its `deps` (where cargo builds it).
pub fn fake_library_beside_this_program(vendor: Vendor) -> Result<PathBuf> {
    let variable = vendor.library_variable();
    if let Some(path) = std::env::var_os(variable).filter(|p| !p.is_empty()) {
        return Ok(PathBuf::from(path));
    }
    let exe = std::env::current_exe().context("this program's path")?;
    let dir = exe.parent().context("this program's folder")?;
    let name = format!("{}{}{}", std::env::consts::DLL_PREFIX, vendor.fake_crate(), std::env::consts::DLL_SUFFIX);
    [dir.join(&name), dir.join("deps").join(&name)].into_iter().find(|p| p.is_file()).with_context(|| {
        format!(
            "the fake library {name} is not in {} nor its deps (cargo build --release --workspace builds it), \
             and {variable} is not set",
            dir.display()
        )
    })
}

/// The tour the pair's hand intends, in the device's frame and units: the OP's place in the workspace,
/// then the welcome's waypoints (see the module documentation); `fake` is the pair's fake library.
pub fn device_tour(point: &DevicePoint, fake: &Path) -> Result<Vec<[f64; 3]>> {
    let scene = builtin::scene(&point.scene).context("built in")??;
    let spec = point.device.device_spec(scene.kind, fake)?;
    match scene.kind {
        SceneKind::Planar => tour_in::<Planar>(&scene, &point.op, spec, point.device),
        SceneKind::Spatial => tour_in::<Spatial>(&scene, &point.op, spec, point.device),
    }
}

fn tour_in<S: Space>(scene: &Scene, op: &str, spec: DeviceSpec, device: FakeDevice) -> Result<Vec<[f64; 3]>> {
    let compiled: Model<S> = Model::compile(scene, &scene.name)?;
    let mut ve = VeCore::new(compiled, VeConfig::default()).map_err(|e| anyhow!("VE configuration: {e}"))?;
    let request = JoinRequest {
        name: "tour".into(),
        role: Role::Manipulator,
        op: op.into(),
        form: LocalModelForm::OpSpace,
        device: Some(spec.caps()),
        mapping: MappingRequest::default(),
    };
    let joined = ve.join(Duration::ZERO, request).map_err(|e| anyhow!("the join is refused: {e}"))?;
    let core = HapticCore::<S>::new(CoreConfig::new(spec), &joined.welcome).map_err(|e| anyhow!("{e}"))?;
    let home = core.home(&S::Point::from_slice(&joined.welcome.op.position));
    let linear = S::KIND.point_dim();
    let mut tour = vec![device.tour_point(home.as_slice(), linear)];
    // In the order the simulated hands tour it, there and back (the fake goes back along the list again).
    let context = UserContext::<S>::from_welcome(&joined.welcome);
    for displacement in tour_order::<S>(&context.tour) {
        let at = home + S::op_lin(&displacement);
        tour.push(device.tour_point(at.as_slice(), linear));
    }
    Ok(tour)
}

/// A child's lines on one stream, each with when it was read.
type Lines = Arc<Mutex<Vec<(Instant, String)>>>;

/// Reads `stream` line by line on a thread, timestamping each line.
fn collect_lines(stream: impl Read + Send + 'static) -> (Lines, std::thread::JoinHandle<()>) {
    let lines: Lines = Arc::new(Mutex::new(Vec::new()));
    let sink = lines.clone();
    let handle = std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(|l| l.ok()) {
            if let Ok(mut v) = sink.lock() {
                v.push((Instant::now(), line));
            }
        }
    });
    (lines, handle)
}

/// Waits for `child` up to `limit`, killing it after.
fn wait_bounded(child: &mut Child, limit: Duration, what: &str) -> Result<std::process::ExitStatus> {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            bail!("{what} did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The link flags of `network` for one side (`seed` differs per side).
fn link_flags(network: Network, seed: u64) -> Vec<String> {
    match network {
        Network::Perfect => Vec::new(),
        Network::Delayed50 => {
            ["--delay", "50ms", "--jitter", "5ms", "--seed", &seed.to_string()].map(String::from).to_vec()
        }
    }
}

/// What the two programs left: the server's JSON statistics, the client's, its log, and the clock offset.
struct Ran {
    server: Value,
    client: Value,
    client_log: String,
    client_ok: bool,
    offset_s: f64,
}

/// Runs the server and the client of `point` for `seconds` in `dir`.
fn run_programs(point: &DevicePoint, seconds: f64, programs: &Programs, dir: &Path) -> Result<Ran> {
    let tour = device_tour(point, &programs.fake)?;
    let mut args: Vec<String> = ["--scene", &point.scene, "--listen", "127.0.0.1:0", "--cert-dir", "cert"]
        .into_iter()
        .chain(["--record", "ve.csv", "--json", "--stats-every", "0", "--duration"])
        .map(String::from)
        .collect();
    args.push((seconds + SERVER_MARGIN_S).to_string());
    args.extend(link_flags(point.network, 1));
    let mut server = programs
        .command("kinloop-server", args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::from(std::fs::File::create(dir.join("server.log"))?))
        .spawn()
        .context("starting kinloop-server")?;
    let mut out = BufReader::new(server.stdout.take().context("the server's stdout")?);
    let log_tail = |dir: &Path| {
        let text = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
        text.lines().rev().take(5).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n")
    };
    let address = line_starting(&mut out, "kinloop-server listening on")
        .with_context(|| format!("the server's log ends:\n{}", log_tail(dir)))?;
    let fingerprint = line_starting(&mut out, "certificate fingerprint")?;
    let last_word = |l: &str| l.split_whitespace().last().unwrap_or("").to_owned();
    let (address, fingerprint) = (last_word(&address), last_word(&fingerprint));
    let device_flag = match point.device.vendor() {
        Vendor::Dhd => "dhd",
        Vendor::Hd => "hd",
    };
    let mut args: Vec<String> = ["--server", &address, "--fingerprint", &fingerprint, "--device", device_flag]
        .into_iter()
        .chain(["--op", &point.op, "--json", "--record", "client.csv", "--duration"])
        .map(String::from)
        .collect();
    args.push(seconds.to_string());
    args.extend(link_flags(point.network, 2));
    let mut client = programs
        .command("kinloop-client", args)
        .env(point.device.vendor().library_variable(), &programs.fake)
        .envs(point.device.fake_env(point.hand, &tour))
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting kinloop-client")?;
    let (log, reader) = collect_lines(client.stderr.take().context("the client's stderr")?);
    let mut client_out = String::new();
    client.stdout.take().context("the client's stdout")?.read_to_string(&mut client_out)?;
    let status = wait_bounded(&mut client, Duration::from_secs_f64(seconds + 30.0), "kinloop-client")?;
    let _ = reader.join();
    let server_status = wait_bounded(&mut server, Duration::from_secs_f64(seconds + 30.0), "kinloop-server")?;
    let mut server_out = String::new();
    out.read_to_string(&mut server_out)?;
    let lines = log.lock().map_err(|_| anyhow!("the client's log"))?.clone();
    let client_log: String = lines.iter().map(|(_, l)| format!("{l}\n")).collect();
    std::fs::write(dir.join("client.log"), &client_log)?;
    let holding = lines.iter().any(|(_, l)| l.contains("kinloop-client: holding"));
    if !server_status.success() {
        bail!("kinloop-server failed (see {})", dir.join("server.log").display());
    }
    let server = json_in(&server_out).context("the server's JSON statistics")?;
    let client = json_in(&client_out).unwrap_or(Value::Null);
    let epochs = (client["loop_epoch_unix_s"].as_f64(), server["ve"]["epoch_unix_s"].as_f64());
    let offset_s = match epochs {
        (Some(client), Some(ve)) => client - ve,
        _ => f64::NAN,
    };
    Ok(Ran { server, client, client_ok: status.success() && holding && offset_s.is_finite(), client_log, offset_s })
}

/// Reads lines from `out` until one holds `prefix`; that line from `prefix` on (a launcher may print
/// before it, as a test harness does).
fn line_starting(out: &mut impl BufRead, prefix: &str) -> Result<String> {
    let mut line = String::new();
    loop {
        line.clear();
        if out.read_line(&mut line)? == 0 {
            bail!("the server ended before printing {prefix:?}");
        }
        if let Some(at) = line.find(prefix) {
            return Ok(line[at..].trim_end().to_owned());
        }
    }
}

/// The JSON object a program printed last on its stdout (anything before it is skipped).
fn json_in(text: &str) -> Result<Value> {
    let start = text.find('{').context("no JSON object")?;
    Ok(serde_json::from_str(&text[start..])?)
}

/// Device-OP RMS in device space (m): the client's ticks with output against the VE's OP at the same
/// instant, over the scene's linear axes.
fn device_op_rms(dir: &Path, kind: SceneKind, offset_s: f64, position_scale: f64) -> Result<f64> {
    let mut samples = crate::demo::records::read_client(&dir.join("client.csv"), kind)?;
    let ve = crate::demo::records::read_ve(&dir.join("ve.csv"), kind)?;
    let user = ve.iter().find_map(|v| v.users.first().map(|u| u.0)).context("the user in the VE's record")?;
    crate::demo::records::merge(&mut samples, &ve, user, offset_s);
    let linear = kind.point_dim();
    let squares: Vec<f64> = samples
        .iter()
        .filter(|s| s.gain > 0.0)
        .filter_map(|s| {
            let op = s.ve_op.as_ref()?;
            Some((0..linear).map(|i| (s.device[i] - op[i]).powi(2)).sum::<f64>())
        })
        .collect();
    if squares.is_empty() {
        bail!("no tick with output to compare");
    }
    Ok((squares.iter().sum::<f64>() / squares.len() as f64).sqrt() * position_scale)
}

/// Runs one pair for `seconds` in a folder under `scratch` and judges it.
pub fn evaluate(point: &DevicePoint, seconds: f64, programs: &Programs, scratch: &Path) -> Result<DeviceResult> {
    let dir = scratch.join(point.label().replace([' ', ':', '+'], "_"));
    std::fs::create_dir_all(&dir)?;
    let ran = run_programs(point, seconds, programs, &dir)?;
    let kind = builtin::scene(&point.scene).context("built in")??.kind;
    let core = &ran.server["ve"]["core"];
    let count = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let (restores, withheld) = (count(&core["state_restores"]), count(&core["snapshots_withheld"]));
    let closure = count(&core["max_closure_error"]);
    let c = &ran.client;
    let non_finite = count(&c["non_finite_events"]);
    let clamped = count(&c["clamped_fraction"]);
    let scale = count(&c["session"]["position_scale"]);
    let mut failures = Vec::new();
    if !ran.client_ok {
        let last = ran.client_log.lines().rfind(|l| l.contains("error")).unwrap_or("no error line");
        failures.push(format!("the client failed: {last}"));
    }
    if !(restores == 0.0 && withheld == 0.0 && non_finite == 0.0) {
        failures
            .push(format!("unstable: {restores} VE restores, {withheld} snapshots withheld, {non_finite} non-finite"));
    }
    let rms = if ran.client_ok { device_op_rms(&dir, kind, ran.offset_s, scale)? } else { f64::NAN };
    failures.extend(bound_failures(closure, clamped, rms, point.network));
    let result = DeviceResult {
        point: point.clone(),
        renders: failures.is_empty(),
        failures,
        clamped_fraction: clamped,
        device_op_rms_m: rms,
        device_model_rms_m: count(&c["tracking_error_rms_m"]),
        max_closure_error_m: closure,
        ve_restores: restores as u64,
    };
    // Each pair's verdict beside its records, so a long run can be read while it goes.
    std::fs::write(dir.join("result.json"), serde_json::to_string_pretty(&result)?)?;
    Ok(result)
}

/// Runs `vendor`'s experiment (see the module documentation), one pair at a time.
pub fn run(vendor: Vendor, options: &Options) -> Result<super::Report> {
    let name = vendor.experiment();
    let out = Output::new(name, options)?;
    let programs = Programs::beside_this_program(vendor)?;
    let all = points(vendor, &[], &HANDS)?;
    let seconds = options.session_seconds(SECONDS, SECONDS / 2.0);
    let scratch = std::env::temp_dir().join(format!("kinloop-{name}"));
    let results = sweep(name, &all, 1, options.progress, |p| evaluate(p, seconds, &programs, &scratch))?;
    let rendering = results.iter().filter(|r| r.renders).count();
    let worst = |f: fn(&DeviceResult) -> f64| results.iter().map(f).fold(0.0, f64::max);
    let (worst_rms, worst_clamped) = (worst(|r| r.device_op_rms_m), worst(|r| r.clamped_fraction));
    let devices = vendor.devices();
    let by_device: Vec<Value> = devices
        .iter()
        .map(|&d| {
            let of: Vec<&DeviceResult> = results.iter().filter(|r| r.point.device == d).collect();
            json!({"device": d.name(), "pairs": of.len(), "rendering": of.iter().filter(|r| r.renders).count()})
        })
        .collect();
    let names: Vec<&str> = devices.iter().map(|d| d.name()).collect();
    let library = match vendor {
        Vendor::Dhd => "the fake DHD library",
        Vendor::Hd => "the fake OpenHaptics library",
    };
    let answer = format!(
        "{rendering} of {} pairs render through {library} in real processes (stable, closure <= 1e-6 m, \
         clamped <= 5 %, device-OP RMS <= 5 mm perfect / 10 mm at 50 ms); worst clamped {} %, worst RMS {} mm",
        results.len(),
        num(worst_clamped * 100.0),
        num(worst_rms * 1e3)
    );
    out.finish(
        &format!("Every shipped linkage through {library} as {}, real processes", names.join(" and ")),
        "one pair at a time, about 7 s each",
        json!({
            "answer": answer,
            "seconds_per_pair": seconds,
            "pairs": results.len(),
            "rendering": rendering,
            "by_device": by_device,
            "failing": results.iter().filter(|r| !r.renders).map(|r| json!({"pair": r.point.label(), "failures": r.failures})).collect::<Vec<_>>(),
            "points": results.iter().map(|r| json!({
                "scene": r.point.scene, "op": r.point.op, "device": r.point.device.name(), "network": r.point.network.name(),
                "hand": r.point.hand.name(), "renders": r.renders, "failures": r.failures,
                "clamped_fraction": round(r.clamped_fraction, 4), "device_op_rms_mm": round(r.device_op_rms_m * 1e3, 3),
                "device_model_rms_mm": round(r.device_model_rms_m * 1e3, 3), "max_closure_error_m": r.max_closure_error_m,
                "ve_restores": r.ve_restores,
            })).collect::<Vec<_>>(),
        }),
    )
}
