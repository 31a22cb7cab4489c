//! The design's rules against closed forms and the shipped scenes' surveys.

use super::*;
use std::f64::consts::TAU;

/// The frequency (Hz) the rule gives at 1 kHz rates for a round trip `trip` (s).
fn hz(trip: Option<f64>) -> f64 {
    CouplingFrequency::designed(1000.0, 1000.0, trip).omega / TAU
}

/// The phase margin (rad) of a critically damped PD on a unit mass at `omega` behind a loop delay of
/// `delay_s`, computed numerically: the open loop `(B s + K) e^{-s τ} / s²` crosses |L| = 1 where a
/// bisection finds it, and the margin is `π + arg L` there.
fn delayed_phase_margin(omega: f64, delay_s: f64) -> f64 {
    let (k, b) = (omega * omega, 2.0 * COUPLING_DAMPING_RATIO * omega);
    let gain = |w: f64| (b * b * w * w + k * k).sqrt() / (w * w);
    let (mut lo, mut hi) = (1e-3 * omega, 1e3 * omega);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if gain(mid) > 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let crossover = 0.5 * (lo + hi);
    (b * crossover / k).atan() - crossover * delay_s
}

/// The rule of the module documentation at 1 kHz: a round trip of a millisecond or less gets the rate
/// margins' 20 Hz, 1.25 ms 16 Hz, 2.5 ms and beyond (a 100 ms link) the default 8 Hz, as does a join
/// whose round trip was not measured or is not a duration.
#[test]
fn a_fast_link_gets_a_stiffer_coupling_and_a_slow_one_the_default() {
    let close = |got: f64, want: f64| (got - want).abs() < 1e-9 * want;
    for (trip, want) in [(Some(0.0), 20.0), (Some(1e-3), 20.0), (Some(1.25e-3), 16.0), (Some(2.5e-3), 8.0)] {
        assert!(close(hz(trip), want), "{trip:?}: {} Hz", hz(trip));
    }
    for trip in [Some(0.1), Some(1.0), None, Some(f64::NAN), Some(-1e-3), Some(f64::INFINITY)] {
        assert_eq!(hz(trip), COUPLING_HZ, "{trip:?}");
    }
}

/// Over round trips from 0 to 0.2 s and rates from 100 Hz to 10 kHz: the frequency never rises with the
/// round trip, never exceeds a fiftieth of either rate, is never below the default unless a rate demands
/// it, and above the default the PD behind the round trip keeps more than 60° of phase margin (computed
/// numerically, not from the rule's constants).
#[test]
fn the_frequency_falls_with_the_round_trip_within_the_rate_margins() {
    for (ve, device) in [(1000.0, 1000.0), (1000.0, 4000.0), (10000.0, 1000.0), (100.0, 1000.0), (4000.0, 4000.0)] {
        let mut last = f64::INFINITY;
        for i in 0..=2000 {
            let trip = i as f64 * 1e-4;
            let omega = CouplingFrequency::designed(ve, device, Some(trip)).omega;
            assert!(omega <= last, "{ve}/{device} Hz: rises at {trip} s");
            last = omega;
            let rates = TAU * f64::min(ve, device) / RATE_MARGIN;
            assert!(omega <= rates * (1.0 + 1e-12), "{ve}/{device} Hz at {trip} s: {omega} rad/s");
            assert!(omega >= (TAU * COUPLING_HZ).min(rates) * (1.0 - 1e-12));
            if omega > TAU * COUPLING_HZ * (1.0 + 1e-12) {
                let margin = delayed_phase_margin(omega, trip).to_degrees();
                assert!(margin > 60.0, "{ve}/{device} Hz at {trip} s: {margin}°");
            }
        }
    }
}

