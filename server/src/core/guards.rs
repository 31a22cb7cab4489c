//! What the VE refuses to act on. The codec has already checked bytes, lengths and gross magnitudes; here
//! an uplink is checked against *physics*: a local model a metre away from the VE's OP, a model moving at
//! 20 m/s, or a hand wrench an order of magnitude beyond what the device is rated for are signs of a broken
//! or hostile client. A rejected uplink changes nothing at all (not even the user's liveness or sequence
//! number).
//!
//! A hand wrench *somewhat* over the device's rating is plausible (a hand can push harder than the motors,
//! and the wrench that drives a local model includes its position channels' reaction) and is clipped to the
//! rating, direction kept, force and torque each on their own: a clipped value keeps the user coupled, a
//! dropped uplink would leave the coupling to fade out.

use kinloop_linkage::math::space::clip_wrench_parts;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
pub use kinloop_protocol::wrench_limits::WrenchLimits;
use kinloop_protocol::{DeviceCaps, Mapping, Uplink};

use super::config::GuardLimits;

/// Largest operational dimension (spatial).
pub const MAX_OP_DIM: usize = 6;
/// Largest pose length (spatial: position and quaternion).
pub const MAX_POSE_LEN: usize = 7;

/// The numbers of an [`Uplink`] the VE uses, in fixed-size storage so uplinks cross from the network to
/// the VE thread without allocating or freeing. Build one with [`UplinkSample::from_uplink`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UplinkSample {
    /// Per-client uplink counter.
    pub seq: u64,
    /// Client clock when sent (s).
    pub client_time_s: f64,
    /// Status bits (`kinloop_protocol::uplink_flags`).
    pub flags: u32,
    /// Newest snapshot the client had applied (`Uplink::last_snapshot_seq`, 0 for none).
    pub last_snapshot_seq: u64,
    /// How long it had held it when the uplink left (s).
    pub last_snapshot_age_s: f64,
    /// How long the uplink waited on the server between its arrival and the call that hands it to the VE (s;
    /// a driver that takes uplinks in at its tick says so): the round trip is dated at the arrival.
    pub waited_s: f64,
    /// F_h, first `op_dim` entries used.
    pub hand_wrench: [f64; MAX_OP_DIM],
    /// Local-model OP pose, first `pose_len` entries used.
    pub model_pose: [f64; MAX_POSE_LEN],
    /// Local-model OP twist, first `op_dim` entries used.
    pub model_twist: [f64; MAX_OP_DIM],
    /// The client's energy books (`Uplink::energy`), first `op_dim` entries used.
    pub energy_received_j: [f64; MAX_OP_DIM],
    /// The same, emitted.
    pub energy_emitted_j: [f64; MAX_OP_DIM],
    /// Length of the wrench and twist.
    pub op_dim: u8,
    /// Length of the pose.
    pub pose_len: u8,
}

impl UplinkSample {
    /// A sample of `op_dim` axes and a pose of `pose_len` numbers with every number zero (sequence, clock,
    /// hand, model, books): what an in-process user fills in.
    pub fn zeroed(op_dim: u8, pose_len: u8) -> Self {
        UplinkSample {
            seq: 0,
            client_time_s: 0.0,
            flags: 0,
            last_snapshot_seq: 0,
            last_snapshot_age_s: 0.0,
            waited_s: 0.0,
            hand_wrench: [0.0; MAX_OP_DIM],
            model_pose: [0.0; MAX_POSE_LEN],
            model_twist: [0.0; MAX_OP_DIM],
            energy_received_j: [0.0; MAX_OP_DIM],
            energy_emitted_j: [0.0; MAX_OP_DIM],
            op_dim,
            pose_len,
        }
    }

    /// Copies the numbers the VE needs; fails only when a vector is longer than any scene uses.
    pub fn from_uplink(uplink: &Uplink) -> Result<Self, UplinkRejection> {
        let k = uplink.hand_wrench.len();
        if k > MAX_OP_DIM || uplink.model_twist.len() != k {
            return Err(UplinkRejection::WrongShape { field: "hand_wrench/model_twist" });
        }
        if uplink.energy.received_j.len() != k || uplink.energy.emitted_j.len() != k {
            return Err(UplinkRejection::WrongShape { field: "energy" });
        }
        if uplink.model_pose.len() > MAX_POSE_LEN {
            return Err(UplinkRejection::WrongShape { field: "model_pose" });
        }
        let mut sample = UplinkSample {
            seq: uplink.seq,
            client_time_s: uplink.client_time_s,
            flags: uplink.flags,
            last_snapshot_seq: uplink.last_snapshot_seq,
            last_snapshot_age_s: uplink.last_snapshot_age_s,
            waited_s: 0.0,
            hand_wrench: [0.0; MAX_OP_DIM],
            model_pose: [0.0; MAX_POSE_LEN],
            model_twist: [0.0; MAX_OP_DIM],
            energy_received_j: [0.0; MAX_OP_DIM],
            energy_emitted_j: [0.0; MAX_OP_DIM],
            op_dim: k as u8,
            pose_len: uplink.model_pose.len() as u8,
        };
        sample.energy_received_j[..k].copy_from_slice(&uplink.energy.received_j);
        sample.energy_emitted_j[..k].copy_from_slice(&uplink.energy.emitted_j);
        sample.hand_wrench[..k].copy_from_slice(&uplink.hand_wrench);
        sample.model_twist[..k].copy_from_slice(&uplink.model_twist);
        sample.model_pose[..uplink.model_pose.len()].copy_from_slice(&uplink.model_pose);
        Ok(sample)
    }
}

