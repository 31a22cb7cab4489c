//! The demo's twin (`kinloop demo --twin`): the same session in virtual time through `kinloop_harness`, so
//! what the real-time demo measures can be read against the floor its physics and sharing rule set.
//!
//! The twin has the demo's scene, VE configuration, users, operational points, devices and hands; each user
//! joins when the real one's loop started (the real joins are a few milliseconds apart, and hands touring
//! one path a few milliseconds apart are part of what each user feels); and each direction of every link
//! is half the real session's median ping round trip (which holds the demo's emulated delay, if any), its
//! jitter the emulated one plus a third of what the loopback adds. What the real demo measures above the twin is real time's: the
//! scheduling of the VE, the shared clock and the network side on the machine's cores.

use std::time::Duration;

use anyhow::{Context, Result};
use kinloop_client::device::DevicePreset;
use kinloop_client::user::UserSpec;
use kinloop_harness::{ClientPlan, SessionPlan};
use kinloop_linkage::model::scene::Scene;
use kinloop_protocol::emulator::LinkConfig;
use kinloop_server::core::metrics::SharingMetrics;
use kinloop_server::ServerConfig;
use serde::Serialize;

/// The demo's session as the twin repeats it.
#[derive(Clone, Debug)]
pub struct TwinSession {
    /// The linkage.
    pub scene: Scene,
    /// Each user's operational point and hand, in the demo's order.
    pub users: Vec<(String, UserSpec)>,
    /// The device every user holds (`None`: the scene's default).
    pub device: Option<DevicePreset>,
    /// The demo's emulated link (each side applies it to what it sends).
    pub link: LinkConfig,
    /// How long the clients run.
    pub duration: Duration,
}

/// The twin's part of the demo's summary.
#[derive(Clone, Debug, Serialize)]
pub struct TwinSummary {
    /// Each direction's mean one-way delay (ms): half the real median ping round trip, at least the demo's
    /// emulated delay.
    pub one_way_ms: f64,
    /// Its standard deviation (ms).
    pub jitter_ms: f64,
    /// Virtual seconds simulated.
    pub duration_s: f64,
    /// Each user's device-OP RMS in the twin (mm, the device's space), in the demo's user order.
    pub device_op_rms_mm: Vec<f64>,
    /// States the twin's VE restored.
    pub ve_restores: u64,
    /// Largest closure residual in the twin's VE (m).
    pub max_closure_error: f64,
    /// The round trips the twin's VE weighted the sharing by.
    pub sharing: SharingMetrics,
    /// Wall-clock seconds the twin took.
    pub wall_s: f64,
}

/// The twin's link for one user: the demo's `link` lengthened to `half_round_trip` (the measured trip holds
/// the emulated delay), the loopback's part adding a third of itself as jitter; the demo's seed offset by
/// `user`.
fn twin_link(link: &LinkConfig, half_round_trip: Duration, user: u64) -> LinkConfig {
    let loopback = half_round_trip.saturating_sub(link.delay);
    LinkConfig {
        delay: link.delay + loopback,
        jitter: link.jitter + loopback / 3,
        seed: link.seed.wrapping_add(0x7717_0000 + user),
        ..link.clone()
    }
}

/// The twin's plan: `session`, user i joining at `join_at[i]`, every link `session.link`
/// lengthened to half of `round_trip`.
pub fn plan(session: &TwinSession, join_at: &[Duration], round_trip: Duration) -> SessionPlan {
    let mut ve = ServerConfig::new(session.scene.clone(), "twin", ([127, 0, 0, 1], 0).into()).ve;
    ve.max_users = ve.max_users.max(session.users.len());
    let device = session.device.unwrap_or_else(|| DevicePreset::for_kind(session.scene.kind));
    let clients = session
        .users
        .iter()
        .enumerate()
        .map(|(i, (op, user))| {
            let mut client = ClientPlan::new(&format!("demo-user{}", i + 1), op, device);
            client.user = user.clone();
            client.join_at = join_at.get(i).copied().unwrap_or_default();
            client.with_link(twin_link(&session.link, round_trip / 2, i as u64))
        })
        .collect();
    SessionPlan { scene: session.scene.clone(), ve, clients, duration: session.duration, record_every: 1000 }
}

