//! The server's edge toward a fleet manager (Agones, [`agones`]): what the driver tells it, as a small
//! interface that knows nothing of the manager, and the executor's heartbeat.
//!
//! The driver feeds a [`FleetFeed`]: listening, rooms opened and closed, users joined and left, draining and
//! drained; the rooms' executor advances the [`Heartbeat`] every time round each real-time thread's loop. An
//! adapter reads the other end, [`FleetEvents`]: it marks the server ready, counts rooms and users, sends
//! health pings only while the heartbeat advances (a stalled executor stops them), and asks to be shut down
//! once drained. Nothing inside a core knows about any of it.

#[cfg(feature = "agones")]
pub mod agones;
pub mod allocation;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::mpsc;

/// How often the server pings by default (the Fleet checks every 1 s, `deploy/agones/fleet.yaml`).
pub const DEFAULT_HEALTH_PERIOD: Duration = Duration::from_millis(500);

/// What happened at the server, for the fleet manager.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FleetEvent {
    /// The server listens (QUIC) at `addr` and admits clients.
    Listening {
        /// Its address.
        addr: SocketAddr,
    },
    /// A room opened.
    RoomOpened {
        /// Its name.
        room: String,
    },
    /// A room closed.
    RoomClosed {
        /// Its name.
        room: String,
    },
    /// A user's session started.
    UserJoined {
        /// The user, unique on this server (`NAME#ID`).
        user: String,
    },
    /// A user's session ended.
    UserLeft {
        /// The user, as it joined.
        user: String,
    },
    /// The server stopped admitting and told its clients to move.
    Draining,
    /// Every client has gone (or the drain time ran out): the server is about to exit.
    Drained,
}

/// The executor's heartbeat: a count its real-time threads advance every pass. Reading it never blocks the thread.
#[derive(Clone, Debug, Default)]
pub struct Heartbeat(Arc<AtomicU64>);

impl Heartbeat {
    /// One tick (from the executor's thread: one relaxed atomic add, no allocation).
    pub fn beat(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }

    /// Ticks so far.
    pub fn count(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// The driver's end: events go out without waiting (an adapter that has gone is ignored).
#[derive(Clone, Debug)]
pub struct FleetFeed {
    events: mpsc::UnboundedSender<FleetEvent>,
    heartbeat: Heartbeat,
}

impl FleetFeed {
    /// Tells the adapter.
    pub fn send(&self, event: FleetEvent) {
        let _ = self.events.send(event);
    }

    /// The heartbeat the executor advances.
    pub fn heartbeat(&self) -> &Heartbeat {
        &self.heartbeat
    }
}

/// One room's side of the feed: it is told opened once and closed once, closed never before opened, whichever
/// way it closes first (removed by the admin command, closed by a panic of its simulation, or at shutdown), so
/// the adapter's count stays true.
#[derive(Debug)]
pub struct FleetRoom {
    feed: Option<FleetFeed>,
    name: String,
    /// Whether it was told opened, and whether it closed.
    told: Mutex<(bool, bool)>,
}

impl FleetRoom {
    /// Room `name`'s side of `feed` (none: nothing is told).
    pub fn new(feed: Option<FleetFeed>, name: String) -> Self {
        FleetRoom { feed, name, told: Mutex::new((false, false)) }
    }

    /// Tells the adapter, if there is one.
    pub fn send(&self, event: FleetEvent) {
        if let Some(feed) = &self.feed {
            feed.send(event);
        }
    }

    /// Tells that the room is open (the first time only; and that it closed, if it already did).
    pub fn opened(&self) {
        let Ok(mut told) = self.told.lock() else { return };
        if !told.0 {
            told.0 = true;
            self.send(FleetEvent::RoomOpened { room: self.name.clone() });
            if told.1 {
                self.send(FleetEvent::RoomClosed { room: self.name.clone() });
            }
        }
    }

    /// The room closed: told the first time only, and once it was told open.
    pub fn closed(&self) {
        let Ok(mut told) = self.told.lock() else { return };
        if !told.1 {
            told.1 = true;
            if told.0 {
                self.send(FleetEvent::RoomClosed { room: self.name.clone() });
            }
        }
    }
}

/// The adapter's end.
#[derive(Debug)]
pub struct FleetEvents {
    /// What happened, in order.
    pub events: mpsc::UnboundedReceiver<FleetEvent>,
    /// The executor's heartbeat.
    pub heartbeat: Heartbeat,
}

/// A feed and its events.
pub fn channel() -> (FleetFeed, FleetEvents) {
    let (tx, rx) = mpsc::unbounded_channel();
    let heartbeat = Heartbeat::default();
    (FleetFeed { events: tx, heartbeat: heartbeat.clone() }, FleetEvents { events: rx, heartbeat })
}

/// A user's name in the fleet's list: unique on the server, readable by a person.
pub fn user_label(name: &str, user_id: u32) -> String {
    format!("{name}#{user_id}")
}
