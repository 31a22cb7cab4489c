//! Warming a real-time VE loop before its deadline.
//!
//! A VE tick after the loop's sleep costs several times the same tick back to back (`kinloop experiment
//! pauses`): whatever ran while the thread slept evicted its code and data from the core's caches, and the
//! tick refetches them as it goes. With one user most of that is the code's: a tick of a second, separate
//! VE just before brings the real one close to its back-to-back time (the pauses experiment's `rehearsed`
//! points). So the loop wakes a little before its deadline, as its hybrid sleep always did to spin out the
//! period's end, and spends the start of that spin on a [`Rehearsal`]: a one-user VE on the same linkage and
//! configuration, ticked and encoded as the real VE is, whose own state nobody reads. The rest of the spin
//! waits for the deadline without entering the kernel, so nothing evicts what the rehearsal brought in. The
//! thread's CPU time is unchanged: the rehearsal replaces part of the spin (`ve.cpu_s` counts both).

use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;
use kinloop_linkage::model::Model;
use kinloop_protocol::{codec, DeviceCaps, LocalModelForm, Role};

use crate::core::{JoinRequest, VeConfig, VeCore};
use crate::synthetic::SyntheticUser;

/// How long before its deadline a warmed loop wakes from its native sleep: the rehearsal runs first, then
/// the loop spins the rest (spin_sleep's default native accuracy on Linux, which the loop spun before).
pub const WAKE_LEAD: Duration = Duration::from_micros(125);

/// A one-user VE on a room's linkage whose tick warms the caches for the room's own (see the module
/// documentation).
pub struct Rehearsal<S: Space> {
    core: VeCore<S>,
    user: Option<(u32, SyntheticUser)>,
    seq: u64,
    frame: Vec<u8>,
}

impl<S: Space> Rehearsal<S> {
    /// A rehearsal of `model` under `config`, its one synthetic user on the first operational point (none
    /// when the scene has none or the VE refuses it: the rehearsal then steps the linkage alone). `None`
    /// when the configuration is refused.
    pub fn new(model: &Model<S>, config: &VeConfig) -> Option<Self> {
        let mut config = config.clone();
        config.max_users = 1;
        let mut core = VeCore::new(model.clone(), config).ok()?;
        let user = model.ops.first().and_then(|op| {
            let request = JoinRequest {
                name: "rehearsal".into(),
                role: Role::Manipulator,
                op: op.name.clone(),
                form: LocalModelForm::OpSpace,
                device: Some(DeviceCaps::generous("rehearsal", S::DIM)),
                mapping: Default::default(),
            };
            core.join(Duration::ZERO, request).ok().map(|joined| (joined.user_id, SyntheticUser::new(1)))
        });
        Some(Rehearsal { core, user, seq: 0, frame: Vec::with_capacity(codec::limits::MAX_DATAGRAM_MESSAGE_BYTES) })
    }

    /// One tick of the rehearsal VE as the loop runs the real one: an uplink, the step, the snapshot terms
    /// and the snapshot's encoding.
    pub fn rehearse(&mut self) {
        let now = self.core.poll_timeout();
        self.seq += 1;
        if let Some((id, user)) = self.user.as_mut() {
            if let Some(sample) = user.uplink(self.seq, now.as_secs_f64()) {
                let _ = self.core.handle_uplink_sample(now, *id, sample);
            }
        }
        self.core.handle_timeout(now);
        while let Some(pending) = self.core.poll_snapshot() {
            let _ = codec::encode_datagram_into(pending.datagram(), &mut self.frame);
            if let Some((_, user)) = self.user.as_mut() {
                user.on_snapshot(pending.snapshot());
            }
        }
        while self.core.poll_event().is_some() {}
    }
}

/// Waits until `deadline`: sleeps natively until [`WAKE_LEAD`] before it, runs `warm`, then spins (a loop
/// already late neither sleeps nor warms). A thread
/// without real-time priority yields while it spins (the machine's other threads get the core); one with it
/// spins on the clock alone (a yield would hand the core to no one and enter the kernel each time round).
pub fn wait_warmed(deadline: Instant, realtime: bool, warm: impl FnOnce()) {
    let Some(left) = deadline.checked_duration_since(Instant::now()) else { return };
    if let Some(sleep) = left.checked_sub(WAKE_LEAD) {
        spin_sleep::native_sleep(sleep);
    }
    warm();
    while Instant::now() < deadline {
        if realtime {
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::VeConfig;

    #[test]
    fn a_rehearsal_steps_its_own_ve_with_its_user_and_encodes_its_snapshots() {
        let scene = kinloop_linkage::model::builtin::scene("paper-testbed").expect("built in").expect("parses");
        let model = Model::<kinloop_linkage::math::space::Planar>::compile(&scene, "paper-testbed").expect("compiles");
        let mut rehearsal = Rehearsal::new(&model, &VeConfig::paper()).expect("the paper's configuration");
        assert!(rehearsal.user.is_some(), "the testbed's OP takes the rehearsal's user");
        for _ in 0..50 {
            rehearsal.rehearse();
        }
        let metrics = rehearsal.core.metrics();
        assert_eq!(metrics.ticks, 50);
        assert_eq!(metrics.state_restores, 0);
        assert!(metrics.uplinks_accepted >= 48, "{} uplinks accepted", metrics.uplinks_accepted);
        assert!(rehearsal.frame.len() > 100, "a snapshot of {} bytes", rehearsal.frame.len());
    }

    #[test]
    fn a_warmed_wait_warms_once_and_returns_at_its_deadline_and_a_late_one_does_not_warm() {
        let deadline = Instant::now() + Duration::from_millis(2);
        let mut warmed = 0;
        wait_warmed(deadline, false, || warmed += 1);
        assert!(Instant::now() >= deadline);
        assert_eq!(warmed, 1);
        wait_warmed(Instant::now() - Duration::from_millis(1), false, || warmed += 1);
        assert_eq!(warmed, 1, "a late loop goes straight to its tick");
    }
}