/// Why an uplink was not used. No variant owns heap memory, so rejecting allocates nothing.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum UplinkRejection {
    /// No such user (never joined, or already removed).
    #[error("no user {user}")]
    UnknownUser {
        /// The user id given.
        user: u32,
    },
    /// Not newer than the last uplink used (a duplicate or a reordered datagram); ignored, not an attack.
    #[error("uplink {seq} is not newer than {last}")]
    Stale {
        /// Its sequence number.
        seq: u64,
        /// The newest used so far.
        last: u64,
    },
    /// A vector of the wrong length for this scene.
    #[error("{field} has the wrong length for this scene")]
    WrongShape {
        /// Which field.
        field: &'static str,
    },
    /// NaN or infinity.
    #[error("{field} is not finite")]
    NonFinite {
        /// Which field.
        field: &'static str,
    },
    /// An orientation that is not a rotation (e.g. a quaternion of the wrong norm).
    #[error("model_pose has an invalid orientation")]
    InvalidOrientation,
    /// The local model is implausibly far from the VE's OP.
    #[error("the local model is {offset_m:.3} m from the VE's operational point (limit {limit_m} m)")]
    ModelTooFar {
        /// Distance (m).
        offset_m: f64,
        /// Limit (m).
        limit_m: f64,
    },
    /// The local model moves implausibly fast.
    #[error("model_twist {field} speed {speed:.3} exceeds {limit}")]
    ModelTooFast {
        /// `linear` or `angular`.
        field: &'static str,
        /// Its norm.
        speed: f64,
        /// The limit.
        limit: f64,
    },
    /// The hand wrench is absurd for the device: beyond its rating times `absurd_wrench_factor`.
    #[error("hand {field} {magnitude:.3} is absurd for a device rated {rating:.3}")]
    WrenchAbsurd {
        /// `force` or `torque`.
        field: &'static str,
        /// Its norm.
        magnitude: f64,
        /// The device's rating (with slack).
        rating: f64,
    },
}

impl UplinkRejection {
    /// True for rejections that mean a broken or hostile client (counted and logged), false for the
    /// ordinary stale/duplicate case of an unreliable network.
    pub fn is_hostile(&self) -> bool {
        !matches!(self, UplinkRejection::Stale { .. } | UplinkRejection::UnknownUser { .. })
    }
}

/// The largest hand force and torque a user's device may report: its announced peaks (with slack) in VE
/// units (divided by the mapping's force and torque scales: uplinks carry VE wrenches), or the defaults where
/// it announced none or no positive, finite one.
pub fn wrench_limits_for_device(device: Option<&DeviceCaps>, mapping: &Mapping, limits: &GuardLimits) -> WrenchLimits {
    let pick = |announced: Option<f64>, scale: f64, default: f64| match announced {
        // An infinite peak (which the wire's checks refuse, but a direct caller may pass) is no rating.
        Some(peak) if peak > 0.0 && peak.is_finite() && scale > 0.0 => peak * (1.0 + limits.device_cap_slack) / scale,
        _ => default,
    };
    WrenchLimits {
        max_force_n: pick(device.map(|d| d.max_force_n), mapping.force_scale, limits.default_max_force_n),
        max_torque_nm: pick(device.map(|d| d.max_torque_nm), mapping.torque_scale(), limits.default_max_torque_nm),
    }
}

/// An uplink that passed the checks, in the VE's types.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckedUplink<S: Space> {
    /// F_h.
    pub hand_wrench: S::OpVec,
    /// Local-model OP pose.
    pub model_pose: OpPose<S>,
    /// Local-model OP twist.
    pub model_twist: S::OpVec,
    /// The hand wrench was over the device's rating and has been clipped to it.
    pub clipped: bool,
}

