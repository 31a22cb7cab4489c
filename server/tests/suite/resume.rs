//! The VE taking up a room's state offered back by a client (`VeCore::handle_resume_offer`, docs/resume.md):
//! a state that closes the loops is resumed where it was, one slightly off is re-assembled onto them, and a state
//! that breaks the loops, does not fit the scene or arrives while users are present is refused and counted,
//! leaving the VE as it was. Closure is checked with a workspace of the test's own.

use crate::support;

use std::time::Duration;

use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::loop_closure::closure_residual;
use kinloop_linkage::math::space::{Planar, Space};
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_linkage::model::{data::Data, Model};
use kinloop_protocol::{ResumeRefusal, Role};
use kinloop_server::core::{VeConfig, VeCore};
use nalgebra::DVector;

use support::*;

/// Closure residual ‖h(q)‖ (m), evaluated apart from any VE.
fn residual(model: &Model<Planar>, q: &DVector<f64>) -> f64 {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    closure_residual(model, &mut data);
    data.closure_residual.norm()
}

/// The paper's manipulation for 1.5 s: a state away from q0, moving.
fn pushed_state() -> (DVector<f64>, DVector<f64>) {
    let mut ve = core(testbed(), VeConfig::paper());
    let user = ve.join(Duration::ZERO, request("paper", Role::Manipulator, "link2", 3)).unwrap().user_id;
    let mut latest = Vec::new();
    let mut seq = 0;
    run(&mut ve, Duration::from_millis(1500), &mut latest, |ve, now, latest| {
        if let Some(Some(s)) = latest.get(user as usize) {
            seq += 1;
            ve.handle_uplink(now, user, &following(s, seq, &PAPER_WRENCH)).unwrap();
        }
    });
    (ve.state().q.clone(), ve.state().qd.clone())
}

fn fresh() -> VeCore<Planar> {
    core(testbed(), VeConfig::paper())
}

#[test]
fn a_closed_state_is_resumed_where_it_was_and_the_welcome_describes_it() {
    let (q, qd) = pushed_state();
    let model = testbed();
    assert!((&q - &model.q0).norm() > 0.1, "the manipulation moved the linkage");
    let mut ve = fresh();
    ve.handle_resume_offer(Duration::ZERO, q.as_slice(), qd.as_slice()).expect("resumed");
    // The VE's own steps leave h(q) near 1e-10 m; re-assembly to 1e-12 L moves q by about as little.
    assert!((ve.state().q - &q).norm() <= 1e-7, "resumed at {:?}, offered {q:?}", ve.state().q);
    assert_eq!(ve.state().qd, &qd);
    // The OP a joining user is told about is where forward kinematics puts link 2's COM at the offered q.
    let joined = ve.join(Duration::ZERO, request("back", Role::Manipulator, "link2", 3)).unwrap();
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &q);
    let op = &model.ops[0];
    let expected = data.kin.body_pos[op.body] + Planar::rotate(&data.kin.body_rot[op.body], &op.point);
    let position = &joined.welcome.op.position;
    assert!(
        (position[0] - expected.as_slice()[0]).abs() < 1e-9 && (position[1] - expected.as_slice()[1]).abs() < 1e-9,
        "welcome OP {position:?}, forward kinematics {expected:?}"
    );
    assert_eq!((ve.metrics().resumes_accepted, ve.metrics().resumes_refused), (1, 0));
}

#[test]
fn a_state_slightly_off_the_loops_is_reassembled_onto_them() {
    let (mut q, qd) = pushed_state();
    let model = testbed();
    q[1] += 2e-4;
    let off = residual(&model, &q);
    assert!(off > 1e-6, "the offer is off the loops ({off} m)");
    let mut ve = fresh();
    ve.handle_resume_offer(Duration::ZERO, q.as_slice(), qd.as_slice()).expect("re-assembled");
    let closed = residual(&model, ve.state().q);
    assert!(closed <= 1e-10, "re-assembled to a residual of {closed} m");
    assert!((ve.state().q - &q).norm() < 1e-3, "re-assembled near the offer");
}

#[test]
fn a_state_that_breaks_the_loops_or_misfits_is_refused_and_the_ve_keeps_its_own() {
    let (q, qd) = pushed_state();
    let model = testbed();
    let mut ve = fresh();
    let mut broken = q.clone();
    broken[1] += 0.3;
    let refused = ve.handle_resume_offer(Duration::ZERO, broken.as_slice(), qd.as_slice()).unwrap_err();
    match refused {
        ResumeRefusal::Loops { residual_m, tolerance_m } => {
            assert!((residual_m - residual(&model, &broken)).abs() <= 1e-12 && residual_m > tolerance_m)
        }
        other => panic!("{other:?}"),
    }
    let short = ve.handle_resume_offer(Duration::ZERO, &q.as_slice()[1..], qd.as_slice()).unwrap_err();
    assert!(matches!(&short, ResumeRefusal::Shape { what } if what.contains("coordinates")), "{short:?}");
    let mut nan = q.clone();
    nan[0] = f64::NAN;
    let not_finite = ve.handle_resume_offer(Duration::ZERO, nan.as_slice(), qd.as_slice()).unwrap_err();
    assert!(matches!(&not_finite, ResumeRefusal::Shape { what } if what.contains("q[0]")), "{not_finite:?}");
    assert_eq!(ve.state().q, &model.q0, "the VE kept its own state");
    ve.join(Duration::ZERO, request("here", Role::Manipulator, "link2", 3)).unwrap();
    let live = ve.handle_resume_offer(Duration::ZERO, q.as_slice(), qd.as_slice()).unwrap_err();
    assert_eq!(live, ResumeRefusal::RoomLive { users: 1 });
    assert_eq!(ve.state().q, &model.q0);
    assert_eq!((ve.metrics().resumes_accepted, ve.metrics().resumes_refused), (0, 4));
}
