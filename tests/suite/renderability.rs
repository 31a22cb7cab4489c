//! Pairs of the renderability matrix that a light operational point makes hard, run over the touring hand's
//! whole tour at 50 ms one way (`kinloop experiment renderability` runs all 196 pairs; CI runs these).

use kinloop::experiments::renderability::{evaluate, Network, Point, SECONDS};
use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::HandKind;

fn pair(scene: &str, op: &str, device: DevicePreset, hand: HandKind) -> Point {
    Point { scene: scene.into(), op: op.into(), device, network: Network::Delayed50, hand }
}

/// The Watt six-bar's output link and the slider-crank's crank tip are light and turn fast under the hand; at
/// 50 ms one way, with the local model's free directions compared with the model's own state that the VE
/// answered (a Smith predictor) instead of with the VE's state predicted to now, the six-bar saturates a Touch
/// and grows energy on a Falcon, and the crank tip grows energy on a Falcon.
#[test]
fn light_outputs_render_on_weak_devices_at_50_ms_over_a_whole_tour() {
    let pairs = [
        pair("watt-six-bar", "link5", DevicePreset::Touch, HandKind::Firm),
        pair("watt-six-bar", "link5", DevicePreset::Touch, HandKind::Soft),
        pair("watt-six-bar", "link5", DevicePreset::Falcon, HandKind::Soft),
        pair("slider-crank", "crank-tip", DevicePreset::Falcon, HandKind::Soft),
    ];
    for p in pairs {
        let r = evaluate(&p, SECONDS).unwrap();
        assert!(
            r.renders,
            "{}:{} on {:?}, {:?} hand: {:?} (clamped {:.1} %, RMS {:.1} mm)",
            p.scene,
            p.op,
            p.device,
            p.hand,
            r.failures,
            r.clamped_fraction * 100.0,
            r.device_op_rms_m * 1e3
        );
    }
}

/// The five-bar robot's effector on `sim:paper` under a firm hand, on a perfect network: in the free
/// directions only the position channels hold the device to the local model, and with a third of the damping
/// budget (the joint-constraint controller took two thirds) they left the device's mass at a damping ratio of
/// 0.3 with the hand on it; where the handle spins near the linkage's singular elbow the controllers then gave
/// the hand more than it put in over the tour (energy growth). With two thirds of the damping in the
/// channels the pair renders, and the same session with the designed gains split the old way still grows
/// energy, more than twice as much, where only the local model's port is checked. Checked at the device's own
/// port too (`CoreConfig::device_port_passivity`, the default), the old split is held as well: the energy its
/// channels made between the model and the device is what that check damps out.
#[test]
fn the_five_bar_effector_renders_under_a_firm_hand_with_the_damping_in_the_channels() {
    use kinloop::experiments::common::session;
    use kinloop::experiments::verdict::judge;
    use kinloop_client::core::config::{ControllerGains, GainChoice};
    use kinloop_client::user::{HandSpec, UserSpec};
    use kinloop_harness::{ClientPlan, CoreEdit, SessionPlan};
    let p =
        Point { network: Network::Perfect, ..pair("five-bar-robot", "effector", DevicePreset::Paper, HandKind::Firm) };
    let designed = evaluate(&p, SECONDS).unwrap();
    assert!(designed.renders, "{:?} (excess {:?} J)", designed.failures, designed.energy_excess_j);
    // k_j, b_j, K_pc (x, y, angle), B_pc (x, y, angle): the linear damping budget is b_j + B_pc, which the old
    // split gave two thirds to the joints; the angular channel had a third of its budget, half of today's.
    let g = designed.gains.clone();
    assert_eq!(g.len(), 8, "{g:?}");
    let budget = g[1] + g[5];
    let old_split = ControllerGains {
        joint_stiffness: g[0],
        joint_damping: budget * 2.0 / 3.0,
        position_stiffness: g[2..5].to_vec(),
        position_damping: vec![budget / 3.0, budget / 3.0, g[7] / 2.0],
    };
    let judged_old_split = |device_port: bool| {
        let old_split = old_split.clone();
        let mut client = ClientPlan::new("user", "effector", DevicePreset::Paper);
        client.user = UserSpec::Hand(HandSpec::touring(HandKind::Firm));
        client.configure = Some(CoreEdit::new(move |c| {
            c.gains = GainChoice::Custom(old_split.clone());
            c.device_port_passivity = device_port;
        }));
        let plan = SessionPlan {
            scene: kinloop_linkage::model::builtin::scene("five-bar-robot").unwrap().unwrap(),
            ve: kinloop_server::core::VeConfig::default(),
            clients: vec![client],
            duration: std::time::Duration::from_secs_f64(SECONDS),
            record_every: 1,
        };
        let (summary, rec) = session(&plan).unwrap();
        judge(&summary, &rec)
    };
    let old = judged_old_split(false);
    assert!(!old.stable && old.reasons.contains(&"energy growth"), "{old:?}");
    let excess = designed.energy_excess_j.unwrap();
    assert!(excess < 0.5 * old.energy_excess_j, "designed {excess} J against the old split's {old:?}");
    let held = judged_old_split(true);
    assert!(held.stable, "the old split with the device's port checked: {held:?}");
}