/// Mid-session the frequency only goes down: a round trip within what it holds changes nothing, a longer
/// one lowers K by (ω'/ω)² and B by ω'/ω (the damping ratio kept), a shorter one afterwards does not
/// raise them again, and gains designed at the default are never softened.
#[test]
fn a_longer_round_trip_only_softens_the_coupling() {
    use kinloop_linkage::math::space::Planar;
    use nalgebra::Vector3;
    let mass = Vector3::new(2.0, 2.0, 0.01);
    let mut frequency = CouplingFrequency::designed(1000.0, 1000.0, Some(0.0));
    let omega0 = frequency.omega;
    assert_eq!(omega0, TAU * 20.0);
    let (mut k, mut b) = (mass * omega0 * omega0, mass * 2.0 * omega0);
    let mut stiffest = k;
    // Estimates as the VE measures them, a tick (1 ms) above the network's round trip.
    for trip in [1e-3, 1.5e-3, 2e-3, 2.1e-3, 1.5e-3, 0.0, 3e-3, 2e-3, 0.1, 0.0, 3.0] {
        let before = k;
        let changed = soften::<Planar>(&mut frequency, Some(trip), 1e-3, &mut k, &mut b);
        assert_eq!(changed, k != before, "{trip}");
        assert!(trip > 2e-3 || !changed, "a round trip within a millisecond changed the gains");
        assert!(k.iter().zip(stiffest.iter()).all(|(now, most)| now <= most), "K rose at {trip} s");
        stiffest = k;
        let omega = frequency.omega;
        for a in 0..3 {
            assert!((k[a] - mass[a] * omega * omega).abs() <= 1e-12 * k[a]);
            assert!((b[a] - 2.0 * mass[a] * omega).abs() <= 1e-12 * b[a]);
        }
    }
    assert_eq!(frequency.omega, TAU * COUPLING_HZ);
    let mut default = CouplingFrequency::designed(1000.0, 1000.0, None);
    assert!(!soften::<Planar>(&mut default, Some(10.0), 1.0, &mut k, &mut b));
    assert!(!soften::<Planar>(&mut frequency, None, 1.0, &mut k, &mut b));
    assert!(!soften::<Planar>(&mut frequency, Some(f64::NAN), 1e-3, &mut k, &mut b));
    // Lost uplinks: on a perfect round trip, a gap of 3 ms holds the reference 2 ms beyond a device
    // period, which 20 Hz does not hold and 10 Hz does.
    let mut fast = CouplingFrequency::designed(1000.0, 1000.0, Some(0.0));
    assert!(!soften::<Planar>(&mut fast, Some(1e-3), 1e-3, &mut k, &mut b));
    assert!(soften::<Planar>(&mut fast, Some(1e-3), 3e-3, &mut k, &mut b));
    assert!((fast.omega - TAU * 10.0).abs() < 1e-9);
}

#[test]
fn the_load_maps_below_both_the_continuous_and_the_peak_bound() {
    let device = |peak: f64, continuous: f64| DeviceCaps {
        max_force_n: peak,
        continuous_force_n: continuous,
        ..DeviceCaps::generous("d", 3)
    };
    // The simulated presets' figures (paper device 10/5 N, Falcon 8.9/4 N, Touch 3.3/0.88 N): the
    // continuous bound binds, so their mappings are what they were before the peak bound.
    for (peak, continuous) in [(10.0, 5.0), (8.9, 4.0), (3.3, 0.88)] {
        assert_eq!(load_target(&device(peak, continuous)), LOAD_FRACTION * continuous);
    }
    // One figure for both (the omega.3's 12 N): the peak bound binds, leaving 1/PEAK_SHARE of headroom.
    let omega = load_target(&device(12.0, 12.0));
    assert!((omega - PEAK_SHARE * 12.0).abs() < 1e-12 && 12.0 / omega > 5.5, "{omega}");
}

