//! The grasp rule (`grasp`) against closed forms, through the mapping that applies it (`choose_mapping`).

use super::grasp::*;
use super::*;
use std::f64::consts::TAU;

use kinloop_linkage::math::space::Planar;

/// The crank-rocker's coupler point and crank tip surveyed, and the paper's planar device (0.2 N m peak,
/// a 0.005 kg m² handle) without its linear mass: the reach keeps the workspace's fill whatever the load
/// (the narrowing for a heavy handle has its own test), so the grasp's closed forms are taken at one scale.
fn crank_rocker() -> (OpReach<Planar>, OpReach<Planar>, DeviceCaps) {
    use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
    use kinloop_linkage::model::{builtin, Model};
    let scene = builtin::scene("fourbar-crank-rocker").expect("built in").expect("parses");
    let model = Model::<Planar>::compile(&scene, "fourbar-crank-rocker").expect("compiles");
    let survey = |op: &str| survey_op(&model, model.op_index(op).expect("an OP"), &SurveyConfig::default());
    let paper = DeviceCaps {
        workspace_min: vec![-0.15, -0.15, -TAU],
        workspace_max: vec![0.15, 0.15, TAU],
        max_force_n: 10.0,
        continuous_force_n: 5.0,
        max_torque_nm: 0.2,
        mass: vec![0.0, 0.0, 0.005],
        ..DeviceCaps::generous("paper", 3)
    };
    (survey("coupler").expect("surveys"), survey("crank-tip").expect("surveys"), paper)
}

/// `reach` with another static load at the OP.
fn loaded(reach: &OpReach<Planar>, force: f64, torque: f64) -> OpReach<Planar> {
    OpReach { static_force_n: force, static_torque_nm: torque, ..reach.clone() }
}

fn chosen(reach: &OpReach<Planar>, device: &DeviceCaps) -> Mapping {
    choose_mapping(reach, &[], device, &MappingRequest::default(), true).expect("a mapping")
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-9 * want.abs()
}

/// The turn of a point passing a fixed centre, `θ(t) = atan(v t / r)`, differentiated twice by central
/// differences over the pass: its largest angular acceleration is [`PASSING_TURN`] `v² / r²`.
#[test]
fn a_point_passing_a_centre_turns_fastest_by_three_root_three_eighths() {
    for (pace, radius) in [(0.04, 0.0044), (0.04, 0.1), (0.3, 0.02)] {
        let theta = |t: f64| (pace * t / radius).atan();
        let (span, steps) = (4.0 * radius / pace, 200_000);
        let h = 2.0 * span / steps as f64;
        let largest = (1..steps)
            .map(|i| {
                let t = -span + i as f64 * h;
                ((theta(t + h) - 2.0 * theta(t) + theta(t - h)) / (h * h)).abs()
            })
            .fold(0.0, f64::max);
        let want = 3.0 * 3f64.sqrt() / 8.0 * pace * pace / (radius * radius);
        assert!((largest - want).abs() <= 1e-6 * want, "{largest} against {want}");
        assert!((PASSING_TURN - 3.0 * 3f64.sqrt() / 8.0).abs() <= 1e-15);
    }
}

/// [`rigid_grasp_torque`] against the closed forms: the crank's tip turns about the crank's pivot at the
/// crank's length (0.1 m), so at the rigid scale its grasp asks the static torque plus
/// `(5/4) I_handle (3√3/8) (v / (0.1 c_p))²`; a point near its instant centre asks more as `1 / r²`, and the
/// rule makes the grasp rigid on one side of the radius where that reaches the peak and leaves it pinned on
/// the other: the actuated four-bar's load on the coupler point (68 N, 2.09 N m), its turning radius set
/// at 0.99 and 1.01 of that radius, and at 4.4 mm on the device (the generated couplers that saturated the
/// device's torque held rigidly).
#[test]
fn a_grasp_stays_pinned_where_turning_the_handle_rigidly_asks_more_than_the_peak_torque() {
    let (coupler, crank_tip, paper) = crank_rocker();
    let (handle, peak, pace) = (0.005, 0.2, HAND_PACE_M_S);
    let passing = 3.0 * 3f64.sqrt() / 8.0;
    let c_p = chosen(&crank_tip, &paper).position_scale;
    let rigid = handle / (4.0 / crank_tip.inverse_rotational_inertia_max * c_p);
    let rate = pace / (0.1 * c_p);
    let want = crank_tip.static_torque_nm * rigid * c_p + 1.25 * handle * passing * rate * rate;
    assert!(close(rigid_grasp_torque(&crank_tip, &paper, c_p, rigid), want));
    // The coupler under the four-bar's load: the radius at which the rigid grasp asks the peak.
    let reach = loaded(&coupler, 68.0, 2.09);
    let c_p = chosen(&reach, &paper).position_scale;
    let rigid = handle * coupler.inverse_rotational_inertia_max / (4.0 * c_p);
    let static_torque = 2.09 * rigid * c_p;
    assert!(static_torque < peak, "the static torque alone fits");
    let edge = pace / c_p * (1.25 * handle * passing / (peak - static_torque)).sqrt();
    let r_g = (coupler.inverse_mass_max / coupler.inverse_rotational_inertia_max).sqrt();
    assert!(edge < 0.5 * r_g, "the edge lies where the OP moves by turning");
    let at = |radius: f64| chosen(&OpReach { turning_radius_min_m: radius, ..reach.clone() }, &paper);
    for (radius, held) in [(1.01 * edge, true), (0.99 * edge, false), (0.0044 / c_p, false), (0.0, false)] {
        let m = at(radius);
        assert_eq!(m.rigid_grasp, held, "turning radius {radius} m (edge {edge} m)");
        let torque = rigid_grasp_torque(&OpReach { turning_radius_min_m: radius, ..reach.clone() }, &paper, c_p, rigid);
        assert_eq!(torque <= peak, held, "{torque} N m");
        if !held {
            assert!(m.force_scale < rigid, "pinned at the load's own scale");
        }
    }
}

