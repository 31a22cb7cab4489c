//! The server's edge toward a fleet manager (Agones, [`agones`]): what the driver tells it, as a small
//! interface that knows nothing of the manager, and the executor's heartbeat.
//!
//! The driver feeds a [`FleetFeed`]: listening, rooms opened and closed, users joined and left, draining and
//! drained; the rooms' executor advances the [`Heartbeat`] every time round each real-time thread's loop. An
//! adapter reads the other end, [`FleetEvents`]: it marks the server ready, counts rooms and users, sends
//! health pings only while the heartbeat advances (a stalled executor stops them), creates the rooms the
//! fleet's allocations ask for through the [`RoomsSlot`] the server fills, and asks to be shut down once
//! drained. Nothing inside a core knows about any of it.

#[cfg(feature = "agones")]
pub mod agones;
pub mod allocation;
#[cfg(feature = "agones")]
mod sidecar;
#[cfg(feature = "agones")]
mod watch;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::Duration;

use tokio::sync::mpsc;

use allocation::RoomCreator;

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
        /// Opened for an allocation, which already counted it.
        allocated: bool,
    },
    /// A room closed.
    RoomClosed {
        /// Its name.
        room: String,
    },
    /// A user's session started.
    UserJoined {
        /// The user, unique on this server ([`user_label`]: `ROOM/NAME#ID`).
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

/// Where the server offers the adapter its rooms, to create the rooms allocations ask for. It is filled
/// before the server says it listens, so an adapter finds it there once told [`FleetEvent::Listening`].
/// It holds them weakly: the server's rooms hold the feed, and the adapter must not keep a stopped server's
/// rooms alive.
#[derive(Clone, Default)]
pub struct RoomsSlot(Arc<OnceLock<Weak<dyn RoomCreator>>>);

impl RoomsSlot {
    /// The server's rooms, while the server runs.
    pub fn get(&self) -> Option<Arc<dyn RoomCreator>> {
        self.0.get().and_then(Weak::upgrade)
    }
}

impl std::fmt::Debug for RoomsSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.get().is_some() { "RoomsSlot(offered)" } else { "RoomsSlot(empty)" })
    }
}

/// The driver's end: events go out without waiting (an adapter that has gone is ignored).
#[derive(Clone, Debug)]
pub struct FleetFeed {
    events: mpsc::UnboundedSender<FleetEvent>,
    heartbeat: Heartbeat,
    rooms: RoomsSlot,
}

impl FleetFeed {
    /// Tells the adapter.
    pub fn send(&self, event: FleetEvent) {
        let _ = self.events.send(event);
    }

    /// Offers the server's rooms to the adapter (the first offer stands).
    pub fn offer_rooms(&self, rooms: Weak<dyn RoomCreator>) {
        let _ = self.rooms.0.set(rooms);
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
    /// Opened for an allocation (which counted it).
    allocated: bool,
}

impl FleetRoom {
    /// Room `name`'s side of `feed` (none: nothing is told); `allocated`: opened for an allocation.
    pub fn new(feed: Option<FleetFeed>, name: String, allocated: bool) -> Self {
        FleetRoom { feed, name, told: Mutex::new((false, false)), allocated }
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
            self.send(FleetEvent::RoomOpened { room: self.name.clone(), allocated: self.allocated });
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
    /// The server's rooms, for allocations.
    pub rooms: RoomsSlot,
}

/// A feed and its events.
pub fn channel() -> (FleetFeed, FleetEvents) {
    let (tx, rx) = mpsc::unbounded_channel();
    let (heartbeat, rooms) = (Heartbeat::default(), RoomsSlot::default());
    let feed = FleetFeed { events: tx, heartbeat: heartbeat.clone(), rooms: rooms.clone() };
    (feed, FleetEvents { events: rx, heartbeat, rooms })
}

/// A user's name in the fleet's list: unique on the server (user ids are per room, and a room's name holds
/// no '/'), readable by a person, and it says which room the user is in: `ROOM/NAME#ID`.
pub fn user_label(room: &str, name: &str, user_id: u32) -> String {
    format!("{room}/{name}#{user_id}")
}