/// The stated load rule: the mapping the server chooses passes it (the load maps to `LOAD_FRACTION` of the
/// continuous force); the same load with the force scale held at the wire's smallest, far above what the
/// device holds, is refused with a message naming the rule and what would change it.
#[test]
fn the_load_rule_refuses_only_a_load_the_scale_could_not_bring_down() {
    use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
    use kinloop_linkage::math::space::Planar;
    use kinloop_linkage::model::{builtin, Model};
    let scene = builtin::scene("paper-testbed").expect("built in").expect("parses");
    let model = Model::<Planar>::compile(&scene, "paper-testbed").expect("compiles");
    let mut reach = survey_op(&model, 0, &SurveyConfig::default()).expect("surveys");
    reach.static_force_n = reach.static_force_n.max(1.0);
    let device = DeviceCaps { continuous_force_n: 5.0, max_force_n: 10.0, ..DeviceCaps::generous("d", 3) };
    let mapping = choose_mapping(&reach, &[], &device, &MappingRequest::default(), true).expect("a mapping");
    assert_eq!(check_holdable(&reach, &device, &mapping), Ok(()));
    let heavy = Mapping { force_scale: 10.0 * device.continuous_force_n / reach.static_force_n, ..mapping };
    let refused = check_holdable(&reach, &device, &heavy).expect_err("refused");
    let text = refused.to_string();
    assert!(text.starts_with(PREDICTED_REFUSAL) && text.contains("would change this"), "{text}");
    let compensated = Mapping { gravity_compensation: true, ..heavy };
    assert_eq!(check_holdable(&reach, &device, &compensated), Ok(()));
}

/// The reach is narrowed exactly where the linkage would feel lighter than the handle can be made, with
/// the margin: a light load keeps the workspace's fill; a heavier one (a smaller force scale) narrows it
/// until the OP's lightest mass feels `handle / (MASS_REDUCTION REDUCTION_MARGIN)`; a far heavier one stops
/// at `MIN_REACH_SHARE` of the fill; a scale the client asks for is kept. (The testbed's static torque is
/// far within the generous device's peak, so the force scale is the load's.)
#[test]
fn the_reach_narrows_until_the_linkage_feels_no_lighter_than_the_handle_can_be_made() {
    use kinloop_linkage::math::space::Planar;
    let mut reach = surveyed("paper-testbed").swap_remove(0);
    let (mass, _) = lightest(&reach);
    let handle = 0.5;
    let device = DeviceCaps { mass: vec![handle, handle, 0.0], ..DeviceCaps::generous("d", 3) };
    let massless = DeviceCaps { mass: vec![0.0; 3], ..device.clone() };
    let mapped = |reach: &OpReach<Planar>, device: &DeviceCaps, request: &MappingRequest| {
        choose_mapping(reach, &[], device, request, true).expect("a mapping")
    };
    let felt = |m: &Mapping| mass * m.force_scale / m.position_scale;
    let bound = MASS_REDUCTION * REDUCTION_MARGIN;
    let mut seen = [false; 3];
    for load in (-6..=12).map(|k| 10f64.powf(k as f64 / 2.0)) {
        reach.static_force_n = load;
        let fill = mapped(&reach, &massless, &MappingRequest::default()).position_scale;
        let m = mapped(&reach, &device, &MappingRequest::default());
        assert_eq!(m.force_scale, mapped(&reach, &massless, &MappingRequest::default()).force_scale);
        if fill * handle <= mass * m.force_scale * bound {
            seen[0] = true;
            assert_eq!(m.position_scale, fill, "load {load}: not narrowed");
            assert!(felt(&m) * bound >= handle * (1.0 - 1e-12));
        } else if m.position_scale > MIN_REACH_SHARE * fill {
            seen[1] = true;
            assert!(m.position_scale < fill);
            assert!((felt(&m) * bound / handle - 1.0).abs() < 1e-12, "load {load}: {}", felt(&m));
        } else {
            seen[2] = true;
            assert!((m.position_scale / fill - MIN_REACH_SHARE).abs() < 1e-12, "load {load}");
        }
        assert!((m.position_scale / fill - reach_narrowing(&reach, &device)).abs() < 1e-12);
        let asked = MappingRequest { position_scale: Some(0.9 * fill), ..MappingRequest::default() };
        assert_eq!(mapped(&reach, &device, &asked).position_scale, 0.9 * fill);
    }
    assert_eq!(seen, [true; 3], "the loads cover the three cases");
}

