//! Hosted rooms: one server, many linkages. The [`Host`] keeps the open rooms by name (the QUIC side routes
//! each session to the room its hello names), opens and closes them (at start from `--rooms`, at run time
//! by the admin command), and hands each room's VE to the real-time [`Executor`]. (`super::room` is another
//! thing: the signed state a client carries so a room survives its server.)

pub(crate) mod admin;
mod executor;
mod file;
mod quarantine;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use kinloop_linkage::math::space::Space;
use kinloop_protocol::{RefusalReason, RoomSummary};
use serde::Serialize;
use tokio::sync::watch;

pub use executor::{default_rt_threads, Executor, OverBudget, RoomCell, Steppable, BUDGET_SHARE};
pub use file::{load_entry, load_rooms_file, EntryShape, RoomSpec, RoomsFileError, TestKnobs};
pub use quarantine::{rest_after, QuarantineReport, QUARANTINE_SHARE};

use super::ve_thread::VeLoop;
use super::{open_room, OpenRoom, ServerConfig, ServerError, ServerStats, Shared};
use crate::access::Access;

/// The name of the one room of a `--scene` server, and the room a hello naming none joins.
pub const DEFAULT_ROOM: &str = "default";

/// The server's rooms and what opening another needs.
pub(crate) struct Host {
    /// The web view's site (`--view`), every room on it.
    pub view: Option<crate::view::ViewSite>,
    /// The server's endpoint.
    pub endpoint: kinloop_protocol::quic::Endpoint,
    /// The rooms' executor.
    pub executor: Arc<Executor>,
    /// The open rooms by name.
    pub table: Mutex<BTreeMap<String, OpenRoom>>,
    /// Tokens of the admin command.
    pub admin: Option<Access>,
    /// The server's settings every room shares (VE rates, gains, room key, view, statistics).
    pub template: ServerConfig,
    /// Set at shutdown.
    pub shutdown: watch::Sender<bool>,
    /// Whether the fleet adapter was told the server listens (rooms opened since are told as they open).
    pub announced: AtomicBool,
}

impl Host {
    /// Opens a room and adds it to the table; a name already open is refused. `allocated`: opened for a
    /// fleet's allocation, which counted it.
    pub fn open(&self, spec: RoomSpec, allocated: bool) -> Result<(), ServerError> {
        if self.table.lock().map(|t| t.contains_key(&spec.name)).unwrap_or(true) {
            return Err(ServerError::Thread {
                which: "rooms",
                what: format!("a room {:?} is already open", spec.name),
            });
        }
        let name = spec.name.clone();
        let opened = open_room(self, spec, allocated)?;
        if self.announced.load(Ordering::Acquire) {
            opened.shared.fleet.opened();
        }
        if let Ok(mut table) = self.table.lock() {
            table.insert(name, opened);
        }
        Ok(())
    }

    /// Tells the fleet adapter that the server listens at `addr`, then which rooms are open.
    pub fn announce(&self, addr: std::net::SocketAddr) {
        self.tell_fleet(crate::fleet::FleetEvent::Listening { addr });
        self.announced.store(true, Ordering::Release);
        if let Ok(table) = self.table.lock() {
            table.values().for_each(|room| room.shared.fleet.opened());
        }
    }

    /// Tells the fleet adapter, if there is one.
    pub fn tell_fleet(&self, event: crate::fleet::FleetEvent) {
        if let Some(fleet) = &self.template.fleet {
            fleet.send(event);
        }
    }

    /// Applies `f` to the first room by name.
    pub fn first<T>(&self, f: impl FnOnce(&OpenRoom) -> T) -> Option<T> {
        self.table.lock().ok().and_then(|t| t.values().next().map(f))
    }

    /// Removes every room from the table (to close them).
    pub fn take_all(&self) -> Vec<OpenRoom> {
        self.table.lock().map(|mut t| std::mem::take(&mut *t).into_values().collect()).unwrap_or_default()
    }

    /// Removes one room from the table (to close it).
    pub fn take(&self, name: &str) -> Option<OpenRoom> {
        self.table.lock().ok().and_then(|mut t| t.remove(name))
    }

    /// The room a hello asks for: by name, or (empty name) the default room or the only one. A room whose
    /// simulation failed is no longer found. Unknown: the rooms whose tokens admit this hello.
    pub fn route(&self, hello: &kinloop_protocol::Hello) -> Result<Arc<Shared>, RefusalReason> {
        let table = self.table.lock().map_err(|_| RefusalReason::Malformed { what: "the server is failing".into() })?;
        let live = |r: &&OpenRoom| !r.shared.cell.done();
        let found = if hello.room.is_empty() {
            table.get(DEFAULT_ROOM).filter(live).or_else(|| (table.len() == 1).then(|| table.values().next()).flatten())
        } else {
            table.get(&hello.room).filter(live)
        };
        match found {
            Some(room) => Ok(room.shared.clone()),
            None => Err(RefusalReason::UnknownRoom {
                requested: hello.room.clone(),
                available: table
                    .values()
                    .filter(|r| live(r) && r.shared.access.admit(&hello.token, hello.role).is_ok())
                    .map(|r| r.shared.name.clone())
                    .collect(),
            }),
        }
    }

