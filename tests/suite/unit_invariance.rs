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
    /// A force scale the client asks for, device newtons per SI newton (`None`: the server's choice); each
    /// unit system asks for the same physical scale in its own units.
    force_scale_si: Option<f64>,
}

struct Run {
    summary: SessionSummary,
    recording: Recording,
    verdict: Verdict,
}

fn session(scene: &Scene, case: &Case, units: UnitSystem) -> Run {
    let mut client = ClientPlan::new("user", case.op, case.device);
    client.user = UserSpec::Hand(HandSpec::touring(case.hand));
    // A scene force unit is (1 / per_kilogram) kg times (1 / per_metre) m per s².
    client.mapping.force_scale = case.force_scale_si.map(|c| c / (units.per_metre() * units.per_kilogram()));
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
    let mut runs = SYSTEMS.iter().map(|u| (u, session(&u.rewrite(&base), case, *u)));
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
        force_scale_si: None,
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
        force_scale_si: None,
    });
}

/// A poking hand on the weak Touch with a force scale asked for three times what the server would choose: the
/// device's force limit binds (a fifth of the ticks are clamped and the session is judged unstable), and binds
/// on the same ticks, with the same verdict, in every unit system.
#[test]
fn a_slider_crank_pushed_into_the_force_limit_clamps_alike_in_four_unit_systems() {
    let si = check(&Case {
        scene: "slider-crank.toml",
        op: "crank-tip",
        device: DevicePreset::Touch,
        hand: HandKind::Poke,
        delay_ms: 0,
        force_scale_si: Some(3.0),
    });
    assert!(clamped_ticks(&si.recording) > 100, "the limit hardly bound: {:?}", si.summary.clients[0]);
}

/// The Gauss-Newton assembly reads its residual and its steps in the scene's length scale: a spherical
/// four-bar and a slider-crank with their first joint moved off q0 close in the same number of iterations,
/// to the same configuration (angles alike, prismatic coordinates in proportion), in every unit system. A
/// residual that mixed millimetres with unit-free rows would keep the spherical four-bar from converging in
/// millimetres.
#[test]
fn assembly_closes_the_loops_alike_in_four_unit_systems() {
    use kinloop_linkage::algorithms::assemble::assemble;
    use kinloop_linkage::math::space::{Planar, Space, Spatial};
    use kinloop_linkage::model::{JointKind, Model};

    fn closed<S: Space>(scene: &Scene) -> (usize, Vec<f64>, Vec<bool>) {
        let model = Model::<S>::compile(scene, &scene.name).expect("compiles");
        let mut q = model.q0.clone();
        q[0] += 0.01;
        let a = assemble(&model, &q, 1e-12 * model.length_scale).unwrap_or_else(|e| panic!("{}: {e}", scene.name));
        let prismatic = model.joints.iter().map(|j| j.kind == JointKind::Prismatic).collect();
        (a.iterations, a.q.iter().copied().collect(), prismatic)
    }
    for (file, spatial) in [("spherical-four-bar.toml", true), ("slider-crank.toml", false)] {
        let base = scene(file);
        let run = |u: UnitSystem| {
            let s = u.rewrite(&base);
            if spatial {
                closed::<Spatial>(&s)
            } else {
                closed::<Planar>(&s)
            }
        };
        let (iterations, q_si, prismatic) = run(UnitSystem::SI);
        for u in &SYSTEMS[1..] {
            let (its, q, _) = run(*u);
            assert_eq!(its, iterations, "{file} in {u:?}: iterations");
            for (i, ((&a, &b), &p)) in q_si.iter().zip(&q).zip(&prismatic).enumerate() {
                let b = if p { b / u.per_metre() } else { b };
                assert!((a - b).abs() <= TOLERANCE * a.abs().max(1.0), "{file} in {u:?}: q[{i}] {b} against {a}");
            }
        }
    }
}