/// Every OP of one linkage is narrowed on a device by the same factor, the least of its OPs' own, so that
/// users at different OPs keep their reaches' proportions; and the force scale never rises above the
/// fill's, though a narrower reach eases the static torque's bound. The crank-rocker on the paper's device
/// (1 kg handle, 0.2 N m): the crank tip needs more narrowing than the coupler, and at the fill its force
/// scale is held down by its static torque.
#[test]
fn one_linkage_is_narrowed_by_one_factor_and_no_force_scale_rises() {
    let reaches = surveyed("fourbar-crank-rocker");
    let paper = DeviceCaps {
        max_force_n: 10.0,
        continuous_force_n: 5.0,
        max_torque_nm: 0.2,
        mass: vec![1.0, 1.0, 0.005],
        workspace_min: vec![-0.15, -0.15, -TAU],
        workspace_max: vec![0.15, 0.15, TAU],
        ..DeviceCaps::generous("paper", 3)
    };
    let own: Vec<f64> = reaches.iter().map(|r| reach_narrowing(r, &paper)).collect();
    let least = own.iter().copied().fold(1.0, f64::min);
    assert!(own.iter().any(|&f| f > least * 1.5), "the OPs differ: {own:?}");
    assert!((MIN_REACH_SHARE..1.0).contains(&least), "{least}");
    let default = MappingRequest::default();
    for reach in &reaches {
        let alone = choose_mapping(reach, &[], &paper, &default, true).expect("a mapping");
        let shared = choose_mapping(reach, &reaches, &paper, &default, true).expect("a mapping");
        let fill = filling_scale(reach, &paper);
        assert!((shared.position_scale / fill - least).abs() < 1e-12, "{} vs {least}", shared.position_scale / fill);
        assert!(shared.position_scale <= alone.position_scale);
        let at_fill = torque_and_grasp(reach, &paper, fill, load_scale(reach, &paper));
        assert!(shared.force_scale <= at_fill && alone.force_scale <= at_fill);
    }
    let tip = &reaches[1];
    let (fill, load) = (filling_scale(tip, &paper), load_scale(tip, &paper));
    let (eased, at_fill) =
        (torque_and_grasp(tip, &paper, least * fill, load), torque_and_grasp(tip, &paper, fill, load));
    assert!(eased > at_fill, "the narrower reach eases the crank tip's torque bound: {eased} vs {at_fill}");
}

