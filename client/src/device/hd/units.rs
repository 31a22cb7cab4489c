//! The one place where OpenHaptics' units meet kinloop's. HD speaks millimetres (`HD_CURRENT_POSITION`),
//! millimetres per second (`HD_CURRENT_VELOCITY`), newtons (`HD_CURRENT_FORCE`), and per-millimetre
//! rendering limits (`HD_NOMINAL_MAX_STIFFNESS` in N/mm, `HD_NOMINAL_MAX_DAMPING` in N s/mm), in the
//! device's frame: x to the user's right, y up, z towards the user, origin at the workspace centre
//! (OpenHaptics' Programmer's Guide). Those are kinloop's axes, so only units convert: a planar scene uses
//! x and y, and the device's z is its unused depth (read, never commanded).

/// Millimetres (or mm/s) to metres (m/s).
pub fn mm_to_m(v: [f64; 3]) -> [f64; 3] {
    v.map(|x| x * 1e-3)
}

/// A per-millimetre figure (N/mm, N s/mm) per metre (N/m, N s/m).
pub fn per_mm_to_per_m(x: f64) -> f64 {
    x * 1e3
}

/// `HD_USABLE_WORKSPACE_DIMENSIONS` (min x, y, z, then max x, y, z in mm) as (min, max) in metres.
pub fn workspace(dims_mm: [f64; 6]) -> ([f64; 3], [f64; 3]) {
    let min = mm_to_m([dims_mm[0], dims_mm[1], dims_mm[2]]);
    let max = mm_to_m([dims_mm[3], dims_mm[4], dims_mm[5]]);
    (min, max)
}

/// kinloop's force (N; `linear` of its axes used: 2 planar, 3 spatial) as the device's `HD_CURRENT_FORCE`:
/// the axes a scene does not use get zero.
pub fn force_to_device(force: &[f64], linear: usize) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (o, f) in out.iter_mut().zip(force).take(linear.min(3)) {
        *o = *f;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn millimetres_and_per_millimetre_figures_convert_to_si() {
        assert_eq!(mm_to_m([80.0, -60.0, 35.0]), [0.08, -0.06, 0.035]);
        // 0.4 N/mm is 400 N/m: a 1 mm deflection gives 0.4 N either way.
        assert!((per_mm_to_per_m(0.4) * 1e-3 - 0.4).abs() < 1e-15);
        let (min, max) = workspace([-80.0, -60.0, -35.0, 80.0, 60.0, 35.0]);
        assert_eq!((min, max), ([-0.08, -0.06, -0.035], [0.08, 0.06, 0.035]));
        assert_eq!(force_to_device(&[1.0, 2.0, 0.5], 2), [1.0, 2.0, 0.0]);
        assert_eq!(force_to_device(&[1.0, 2.0, 0.5], 3), [1.0, 2.0, 0.5]);
    }
}
