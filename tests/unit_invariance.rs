//! Unit invariance: one linkage written in four unit systems (m+kg, cm+g, mm+kg, mm+g; `generate::units`
//! rewrites the SI scene) and held by the same simulated device and hand (device and hand stay in SI) gives the
//! same device-space trajectory, the same commands, the same count of clamped ticks and the same stability
//! verdict, in virtual time, to 1e-6 relative. The physics is unit-invariant, so any difference is a default
//! of the code (a gain, threshold, step or bound) written in metres or kilograms on the scene side. The runs
//! include ones where the device's force limit binds (a firm hand on a weak device).

use std::time::Duration;

use kinloop::experiments::verdict::{judge, Verdict};
use kinloop::generate::units::{LengthUnit, MassUnit, UnitSystem};
use kinloop_client::device::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec, UserSpec};
use kinloop_harness::{run, ClientPlan, ClientSample, Recording, SessionPlan, SessionSummary};
use kinloop_linkage::model::scene::Scene;
use kinloop_protocol::emulator::LinkConfig;
use kinloop_server::core::VeConfig;

/// The four unit systems the test compares, SI first.
const SYSTEMS: [UnitSystem; 4] = [
    UnitSystem::SI,
    UnitSystem { length: LengthUnit::Cm, mass: MassUnit::G },
    UnitSystem { length: LengthUnit::Mm, mass: MassUnit::Kg },
    UnitSystem { length: LengthUnit::Mm, mass: MassUnit::G },
];

/// Relative agreement required between unit systems.
const TOLERANCE: f64 = 1e-6;

fn scene(file: &str) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(file);
    Scene::from_file(&path).expect("a shipped scene")
}

struct Case {
    scene: &'static str,
    op: &'static str,
    device: DevicePreset,
    hand: HandKind,
    delay_ms: u64,
}

struct Run {
    summary: SessionSummary,
    recording: Recording,
    verdict: Verdict,
}

fn session(scene: &Scene, case: &Case) -> Run {
    let mut client = ClientPlan::new("user", case.op, case.device);
    client.user = UserSpec::Hand(HandSpec::touring(case.hand));
    let link = LinkConfig {
        delay: Duration::from_millis(case.delay_ms),
        jitter: Duration::from_millis(case.delay_ms / 10),
        seed: 11,
        ..LinkConfig::default()
    };
    let plan = SessionPlan {
        scene: scene.clone(),
        ve: VeConfig::default(),
        clients: vec![client.with_link(link)],
        duration: Duration::from_secs(4),
        record_every: 1,
    };
    let (summary, recording) = run(&plan, &mut |_| {}).unwrap_or_else(|e| panic!("{}: {e:#}", case.scene));
    let verdict = judge(&summary, &recording);
    Run { summary, recording, verdict }
}

fn clamped_ticks(rec: &Recording) -> usize {
    rec.clients[0].iter().filter(|s| s.clamp_scale < 1.0).count()
}

/// Largest absolute value of `pick` over the samples (the scale relative differences are taken against).
fn peak(samples: &[ClientSample], pick: impl Fn(&ClientSample) -> &[f64]) -> f64 {
    samples.iter().flat_map(|s| pick(s).iter().map(|x| x.abs())).fold(0.0, f64::max)
}

/// Compares `got` (in `units`) with the SI run: the device's position in metres (the recorded handle position,
/// in the VE's frame, divided by the units' length per metre), the wrench commanded to the device (device units), the
/// clamping and the verdict.
fn assert_same(label: &str, si: &Run, got: &Run, units: UnitSystem) {
    let (a, b) = (&si.recording.clients[0], &got.recording.clients[0]);
    assert_eq!(a.len(), b.len(), "{label}: tick count");
    let position_scale = peak(a, |s| &s.device).max(1e-3);
    let command_scale = peak(a, |s| &s.command).max(1e-3);
    for (sa, sb) in a.iter().zip(b) {
        for (i, (&x, &y)) in sa.device.iter().zip(&sb.device).enumerate() {
            let y = y / units.per_metre();
            assert!(
                (x - y).abs() <= TOLERANCE * position_scale,
                "{label}: device axis {i} at t = {:.3} s: {y} in {units:?} against {x} in SI",
                sa.t
            );
        }
        for (i, (&x, &y)) in sa.command.iter().zip(&sb.command).enumerate() {
            assert!(
                (x - y).abs() <= TOLERANCE * command_scale,
                "{label}: command axis {i} at t = {:.3} s: {y} in {units:?} against {x} in SI",
                sa.t
            );
        }
    }
    assert_eq!(clamped_ticks(&si.recording), clamped_ticks(&got.recording), "{label}: clamped ticks");
    let (ca, cb) = (&si.summary.clients[0], &got.summary.clients[0]);
    assert!(
        (ca.device_op_rms_m - cb.device_op_rms_m).abs() <= TOLERANCE * ca.device_op_rms_m.max(1e-6),
        "{label}: device-OP RMS {} m in {units:?} against {} m in SI",
        cb.device_op_rms_m,
        ca.device_op_rms_m
    );
    assert_eq!(si.verdict.stable, got.verdict.stable, "{label}: verdict {:?} against SI {:?}", got.verdict, si.verdict);
    assert_eq!(si.verdict.reasons, got.verdict.reasons, "{label}");
    assert_eq!(si.summary.ve_restores, got.summary.ve_restores, "{label}: VE restores");
}