/// On a path the linear damping is the larger of the PD's critical damping on the lightest mass and, at
/// the 90th percentile of the path's poses, `2 ζ_p √(m (K + K_rest))` (a hill counting as no stiffness);
/// the stiffness and the angular gains do not change, and a pose next to a dead point (an inertia of
/// 10⁹ kg) does not set it. Without path modes the gains are the PD's alone. Closed forms on the crank-
/// rocker's coupler with its surveyed lightest mass and modes put in by hand.
#[test]
fn the_damping_holds_the_heavier_modes_along_the_path_and_nothing_else_changes() {
    use kinloop_linkage::algorithms::reach::PathMode;
    let coupler = surveyed("fourbar-crank-rocker").remove(0);
    let omega = TAU * COUPLING_HZ;
    let none = OpReach { path_modes: Vec::new(), ..coupler.clone() };
    let (k0, b0) = coupling_gains(&none, omega, true);
    let (mass, inertia) = grasp::lightest(&none);
    assert!((k0[0] - mass * omega * omega).abs() < 1e-9 * k0[0] && (b0[0] - 2.0 * mass * omega).abs() < 1e-9 * b0[0]);
    // Nine poses of 2 kg held at 500 N/m, one at 3 kg on a hill, one next to a dead point.
    let mut modes = vec![PathMode { mass: 2.0, rest_stiffness: 500.0 }; 9];
    modes.push(PathMode { mass: 3.0, rest_stiffness: -1e6 });
    modes.push(PathMode { mass: 1e9, rest_stiffness: 500.0 });
    let with = OpReach { path_modes: modes, ..coupler.clone() };
    let (k, b) = coupling_gains(&with, omega, true);
    assert_eq!(k, k0, "the stiffness is the lightest mass's");
    let held = 2.0 * PATH_DAMPING_RATIO * (2.0 * (k0[0] + 500.0)).sqrt();
    let hill = 2.0 * PATH_DAMPING_RATIO * (3.0 * k0[0]).sqrt();
    let want = held.max(hill).max(b0[0]);
    assert!(want > 2.0 * b0[0], "the modes ask for more than the PD's own: {want} vs {}", b0[0]);
    for a in 0..2 {
        assert!((b[a] - want).abs() < 1e-9 * want, "axis {a}: {} vs {want}", b[a]);
    }
    assert_eq!(b[2], b0[2], "the angular damping is the lightest inertia's ({inertia} kg m²)");
    // Modes lighter and looser than the PD's design leave it as it was.
    let light = OpReach { path_modes: vec![PathMode { mass: 1e-6, rest_stiffness: 0.0 }; 5], ..coupler };
    assert_eq!(coupling_gains(&light, omega, true), (k0, b0));
}

/// A load the lightest mass's spring would not hold near the device raises the linear stiffness to hold it
/// within [`HOLD_STRETCH`] of the reach's extent, critically damped at that stiffness; the load is the least
/// wrench's force on a device with torque and the pin's on one without; the angular gains do not change, and
/// a load the spring already holds changes nothing.
#[test]
fn the_coupling_holds_a_heavy_static_load_within_a_tenth_of_the_reach() {
    let coupler = surveyed("fourbar-crank-rocker").remove(0);
    let omega = TAU * COUPLING_HZ;
    let free = OpReach { static_force_n: 0.0, static_pin_force_n: 0.0, path_modes: Vec::new(), ..coupler.clone() };
    let (k0, b0) = coupling_gains(&free, omega, true);
    let (mass, _) = grasp::lightest(&free);
    let extent = free.largest_extent();
    for (torque, force, pin) in [(true, 1e4, 1.0), (false, 1.0, 1e4)] {
        let heavy = OpReach { static_force_n: force, static_pin_force_n: pin, ..free.clone() };
        let (k, b) = coupling_gains(&heavy, omega, torque);
        let want = 1e4 / (HOLD_STRETCH * extent);
        assert!(want > 2.0 * k0[0], "the case is a load the spring does not hold");
        for a in 0..2 {
            assert!((k[a] - want).abs() < 1e-9 * want, "axis {a}: {} vs {want}", k[a]);
            let critical = 2.0 * COUPLING_DAMPING_RATIO * (mass * want).sqrt();
            assert!((b[a] - critical).abs() < 1e-9 * critical, "axis {a}: {} vs {critical}", b[a]);
        }
        let angular = if torque { (k0[2], b0[2]) } else { (0.0, 0.0) };
        assert_eq!((k[2], b[2]), angular);
    }
    let light = OpReach { static_force_n: 1e-9, static_pin_force_n: 1e-9, ..free };
    assert_eq!(coupling_gains(&light, omega, true), (k0, b0));
}

/// Every OP of built-in planar scene `name`, surveyed.
fn surveyed(name: &str) -> Vec<OpReach<kinloop_linkage::math::space::Planar>> {
    use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
    use kinloop_linkage::math::space::Planar;
    use kinloop_linkage::model::{builtin, Model};
    let scene = builtin::scene(name).expect("built in").expect("parses");
    let model = Model::<Planar>::compile(&scene, name).expect("compiles");
    (0..model.ops.len()).map(|op| survey_op(&model, op, &SurveyConfig::default()).expect("surveys")).collect()
}
