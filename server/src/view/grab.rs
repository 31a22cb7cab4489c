//! A page holding an operational point with the mouse, as the VE sees it: a manipulator without a device,
//! whose "local model" is the drag target. Sans-IO: time is an argument; the socket task moves the bytes.
//!
//! Each uplink is built from the user's newest snapshot (the VE's OP pose and twist) and the newest drag
//! target:
//! - position: the target, pulled to within [`Grip::reach_m`] of the VE's OP, so the coupling's pull stays
//!   bounded (K_g times the reach) and far inside the core's guard (a model 1 m away is refused);
//! - orientation and angular twist: the VE's own, so the grip turns freely: a drag moves the point, not
//!   its angle (the paper's angular gains, 10⁴ N·m/rad, would otherwise pin the link's orientation);
//! - linear twist: a finite-difference estimate of the target's velocity (zero once the mouse rests), so
//!   the coupling's damping does not drag behind a moving hand;
//! - hand wrench: zero (no force channel: a mouse measures none).

use std::time::Duration;

use crate::core::guards::{MAX_OP_DIM, MAX_POSE_LEN};
use crate::core::UplinkSample;

/// A drag target older than this no longer moves: the velocity estimate drops to zero.
const RESTING_AFTER: Duration = Duration::from_millis(100);
/// Largest target speed sent (m/s), well under the guard's 20 m/s.
pub const MAX_TARGET_SPEED: f64 = 2.0;
/// Farthest a target may be from its OP (m) by default.
pub const DEFAULT_REACH_M: f64 = 0.05;
/// Coordinates farther from the origin than this are not a drag target (m).
const FARTHEST_TARGET_M: f64 = 1.0e3;

/// Why a drag target was not used.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TargetError {
    /// Not 2 (planar) or 3 (spatial) numbers.
    #[error("a drag target has {expected} numbers in this scene, not {got}")]
    WrongLength {
        /// Needed.
        expected: usize,
        /// Given.
        got: usize,
    },
    /// NaN, infinite or absurdly far.
    #[error("a drag target must be finite and within 1 km")]
    NotFinite,
}

/// One grip (see the module documentation).
#[derive(Clone, Debug)]
pub struct Grip {
    /// Linear dimension (2 or 3).
    point_dim: usize,
    /// Operational dimension (3 or 6).
    op_dim: usize,
    /// Pose length (3 or 7).
    pose_len: usize,
    /// Farthest target from the OP (m).
    pub reach_m: f64,
    target: Option<([f64; 3], Duration)>,
    velocity: [f64; 3],
    seq: u64,
}

impl Grip {
    /// A grip in a scene of operational dimension `op_dim` (3 planar, 6 spatial).
    pub fn new(op_dim: usize, reach_m: f64) -> Self {
        let (point_dim, pose_len) = if op_dim == 3 { (2, 3) } else { (3, 7) };
        Grip { point_dim, op_dim, pose_len, reach_m, target: None, velocity: [0.0; 3], seq: 0 }
    }

    /// A new drag target at `now`.
    pub fn set_target(&mut self, now: Duration, target: &[f64]) -> Result<(), TargetError> {
        if target.len() != self.point_dim {
            return Err(TargetError::WrongLength { expected: self.point_dim, got: target.len() });
        }
        if target.iter().any(|v| !v.is_finite() || v.abs() > FARTHEST_TARGET_M) {
            return Err(TargetError::NotFinite);
        }
        let mut p = [0.0; 3];
        p[..self.point_dim].copy_from_slice(target);
        if let Some((previous, at)) = self.target {
            let dt = now.saturating_sub(at).as_secs_f64();
            if dt > 1e-3 {
                // A light low-pass: mouse events come unevenly.
                for a in 0..3 {
                    self.velocity[a] = 0.5 * self.velocity[a] + 0.5 * (p[a] - previous[a]) / dt;
                }
                clamp_norm(&mut self.velocity, MAX_TARGET_SPEED);
            }
        }
        self.target = Some((p, now));
        Ok(())
    }

