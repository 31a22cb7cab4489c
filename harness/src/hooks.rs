//! How a stepped [`Session`](crate::Session) calls its haptic cores, for tests that watch, alter or count those
//! calls: the snapshot a core is handed, the device reading and clock a tick sees, whether an uplink leaves,
//! and what every tick produced. [`Plain`] passes everything through, as [`Session::run`](crate::Session::run)
//! does; [`Probe`] records every tick and can cut the links.

use std::time::Duration;

use kinloop_client::core::{HapticCore, TickOutput, TickReport};
use kinloop_client::device::DeviceState;
use kinloop_linkage::math::space::{OpPose, Space};
use kinloop_protocol::{Snapshot, Uplink, Welcome};

/// What one participant's tick produced, with the VE's OP as the VE's last tick left it.
#[derive(Clone, Copy, Debug)]
pub struct TickSample<S: Space> {
    /// The participant's index in the plan.
    pub who: usize,
    /// What the core computed.
    pub report: TickReport<S>,
    /// The device reading the tick saw.
    pub device: DeviceState<S>,
    /// The wrench commanded to the device (device units).
    pub command: S::OpVec,
    /// The core built an uplink this tick.
    pub uplink_sent: bool,
    /// The participant's OP in the VE (none before the VE has it).
    pub ve_op: Option<OpPose<S>>,
}

/// The calls a [`Session`](crate::Session) makes on participant `who`'s core; each default is what the
/// session does without hooks.
pub trait CoreHooks<S: Space> {
    /// The participant joined with `welcome`.
    fn joined(&mut self, _who: usize, _welcome: &Welcome) {}

    /// A snapshot decoded for the participant: hand it to the core (or alter it, or drop it).
    fn snapshot(&mut self, _who: usize, core: &mut HapticCore<S>, now: Duration, snapshot: &mut Snapshot) {
        let _ = core.handle_snapshot(now, snapshot);
    }

    /// The participant's haptic tick on what its device read.
    fn tick<'c>(
        &mut self,
        _who: usize,
        core: &'c mut HapticCore<S>,
        now: Duration,
        device: &DeviceState<S>,
    ) -> TickOutput<'c, S> {
        core.tick(now, device)
    }

    /// Whether the uplink the tick built goes onto the link.
    fn send_uplink(&mut self, _who: usize, _uplink: &Uplink) -> bool {
        true
    }

    /// After the tick, its command applied to the device.
    fn ticked(&mut self, _sample: &TickSample<S>) {}
}

/// No hooks: every call as the session makes it.
pub struct Plain;

impl<S: Space> CoreHooks<S> for Plain {}

/// Records every tick and the newest snapshot handed to a core, and cuts both links of every participant
/// while `link_up` is false (snapshots and uplinks lost, as in an outage).
pub struct Probe<S: Space> {
    /// Every tick, in order.
    pub samples: Vec<TickSample<S>>,
    /// The newest snapshot a core was handed.
    pub last_snapshot: Option<Snapshot>,
    /// The welcome of the newest participant to join.
    pub welcome: Option<Welcome>,
    /// Links up (the default) or cut.
    pub link_up: bool,
}

impl<S: Space> Default for Probe<S> {
    fn default() -> Self {
        Probe { samples: Vec::new(), last_snapshot: None, welcome: None, link_up: true }
    }
}

impl<S: Space> CoreHooks<S> for Probe<S> {
    fn joined(&mut self, _who: usize, welcome: &Welcome) {
        self.welcome = Some(welcome.clone());
    }

    fn snapshot(&mut self, _who: usize, core: &mut HapticCore<S>, now: Duration, snapshot: &mut Snapshot) {
        if self.link_up {
            let _ = core.handle_snapshot(now, snapshot);
            self.last_snapshot = Some(snapshot.clone());
        }
    }

    fn send_uplink(&mut self, _who: usize, _uplink: &Uplink) -> bool {
        self.link_up
    }

    fn ticked(&mut self, sample: &TickSample<S>) {
        self.samples.push(*sample);
    }
}
