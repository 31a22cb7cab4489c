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
//! network and 10 mm at 50 ms. The programs are run, and their records read, by [`super::programs`].

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
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

use super::common::{sweep, Options, Output, Report};
use super::programs::{self, Launch, Launcher, Measured, Pair, Ran};
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

/// The programs a pair runs: `kinloop-server`, `kinloop-client` and the vendor's fake library.
pub struct Programs {
    launcher: Launcher,
    /// The fake library.
    pub fake: PathBuf,
}

impl Programs {
    /// Programs started by `launch` (tests re-execute their own binary as each), the fake at `fake`.
    pub fn launched_by(launch: Box<Launch>, fake: PathBuf) -> Programs {
        Programs { launcher: Launcher::launched_by(launch), fake }
    }

    /// The programs beside this executable, the library from the vendor's variable (`KINLOOP_DHD_LIB`,
    /// `KINLOOP_HD_LIB`) when set, else beside this executable or in its `deps`.
    pub fn beside_this_program(vendor: Vendor) -> Result<Programs> {
        Ok(Programs { launcher: Launcher::beside_this_program()?, fake: fake_library_beside_this_program(vendor)? })
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
/// The link flags of `network` for one side (`seed` differs per side).
fn network_flags(network: Network, seed: u64) -> Vec<String> {
    let link = network.link(seed);
    programs::link_flags(link.delay, link.jitter, seed)
}

/// Runs the server and the client of `point` for `seconds` in `dir`.
fn run_programs(point: &DevicePoint, seconds: f64, programs: &Programs, dir: &Path) -> Result<Ran> {
    let tour = device_tour(point, &programs.fake)?;
    let device = match point.device.vendor() {
        Vendor::Dhd => "dhd",
        Vendor::Hd => "hd",
    };
    let mut client_env = vec![(point.device.vendor().library_variable().to_owned(), path_text(&programs.fake))];
    client_env.extend(point.device.fake_env(point.hand, &tour).into_iter().map(|(k, v)| (k.to_owned(), v)));
    let pair = Pair {
        scene: point.scene.clone(),
        op: point.op.clone(),
        device: device.into(),
        client_flags: Vec::new(),
        client_env,
        links: [network_flags(point.network, 1), network_flags(point.network, 2)],
    };
    programs::run(&pair, seconds, &programs.launcher, dir)
}

fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// Runs one pair for `seconds` in a folder under `scratch` and judges it.
pub fn evaluate(point: &DevicePoint, seconds: f64, programs: &Programs, scratch: &Path) -> Result<DeviceResult> {
    let dir = scratch.join(point.label().replace([' ', ':', '+'], "_"));
    std::fs::create_dir_all(&dir)?;
    let ran = run_programs(point, seconds, programs, &dir)?;
    let kind = builtin::scene(&point.scene).context("built in")??.kind;
    let measured = Measured::of(&ran, &dir, kind)?;
    let mut failures = measured.failures;
    failures.extend(bound_failures(
        measured.max_closure_error,
        measured.clamped_fraction,
        measured.device_op_rms_m,
        point.network,
    ));
    let result = DeviceResult {
        point: point.clone(),
        renders: failures.is_empty(),
        failures,
        clamped_fraction: measured.clamped_fraction,
        device_op_rms_m: measured.device_op_rms_m,
        device_model_rms_m: measured.device_model_rms_m,
        max_closure_error_m: measured.max_closure_error,
        ve_restores: measured.ve_restores,
    };
    // Each pair's verdict beside its records, so a long run can be read while it goes.
    std::fs::write(dir.join("result.json"), serde_json::to_string_pretty(&result)?)?;
    Ok(result)
}

/// Runs `vendor`'s experiment (see the module documentation), one pair at a time.
pub fn run(vendor: Vendor, options: &Options) -> Result<Report> {
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
