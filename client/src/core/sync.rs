//! Keeping the local model on the VE without a loop through the network's delay.
//!
//! The VE follows the local model (its graphics controller is tied to the uplinked model pose, its force
//! channel carries the model's driving wrench), and the local model must in turn be kept on the VE: its
//! frozen terms make it drift off the linkage's curved motion along the constrained directions, and other
//! users, contacts and the VE's own integration move the VE in ways the model does not know. Pulling the
//! model toward the VE's newest state closes a loop through both directions of the network: the state
//! answers an uplink sent a round trip ago, so the pull chases the model's own past, and at 50 ms one way
//! that loop oscillated on light OPs (a serial arm's tip, a six-bar's output).
//!
//! So the comparison is made like with like, as a Smith predictor does: every snapshot names the client
//! time of the uplink the VE had used (`Snapshot::uplink_time_s`), the core keeps its model's states by
//! that time ([`History`]), and the discrepancy is the VE's state against the model's state *then*, less
//! the corrections already applied since (which the VE had not seen yet). When the VE follows the model
//! faithfully this is zero whatever the delay: nothing is corrected, and there is no loop; what remains is
//! the real drift, corrected once. Without a usable time (an observer's snapshots, or a state older than
//! the history) the core falls back to the pull toward the VE's state predicted to now.

use kinloop_linkage::local_model::OpPose;
use kinloop_linkage::space::{Space, VecOps};

/// Entries kept: 4 s of a 1 kHz loop, so a round trip of up to 4 s finds the state it answers.
pub const HISTORY_LEN: usize = 4096;

/// One recorded state of the local model.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Entry<S: Space> {
    /// Client clock of the tick (s), as the uplink of that tick carried it.
    pub time_s: f64,
    /// The model's OP pose after the tick's step.
    pub pose: OpPose<S>,
    /// Its twist.
    pub twist: S::OpVec,
    /// Cumulative position correction applied up to this tick.
    pub moved: S::OpVec,
    /// Cumulative velocity correction applied up to this tick.
    pub sped: S::OpVec,
}

/// The local model's recent states, oldest first, in a ring allocated once.
pub(crate) struct History<S: Space> {
    entries: Box<[Entry<S>]>,
    /// Index of the oldest entry.
    start: usize,
    len: usize,
    /// Cumulative corrections so far.
    pub moved: S::OpVec,
    pub sped: S::OpVec,
}

impl<S: Space> History<S> {
    pub fn new() -> Self {
        let empty = Entry {
            time_s: f64::NEG_INFINITY,
            pose: OpPose::identity(),
            twist: S::OpVec::zero(),
            moved: S::OpVec::zero(),
            sped: S::OpVec::zero(),
        };
        History {
            entries: vec![empty; HISTORY_LEN].into_boxed_slice(),
            start: 0,
            len: 0,
            moved: S::OpVec::zero(),
            sped: S::OpVec::zero(),
        }
    }

    /// Forgets every state (a new session's model).
    pub fn clear(&mut self) {
        self.start = 0;
        self.len = 0;
    }

    fn get(&self, i: usize) -> &Entry<S> {
        &self.entries[(self.start + i) % HISTORY_LEN]
    }

    /// Records the model's state of the tick at `time_s` (times must not go back; an earlier one clears).
    pub fn record(&mut self, time_s: f64, pose: OpPose<S>, twist: S::OpVec) {
        if self.len > 0 && time_s < self.get(self.len - 1).time_s {
            self.clear();
        }
        let entry = Entry { time_s, pose, twist, moved: self.moved, sped: self.sped };
        if self.len < HISTORY_LEN {
            self.entries[(self.start + self.len) % HISTORY_LEN] = entry;
            self.len += 1;
        } else {
            self.entries[self.start] = entry;
            self.start = (self.start + 1) % HISTORY_LEN;
        }
    }

    /// The state recorded at `time_s`, if still kept: the nearer of the two ticks around it when it falls
    /// within the ticks kept (a VE that leads its target names a client time a whole number of its own ticks
    /// after an uplink's, which in real time need not be a tick of the client's, and in virtual time may miss
    /// one by a rounding error), or the newest when it is at most half a millisecond past it.
    pub fn at(&self, time_s: f64) -> Option<&Entry<S>> {
        if self.len == 0 || time_s.is_nan() || time_s <= 0.0 {
            return None;
        }
        // Binary search for the last entry with time ≤ time_s.
        let (mut lo, mut hi) = (0, self.len);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.get(mid).time_s <= time_s {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        let index = lo.checked_sub(1)?;
        let found = self.get(index);
        if index + 1 < self.len {
            // Between two ticks: the nearer (a time a rounding error short of a tick is that tick).
            let next = self.get(index + 1);
            return Some(if next.time_s - time_s < time_s - found.time_s { next } else { found });
        }
        (time_s - found.time_s <= 5e-4).then_some(found)
    }

    /// What the VE says the model's state was at `then`, less the corrections applied since: the pose
    /// and twist discrepancies still to correct.
    pub fn discrepancy(&self, then: &Entry<S>, ve_pose: &OpPose<S>, ve_twist: &S::OpVec) -> (S::OpVec, S::OpVec) {
        (ve_pose.difference(&then.pose) - (self.moved - then.moved), *ve_twist - then.twist - (self.sped - then.sped))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::Planar;

    fn at_x(x: f64) -> OpPose<Planar> {
        let mut pose = OpPose::<Planar>::identity();
        pose.position = nalgebra::Vector2::new(x, 0.0);
        pose
    }

    #[test]
    fn a_state_is_found_by_its_tick_or_between_ticks_but_not_past_the_newest() {
        let mut history = History::<Planar>::new();
        // Ticks about a millisecond apart, as a real-time loop keeps them.
        let times = [1.0000, 1.0011, 1.0019, 1.0031];
        for (i, &t) in times.iter().enumerate() {
            history.record(t, at_x(i as f64), <Planar as Space>::OpVec::zero());
        }
        let x = |t: f64| history.at(t).map(|e| e.pose.position[0]);
        assert_eq!(x(1.0011), Some(1.0), "a tick's own time");
        // Between two ticks: the nearer one's state; a rounding error short of a tick is that tick.
        assert_eq!(x(1.0019 + 0.0004), Some(2.0));
        assert_eq!(x(1.0019 + 0.0008), Some(3.0));
        assert_eq!(x(1.0011 - 1e-12), Some(1.0));
        // Past the newest: within half a millisecond only.
        assert_eq!(x(1.0031 + 0.0004), Some(3.0));
        assert_eq!(x(1.0031 + 0.0008), None);
        // Before the oldest, or no time: none.
        assert_eq!(x(0.9995), None);
        assert_eq!(x(0.0), None);
        assert_eq!(x(f64::NAN), None);
    }
}
