//! The rooms' real-time executor: a few threads (`--rt-threads`, default one fewer than the cores), each
//! stepping the rooms placed on it at their deadlines, and a quarantine thread for rooms that overrun.
//!
//! - **Cost.** Each room's step time is the CPU time its tick used (its wall time where the platform has no
//!   per-thread CPU clock), kept as an exponentially weighted moving average ([`EWMA_WEIGHT`]); a thread's
//!   load is the sum of its rooms' costs times their rates (the share of a second the thread spends stepping
//!   them). CPU time, because a thread that another process preempts mid-tick on a busy host has not made
//!   its room any costlier: charging the wall time would quarantine a room for its neighbours' work.
//! - **Placement and admission.** A new room goes to the least-loaded thread, and only if that thread's load
//!   plus the room's estimate ([`ROOM_ESTIMATE`] per tick) stays within [`BUDGET_SHARE`]; a new user joins
//!   only if its room's thread load plus the user's estimate (its room's measured cost per user, at least
//!   [`USER_ESTIMATE`]) stays within it. Refusals say the load and the share.
//! - **Isolation.** A room whose own load passes the share, or whose last [`OVERRUN_STREAK`] ticks each
//!   took more than the share of a period, is moved off its real-time thread to the
//!   quarantine thread (normal priority, `super::quarantine`), so it never delays a room within budget; it
//!   refuses new users, and is stepped there in slow motion within a CPU budget of its own. A
//!   tick that panics is caught (`catch_unwind`): that room is closed with the reason, its users told; the
//!   thread's other rooms go on.
//! - **Liveness.** Every pass of a real-time thread's loop advances the fleet's [`Heartbeat`], rooms or
//!   none, so a fleet manager's health pings stop when the stepping stalls (`crate::fleet`).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use rtrb::{Consumer, Producer, RingBuffer};

use super::quarantine::{self, Calm, QuarantineReport, QuarantineTally};
use crate::driver::rehearsal::wait_warmed;
use crate::fleet::Heartbeat;
use kinloop_process::cpu::thread_cpu_time;

/// Weight of the newest step time in a room's cost average (about the last 64 ticks).
pub const EWMA_WEIGHT: f64 = 1.0 / 64.0;
/// The most one tick is charged to its room's cost, in periods (see `RoomCell::record`).
pub const MAX_CHARGED_PERIODS: f64 = 4.0;
/// The share of each real-time thread's time that rooms may fill; the rest absorbs jitter.
pub const BUDGET_SHARE: f64 = 0.7;
/// Consecutive ticks each longer than [`BUDGET_SHARE`] of a period that send a room to the quarantine at
/// once, before its cost average has caught up: a room that takes 2 ms a tick at 1 kHz would otherwise hold
/// its thread for a few dozen ticks (its average climbing from [`ROOM_ESTIMATE`]), and make every other room
/// there miss as many deadlines. Eight, not fewer: on a busy 2-core host a calm room's single ticks of
/// 20 µs now and then take 0.6-1.4 ms of thread CPU time (one VE step each, not a catch-up; the cause is
/// not traced), a few a second and sometimes back to back, and three in a row once sent a calm room away.
/// A room that is really slow holds its thread for eight of its ticks, once.
pub const OVERRUN_STREAK: u32 = 8;
/// The most of a period a quarantined room's cost average may take to be released back onto a real-time
/// thread: half the admission share, so that a released room is well clear of the share that sent it away.
pub const RELEASE_SHARE: f64 = BUDGET_SHARE / 2.0;
/// A new room's cost per tick before it is measured.
pub const ROOM_ESTIMATE: Duration = Duration::from_micros(50);
/// The least a new user is expected to add to its room's tick.
pub const USER_ESTIMATE: Duration = Duration::from_micros(10);
/// Rooms waiting to be taken by one thread.
const INBOX: usize = 64;
/// How long an idle thread sleeps between looks at its inbox.
const IDLE: Duration = Duration::from_millis(1);

