//! The one place where the DHD frame and units meet kinloop's.
//!
//! The DHD SDK speaks metres, metres per second and newtons in the device's frame: x towards the user, y to
//! the right, z up, origin at the workspace centre (`dhdc.h`, Force Dimension's user manuals). kinloop's
//! axes are taken as x = device y (right), y = device z (up), z = device x (towards the user): a proper
//! rotation (device y × device z = device x), so a spatial scene keeps its handedness, and a planar scene's
//! (x, y) plane is the vertical plane facing the user, where a hand moves most freely. The device's x is
//! then a planar scene's unused depth: the device reads it and kinloop ignores it (nothing is commanded on
//! it, so the hand moves freely in depth). On a 3-DOF device (omega.3, delta.3, Falcon) the angular axes
//! are locked: θ of a planar scene, and the rotations of a spatial one, read 0 and are never commanded.

/// kinloop axis `i` (0, 1, 2) is this device axis.
pub const DEVICE_AXIS_OF: [usize; 3] = [1, 2, 0];

/// A device-frame vector (m, m/s, N) in kinloop's axes.
pub fn to_kinloop(device: [f64; 3]) -> [f64; 3] {
    DEVICE_AXIS_OF.map(|d| device[d])
}

/// A kinloop-axes vector (m, m/s, N) in the device frame; `linear` is how many of kinloop's axes the scene
/// uses (2 planar, 3 spatial): the others get zero.
pub fn to_device(kinloop: &[f64], linear: usize) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (axis, &device_axis) in DEVICE_AXIS_OF.iter().enumerate().take(linear.min(3)) {
        out[device_axis] = kinloop.get(axis).copied().unwrap_or(0.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axes_map_back_and_forth_and_keep_handedness() {
        let device = [0.01, 0.02, 0.03];
        assert_eq!(to_kinloop(device), [0.02, 0.03, 0.01]);
        assert_eq!(to_device(&to_kinloop(device), 3), device);
        // Planar: device y and z only; depth (device x) is never commanded.
        assert_eq!(to_device(&[1.0, 2.0, 0.5], 2), [0.0, 1.0, 2.0]);
        // kinloop x × y = z holds in the device frame: ŷ × ẑ = x̂.
        let (ex, ey) = (to_device(&[1.0, 0.0, 0.0], 3), to_device(&[0.0, 1.0, 0.0], 3));
        let cross = [ex[1] * ey[2] - ex[2] * ey[1], ex[2] * ey[0] - ex[0] * ey[2], ex[0] * ey[1] - ex[1] * ey[0]];
        assert_eq!(cross, to_device(&[0.0, 0.0, 1.0], 3));
    }
}
