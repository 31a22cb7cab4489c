//! Things the VE reports for logs, drained by the driver away from the VE thread. The queue has a fixed
//! capacity and no event owns heap memory, so reporting never allocates inside a tick; when the queue is
//! full, events are counted and dropped.

use std::collections::VecDeque;

use kinloop_linkage::error::DynamicsError;
use kinloop_protocol::codec::DecodeError;

use super::guards::UplinkRejection;
use super::users::UserId;

/// Most events held between two drains.
pub const EVENT_CAPACITY: usize = 256;

/// Why a coupling started fading out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum FadeReason {
    /// The user left.
    Left,
    /// The user's uplinks stopped for the silent timeout.
    Silent,
    /// The user's hand is off its handle while another user's hand is on the linkage.
    LetGo,
}

/// Something worth a log line.
#[derive(Clone, Debug, PartialEq)]
pub enum VeEvent {
    /// A user joined.
    UserJoined {
        /// Who.
        user: UserId,
    },
    /// A user's coupling started fading out.
    FadingOut {
        /// Who.
        user: UserId,
        /// Why.
        reason: FadeReason,
    },
    /// A silent user's uplinks resumed; its coupling fades back in.
    Resumed {
        /// Who.
        user: UserId,
    },
    /// The room resumed from a state a client offered (see `docs/resume.md`).
    RoomResumed {
        /// The VE's step counter then.
        step: u64,
    },
    /// A user that left has faded out and is gone.
    UserRemoved {
        /// Who.
        user: UserId,
    },
    /// The first rejected uplink of a burst (later ones in the burst are only counted).
    UplinkRejected {
        /// Whose.
        user: UserId,
        /// Why.
        rejection: UplinkRejection,
        /// Rejections in the user's previous burst.
        previous_burst: u64,
    },
    /// A step failed or left a non-finite state; the last good configuration was restored at rest.
    StateRestored {
        /// The VE step that failed.
        step: u64,
        /// Why.
        error: DynamicsError,
    },
    /// The dynamics at the current state could not be evaluated: no snapshot this tick.
    SnapshotsWithheld {
        /// The VE step.
        step: u64,
        /// Why.
        error: DynamicsError,
    },
    /// One user's snapshot failed the wire checks and was not offered.
    SnapshotInvalid {
        /// Whose.
        user: UserId,
        /// Why.
        error: DecodeError,
    },
    /// The VE fell more than `max_catch_up_ticks` behind and skipped ticks.
    TicksSkipped {
        /// How many.
        count: u64,
    },
}

/// Fixed-capacity event queue.
#[derive(Debug)]
pub struct EventQueue {
    queue: VecDeque<VeEvent>,
    /// Events dropped because the queue was full.
    pub dropped: u64,
}

impl EventQueue {
    /// An empty queue with room for [`EVENT_CAPACITY`] events.
    pub fn new() -> Self {
        EventQueue { queue: VecDeque::with_capacity(EVENT_CAPACITY), dropped: 0 }
    }

    /// Queues an event, or counts it when full.
    pub fn push(&mut self, event: VeEvent) {
        if self.queue.len() < EVENT_CAPACITY {
            self.queue.push_back(event);
        } else {
            self.dropped += 1;
        }
    }

    /// The oldest event.
    pub fn pop(&mut self) -> Option<VeEvent> {
        self.queue.pop_front()
    }
}

impl Default for EventQueue {
    fn default() -> Self {
        Self::new()
    }
}