/// A room as a thread steps it (its VE loop behind the room's test knobs).
pub trait Steppable: Send {
    /// When its next tick is due.
    fn next_deadline(&self) -> Instant;
    /// One tick.
    fn tick(&mut self);
    /// One tick at its own next deadline however far behind real time that is: its time advances one
    /// period, never skipped forward (the quarantine's slow motion, `super::quarantine`).
    fn tick_behind(&mut self) {
        self.tick();
    }
    /// Readies the caches for its coming tick, shortly before the deadline (`crate::driver::rehearsal`).
    fn warm(&mut self) {}
    /// It was taken in by a thread that runs at real-time priority (`realtime`) or not.
    fn placed(&mut self, _realtime: bool) {}
    /// Whether it was told to stop.
    fn stopped(&self) -> bool;
    /// Users in it now.
    fn users(&self) -> usize;
    /// Publishes its final statistics.
    fn finish(self: Box<Self>);
}

/// What the network side and the executor share about one room.
pub struct RoomCell {
    /// The room's name.
    pub name: String,
    /// Ticks per second.
    pub rate_hz: f64,
    cost_ns: AtomicU64,
    /// Consecutive ticks longer than the share of a period (only its thread writes it).
    streak: AtomicU32,
    /// The shortest tick of the current streak, in ns (only its thread writes it).
    streak_least_ns: AtomicU64,
    users: AtomicUsize,
    thread: AtomicUsize,
    quarantined: AtomicBool,
    quarantines: AtomicU32,
    done: AtomicBool,
    closed: Mutex<Option<String>>,
    quarantine: Mutex<Option<QuarantineTally>>,
    on_close: Box<dyn Fn(&str) + Send + Sync>,
}

impl RoomCell {
    /// A cell for a room ticking at `rate_hz`; `on_close` tells its users why it closed.
    pub fn new(name: String, rate_hz: f64, on_close: Box<dyn Fn(&str) + Send + Sync>) -> Self {
        RoomCell {
            name,
            rate_hz,
            cost_ns: AtomicU64::new(f64::to_bits(ROOM_ESTIMATE.as_nanos() as f64)),
            streak: AtomicU32::new(0),
            streak_least_ns: AtomicU64::new(0),
            users: AtomicUsize::new(0),
            thread: AtomicUsize::new(0),
            quarantined: AtomicBool::new(false),
            quarantines: AtomicU32::new(0),
            done: AtomicBool::new(false),
            closed: Mutex::new(None),
            quarantine: Mutex::new(None),
            on_close,
        }
    }

    /// The measured cost of a tick (EWMA).
    pub fn cost(&self) -> Duration {
        Duration::from_nanos(f64::from_bits(self.cost_ns.load(Ordering::Relaxed)) as u64)
    }

    /// The share of a second the room takes.
    pub fn load(&self) -> f64 {
        self.cost().as_secs_f64() * self.rate_hz
    }

    /// Whether it takes more than a real-time thread's share: its cost average says so, or its last
    /// [`OVERRUN_STREAK`] ticks each took more than the share of a period.
    pub fn overruns(&self) -> bool {
        self.load() > BUDGET_SHARE || self.streak.load(Ordering::Relaxed) >= OVERRUN_STREAK
    }

    /// The thread that steps it.
    pub fn thread(&self) -> usize {
        self.thread.load(Ordering::Relaxed)
    }

    /// Whether it was moved to the quarantine thread for overrunning.
    pub fn quarantined(&self) -> bool {
        self.quarantined.load(Ordering::Relaxed)
    }

    /// How many times it was moved to the quarantine thread (a room released since counts too).
    pub fn quarantines(&self) -> u32 {
        self.quarantines.load(Ordering::Relaxed)
    }

    /// Users in it (as of its last tick).
    pub fn users(&self) -> usize {
        self.users.load(Ordering::Relaxed)
    }

    /// Whether the executor has let it go (stopped, or closed after a panic).
    pub fn done(&self) -> bool {
        self.done.load(Ordering::Acquire)
    }

    /// Why it closed on its own (a panic), if it did.
    pub fn closed_reason(&self) -> Option<String> {
        self.closed.lock().ok().and_then(|c| c.clone())
    }

    /// What the quarantine measured of it (its CPU share, slowdown and lag), once it was quarantined.
    pub fn quarantine_report(&self) -> Option<QuarantineReport> {
        let tally = *self.quarantine.lock().ok()?;
        tally.map(|t| t.report(Instant::now()))
    }

