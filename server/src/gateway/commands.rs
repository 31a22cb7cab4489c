//! What the network side asks of the VE thread: joins and leaves, each carrying the VE thread's ends of the
//! user's rings, through one bounded command ring.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use kinloop_protocol::{RefusalReason, ResumeRefusal};
use rtrb::{Consumer, Producer};
use tokio::sync::{oneshot, Notify};

use crate::core::{JoinRequest, Joined, UplinkSample, UserId};

/// A request from the network side. Joins are rare and cross the ring by value; boxing them would only
/// move the allocation elsewhere.
#[allow(clippy::large_enum_variant)]
pub enum Command {
    /// Admit a user; the reply carries the welcome or the refusal.
    Join {
        /// What the client asked for.
        request: JoinRequest,
        /// The user's network round trip as the server measured it (the QUIC connection's), if it did.
        round_trip: Option<Duration>,
        /// The VE thread's ends of the user's rings.
        link: UserLink,
        /// Where the decision goes.
        reply: oneshot::Sender<Result<Joined, RefusalReason>>,
    },
    /// Resume the room from an authenticated state (see `VeCore::handle_resume_offer`).
    Resume {
        /// Generalized coordinates.
        q: Vec<f64>,
        /// Generalized velocities.
        qd: Vec<f64>,
        /// Where the decision goes.
        reply: oneshot::Sender<Result<(), ResumeRefusal>>,
    },
    /// The user's session ended.
    Leave {
        /// Who.
        user: UserId,
    },
}

/// An uplink as the network side hands it to the VE thread: the sample and when it arrived, so that the VE
/// thread, which takes it in at its next tick, says how long it waited (`UplinkSample::waited_s`).
#[derive(Clone, Copy, Debug)]
pub struct ArrivedUplink {
    /// When it arrived.
    pub at: Instant,
    /// What it carries.
    pub sample: UplinkSample,
}

impl ArrivedUplink {
    /// `sample`, arrived now.
    pub fn now(sample: UplinkSample) -> Self {
        ArrivedUplink { at: Instant::now(), sample }
    }

    /// The sample as the VE takes it in at `woke`, with the time it waited since its arrival.
    pub fn taken_in(&self, woke: Instant) -> UplinkSample {
        UplinkSample { waited_s: woke.saturating_duration_since(self.at).as_secs_f64(), ..self.sample }
    }
}

/// The VE thread's ends of one user's rings.
pub struct UserLink {
    /// Uplinks from the user's receive task.
    pub uplinks: Consumer<ArrivedUplink>,
    /// Length-prefixed encoded snapshots to the user's send task.
    pub snapshots: Producer<u8>,
    /// Wakes the send task.
    pub notify: Arc<Notify>,
}

/// A full command ring for this long means the VE thread is gone.
const COMMAND_PATIENCE: Duration = Duration::from_secs(2);

/// The network side's end of the command ring: many sessions send, so the producer sits behind a mutex
/// that only network tasks take; the VE thread owns the consumer and never waits.
pub struct CommandSender {
    ring: Mutex<Producer<Command>>,
}

impl CommandSender {
    /// Wraps the producer of the command ring whose consumer the VE thread holds.
    pub fn new(ring: Producer<Command>) -> Self {
        CommandSender { ring: Mutex::new(ring) }
    }

    /// Hands a command to the VE thread, waiting (on the network side) while its ring is full; `Err` when
    /// the VE thread is gone.
    pub async fn send(&self, mut command: Command) -> Result<(), ()> {
        let give_up = Instant::now() + COMMAND_PATIENCE;
        loop {
            let pushed = match self.ring.lock() {
                Ok(mut ring) => ring.push(command),
                Err(_) => return Err(()),
            };
            match pushed {
                Ok(()) => return Ok(()),
                Err(rtrb::PushError::Full(back)) if Instant::now() < give_up => {
                    command = back;
                    tokio::time::sleep(Duration::from_millis(1)).await;
                }
                Err(_) => return Err(()),
            }
        }
    }

    /// Tells the VE thread that `user` left, from code that cannot wait (a drop): at once if the command
    /// ring has room, else from a task.
    pub fn leave_soon(self: &Arc<Self>, user: UserId) {
        let pushed = match self.ring.lock() {
            Ok(mut ring) => ring.push(Command::Leave { user }).is_ok(),
            Err(_) => return,
        };
        if !pushed {
            if let Ok(runtime) = tokio::runtime::Handle::try_current() {
                let sender = self.clone();
                runtime.spawn(async move { sender.send(Command::Leave { user }).await });
            }
        }
    }
}