/// Runs the twin of `session` (see the module documentation).
pub fn run(session: &TwinSession, join_at: &[Duration], round_trip: Duration) -> Result<TwinSummary> {
    let plan = plan(session, join_at, round_trip);
    let started = std::time::Instant::now();
    let (summary, _) = kinloop_harness::run(&plan, &mut |_| {}).context("the demo's twin in virtual time")?;
    let link = &plan.clients.first().map(|c| c.uplink.clone()).unwrap_or_default();
    Ok(TwinSummary {
        one_way_ms: link.delay.as_secs_f64() * 1e3,
        jitter_ms: link.jitter.as_secs_f64() * 1e3,
        duration_s: summary.duration_s,
        device_op_rms_mm: summary.clients.iter().map(|c| c.device_op_rms_m * 1e3).collect(),
        ve_restores: summary.ve_restores,
        max_closure_error: summary.max_closure_error,
        sharing: summary.ve_sharing,
        wall_s: started.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The testbed with `users` hands, soft and firm in turn, on its first OP, for `seconds`.
    fn testbed(users: usize, seconds: u64) -> TwinSession {
        let scene = kinloop_linkage::model::builtin::scene("paper-testbed").expect("built in").expect("parses");
        let op = scene.ops[0].name.clone();
        TwinSession {
            users: (0..users).map(|i| (op.clone(), UserSpec::Hand(crate::load::hand_in_turn(i)))).collect(),
            scene,
            device: None,
            link: LinkConfig::default(),
            duration: Duration::from_secs(seconds),
        }
    }

    #[test]
    fn the_twin_has_the_demos_users_joins_and_a_link_of_half_the_round_trip() {
        let mut session = testbed(3, 60);
        session.link.delay = Duration::from_millis(2);
        let joins = [Duration::ZERO, Duration::from_micros(2700), Duration::from_micros(5400)];
        let plan = plan(&session, &joins, Duration::from_micros(300));
        assert_eq!(plan.clients.len(), 3);
        for (i, client) in plan.clients.iter().enumerate() {
            assert_eq!(client.join_at, joins[i]);
            assert_eq!(client.op, session.users[i].0);
            assert_eq!(client.uplink.delay, Duration::from_micros(2000), "the measured trip holds the emulated");
            assert_eq!(client.uplink.jitter, Duration::ZERO);
        }
        assert_ne!(plan.clients[0].uplink.seed, plan.clients[1].uplink.seed);
        let loopback = super::plan(&session, &joins, Duration::from_micros(4600));
        assert_eq!(loopback.clients[0].uplink.delay, Duration::from_micros(2300));
        assert_eq!(loopback.clients[0].uplink.jitter, Duration::from_micros(100));
        assert!(plan.ve.max_users >= 3);
        assert_eq!(plan.duration, session.duration);
    }

    #[test]
    fn a_twin_of_two_hands_reports_each_users_tracking_and_a_stable_ve() {
        let joins = [Duration::ZERO, Duration::from_millis(3)];
        let twin = run(&testbed(2, 2), &joins, Duration::from_micros(300)).expect("the twin runs");
        assert_eq!(twin.device_op_rms_mm.len(), 2);
        for rms in &twin.device_op_rms_mm {
            assert!(rms.is_finite() && *rms > 0.0 && *rms < 1.0, "{twin:?}");
        }
        assert_eq!(twin.ve_restores, 0, "{twin:?}");
        assert!(twin.max_closure_error < 1e-6, "{twin:?}");
        assert!((twin.one_way_ms - 0.15).abs() < 1e-9, "{twin:?}");
        assert!((twin.duration_s - 2.0).abs() < 0.01, "{twin:?}");
    }
}
