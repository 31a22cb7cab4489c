//! The uplink's perceptual deadband (IEEE 1918.1.1's perceptual data reduction, Weber's law): a sample is
//! sent only when it differs perceptibly from the last one sent, or when the last one is too old.

use std::time::Duration;

use kinloop_linkage::algorithms::constraint_directions::scale_op;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::uplink_flags;

use super::config::UplinkDeadband;

/// What was last sent.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Deadband<S: Space> {
    config: Option<UplinkDeadband>,
    last_wrench: S::OpVec,
    last_pose: OpPose<S>,
    last_flags: u32,
    last_sent: Option<Duration>,
    /// True when samples were held back since the last one sent.
    pub skipped: bool,
}

impl<S: Space> Deadband<S> {
    pub fn new(config: Option<UplinkDeadband>) -> Self {
        Deadband {
            config,
            last_wrench: S::OpVec::zero(),
            last_pose: OpPose::identity(),
            last_flags: 0,
            last_sent: None,
            skipped: false,
        }
    }

    /// Decides whether this sample leaves; records it when it does. Wrench and pose changes are measured in
    /// the unit-consistent coordinates (torques over L, rotations times L).
    pub fn admit(&mut self, now: Duration, wrench: &S::OpVec, pose: &OpPose<S>, flags: u32, length_scale: f64) -> bool {
        let send = match (&self.config, self.last_sent) {
            (None, _) | (_, None) => true,
            (Some(c), Some(last)) => {
                let scaled = |w: &S::OpVec| scale_op::<S>(w, 1.0 / length_scale);
                let change = scaled(&(*wrench - self.last_wrench)).norm();
                let wrench_moved = change > c.weber_fraction * scaled(&self.last_wrench).norm() + c.wrench_floor_n;
                let pose_moved =
                    scale_op::<S>(&pose.difference(&self.last_pose), length_scale).norm() > c.pose_threshold_m;
                let significant = !uplink_flags::DEADBAND_SKIPPED;
                let flags_changed = (flags ^ self.last_flags) & significant != 0;
                wrench_moved || pose_moved || flags_changed || now.saturating_sub(last) >= c.max_interval
            }
        };
        if send {
            self.last_wrench = *wrench;
            self.last_pose = *pose;
            self.last_flags = flags;
            self.last_sent = Some(now);
        }
        send
    }
}