    /// The quarantine thread took it: its tally starts.
    fn begin_quarantine(&self) {
        if let Ok(mut tally) = self.quarantine.lock() {
            *tally = Some(QuarantineTally::new(Duration::from_secs_f64(1.0 / self.rate_hz.max(1e-3))));
        }
    }

    /// One tick in quarantine: its CPU time, and how far behind real time its deadline was. Whether the room
    /// has run calm long enough to be released (`quarantine::Calm`).
    fn note_quarantine_tick(&self, busy: Duration, behind: Duration) -> bool {
        let load = self.load();
        let Ok(mut tally) = self.quarantine.lock() else { return false };
        let Some(t) = tally.as_mut() else { return false };
        t.busy += busy;
        t.ticks += 1;
        t.behind = behind;
        t.calm.observe(Instant::now(), Calm::is_calm(behind, t.period, load, RELEASE_SHARE))
    }

    /// A released room's calm starts over: no real-time thread had room for it.
    fn restart_calm(&self) {
        if let Ok(mut tally) = self.quarantine.lock() {
            if let Some(t) = tally.as_mut() {
                t.calm = Calm::default();
            }
        }
    }

    /// Its thread sends it to the quarantine: it admits no one from here, and the send is counted. Sent for
    /// a streak, its cost is at least the streak's shortest tick: the average has not caught up yet, and
    /// what the room reports and the quarantine's release rule read should be what it takes.
    fn send_to_quarantine(&self) {
        if self.streak.load(Ordering::Relaxed) >= OVERRUN_STREAK {
            let least = self.streak_least_ns.load(Ordering::Relaxed) as f64;
            let cost = f64::from_bits(self.cost_ns.load(Ordering::Relaxed));
            self.cost_ns.store(cost.max(least).to_bits(), Ordering::Relaxed);
        }
        self.quarantined.store(true, Ordering::Relaxed);
        self.quarantines.fetch_add(1, Ordering::Relaxed);
    }

    /// The quarantine let it go to real-time thread `index`: it is measured afresh there and admits users.
    fn end_quarantine(&self, index: usize) {
        if let Ok(mut tally) = self.quarantine.lock() {
            *tally = None;
        }
        self.streak.store(0, Ordering::Relaxed);
        self.thread.store(index, Ordering::Relaxed);
        self.quarantined.store(false, Ordering::Relaxed);
    }

    /// The executor let it go.
    fn mark_done(&self) {
        self.done.store(true, Ordering::Release);
    }

    /// One tick's cost (`step`, its CPU time: `cpu_since`) and the users it had.
    fn record(&self, step: Duration, users: usize) {
        // One tick is charged at most MAX_CHARGED_PERIODS periods: a thread preempted mid-tick on a busy host
        // (or a page fault storm) must not make a room look over budget for the next hundred ticks, while a
        // room that really takes a few periods a tick still reads as what it takes.
        let charged = (step.as_nanos() as f64).min(MAX_CHARGED_PERIODS * 1e9 / self.rate_hz);
        let old = f64::from_bits(self.cost_ns.load(Ordering::Relaxed));
        let new = old + EWMA_WEIGHT * (charged - old);
        self.cost_ns.store(new.to_bits(), Ordering::Relaxed);
        let long = step.as_secs_f64() * self.rate_hz > BUDGET_SHARE;
        let streak = if long { self.streak.load(Ordering::Relaxed).saturating_add(1) } else { 0 };
        self.streak.store(streak, Ordering::Relaxed);
        if long {
            let least =
                if streak == 1 { charged } else { charged.min(self.streak_least_ns.load(Ordering::Relaxed) as f64) };
            self.streak_least_ns.store(least as u64, Ordering::Relaxed);
        }
        self.users.store(users, Ordering::Relaxed);
    }

    /// Keeps the reason, then tells the room's sessions (which read it).
    fn close(&self, reason: String) {
        if let Ok(mut closed) = self.closed.lock() {
            *closed = Some(reason.clone());
        }
        (self.on_close)(&reason);
    }
}

/// Why a room or a user was not admitted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{what}")]
pub struct OverBudget {
    /// The load, the estimate and the share, in words.
    pub what: String,
}

