//! The local model's pull toward the VE is paid from an energy tank that only the coupling's dampers fill
//! (`CoreConfig::passive_update`), checked from outside the core on a VE that runs away from a still hand.

use std::time::Duration;

use kinloop_client::core::{ConstraintMode, HapticCore, ModelForm, UPDATE_TANK_CAPACITY_J};
use kinloop_client::device::DeviceState;
use kinloop_harness::{first_terms, CoreEdit, Plain, Session, SessionPlan};
use kinloop_linkage::math::space::{OpPose, Planar};
use nalgebra::Vector3;

/// The largest energy the position channels' springs hold over 3 s while the VE's OP runs off at 5 cm/s
/// along x and the device is held still where the OP started (the hand does no work on the device).
fn largest_spring_energy(passive_update: bool) -> f64 {
    let mut plan = SessionPlan::paper_manipulation(ConstraintMode::Stiffness, ModelForm::Op).expect("the plan");
    plan.clients[0].configure = Some(CoreEdit::new(move |c| c.passive_update = passive_update));
    // The testbed at rest, a few milliseconds into the session: its welcome and a snapshot to run away from.
    let (welcome, base, config) = first_terms::<Planar>(&plan, Duration::from_millis(4)).expect("terms");
    let mut core = HapticCore::<Planar>::new(config, &welcome).expect("core");
    let start = OpPose::<Planar>::from_slice(&base.op_pose).expect("a valid pose");
    let device = DeviceState::<Planar> { pose: start, twist: Vector3::zeros(), hand_wrench: None, grasped: None };
    let speed = 0.05;
    let mut largest = 0.0f64;
    for k in 1..=3000u64 {
        let now = Duration::from_millis(k);
        let t = now.as_secs_f64();
        let mut snapshot = base.clone();
        snapshot.seq = k;
        snapshot.server_time_s = t;
        // The VE answers the client's previous tick, and is somewhere else than it was told.
        snapshot.uplink_time_s = t - 1e-3;
        snapshot.op_pose[0] += speed * t;
        snapshot.op_twist = vec![speed, 0.0, 0.0];
        core.handle_snapshot(now, &snapshot).expect("a valid snapshot");
        let e = core.tick(now, &device).report.tracking_error;
        let k_pc = core.gains().position_stiffness;
        let spring: f64 = (0..3).map(|i| 0.5 * k_pc[i] * e[i] * e[i]).sum();
        largest = largest.max(spring);
    }
    largest
}

/// With the hand still, all energy in the device-model coupling came from the updates, which may spend only
/// the tank's capacity plus what the dampers dissipated of it: the springs never hold more than the capacity.
/// Without the tank the model follows the VE away and the springs load up without bound.
#[test]
fn a_ve_running_away_cannot_load_a_still_hand_with_more_than_the_tank_holds() {
    let with_tank = largest_spring_energy(true);
    let without = largest_spring_energy(false);
    println!("largest spring energy: {with_tank:.3e} J with the tank, {without:.3e} J without");
    assert!(with_tank <= UPDATE_TANK_CAPACITY_J * 1.05, "{with_tank} J");
    assert!(without > 10.0 * UPDATE_TANK_CAPACITY_J, "the runaway VE is a real load without the tank: {without} J");
}

/// In an ordinary session the dampers dissipate more than the pull needs: the tank never holds it back (the
/// paper's push, 3 s).
#[test]
fn the_tank_does_not_hold_back_the_pull_in_an_ordinary_session() {
    let plan = SessionPlan::paper_manipulation(ConstraintMode::Stiffness, ModelForm::Op).expect("the plan");
    let mut session = Session::<Planar>::new(&plan).expect("the session");
    session.run_until_with(Duration::from_millis(2999), &mut Plain).expect("steps");
    let core = session.core(0).expect("joined");
    assert!(core.config().passive_update, "on by default");
    let stats = core.stats();
    assert!(stats.active_ticks > 2900);
    assert_eq!(stats.updates_limited, 0);
}