/// The grasp rule ([`held_rigidly`]) against the closed forms, on the crank-rocker's two OPs surveyed. The
/// coupler point, given the actuated four-bar's load (a position actuator's pull far from its target: 68 N
/// and 2.09 N m), whose own scale `min(0.35 F_cont / F, 0.35 · ½ τ_peak / (τ c_p))` pins the grasp,
/// turns about its instant centre nearer than its `r_g = √(I / m)`: it gets the smallest scale at which its
/// rotational inertia on the device is the quarter of the handle's the impedance controller can reach,
/// `I_handle / (4 I_op c_p)`. The crank's tip turns about the crank's pivot at the crank's length, which is
/// its `r_g` too: its pin keeps half the coupling's hold everywhere, and under its own load, pinned and
/// holdable rigidly, its scale stays the load's own. So do a load the device would not hold continuously at
/// the rigid scale, a static torque beyond its peak and a device without torque (whose load is the force a
/// pin holds it with, `OpReach::static_pin_force_n`).
#[test]
fn a_pinned_grasp_is_held_rigidly_where_the_op_moves_by_turning() {
    let (coupler, crank_tip, paper) = crank_rocker();
    let (force, torque, handle, quarter) = (68.0, 2.09, 0.005, 0.25);
    // The load's own scale, computed apart from the code: the force and the torque bounds.
    let own = |force: f64, torque: f64, c_p: f64, renders_torque: bool| {
        let by_force = LOAD_FRACTION * 5.0 / force;
        if renders_torque {
            by_force.min(LOAD_FRACTION * 0.5 * 0.2 / (torque * c_p))
        } else {
            by_force
        }
    };
    let inertia = |reach: &OpReach<Planar>| 1.0 / reach.inverse_rotational_inertia_max;
    let r_g = |reach: &OpReach<Planar>| (reach.inverse_mass_max / reach.inverse_rotational_inertia_max).sqrt();
    // The crank's tip: r = r_g = 0.1 m, the crank's length.
    assert!(close(crank_tip.turning_radius_min_m, 0.1) && close(r_g(&crank_tip), 0.1));
    let (tip_force, tip_torque) = (crank_tip.static_force_n, crank_tip.static_torque_nm);
    let m = chosen(&crank_tip, &paper);
    let (rigid, tip_own) = (
        handle / (MASS_REDUCTION * inertia(&crank_tip) * m.position_scale),
        own(tip_force, tip_torque, m.position_scale, true),
    );
    let holds = tip_force * rigid <= 5.0 && tip_torque * rigid * m.position_scale <= 0.2;
    assert!(tip_own < rigid && holds, "the pin at the crank's tip is not one the device could hold rigidly");
    assert!(close(m.force_scale, tip_own) && !m.rigid_grasp);
    // The coupler point: nearer its instant centre than its r_g somewhere.
    assert!(coupler.turning_radius_min_m < 0.9 * r_g(&coupler), "{} m", coupler.turning_radius_min_m);
    let reach = loaded(&coupler, force, torque);
    let m = chosen(&reach, &paper);
    let c_p = m.position_scale;
    let rigid = handle / (MASS_REDUCTION * inertia(&coupler) * c_p);
    assert!(own(force, torque, c_p, true) < rigid, "the case pins the grasp at the load's own scale");
    assert!(force * rigid <= 5.0 && torque * rigid * c_p <= 0.2, "the case holds the load rigidly");
    assert!(close(m.force_scale, rigid), "{} against {rigid}", m.force_scale);
    assert!(m.rigid_grasp);
    let seen = inertia(&coupler) * m.force_scale * c_p;
    assert!(close(seen, quarter * handle), "the device feels a quarter of its handle");
    assert_eq!(check_holdable(&reach, &paper, &m), Ok(()));
    // The load beyond the continuous force at the rigid scale, the torque beyond the peak: the load's own.
    for (force, torque) in [(1.01 * 5.0 / rigid, torque), (force, 1.01 * 0.2 / (rigid * c_p))] {
        let m = chosen(&loaded(&coupler, force, torque), &paper);
        assert!(close(m.force_scale, own(force, torque, c_p, true)), "{force} N, {torque} N m");
        assert!(!m.rigid_grasp);
    }
    // A device without torque: the force bound alone, on the force a pin holds the load with, pinned.
    let falcon = DeviceCaps { max_torque_nm: 0.0, ..paper.clone() };
    let pin_load = 3.0 * force;
    let m = chosen(&OpReach { static_pin_force_n: pin_load, ..reach.clone() }, &falcon);
    assert!(close(m.force_scale, own(pin_load, torque, c_p, false)) && !m.rigid_grasp);
}