struct Slot {
    room: Box<dyn Steppable>,
    cell: Arc<RoomCell>,
}

struct ThreadEnd {
    inbox: Mutex<Producer<Slot>>,
}

/// What the real-time threads tell a fleet manager: the heartbeat they advance, and a test knob that
/// stalls them.
struct Pulse {
    heartbeat: Option<Heartbeat>,
    epoch: Instant,
    /// Until when (ns after `epoch`) the real-time threads stall; 0: they do not.
    stall_until_ns: AtomicU64,
}

impl Pulse {
    /// One pass of a real-time thread: first sits out a stall, if one is asked for, then beats.
    fn pass(&self) {
        let until = self.stall_until_ns.load(Ordering::Relaxed);
        if until > 0 {
            let until = self.epoch + Duration::from_nanos(until);
            std::thread::sleep(until.saturating_duration_since(Instant::now()));
        }
        if let Some(heartbeat) = &self.heartbeat {
            heartbeat.beat();
        }
    }
}

/// The executor: its threads and every room placed on them.
pub struct Executor {
    threads: Vec<Arc<ThreadEnd>>,
    cells: Mutex<Vec<Arc<RoomCell>>>,
    stop: Arc<AtomicBool>,
    handles: Mutex<Vec<std::thread::JoinHandle<()>>>,
    pulse: Arc<Pulse>,
}

/// The default number of real-time threads: one fewer than the cores, at least one.
pub fn default_rt_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().saturating_sub(1)).max(1)
}

impl Executor {
    /// Starts `threads` real-time threads (SCHED_FIFO when `realtime` and granted) and the quarantine thread;
    /// the real-time threads advance `heartbeat`, if given, on every pass. The first is pinned to CPU `pin`,
    /// if given (`ServerConfig::network_cpu`).
    pub fn start(
        threads: usize,
        realtime: bool,
        heartbeat: Option<Heartbeat>,
        pin: Option<usize>,
    ) -> std::io::Result<Arc<Executor>> {
        let stop = Arc::new(AtomicBool::new(false));
        let pulse = Arc::new(Pulse { heartbeat, epoch: Instant::now(), stall_until_ns: AtomicU64::new(0) });
        let quarantine_stop = stop.clone();
        // The quarantine hands calm rooms back through the executor, which exists only once its threads do.
        let executor_for_quarantine: Arc<OnceLock<Weak<Executor>>> = Arc::new(OnceLock::new());
        let release_to = executor_for_quarantine.clone();
        let (quarantine, quarantine_handle) = spawn_thread("kinloop-rooms-q".into(), move |inbox| {
            // Spawned by a real-time thread it would inherit SCHED_FIFO and spin its rooms' long ticks at
            // the rooms threads' own priority, delaying their wake-ups; it is to yield to them.
            if let Err(why) = kinloop_process::realtime::normal_priority() {
                tracing::warn!(%why, "the quarantine thread keeps its creator's priority");
            }
            run_quarantine(inbox, &quarantine_stop, &release_to)
        })?;
        let mut ends = Vec::new();
        let mut handles = vec![quarantine_handle];
        for index in 0..threads.max(1) {
            let (stop, quarantine, pulse) = (stop.clone(), quarantine.clone(), pulse.clone());
            let (end, handle) = spawn_thread(format!("kinloop-rooms-{index}"), move |inbox| {
                if let Some(cpu) = pin.filter(|_| index == 0) {
                    if let Err(why) = kinloop_process::affinity::pin_current_thread(cpu) {
                        tracing::warn!(%why, "the first rooms thread is not pinned");
                    }
                }
                let granted = realtime
                    && kinloop_process::realtime::try_realtime_priority()
                        .inspect_err(
                            |why| tracing::warn!(%why, thread = index, "a rooms thread runs at normal priority"),
                        )
                        .is_ok();
                if !realtime {
                    // Not to run at a real-time priority inherited from its creator when none was asked for.
                    drop(kinloop_process::realtime::normal_priority());
                }
                run_thread(inbox, &stop, &quarantine, &pulse, granted)
            })?;
            ends.push(end);
            handles.push(handle);
        }
        let executor = Arc::new(Executor {
            threads: ends,
            cells: Mutex::new(Vec::new()),
            stop,
            handles: Mutex::new(handles),
            pulse,
        });
        drop(executor_for_quarantine.set(Arc::downgrade(&executor)));
        Ok(executor)
    }

