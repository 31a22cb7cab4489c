//! A [`Frame`] from a [`Sample`], the scene's [`Geometry`] and what the network side knows of each user.

use std::sync::atomic::Ordering;

use super::draw::Geometry;
use super::messages::{Frame, LoopView, UserView};
use super::sample::Sample;
use crate::gateway::{UserEntry, UserRegistry};

/// What the network side knows of a user (the VE thread knows none of it).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UserInfo {
    /// VE user id.
    pub id: u32,
    /// Client name.
    pub name: String,
    /// Device name.
    pub device: String,
    /// Operational point.
    pub op: String,
    /// A page grabbing with the mouse.
    pub browser: bool,
    /// QUIC round trip (ms).
    pub rtt_ms: Option<f64>,
    /// Fraction of uplinks flagged `CLAMPED`.
    pub clamped: Option<f64>,
    /// Device pose from the newest uplink.
    pub device_pose: Option<Vec<f64>>,
    /// Local-model pose from the newest uplink.
    pub model_pose: Option<Vec<f64>>,
}

impl UserInfo {
    /// What a QUIC session knows of its user.
    fn of_session(e: &UserEntry) -> Self {
        let c = &e.counters;
        let received = c.uplinks_received.load(Ordering::Relaxed);
        let clamped = c.uplinks_clamped.load(Ordering::Relaxed);
        let poses = c.poses.load();
        UserInfo {
            id: e.user_id,
            name: e.name.clone(),
            device: e.device.clone(),
            op: e.op.clone(),
            browser: false,
            rtt_ms: Some(e.connection.rtt().as_secs_f64() * 1e3),
            clamped: (received > 0).then(|| clamped as f64 / received as f64),
            device_pose: poses.as_ref().map(|p| p.0.clone()),
            model_pose: poses.map(|p| p.1),
        }
    }
}

/// Appends what the sessions know of each connected user to `out`, for the panel.
pub fn connected_users(registry: &UserRegistry, out: &mut Vec<UserInfo>) {
    registry.for_each(|e| {
        if e.counters.connected.load(Ordering::Relaxed) {
            out.push(UserInfo::of_session(e));
        }
    });
}

/// The frame for `sample`: the linkage drawn at its q, each user with what `info` adds.
pub fn compose(seq: u64, sample: &Sample, geometry: &mut dyn Geometry, info: &[UserInfo]) -> Frame {
    let users = sample
        .users
        .iter()
        .map(|u| {
            let known = info.iter().find(|i| i.id == u.id);
            UserView {
                id: u.id,
                name: known.map(|k| k.name.clone()).unwrap_or_default(),
                device: known.map(|k| k.device.clone()).unwrap_or_default(),
                role: if u.observer { "observer" } else { "manipulator" },
                op: known.map(|k| k.op.clone()).unwrap_or_default(),
                browser: known.is_some_and(|k| k.browser),
                present: u.present,
                weight: u.weight,
                pose: u.op_pose.clone(),
                wrench: u.wrench.clone(),
                count: u.constraint_count,
                sv: u.singular_values.clone(),
                dirs: u.directions.clone(),
                device_pose: u.device_pose.clone().or_else(|| known.and_then(|k| k.device_pose.clone())),
                model_pose: u.model_pose.clone().or_else(|| known.and_then(|k| k.model_pose.clone())),
                rtt_ms: known.and_then(|k| k.rtt_ms),
                clamped: known.and_then(|k| k.clamped),
            }
        })
        .collect();
    Frame {
        seq,
        t: sample.t_s,
        step: sample.step,
        closure_error: sample.closure_error,
        linkage: geometry.draw(&sample.q),
        users,
        ve_loop: sample.timing.map(|t| LoopView {
            p50_us: t.p50_ns / 1e3,
            p99_us: t.p99_ns / 1e3,
            max_us: t.max_ns / 1e3,
            misses: t.misses as u64,
        }),
    }
}
