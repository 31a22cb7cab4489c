//! A page holding an operational point with the mouse, as the VE sees it: a client whose "device" is the
//! mouse on a spring. Sans-IO: time is an argument; the socket task moves the bytes.
//!
//! **Why not just send the drag target as the local-model pose.** The VE couples every user with the
//! paper's graphics controller, angular K_g = B_g = 10⁴, made stable by an implicit step that adds
//! `h B_g + h² K_g` ≈ 10 kg·m² to the OP's rotational inertia against any change of the angular velocity
//! the uplink reports. A target that only moves the point therefore leaves the gripped link 5,000 times
//! heavier to turn (the testbed's link2 has 0.0021 kg·m²), and a drag barely moves it. So the grip does what a
//! haptic client does, in miniature:
//! - the *force channel* carries the pull: `F_h = K_m (x_target − x_op) + B_m (v_target − v_op)` on the
//!   linear axes, no torque, with the target pulled to within [`Grip::reach_m`] of the OP (so
//!   `|F_h| ≤ K_m · reach`, well under the core's 100 N default for a user without a device);
//! - the *local-model pose and twist* are the OP's one snapshot period ahead under that force, from the
//!   snapshot's own op-space local model (`a = Λ̂⁻¹ F_h + b̂`, eq 13): where the VE is about to be, so its
//!   coupling adds almost nothing and the link turns as its dynamics say.
//!
//! `B_m` damps critically along the pull, from the OP's effective mass `1 / (uᵀ Λ̂⁻¹ u)` in the pull's
//! direction `u`; `v_target` is a finite-difference estimate of the mouse's velocity (zero once it rests).

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Planar, math::space::Space, math::space::Spatial, math::space::VecOps};
use kinloop_protocol::Snapshot;

use crate::core::guards::{MAX_OP_DIM, MAX_POSE_LEN};
use crate::core::UplinkSample;

/// A drag target older than this no longer moves: its velocity estimate drops to zero.
const RESTING_AFTER: Duration = Duration::from_millis(100);
/// Largest target speed used (m/s).
pub const MAX_TARGET_SPEED: f64 = 2.0;
/// Farthest a target may be from its OP (m) by default.
pub const DEFAULT_REACH_M: f64 = 0.05;
/// The mouse's spring (N/m): 2 N per centimetre, at most 10 N at the default reach.
pub const SPRING_N_PER_M: f64 = 200.0;
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
    /// Operational dimension (3 planar, 6 spatial).
    op_dim: usize,
    /// Farthest target from the OP (m).
    pub reach_m: f64,
    /// Spring stiffness (N/m).
    pub spring: f64,
    target: Option<([f64; 3], Duration)>,
    velocity: [f64; 3],
    seq: u64,
}

impl Grip {
    /// A grip in a scene of operational dimension `op_dim` (3 planar, 6 spatial).
    pub fn new(op_dim: usize, reach_m: f64) -> Self {
        Grip { op_dim, reach_m, spring: SPRING_N_PER_M, target: None, velocity: [0.0; 3], seq: 0 }
    }

    fn point_dim(&self) -> usize {
        if self.op_dim == 3 {
            2
        } else {
            3
        }
    }