    /// Every room's statistics so far.
    pub fn reports(&self) -> Vec<RoomReport> {
        self.table.lock().map(|t| t.values().map(|r| RoomReport::of(&r.shared)).collect()).unwrap_or_default()
    }

    /// Every room as the admin command lists it.
    pub fn summaries(&self) -> Vec<RoomSummary> {
        self.reports()
            .into_iter()
            .map(|r| RoomSummary {
                name: r.name,
                scene: r.scene,
                users: r.stats.users,
                thread: r.thread as u32,
                cost_us: r.cost_us,
            })
            .collect()
    }
}

/// One room's statistics, with what the executor measured of it (`--json` prints one per room).
#[derive(Clone, Debug, Serialize)]
pub struct RoomReport {
    /// Its name.
    pub name: String,
    /// Its scene's name.
    pub scene: String,
    /// The real-time thread that steps it.
    pub thread: usize,
    /// Moved off the real-time threads for overrunning its share, and not yet released.
    pub quarantined: bool,
    /// Times it was moved to the quarantine, released or not: a room that overran for a while and runs
    /// within its share again reads `quarantined: false` and a count here.
    pub quarantines: u32,
    /// Its step cost as the executor measured it (EWMA, µs), test knobs included.
    pub cost_us: f64,
    /// What the quarantine measured of it (CPU share, slowdown, lag behind real time), when quarantined.
    pub quarantine: Option<QuarantineReport>,
    /// Why it closed on its own (its simulation failed), if it did.
    pub closed: Option<String>,
    /// The room's statistics, as a one-room server reports them.
    pub stats: ServerStats,
}

impl RoomReport {
    pub(crate) fn of(shared: &Shared) -> RoomReport {
        RoomReport {
            name: shared.name.clone(),
            scene: shared.scene_info.name.clone(),
            thread: shared.cell.thread(),
            quarantined: shared.cell.quarantined(),
            quarantines: shared.cell.quarantines(),
            cost_us: shared.cell.cost().as_secs_f64() * 1e6,
            quarantine: shared.cell.quarantine_report(),
            closed: shared.cell.closed_reason(),
            stats: shared.stats(),
        }
    }
}

/// A room's VE loop behind its test knobs, as the executor steps it.
pub(crate) struct Hosted<S: Space> {
    ve: VeLoop<S>,
    knobs: TestKnobs,
    ticks: u64,
}

impl<S: Space> Hosted<S> {
    pub fn new(ve: VeLoop<S>, knobs: TestKnobs) -> Self {
        Hosted { ve, knobs, ticks: 0 }
    }

    /// One tick of its VE, at the deadline it was due or (`behind`, in quarantine) at its VE's own next tick
    /// however late, then the test knobs.
    fn step(&mut self, behind: bool) {
        let started = std::time::Instant::now();
        // The cost knob is CPU time, as a costly simulation's would be: a tick preempted on a busy host takes
        // longer in wall time, not less of its thread.
        let cpu_started = self.knobs.cost.and_then(|_| kinloop_process::cpu::thread_cpu_time());
        if behind {
            self.ve.tick_back_to_back();
        } else {
            self.ve.tick();
        }
        self.ticks += 1;
        if self.knobs.panic_after_ticks.is_some_and(|at| self.ticks >= at) {
            panic!("test knob: debug_panic_after_ticks");
        }
        if let Some(cost) = self.knobs.cost {
            kinloop_process::cpu::spin_until_spent(cpu_started, started, cost);
        }
    }
}

impl<S: Space> Steppable for Hosted<S>
where
    VeLoop<S>: Send,
{
    fn next_deadline(&self) -> std::time::Instant {
        self.ve.next_deadline()
    }

    fn tick(&mut self) {
        self.step(false);
    }

    fn tick_behind(&mut self) {
        self.step(true);
    }

    fn warm(&mut self) {
        self.ve.warm();
    }

    fn placed(&mut self, realtime: bool) {
        self.ve.stats.realtime_priority = realtime;
    }

    fn stopped(&self) -> bool {
        self.ve.stopped()
    }

    fn users(&self) -> usize {
        self.ve.users()
    }

    fn finish(self: Box<Self>) {
        self.ve.finish();
    }
}
