//! The step's energy account (`energy_guard`), checked by energies and works computed here on their own:
//! the mechanical energy from the bodies' velocities and positions, the work of a user's wrench from its
//! operational point's displacement.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::dynamics::OpWrench;
use kinloop_linkage::algorithms::energy_guard::EnergyGuard;
use kinloop_linkage::algorithms::gravity::{kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::integrator::{project, step_guarded, StepConfig};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::math::space::{Planar, Space};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::Model;
use kinloop_linkage::testing::paper_testbed;
use nalgebra::{DVector, Vector3};

fn energy<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>) -> (f64, f64) {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, qd);
    (kinetic_energy(model, data), potential_energy(model, data, q))
}

/// A state on the constraint manifold near q0, its joints turning at up to `speed` (rad/s or m/s).
fn spun<S: Space>(model: &Model<S>, seed: u64, speed: f64) -> (DVector<f64>, DVector<f64>) {
    let (q, qd) = random_state(model, seed);
    let (mut q, mut qd) = (q, qd * speed);
    let mut data = Data::new(model);
    // The projection needs the factors of a solve near the state.
    kinloop_linkage::algorithms::dynamics::forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
    project(model, &mut data, &mut q, &mut qd);
    let top = qd.amax();
    (q, qd * (speed / top))
}

/// Over `seconds` of free motion at the VE's step, with or without the account: the largest rise of the
/// mechanical energy above its start as each step begins (after the account's correction: the energy a step
/// makes is taken out when the next begins), relative to the start's kinetic energy; and the energy the
/// account took out, relative to the same.
fn free_rise<S: Space>(model: &Model<S>, q0: &DVector<f64>, qd0: &DVector<f64>, guarded: bool) -> (f64, f64) {
    let cfg = StepConfig::euler(1e-3);
    let mut data = Data::new(model);
    let (mut q, mut qd) = (q0.clone(), qd0.clone());
    let (t0, v0) = energy(model, &mut data, &q, &qd);
    let mut guard = EnergyGuard::default();
    let (mut rise, mut ended_at, mut removed): (f64, f64, f64) = (0.0, t0 + v0, 0.0);
    for _ in 0..1000 {
        let g = guarded.then_some(&mut guard);
        if step_guarded(model, &mut data, &mut q, &mut qd, &mut (), &cfg, g).is_err() {
            return (f64::INFINITY, guard.removed / t0);
        }
        // What the account took out as this step began came off the energy the last one ended with.
        rise = rise.max((ended_at - (guard.removed - removed) - t0 - v0) / t0);
        removed = guard.removed;
        let (t, v) = energy(model, &mut data, &q, &qd);
        ended_at = t + v;
    }
    (rise, guard.removed / t0)
}

/// Spun fast and left to itself (gravity, springs and dampers only), a linkage stepped with the account
/// begins no step with more mechanical energy than it started with; without it, semi-implicit Euler makes
/// energy (the account has work to do).
#[test]
fn a_fast_free_swing_never_gains_energy_with_the_account() {
    let mut worst_plain: f64 = 0.0;
    for (name, model) in planar_models().iter() {
        for seed in 0..3 {
            let (q0, qd0) = spun(model, seed, 60.0);
            let (plain, _) = free_rise(model, &q0, &qd0, false);
            let (guarded, removed) = free_rise(model, &q0, &qd0, true);
            eprintln!("{name} seed {seed}: rise plain {plain:.3e}, guarded {guarded:.3e}, removed {removed:.3e}");
            worst_plain = worst_plain.max(plain);
            assert!(guarded <= 1e-9, "{name} seed {seed}: the guarded swing rose by {guarded:.3e} of its energy");
        }
    }
    assert!(worst_plain > 0.05, "no plain swing made energy ({worst_plain:.3e}): the test shows nothing");
}

/// Under a user's constant wrench at a fine step (where the step makes next to no energy) the account books
/// the wrench's work as the operational point's displacement gives it: it takes out almost nothing. Booked
/// with the wrong sign or scale, it would take out about twice the work.
#[test]
fn the_account_books_a_users_work_as_the_points_displacement_gives_it() {
    let model = paper_testbed();
    let op = 0;
    let cfg = StepConfig::euler(2e-5);
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), DVector::zeros(model.nv()));
    let mut push = OpWrench::<Planar> { op, wrench: Vector3::new(0.4, -0.3, 0.002) };
    let mut guard = EnergyGuard::default();
    let op_position = |data: &Data<Planar>| {
        let o = &model.ops[op];
        data.kin.body_pos[o.body] + Planar::rotate(&data.kin.body_rot[o.body], &o.point)
    };
    forward_kinematics(&model, &mut data, &q);
    let (mut at, mut angle) = (op_position(&data), data.kin.body_rot[model.ops[op].body].angle());
    let mut work: f64 = 0.0;
    for _ in 0..25_000 {
        step_guarded(&model, &mut data, &mut q, &mut qd, &mut push, &cfg, Some(&mut guard)).unwrap();
        forward_kinematics(&model, &mut data, &q);
        let (now, turned) = (op_position(&data), data.kin.body_rot[model.ops[op].body].angle());
        work +=
            push.wrench[0] * (now[0] - at[0]) + push.wrench[1] * (now[1] - at[1]) + push.wrench[2] * (turned - angle);
        (at, angle) = (now, turned);
    }
    let (t, _) = energy(&model, &mut data, &q, &qd);
    assert!(work.abs() > 1e-3 && t > 1e-4, "the wrench must move the linkage: work {work:.3e} J, T {t:.3e} J");
    assert!(
        guard.removed <= 1e-3 * work.abs() && guard.reservoir().abs() <= 1e-3 * work.abs(),
        "removed {:.3e} J, reservoir {:.3e} J of a work of {work:.3e} J",
        guard.removed,
        guard.reservoir()
    );
}

/// In the paper's manipulation range (the testbed turning at a few rad/s) the account leaves the motion as the
/// plain step makes it, to a small fraction of its energy: the credit for the step's own losses keeps
/// symplectic Euler's bounded swing of energy from being cut at each peak.
#[test]
fn an_ordinary_swing_is_left_alone() {
    let model = paper_testbed();
    let mut data = Data::new(&model);
    let cfg = StepConfig::euler(1e-3);
    let mut guard = EnergyGuard::default();
    let (q0, qd0) = spun(&model, 1, 3.0);
    let (kinetic, _) = energy(&model, &mut data, &q0, &qd0);
    let (mut q, mut qd) = (q0.clone(), qd0.clone());
    let (mut q_plain, mut qd_plain) = (q0, qd0);
    for _ in 0..3000 {
        step_guarded(&model, &mut data, &mut q, &mut qd, &mut (), &cfg, Some(&mut guard)).unwrap();
        step_guarded(&model, &mut data, &mut q_plain, &mut qd_plain, &mut (), &cfg, None).unwrap();
    }
    assert!(guard.removed <= 0.01 * kinetic, "took out {:.3e} J of a swing of {kinetic:.3e} J", guard.removed);
    let strayed = (&q - &q_plain).amax();
    assert!(strayed <= 0.05, "the guarded swing strayed {strayed:.3e} rad from the plain one");
}