    /// A new drag target at `now`.
    pub fn set_target(&mut self, now: Duration, target: &[f64]) -> Result<(), TargetError> {
        let d = self.point_dim();
        if target.len() != d {
            return Err(TargetError::WrongLength { expected: d, got: target.len() });
        }
        if target.iter().any(|v| !v.is_finite() || v.abs() > FARTHEST_TARGET_M) {
            return Err(TargetError::NotFinite);
        }
        let mut p = [0.0; 3];
        p[..d].copy_from_slice(target);
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

    /// The uplink for `now` from the user's newest snapshot, predicting `dt` seconds (one snapshot period)
    /// ahead; `None` when the snapshot does not fit the scene.
    pub fn uplink(&mut self, now: Duration, snapshot: &Snapshot, dt: f64) -> Option<UplinkSample> {
        let k = self.op_dim;
        if snapshot.op_twist.len() != k
            || snapshot.bias_accel.len() != k
            || snapshot.inverse_inertia.len() != k * (k + 1) / 2
            || !(dt.is_finite() && dt > 0.0)
        {
            return None;
        }
        let inverse_inertia = unpack_symmetric(&snapshot.inverse_inertia, k);
        let hand = self.hand_wrench(now, snapshot, &inverse_inertia);
        let mut accel = [0.0; MAX_OP_DIM];
        for r in 0..k {
            accel[r] = snapshot.bias_accel[r] + (0..k).map(|c| inverse_inertia[r * k + c] * hand[c]).sum::<f64>();
        }
        let mut sample = UplinkSample {
            seq: 0,
            client_time_s: now.as_secs_f64(),
            flags: 0,
            last_snapshot_seq: snapshot.seq,
            last_snapshot_age_s: 0.0,
            waited_s: 0.0,
            hand_wrench: hand,
            model_pose: [0.0; MAX_POSE_LEN],
            model_twist: [0.0; MAX_OP_DIM],
            energy_received_j: [0.0; MAX_OP_DIM],
            energy_emitted_j: [0.0; MAX_OP_DIM],
            op_dim: k as u8,
            pose_len: 0,
        };
        let ahead = if k == 3 {
            predict::<Planar>(snapshot, &accel, dt, &mut sample)
        } else {
            predict::<Spatial>(snapshot, &accel, dt, &mut sample)
        };
        ahead?;
        self.seq += 1;
        sample.seq = self.seq;
        Some(sample)
    }

    /// The spring's pull at the snapshot's OP (zero before the first target).
    fn hand_wrench(&self, now: Duration, snapshot: &Snapshot, inverse_inertia: &[f64]) -> [f64; MAX_OP_DIM] {
        let (d, k) = (self.point_dim(), self.op_dim);
        let mut hand = [0.0; MAX_OP_DIM];
        let Some((target, at)) = self.target else { return hand };
        if snapshot.op_pose.len() < d {
            return hand;
        }
        let mut offset = [0.0; 3];
        for a in 0..d {
            offset[a] = target[a] - snapshot.op_pose[a];
        }
        clamp_norm(&mut offset, self.reach_m);
        // Effective mass along the pull (or along the stiffest linear axis when the target is reached).
        let norm = offset.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mobility = if norm > 1e-9 {
            let u: Vec<f64> = offset[..d].iter().map(|x| x / norm).collect();
            (0..d).map(|r| (0..d).map(|c| u[r] * inverse_inertia[r * k + c] * u[c]).sum::<f64>()).sum::<f64>()
        } else {
            (0..d).map(|a| inverse_inertia[a * k + a]).fold(f64::INFINITY, f64::min)
        };
        let mass = if mobility.is_finite() && mobility > 1e-9 { 1.0 / mobility } else { 1.0 };
        let damping = 2.0 * (self.spring * mass).sqrt();
        let moving = now.saturating_sub(at) < RESTING_AFTER;
        for a in 0..d {
            let v_target = if moving { self.velocity[a] } else { 0.0 };
            hand[a] = self.spring * offset[a] + damping * (v_target - snapshot.op_twist[a]);
        }
        hand
    }
}

/// The OP `dt` ahead under the acceleration `accel`, into `sample`'s model pose and twist.
fn predict<S: Space>(snapshot: &Snapshot, accel: &[f64; MAX_OP_DIM], dt: f64, sample: &mut UplinkSample) -> Option<()> {
    let k = S::DIM;
    let mut pose = OpPose::<S>::from_slice(&snapshot.op_pose)?;
    let mut twist = S::OpVec::zero();
    let mut mean = S::OpVec::zero();
    for a in 0..k {
        twist[a] = snapshot.op_twist[a] + accel[a] * dt;
        mean[a] = snapshot.op_twist[a] + 0.5 * accel[a] * dt;
    }
    pose.integrate(&mean, dt);
    let len = OpPose::<S>::wire_len();
    pose.to_slice(&mut sample.model_pose[..len]);
    sample.model_twist[..k].copy_from_slice(twist.as_slice());
    sample.pose_len = len as u8;
    Some(())
}

/// The full row-major k×k matrix of a symmetric matrix sent as its upper triangle, row-major.
fn unpack_symmetric(upper: &[f64], k: usize) -> [f64; MAX_OP_DIM * MAX_OP_DIM] {
    let mut full = [0.0; MAX_OP_DIM * MAX_OP_DIM];
    let mut i = 0;
    for r in 0..k {
        for c in r..k {
            full[r * k + c] = upper[i];
            full[c * k + r] = upper[i];
            i += 1;
        }
    }
    full
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

    /// A planar snapshot at rest at (0.1, 0.2, 0.7) with Λ̂⁻¹ = diag(1, 0.5, 100) and no bias.
    fn at_rest() -> Snapshot {
        Snapshot {
            seq: 1,
            server_time_s: 0.0,
            ve_step: 1,
            user_id: 1,
            uplink_time_s: 0.0,
            op_pose: vec![0.1, 0.2, 0.7],
            op_twist: vec![0.0; 3],
            inverse_inertia: vec![1.0, 0.0, 0.0, 0.5, 0.0, 100.0],
            bias_accel: vec![0.0; 3],
            directions: vec![0.0; 9],
            singular_values: vec![0.0; 3],
            constraint_count: 0,
            contacts: Vec::new(),
            other_manipulators: 0,
            config: None,
            energy: kinloop_protocol::PortEnergy::zero(3),
        }
    }

    #[test]
    fn a_far_target_pulls_with_the_spring_at_the_reach_and_no_torque() {
        let mut grip = Grip::new(3, 0.05);
        grip.set_target(MS, &[1.0, 0.2]).unwrap();
        let s = grip.uplink(200 * MS, &at_rest(), 1e-3).unwrap();
        assert!((s.hand_wrench[0] - SPRING_N_PER_M * 0.05).abs() < 1e-9, "{s:?}");
        assert_eq!((s.hand_wrench[1], s.hand_wrench[2]), (0.0, 0.0));
        // a = Λ̂⁻¹ F: 10 m/s² along x; one millisecond ahead.
        assert!((s.model_twist[0] - 10.0 * 1e-3).abs() < 1e-12, "{s:?}");
        assert!((s.model_pose[0] - (0.1 + 0.5 * 10.0 * 1e-6)).abs() < 1e-12, "{s:?}");
        assert_eq!((s.model_pose[1], s.model_pose[2]), (0.2, 0.7), "no pull along y, no turn");
        assert_eq!((s.seq, s.op_dim, s.pose_len), (1, 3, 3));
        assert_eq!(grip.uplink(201 * MS, &at_rest(), 1e-3).unwrap().seq, 2, "sequence numbers increase");
    }

    #[test]
    fn the_pull_is_damped_critically_and_follows_a_moving_mouse() {
        let mut grip = Grip::new(3, 0.05);
        grip.set_target(Duration::ZERO, &[0.1, 0.2]).unwrap();
        let mut moving = at_rest();
        moving.op_twist = vec![0.1, 0.0, 0.0];
        // Resting target, OP on it moving at 0.1 m/s: the damping 2√(K m) with the heavier linear axis's
        // mass (no pull to take a direction from), 2 kg along y.
        let s = grip.uplink(200 * MS, &moving, 1e-3).unwrap();
        assert!((s.hand_wrench[0] + 2.0 * (SPRING_N_PER_M * 2.0).sqrt() * 0.1).abs() < 1e-9, "{s:?}");
        // A mouse moving with the OP: no damping force.
        grip.set_target(210 * MS, &[0.101, 0.2]).unwrap();
        grip.set_target(220 * MS, &[0.102, 0.2]).unwrap();
        let with = grip.uplink(221 * MS, &moving, 1e-3).unwrap();
        assert!(with.hand_wrench[0] > s.hand_wrench[0], "{with:?}");
    }

    #[test]
    fn the_velocity_estimate_is_bounded() {
        let mut grip = Grip::new(3, 0.05);
        grip.set_target(Duration::ZERO, &[0.0, 0.0]).unwrap();
        grip.set_target(10 * MS, &[1.0, 0.0]).unwrap();
        assert!(grip.velocity.iter().map(|v| v * v).sum::<f64>().sqrt() <= MAX_TARGET_SPEED + 1e-12);
    }

    #[test]
    fn bad_targets_and_snapshots_are_refused() {
        let mut grip = Grip::new(6, 0.05);
        assert_eq!(grip.set_target(MS, &[0.0, 0.0]), Err(TargetError::WrongLength { expected: 3, got: 2 }));
        assert_eq!(grip.set_target(MS, &[0.0, f64::NAN, 0.0]), Err(TargetError::NotFinite));
        assert_eq!(grip.set_target(MS, &[0.0, 1e9, 0.0]), Err(TargetError::NotFinite));
        assert!(grip.uplink(MS, &at_rest(), 1e-3).is_none(), "a planar snapshot in a spatial grip");
        let mut planar = Grip::new(3, 0.05);
        assert!(planar.uplink(MS, &at_rest(), f64::NAN).is_none());
        let held = planar.uplink(MS, &at_rest(), 1e-3).unwrap();
        assert_eq!(&held.model_pose[..3], &[0.1, 0.2, 0.7], "no target, at rest: stay");
        assert_eq!(&held.hand_wrench[..3], &[0.0; 3]);
    }
}
