//! Names of operational axes: the records' column suffixes, and the replay user's wrench columns, so a
//! recording replays as is.

use kinloop_linkage::math::space::SceneKind;

/// Pose components: planar `x, y, theta`; spatial `x, y, z, qw, qx, qy, qz`.
pub fn pose_names(kind: SceneKind) -> &'static [&'static str] {
    match kind {
        SceneKind::Planar => &["x", "y", "theta"],
        SceneKind::Spatial => &["x", "y", "z", "qw", "qx", "qy", "qz"],
    }
}

/// Wrench components: planar `fx, fy, tz`; spatial `fx, fy, fz, tx, ty, tz`.
pub fn wrench_names(kind: SceneKind) -> &'static [&'static str] {
    match kind {
        SceneKind::Planar => &["fx", "fy", "tz"],
        SceneKind::Spatial => &["fx", "fy", "fz", "tx", "ty", "tz"],
    }
}