    /// A test knob: every real-time thread stops stepping (and beating) for `duration` from its next pass,
    /// as a stalled executor would; what a fleet manager sees of it is the test.
    pub fn stall(&self, duration: Duration) {
        let until = self.pulse.epoch.elapsed() + duration;
        self.pulse.stall_until_ns.store(until.as_nanos().max(1) as u64, Ordering::Relaxed);
    }

    /// The first instant on the executor's grid of `period` (its start plus a whole number of periods) not
    /// before now. Rooms of one rate whose time starts there share their deadlines, so a thread wakes once a
    /// period for all of them, not once for each: rooms started at scattered moments would each have the
    /// thread wake (and spin for the end of its sleep) at a phase of their own.
    pub fn grid_start(&self, period: Duration) -> Instant {
        let since = self.pulse.epoch.elapsed().as_nanos();
        let period = period.as_nanos().max(1);
        let periods = since.div_ceil(period);
        self.pulse.epoch + Duration::from_nanos(u64::try_from(periods * period).unwrap_or(u64::MAX))
    }

    /// Real-time threads (the quarantine thread not counted).
    pub fn rt_threads(&self) -> usize {
        self.threads.len()
    }

    /// The load of real-time thread `index`: its rooms' shares of a second.
    pub fn thread_load(&self, index: usize) -> f64 {
        self.live_cells().iter().filter(|c| !c.quarantined() && c.thread() == index).map(|c| c.load()).sum()
    }

    fn live_cells(&self) -> Vec<Arc<RoomCell>> {
        let mut cells = self.cells.lock().map(|c| c.clone()).unwrap_or_default();
        cells.retain(|c| !c.done());
        cells
    }

    /// The least-loaded real-time thread and its load.
    fn least_loaded(&self) -> (usize, f64) {
        (0..self.threads.len()).map(|i| (i, self.thread_load(i))).min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0, 0.0))
    }

    /// Places a room on the least-loaded real-time thread when its estimate fits the budget there.
    pub fn place(&self, room: Box<dyn Steppable>, cell: Arc<RoomCell>) -> Result<(), OverBudget> {
        let estimate = ROOM_ESTIMATE.as_secs_f64() * cell.rate_hz;
        let (index, load) = self.least_loaded();
        if load + estimate > BUDGET_SHARE {
            return Err(OverBudget {
                what: format!(
                    "the least-loaded real-time thread is {:.0} % busy; a new room ({:.0} % estimated) would pass the {:.0} % share",
                    load * 100.0,
                    estimate * 100.0,
                    BUDGET_SHARE * 100.0
                ),
            });
        }
        cell.thread.store(index, Ordering::Relaxed);
        if let Ok(mut cells) = self.cells.lock() {
            cells.retain(|c| !c.done());
            cells.push(cell.clone());
        }
        push(&self.threads[index], Slot { room, cell });
        Ok(())
    }

    /// Hands a quarantined room that ran calm back to the least-loaded real-time thread when its measured load
    /// fits the share there; otherwise gives it back to stay in quarantine.
    fn release(&self, slot: Slot) -> Result<(), Slot> {
        let (index, load) = self.least_loaded();
        if load + slot.cell.load() > BUDGET_SHARE {
            return Err(slot);
        }
        tracing::info!(
            room = %slot.cell.name,
            cost_us = slot.cell.cost().as_secs_f64() * 1e6,
            thread = index,
            "the room runs within its share again; released from the quarantine"
        );
        slot.cell.end_quarantine(index);
        push(&self.threads[index], slot);
        Ok(())
    }

    /// Whether one more user fits `cell`'s room: its thread's load plus the user's estimate within the share.
    pub fn admit_user(&self, cell: &RoomCell) -> Result<(), OverBudget> {
        if cell.quarantined() {
            return Err(OverBudget {
                what: format!(
                    "room {:?} takes {:.0} µs a tick, over a real-time thread's {:.0} % share; it admits no one",
                    cell.name,
                    cell.cost().as_secs_f64() * 1e6,
                    BUDGET_SHARE * 100.0
                ),
            });
        }
        let per_user = cell.cost() / (cell.users() as u32 + 1);
        let estimate = per_user.max(USER_ESTIMATE).as_secs_f64() * cell.rate_hz;
        let load = self.thread_load(cell.thread());
        if load + estimate > BUDGET_SHARE {
            return Err(OverBudget {
                what: format!(
                    "room {:?}'s real-time thread is {:.0} % busy; a user ({:.1} % estimated) would pass the {:.0} % share",
                    cell.name,
                    load * 100.0,
                    estimate * 100.0,
                    BUDGET_SHARE * 100.0
                ),
            });
        }
        Ok(())
    }

    /// Tells every thread to stop without waiting.
    pub fn shutdown_soon(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// Stops every thread (after the rooms were told to stop) and waits for them.
    pub fn shutdown(&self) {
        self.stop.store(true, Ordering::Release);
        let handles = self.handles.lock().map(|mut h| std::mem::take(&mut *h)).unwrap_or_default();
        for handle in handles {
            let _ = handle.join();
        }
    }
}