fn check(case: &Case) -> Run {
    let base = scene(case.scene);
    let mut runs = SYSTEMS.iter().map(|u| (u, session(&u.rewrite(&base), case)));
    let (_, si) = runs.next().expect("SI first");
    for (units, run) in runs {
        let label = format!("{}:{} {:?} {:?} {} ms", case.scene, case.op, case.device, case.hand, case.delay_ms);
        assert_same(&label, &si, &run, *units);
    }
    si
}

#[test]
fn the_testbed_behaves_alike_in_four_unit_systems() {
    let si = check(&Case {
        scene: "paper-testbed.toml",
        op: "link2",
        device: DevicePreset::Paper,
        hand: HandKind::Soft,
        delay_ms: 0,
    });
    assert!(si.verdict.stable, "{:?}", si.verdict);
}

#[test]
fn the_testbed_under_delay_behaves_alike_in_four_unit_systems() {
    check(&Case {
        scene: "paper-testbed.toml",
        op: "link2",
        device: DevicePreset::Falcon,
        hand: HandKind::Soft,
        delay_ms: 300,
    });
}

/// A firm hand on the weak Touch: the device's force limit binds, and binds on the same ticks in every unit
/// system.
#[test]
fn a_slider_crank_pushed_into_the_force_limit_clamps_alike_in_four_unit_systems() {
    let si = check(&Case {
        scene: "slider-crank.toml",
        op: "slider",
        device: DevicePreset::Touch,
        hand: HandKind::Poke,
        delay_ms: 0,
    });
    assert!(clamped_ticks(&si.recording) > 0, "the limit never bound: {:?}", si.summary.clients[0]);
}

#[test]
fn zz_debug_print() {
    let case = Case { scene: "slider-crank.toml", op: "slider", device: DevicePreset::Touch, hand: HandKind::Poke, delay_ms: 0 };
    let base = scene(case.scene);
    let si = session(&base, &case);
    let u = UnitSystem { length: LengthUnit::Cm, mass: MassUnit::G };
    let r = session(&u.rewrite(&base), &case);
    let (a, b) = (&si.recording.clients[0], &r.recording.clients[0]);
    let (l, m) = (u.per_metre(), u.per_kilogram());
    let wrench = [l * m, l * m, l * l * m];
    let twist = [l, l, 1.0];
    let fields: Vec<(&str, Box<dyn Fn(&ClientSample) -> Vec<f64>>, Vec<f64>)> = vec![
        ("model", Box::new(|s: &ClientSample| s.model.clone()), vec![l, l]),
        ("model_twist", Box::new(|s: &ClientSample| s.model_twist.clone()), twist.to_vec()),
        ("device_twist", Box::new(|s: &ClientSample| s.device_twist.clone()), twist.to_vec()),
        ("ve_op", Box::new(|s: &ClientSample| s.ve_op.clone().unwrap_or_default()), vec![l, l]),
        ("jc", Box::new(|s: &ClientSample| s.joint_constraint.clone()), wrench.to_vec()),
        ("pc", Box::new(|s: &ClientSample| s.position_channel.clone()), wrench.to_vec()),
        ("imp", Box::new(|s: &ClientSample| s.impedance.clone()), wrench.to_vec()),
        ("hand", Box::new(|s: &ClientSample| s.hand.clone()), wrench.to_vec()),
    ];
    let (ca, cb) = (&si.summary.clients[0], &r.summary.clients[0]);
    eprintln!("cp {} {} cf {} {} coupling {:?} {:?} gains {:?} {:?}", ca.position_scale, cb.position_scale * l, ca.force_scale, cb.force_scale * l * m, ca.coupling, cb.coupling, ca.gains, cb.gains);
    for (name, f, scale) in &fields {
        let peak = a.iter().flat_map(|s| f(s)).map(f64::abs).fold(1e-12, f64::max);
        for (k, (sa, sb)) in a.iter().zip(b).enumerate() {
            let (x, y) = (f(sa), f(sb));
            let d = x.iter().zip(&y).zip(scale).map(|((x, y), s)| (x - y / s).abs()).fold(0.0, f64::max);
            if d > 1e-7 * peak {
                eprintln!("{name}: first off at k {k} t {}: {x:?} vs {:?} (peak {peak})", sa.t, y.iter().zip(scale).map(|(y, s)| y / s).collect::<Vec<_>>());
                break;
            }
        }
    }
}