/// The ball-jointed Delta robot with the paper's configuration-space local model (eq 11): its snapshots
/// carry nq = 31 positions against 24 rates, the client's model steps q with the VE's own configuration
/// update, and the pair renders by the matrix's bounds on a Falcon at 50 ms. Between ticks the client's q
/// is, to round-off, the VE's `configuration::integrate` of the q it started from (its own, or the newest
/// snapshot's) by the q̇ it then held: the quaternions turn on the sphere instead of staying frozen.
#[test]
fn the_ball_jointed_delta_renders_with_the_configuration_space_local_model() {
    use kinloop::experiments::renderability::{judged, plan};
    use kinloop_client::core::{HapticCore, ModelForm, TickOutput};
    use kinloop_client::device::DeviceState;
    use kinloop_harness::{CoreHooks, Session};
    use kinloop_linkage::algorithms::configuration::integrate;
    use kinloop_linkage::math::space::Spatial;
    use kinloop_linkage::model::Model;
    use nalgebra::DVector;
    use std::time::Duration;

    /// When a tick found the local model, and its q, q̇ and the frozen terms' q.
    type State = (Duration, DVector<f64>, DVector<f64>, DVector<f64>);
    /// Every tick's [`State`] while the configuration form steps.
    #[derive(Default)]
    struct Watch {
        states: Vec<State>,
        ticks: usize,
    }
    impl CoreHooks<Spatial> for Watch {
        fn tick<'c>(
            &mut self,
            _who: usize,
            core: &'c mut HapticCore<Spatial>,
            now: Duration,
            device: &DeviceState<Spatial>,
        ) -> TickOutput<'c, Spatial> {
            self.ticks += 1;
            match core.config_local_model() {
                Some(c) => self.states.push((now, c.q.clone(), c.qd.clone(), c.terms().q.clone())),
                None => self.states.clear(),
            }
            core.tick(now, device)
        }
    }

    let point = pair("delta", "platform", DevicePreset::Falcon, HandKind::Soft);
    let mut plan = plan(&point, 8.0).unwrap();
    plan.clients[0].form = ModelForm::Config;
    let model: Model<Spatial> = Model::compile(&plan.scene, "delta").unwrap();
    assert_eq!((model.nq(), model.nv()), (31, 24));
    let mut session = Session::<Spatial>::new(&plan).unwrap();
    let mut watch = Watch::default();
    let (mut stepped, mut held, mut turned, mut worst) = (0, 0, 0.0_f64, 0.0_f64);
    // Checked in stretches, so the states need not all be kept.
    for second in 1..=8 {
        session.run_until_with(Duration::from_secs(second), &mut watch).unwrap();
        for w in watch.states.windows(2) {
            let ((t0, q0, _, _), (t1, q1, qd1, base)) = (&w[0], &w[1]);
            let dt = (*t1 - *t0).as_secs_f64();
            let mut from_own = q0.clone();
            integrate(&model, &mut from_own, qd1, dt);
            let mut from_update = base.clone();
            integrate(&model, &mut from_update, qd1, dt);
            let error = (q1 - &from_own).amax().min((q1 - &from_update).amax());
            turned = turned.max((q1 - base).amax());
            if error < 1e-12 {
                stepped += 1;
            } else if q1 == q0 || q1 == base {
                // A tick with the hand off the handle holds the model still.
                held += 1;
            } else {
                worst = worst.max(error);
            }
        }
        watch.states.drain(..watch.states.len().saturating_sub(1));
    }
    assert_eq!(worst, 0.0, "the client's q left the VE's configuration update by {worst:e}");
    assert!(stepped > 7000, "the configuration form stepped {stepped} of {} ticks ({held} held)", watch.ticks);
    assert!(turned > 1e-6, "the client's q never moved from the snapshots' ({turned:e})");
    let (summary, rec) = session.run(&mut |_| {}).unwrap();
    let r = judged(&point, &summary, &rec);
    assert!(
        r.renders,
        "{:?} (clamped {:.1} %, RMS {:.1} mm, closure {:.1e} m)",
        r.failures,
        r.clamped_fraction * 100.0,
        r.device_op_rms_m * 1e3,
        r.max_closure_error_m
    );
}

/// The serial arm's tip on a Falcon without delay, over a whole tour: the arm passes near its stretched,
/// singular pose, where a direction turns constrained. The device feels the position channels there as part
/// of the wall; a local model that took no reaction from them there (only their free part) left the device
/// on a spring to a wall the model does not feel, and the session made energy (0.034 J over the tour against
/// the 0.006 J the hand's own work explains). Taken at the walls' gains (`ResolvedGains::wall_stiffness`) the
/// pair renders.
#[test]
fn the_serial_arms_tip_renders_on_a_falcon_without_delay() {
    let p = Point {
        scene: "serial-arm".into(),
        op: "tip".into(),
        device: DevicePreset::Falcon,
        network: Network::Perfect,
        hand: HandKind::Soft,
    };
    let r = evaluate(&p, SECONDS).unwrap();
    assert!(r.renders, "{:?}: energy excess {:?} J", r.failures, r.energy_excess_j);
}