impl Drop for Executor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

fn push(end: &ThreadEnd, slot: Slot) {
    if let Ok(mut inbox) = end.inbox.lock() {
        if let Err(rtrb::PushError::Full(slot)) = inbox.push(slot) {
            slot.cell.close("the executor's inbox was full".into());
            slot.cell.mark_done();
        }
    }
}

/// Starts a thread named `name` that runs `body` on the consumer end of its inbox.
fn spawn_thread(
    name: String,
    body: impl FnOnce(Consumer<Slot>) + Send + 'static,
) -> std::io::Result<(Arc<ThreadEnd>, std::thread::JoinHandle<()>)> {
    let (producer, consumer) = RingBuffer::new(INBOX);
    let handle = std::thread::Builder::new().name(name).spawn(move || body(consumer))?;
    Ok((Arc::new(ThreadEnd { inbox: Mutex::new(producer) }), handle))
}

/// The CPU time the calling thread used since `before` (its reading of [`thread_cpu_time`]), and the clock's
/// reading now; without a thread CPU clock, `wall` (the same span's wall time) stands for it. Never more than
/// `wall`: the CPU clock's tick may round a span up past the wall time it took.
fn cpu_since(before: Option<Duration>, wall: Duration) -> (Duration, Option<Duration>) {
    let now = thread_cpu_time();
    let busy = now.zip(before).map_or(wall, |(after, before)| after.saturating_sub(before).min(wall));
    (busy, now)
}

/// The quarantine thread's loop (the rule: `super::quarantine`): take the rooms sent here, step the one furthest behind (its deadline the
/// earliest) one tick, then rest as the budget says; let go of stopped rooms, close one whose tick panics,
/// and hand one that has run calm back to `executor`.
fn run_quarantine(mut inbox: Consumer<Slot>, stop: &AtomicBool, executor: &OnceLock<Weak<Executor>>) {
    let mut slots: Vec<Slot> = Vec::with_capacity(INBOX);
    loop {
        while let Ok(mut slot) = inbox.pop() {
            slot.room.placed(false);
            slot.cell.begin_quarantine();
            slots.push(slot);
        }
        if stop.load(Ordering::Acquire) {
            break;
        }
        let_go_of_stopped(&mut slots);
        let Some(i) = (0..slots.len()).min_by_key(|&i| slots[i].room.next_deadline()) else {
            std::thread::sleep(IDLE);
            continue;
        };
        let deadline = slots[i].room.next_deadline();
        let started = Instant::now();
        if let Some(ahead) = deadline.checked_duration_since(started) {
            // Within real time again: wait for the deadline (a little at a time, to see new rooms and stop).
            std::thread::sleep(ahead.min(IDLE));
            continue;
        }
        let cpu_before = thread_cpu_time();
        let room = &mut slots[i].room;
        let ticked = catch_unwind(AssertUnwindSafe(|| room.tick_behind()));
        let (busy, _) = cpu_since(cpu_before, started.elapsed());
        let users = room.users();
        let cell = slots[i].cell.clone();
        cell.record(busy, users);
        let calm = cell.note_quarantine_tick(busy, started.saturating_duration_since(deadline));
        if let Err(panic) = ticked {
            close_panicked(&mut slots, i, panic);
        } else if calm {
            if let Some(executor) = executor.get().and_then(Weak::upgrade) {
                if let Err(slot) = executor.release(slots.swap_remove(i)) {
                    slot.cell.restart_calm();
                    slots.push(slot);
                }
            }
        }
        std::thread::sleep(quarantine::rest_after(busy, quarantine::QUARANTINE_SHARE));
    }
    finish_all(slots);
}

