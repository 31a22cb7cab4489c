//! The VE with ball joints (nq ≠ nv): the Delta robot of the linkage tests, pushed by a user.

use crate::support;

use std::time::Duration;

use kinloop_protocol::Role;
use kinloop_server::core::VeConfig;

use support::*;

/// A Delta robot written with ball joints (nq = 31, nv = 24) runs in the VE: a manipulator pushing its
/// platform with the operational-space local model moves it for a second with the loops closed to 1e-9 m and
/// every snapshot finite, and an observer with the configuration-space form gets the scene's ball layout in
/// its welcome and snapshots whose `config.q` holds nq positions (each ball's a unit quaternion) and
/// `config.qd` nv rates, as the wire's checks against that shape find.
#[test]
fn a_ball_jointed_delta_runs_in_the_ve() {
    use kinloop_linkage::algorithms::configuration::ConfigLayout;
    use kinloop_linkage::math::space::Spatial;
    use kinloop_linkage::model::scene::Scene;
    use kinloop_protocol::{codec::validate, LocalModelForm};
    let text = include_str!("../../../scenes/delta.toml");
    let scene = Scene::from_toml_str(text, "scenes/delta.toml").unwrap();
    let model: kinloop_linkage::model::Model<Spatial> =
        kinloop_linkage::model::Model::compile(&scene, "delta").unwrap();
    let layout = ConfigLayout::of(&model);
    let mut ve = core(model, VeConfig::default());
    let mut config_form = request("c", Role::Observer, "platform", 6);
    config_form.form = LocalModelForm::ConfigSpace;
    let watcher = ve.join(Duration::ZERO, config_form).unwrap();
    let summary = &watcher.welcome.scene;
    let shape = summary.shape();
    assert_eq!((shape.nq, shape.n), (31, 24));
    assert_eq!(summary.ball_rates.iter().map(|&r| r as usize).collect::<Vec<_>>(), layout.ball_rates());
    let user = ve.join(Duration::ZERO, request("u", Role::Manipulator, "platform", 6)).unwrap().user_id;
    let push = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0];
    let (mut latest, mut seq, mut worst, mut snapshots) = (Vec::new(), 0, 0.0_f64, 0);
    let mut configurations = 0;
    run(&mut ve, Duration::from_secs(1), &mut latest, |ve, now, latest| {
        if let Some(Some(s)) = latest.get(watcher.user_id as usize) {
            validate::snapshot(s, &shape).unwrap();
            let config = s.config.as_ref().unwrap();
            assert_eq!((config.q.len(), config.qd.len()), (31, 24));
            assert_eq!(layout.first_non_unit(&config.q), None);
            configurations += 1;
        }
        if let Some(Some(s)) = latest.get(user as usize) {
            assert!(s.op_pose.iter().chain(&s.inverse_inertia).all(|x| x.is_finite()));
            seq += 1;
            snapshots += 1;
            ve.handle_uplink(now, user, &following(s, seq, &push)).unwrap();
        }
        worst = worst.max(ve.state().closure_error);
    });
    assert!(snapshots > 100 && configurations > 100, "{snapshots} snapshots, {configurations} with configurations");
    assert_eq!(ve.metrics().state_restores, 0);
    assert!(worst <= 1e-9, "closure error reached {worst:e} m");
    let moved = (ve.state().q.rows(0, 3) - ve.model().q0.rows(0, 3)).norm();
    assert!(moved > 0.01, "the arms barely moved ({moved} rad)");
}
