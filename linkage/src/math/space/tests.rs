use nalgebra::{Matrix3, Rotation3, UnitComplex, Vector2, Vector3, Vector6};

use super::*;

/// The chord is 2 sin(θ/2) for the angle θ between two orientations, computed here from the angles the
/// orientations were built with (planar) and from an axis and angle composed onto an arbitrary start
/// (spatial).
#[test]
fn the_chord_between_orientations_is_two_sines_of_the_half_angle() {
    for (a, b) in [(0.3, 0.3), (0.3, 0.5), (-3.0, 3.0), (1.0, -2.5)] {
        let (ra, rb) = (Planar::rot_from_vector(&a), Planar::rot_from_vector(&b));
        let theta = (b - a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        let expected = 2.0 * (theta.abs() / 2.0).sin();
        assert!((Planar::rot_chord(&ra, &rb) - expected).abs() < 1e-9, "{a} {b}");
    }
    let start = Spatial::rot_from_vector(&Vector3::new(0.4, -1.1, 0.7));
    let axis = Vector3::new(2.0, -1.0, 2.0) / 3.0;
    for theta in [0.0, 1e-4, 0.5, 2.0, 3.1] {
        let turned = Spatial::rot_mul(&Spatial::rot_from_vector(&(axis * theta)), &start);
        let expected = 2.0 * (theta / 2.0).sin();
        assert!((Spatial::rot_chord(&start, &turned) - expected).abs() < 1e-9, "{theta}");
    }
}

/// A planar tour through ±π: the wrapped angles 2.9, −3.1 (0.28 rad apart the short way) unwrap to 2.9,
/// 3.18, and a whole further turn keeps counting; a spatial rotation vector unwraps along its axis.
#[test]
fn rotations_unwrap_to_the_turn_nearest_the_previous() {
    let mut d = Vector3::new(0.1, 0.2, -3.1);
    unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 2.9));
    assert!((d[2] - (-3.1 + std::f64::consts::TAU)).abs() < 1e-12 && d[0] == 0.1 && d[1] == 0.2);
    let mut d = Vector3::new(0.0, 0.0, 0.5);
    unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 6.6));
    assert!((d[2] - (0.5 + std::f64::consts::TAU)).abs() < 1e-12);
    let mut d = Vector3::new(0.0, 0.0, 0.3);
    unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 0.1));
    assert_eq!(d[2], 0.3, "already nearest");
    let axis = Vector3::new(1.0, 2.0, 2.0) / 3.0;
    let mut d = Vector6::zeros();
    d.fixed_rows_mut::<3>(3).copy_from(&(axis * -3.0));
    let mut previous = Vector6::zeros();
    previous.fixed_rows_mut::<3>(3).copy_from(&(axis * 3.0));
    unwrap_rotation_near::<Spatial>(&mut d, &previous);
    let expected = axis * (std::f64::consts::TAU - 3.0);
    assert!((d.fixed_rows::<3>(3) - expected).norm() < 1e-12, "{d:?}");
}

/// Force and torque saturate apart: a torque past its limit is scaled back without touching the
/// force, each part keeps its direction, and a zero limit zeroes its part.
#[test]
fn wrench_parts_clip_independently_keeping_direction() {
    let w = Vector3::new(3.0, 4.0, 2.0); // planar: force (3, 4), |f| = 5; torque 2
    let (out, scales) = clip_wrench_parts::<Planar>(&w, 10.0, 0.5);
    assert!(scales.clipped());
    assert_eq!((out[0], out[1]), (3.0, 4.0));
    assert!((out[2] - 0.5).abs() < 1e-15);
    let (out, scales) = clip_wrench_parts::<Planar>(&w, 2.5, 0.0);
    assert!(scales.clipped());
    assert!((out[0] - 1.5).abs() < 1e-15 && (out[1] - 2.0).abs() < 1e-15 && out[2] == 0.0);
    let (out, scales) = clip_wrench_parts::<Planar>(&w, 5.0, 2.0);
    assert!(!scales.clipped());
    assert_eq!(out, w);
}

/// Kinetic energy from the world-frame spatial inertia equals ½ m |v_c|² + ½ ωᵀ I ω computed directly.
#[test]
fn spatial_inertia_gives_rigid_body_kinetic_energy() {
    let c = Vector3::new(0.3, -0.2, 0.5);
    let ic = Matrix3::new(0.2, 0.01, 0.02, 0.01, 0.3, 0.03, 0.02, 0.03, 0.4);
    let rot = Rotation3::new(Vector3::new(0.1, 0.7, -0.3));
    let m = 2.5;
    let inertia = Spatial::inertia_world(m, &c, &ic, &rot);
    let w = Vector3::new(0.4, -1.1, 0.7);
    let v_origin = Vector3::new(0.2, 0.9, -0.5);
    let motion = Spatial::spatial(w, v_origin);
    let ke_spatial = 0.5 * motion.dot(&(inertia * motion));
    let v_com = v_origin + w.cross(&c);
    let i_world = rot.matrix() * ic * rot.matrix().transpose();
    let ke_direct = 0.5 * m * v_com.norm_squared() + 0.5 * w.dot(&(i_world * w));
    assert!((ke_spatial - ke_direct).abs() < 1e-12, "{ke_spatial} vs {ke_direct}");
}

#[test]
fn planar_inertia_gives_rigid_body_kinetic_energy() {
    let c = Vector2::new(0.3, -0.2);
    let m = 1.7;
    let ic = 0.05;
    let inertia = Planar::inertia_world(m, &c, &ic, &UnitComplex::new(0.3));
    let (w, v) = (0.8, Vector2::new(-0.4, 1.2));
    let motion = Planar::spatial(w, v);
    let ke = 0.5 * motion.dot(&(inertia * motion));
    let v_com = v + Planar::ang_cross_point(&w, &c);
    let direct = 0.5 * m * v_com.norm_squared() + 0.5 * ic * w * w;
    assert!((ke - direct).abs() < 1e-12);
}

/// The planar algebra is the spatial algebra restricted to the plane: (ω_z, v_x, v_y).
#[test]
fn planar_cross_products_match_spatial_ones_restricted_to_the_plane() {
    let lift = |p: &Vector3<f64>| Vector6::new(0.0, 0.0, p[0], p[1], p[2], 0.0);
    let v = Vector3::new(0.7, -0.3, 1.1);
    let m = Vector3::new(-0.4, 0.9, 0.2);
    let planar = Planar::cross_motion(&v, &m);
    let spatial = Spatial::cross_motion(&lift(&v), &lift(&m));
    assert!((lift(&planar) - spatial).norm() < 1e-14);
    let planar_f = Planar::cross_force(&v, &m);
    let spatial_f = Spatial::cross_force(&lift(&v), &lift(&m));
    assert!((lift(&planar_f) - spatial_f).norm() < 1e-14);
}

#[test]
fn rotation_log_is_accurate_for_small_and_large_angles() {
    for angle in [1e-9, 1e-6, 0.3, 2.0, 3.0] {
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        let log = Spatial::rot_log(&Rotation3::new(axis * angle));
        assert!((log - axis * angle).norm() < 1e-13 * angle.max(1e-3), "angle {angle}: {log}");
    }
}

#[test]
fn rodrigues_matches_nalgebra_axis_angle() {
    let axis = Vector3::new(1.0, 2.0, -0.5).normalize();
    let angle: f64 = 0.83;
    let ours = Spatial::rot_about_axis(&axis, angle.cos(), angle.sin());
    let theirs = Rotation3::new(axis * angle);
    assert!((ours.matrix() - theirs.matrix()).norm() < 1e-14);
}