/// Lets go of the rooms told to stop: their final statistics published, their cells marked done.
fn let_go_of_stopped(slots: &mut Vec<Slot>) {
    let mut i = 0;
    while i < slots.len() {
        if slots[i].room.stopped() {
            let slot = slots.swap_remove(i);
            slot.room.finish();
            slot.cell.mark_done();
        } else {
            i += 1;
        }
    }
}

/// Lets go of every room a stopping thread still holds: their final statistics published, their cells done.
fn finish_all(slots: Vec<Slot>) {
    for slot in slots {
        slot.room.finish();
        slot.cell.mark_done();
    }
}

/// Closes room `i`, whose tick panicked with `panic`: its state is not to be trusted, so it is dropped, not
/// finished, and its users are told why.
fn close_panicked(slots: &mut Vec<Slot>, i: usize, panic: Box<dyn std::any::Any + Send>) {
    let what = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".into());
    let slot = slots.swap_remove(i);
    let cell = slot.cell.clone();
    drop(slot);
    cell.close(format!("the room's simulation failed ({what}); it is closed"));
    cell.mark_done();
}

/// A real-time thread's loop: take new rooms, sleep until the earliest deadline (warming the caches with the
/// room due first just before it: the rooms of a kind share its code), step every room that is due (each
/// inside `catch_unwind`, its cost measured), let go of stopped rooms, send overrunning ones to the
/// `quarantine`; pass the `pulse` every time round. `granted` says whether it runs at real-time priority.
fn run_thread(mut inbox: Consumer<Slot>, stop: &AtomicBool, quarantine: &ThreadEnd, pulse: &Pulse, granted: bool) {
    let mut slots: Vec<Slot> = Vec::with_capacity(INBOX);
    loop {
        while let Ok(mut slot) = inbox.pop() {
            slot.room.placed(granted);
            slots.push(slot);
        }
        if stop.load(Ordering::Acquire) {
            break;
        }
        pulse.pass();
        let_go_of_stopped(&mut slots);
        let first = slots.iter_mut().min_by_key(|s| s.room.next_deadline());
        match first {
            Some(slot) => {
                let deadline = slot.room.next_deadline();
                // A warm-up is a hint: one that panics (in its rehearsal's own VE) leaves the room to its tick.
                wait_warmed(deadline, granted, || {
                    let _ = catch_unwind(AssertUnwindSafe(|| slot.room.warm()));
                });
            }
            None => std::thread::sleep(IDLE),
        }
        let mut i = 0;
        // One CPU clock read per tick: each tick's reading after it is the next one's before it (what lies
        // between, a deadline comparison, is charged to the next tick).
        let mut cpu_mark = thread_cpu_time();
        while i < slots.len() {
            if slots[i].room.next_deadline() > Instant::now() {
                i += 1;
                continue;
            }
            let started = Instant::now();
            let room = &mut slots[i].room;
            let ticked = catch_unwind(AssertUnwindSafe(|| room.tick()));
            let (busy, cpu_now) = cpu_since(cpu_mark, started.elapsed());
            cpu_mark = cpu_now;
            let users = room.users();
            let cell = slots[i].cell.clone();
            cell.record(busy, users);
            match ticked {
                Ok(()) if cell.overruns() => {
                    let slot = slots.swap_remove(i);
                    slot.cell.send_to_quarantine();
                    tracing::warn!(room = %cell.name, cost_us = cell.cost().as_secs_f64() * 1e6, "the room overruns its share; moved to the quarantine thread");
                    push(quarantine, slot);
                }
                Ok(()) => i += 1,
                Err(panic) => close_panicked(&mut slots, i, panic),
            }
        }
    }
    finish_all(slots);
}

#[cfg(test)]
mod tests;