    /// The uplink for `now`, given the VE's OP pose and twist from the user's newest snapshot.
    pub fn uplink(&mut self, now: Duration, op_pose: &[f64], op_twist: &[f64]) -> Option<UplinkSample> {
        if op_pose.len() != self.pose_len || op_twist.len() != self.op_dim {
            return None;
        }
        let d = self.point_dim;
        let mut sample = UplinkSample {
            seq: 0,
            client_time_s: now.as_secs_f64(),
            flags: 0,
            hand_wrench: [0.0; MAX_OP_DIM],
            model_pose: [0.0; MAX_POSE_LEN],
            model_twist: [0.0; MAX_OP_DIM],
            op_dim: self.op_dim as u8,
            pose_len: self.pose_len as u8,
        };
        sample.model_pose[..self.pose_len].copy_from_slice(op_pose);
        sample.model_twist[..self.op_dim].copy_from_slice(op_twist);
        if let Some((target, at)) = self.target {
            let mut offset = [0.0; 3];
            for a in 0..d {
                offset[a] = target[a] - op_pose[a];
            }
            clamp_norm(&mut offset, self.reach_m);
            for a in 0..d {
                sample.model_pose[a] = op_pose[a] + offset[a];
            }
            let moving = now.saturating_sub(at) < RESTING_AFTER;
            for a in 0..d {
                sample.model_twist[a] = if moving { self.velocity[a] } else { 0.0 };
            }
        }
        self.seq += 1;
        sample.seq = self.seq;
        Some(sample)
    }
}

fn clamp_norm(v: &mut [f64; 3], max: f64) {
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > max {
        for x in v.iter_mut() {
            *x *= max / norm;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_far_target_is_pulled_in_to_the_reach_and_the_grip_keeps_the_ops_angle() {
        let mut grip = Grip::new(3, 0.05);
        grip.set_target(MS, &[1.0, 0.0]).unwrap();
        let s = grip.uplink(2 * MS, &[0.1, 0.2, 0.7], &[0.0, 0.0, 3.0]).unwrap();
        assert!((s.model_pose[0] - 0.15).abs() < 1e-12 && (s.model_pose[1] - 0.2).abs() < 1e-12, "{s:?}");
        assert_eq!(s.model_pose[2], 0.7, "orientation is the VE's");
        assert_eq!(s.model_twist[2], 3.0, "angular twist is the VE's");
        assert_eq!(&s.hand_wrench[..3], &[0.0; 3]);
        assert_eq!((s.seq, s.op_dim, s.pose_len), (1, 3, 3));
        assert_eq!(grip.uplink(3 * MS, &[0.1, 0.2, 0.7], &[0.0; 3]).unwrap().seq, 2, "sequence numbers increase");
    }

    #[test]
    fn the_velocity_estimate_follows_the_mouse_is_bounded_and_rests() {
        let mut grip = Grip::new(3, 0.05);
        grip.set_target(Duration::ZERO, &[0.0, 0.0]).unwrap();
        grip.set_target(10 * MS, &[0.001, 0.0]).unwrap();
        let moving = grip.uplink(12 * MS, &[0.0, 0.0, 0.0], &[0.0; 3]).unwrap();
        assert!((moving.model_twist[0] - 0.05).abs() < 1e-9, "half of 0.1 m/s after one event: {moving:?}");
        grip.set_target(20 * MS, &[1.0, 0.0]).unwrap();
        let fast = grip.uplink(21 * MS, &[0.0, 0.0, 0.0], &[0.0; 3]).unwrap();
        assert!((fast.model_twist[0] - MAX_TARGET_SPEED).abs() < 1e-9, "{fast:?}");
        let resting = grip.uplink(200 * MS, &[0.0, 0.0, 0.0], &[0.0; 3]).unwrap();
        assert_eq!(resting.model_twist[0], 0.0);
    }

    #[test]
    fn bad_targets_and_poses_are_refused() {
        let mut grip = Grip::new(6, 0.05);
        assert_eq!(grip.set_target(MS, &[0.0, 0.0]), Err(TargetError::WrongLength { expected: 3, got: 2 }));
        assert_eq!(grip.set_target(MS, &[0.0, f64::NAN, 0.0]), Err(TargetError::NotFinite));
        assert_eq!(grip.set_target(MS, &[0.0, 1e9, 0.0]), Err(TargetError::NotFinite));
        assert!(grip.uplink(MS, &[0.0; 3], &[0.0; 6]).is_none(), "a planar pose in a spatial grip");
        let held = grip.uplink(MS, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], &[0.0; 6]).unwrap();
        assert_eq!(&held.model_pose[..7], &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], "no target: hold where the OP is");
    }
}