/// Checks a sample against the scene's dimensions, the user's device and the VE's OP pose. `pose_memo`
/// anchors the reading of the model pose's orientation (the user's, from one uplink to the next).
pub fn check_uplink<S: Space>(
    sample: &UplinkSample,
    ve_op_pose: &OpPose<S>,
    wrench_limits: &WrenchLimits,
    limits: &GuardLimits,
    pose_memo: &mut S::RotParamsMemo,
) -> Result<CheckedUplink<S>, UplinkRejection> {
    let k = S::DIM;
    if usize::from(sample.op_dim) != k {
        return Err(UplinkRejection::WrongShape { field: "hand_wrench" });
    }
    if usize::from(sample.pose_len) != OpPose::<S>::wire_len() {
        return Err(UplinkRejection::WrongShape { field: "model_pose" });
    }
    let pose_slice = &sample.model_pose[..usize::from(sample.pose_len)];
    for (field, values) in [
        ("hand_wrench", &sample.hand_wrench[..k]),
        ("model_pose", pose_slice),
        ("model_twist", &sample.model_twist[..k]),
    ] {
        if values.iter().any(|x| !x.is_finite()) {
            return Err(UplinkRejection::NonFinite { field });
        }
    }
    let hand_wrench = S::OpVec::from_slice(&sample.hand_wrench[..k]);
    let model_twist = S::OpVec::from_slice(&sample.model_twist[..k]);
    let model_pose = OpPose::<S>::from_slice_memo(pose_slice, pose_memo).ok_or(UplinkRejection::InvalidOrientation)?;

    let offset_m = (model_pose.position - ve_op_pose.position).norm();
    if offset_m > limits.max_model_offset_m {
        return Err(UplinkRejection::ModelTooFar { offset_m, limit_m: limits.max_model_offset_m });
    }
    let speeds = [
        ("linear", S::op_lin(&model_twist).norm(), limits.max_model_speed_m_per_s),
        ("angular", S::op_ang(&model_twist).norm(), limits.max_model_angular_speed_rad_per_s),
    ];
    if let Some((field, speed, limit)) = speeds.into_iter().find(|(_, speed, limit)| speed > limit) {
        return Err(UplinkRejection::ModelTooFast { field, speed, limit });
    }
    let (hand_wrench, clipped) = clip_hand_wrench::<S>(&hand_wrench, wrench_limits, limits.absurd_wrench_factor)?;
    Ok(CheckedUplink { hand_wrench, model_pose, model_twist, clipped })
}

/// The hand wrench with its force and its torque each clipped to the device's rating (direction kept), and
/// whether anything was clipped; an error when either is beyond the rating times `absurd_factor`.
pub fn clip_hand_wrench<S: Space>(
    wrench: &S::OpVec,
    rating: &WrenchLimits,
    absurd_factor: f64,
) -> Result<(S::OpVec, bool), UplinkRejection> {
    let magnitudes = [
        ("force", S::op_lin(wrench).norm(), rating.max_force_n),
        ("torque", S::op_ang(wrench).norm(), rating.max_torque_nm),
    ];
    if let Some((field, magnitude, limit)) = magnitudes.into_iter().find(|(_, m, limit)| *m > limit * absurd_factor) {
        return Err(UplinkRejection::WrenchAbsurd { field, magnitude, rating: limit });
    }
    let (clipped, scales) = clip_wrench_parts::<S>(wrench, rating.max_force_n, rating.max_torque_nm);
    Ok((clipped, scales.clipped()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;

    type V = <Planar as Space>::OpVec;
    const RATING: WrenchLimits = WrenchLimits { max_force_n: 10.0, max_torque_nm: 0.2 };

    #[test]
    fn a_wrench_within_the_rating_passes_unchanged() {
        let w = V::from_slice(&[6.0, -8.0, 0.2]);
        assert_eq!(clip_hand_wrench::<Planar>(&w, &RATING, 10.0), Ok((w, false)));
    }

    #[test]
    fn a_plausible_wrench_over_the_rating_is_clipped_to_it_direction_kept() {
        // 25 N along (3, −4)/5 and 0.5 N·m: force to 10 N along the same direction, torque to 0.2 N·m.
        let (out, clipped) = clip_hand_wrench::<Planar>(&V::from_slice(&[15.0, -20.0, -0.5]), &RATING, 10.0).unwrap();
        assert!(clipped);
        let expected = [6.0, -8.0, -0.2];
        for (got, want) in out.as_slice().iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{out:?}");
        }
        // Only the part over its rating is touched.
        let (out, _) = clip_hand_wrench::<Planar>(&V::from_slice(&[1.0, 0.0, 0.5]), &RATING, 10.0).unwrap();
        assert_eq!(out.as_slice()[0], 1.0);
    }

    #[test]
    fn an_absurd_wrench_is_rejected_naming_the_part() {
        let err = clip_hand_wrench::<Planar>(&V::from_slice(&[0.0, 101.0, 0.0]), &RATING, 10.0).unwrap_err();
        assert_eq!(err, UplinkRejection::WrenchAbsurd { field: "force", magnitude: 101.0, rating: 10.0 });
        let err = clip_hand_wrench::<Planar>(&V::from_slice(&[0.0, 0.0, -2.5]), &RATING, 10.0).unwrap_err();
        assert!(matches!(err, UplinkRejection::WrenchAbsurd { field: "torque", .. }), "{err}");
        assert!(err.is_hostile());
    }
}
