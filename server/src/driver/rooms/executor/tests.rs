//! The executor's tests: cost accounting, the grid, and rooms that overrun or are preempted on real threads.

use super::*;

#[test]
fn one_preempted_tick_does_not_put_a_room_over_budget_and_a_slow_room_overruns_within_a_streak() {
    let quiet = RoomCell::new("quiet".into(), 1000.0, Box::new(|_| {}));
    for _ in 0..200 {
        quiet.record(Duration::from_micros(20), 1);
    }
    quiet.record(Duration::from_millis(200), 1);
    assert!(quiet.load() < 0.1, "one 200 ms tick made the room {:.0} % busy", quiet.load() * 100.0);
    assert!(!quiet.overruns(), "one long tick is not a streak");
    quiet.record(Duration::from_millis(2), 1);
    quiet.record(Duration::from_micros(20), 1);
    quiet.record(Duration::from_millis(2), 1);
    assert!(!quiet.overruns(), "long ticks apart are not a streak");
    // What a busy 2-core host does to a calm room now and then: a few ticks of over a millisecond of CPU
    // time back to back.
    for _ in 0..3 {
        quiet.record(Duration::from_micros(1_400), 1);
    }
    assert!(!quiet.overruns(), "three spikes in a row are not a streak");
    let slow = RoomCell::new("slow".into(), 1000.0, Box::new(|_| {}));
    for tick in 0..OVERRUN_STREAK {
        assert!(!slow.overruns(), "{tick} long ticks");
        slow.record(Duration::from_millis(2), 1);
    }
    assert!(slow.overruns(), "a streak of {OVERRUN_STREAK} ticks of 2 ms at 1 kHz");
    assert!(slow.cost() < Duration::from_micros(500), "the average has not caught up: {:?}", slow.cost());
    slow.send_to_quarantine();
    assert!(slow.cost() >= Duration::from_micros(1_999), "a streak of 2 ms ticks reads {:?}", slow.cost());
    for _ in 0..400 {
        slow.record(Duration::from_millis(2), 1);
    }
    assert!(slow.cost() > Duration::from_micros(1900), "a 2 ms room reads {:?}", slow.cost());
    assert!(slow.load() > BUDGET_SHARE);
}

/// Rooms opened at scattered moments start on one grid: their deadlines differ by whole periods.
#[test]
fn rooms_opened_apart_start_on_the_executors_grid() {
    let executor = Executor::start(1, false, None, None).expect("threads");
    let period = Duration::from_millis(1);
    let first = executor.grid_start(period);
    std::thread::sleep(Duration::from_micros(2_300));
    let before = Instant::now();
    let second = executor.grid_start(period);
    assert!(second >= before && second < before + period, "{:?} after now", second.saturating_duration_since(before));
    let apart = second.duration_since(first).as_nanos();
    assert_eq!(apart % period.as_nanos(), 0, "{apart} ns apart");
    assert!(apart >= 2 * period.as_nanos(), "{apart} ns apart");
    executor.shutdown();
}

/// A room whose every tick spins `cost` of CPU (or, `off_cpu`, sleeps it: a thread preempted by another
/// process), down to 20 µs after `cheap_after` ticks in quarantine; it counts, from inside its tick, the CPU
/// time its ticks took and how many it stepped behind real time.
struct Spinner {
    cost: Duration,
    off_cpu: bool,
    cheap_after: Option<u64>,
    epoch: Instant,
    ticks: u64,
    counted: Arc<Counted>,
    stop: Arc<AtomicBool>,
}

impl Steppable for Spinner {
    fn next_deadline(&self) -> Instant {
        self.epoch + Duration::from_millis(self.ticks)
    }
    fn tick(&mut self) {
        let (started, cpu) = (Instant::now(), kinloop_process::cpu::thread_cpu_time());
        if self.off_cpu {
            std::thread::sleep(self.cost);
        } else {
            // CPU time, as the executor charges it: a busy host that preempts the spin lengthens the tick
            // in wall time, not its cost.
            kinloop_process::cpu::spin_until_spent(cpu, started, self.cost);
        }
        self.ticks = (started.duration_since(self.epoch).as_millis() as u64 + 1).max(self.ticks + 1);
        let busy = kinloop_process::cpu::thread_cpu_time().zip(cpu).map_or(Duration::ZERO, |(b, a)| b - a);
        self.counted.0.fetch_add(busy.as_nanos() as u64, Ordering::Relaxed);
    }
    fn tick_behind(&mut self) {
        let before = self.ticks;
        self.tick();
        self.ticks = before + 1;
        let behind = self.counted.1.fetch_add(1, Ordering::Relaxed) + 1;
        if self.cheap_after.is_some_and(|n| behind >= n) {
            self.cost = Duration::from_micros(20);
        }
        if kinloop_process::realtime::runs_realtime() {
            self.counted.2.fetch_add(1, Ordering::Relaxed);
        }
    }
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
    fn users(&self) -> usize {
        1
    }
    fn finish(self: Box<Self>) {}
}

/// What a [`Spinner`] counts: its ticks' CPU time (ns), its ticks in quarantine, and those of them stepped at
/// a real-time priority.
type Counted = (AtomicU64, AtomicU64, AtomicU64);

/// Places a [`Spinner`] of 2 ms a tick at 1 kHz named `name`: its cell, what it counts, and its stop flag.
fn place_spinner(
    executor: &Executor,
    name: &str,
    off_cpu: bool,
    cheap_after: Option<u64>,
) -> (Arc<RoomCell>, Arc<Counted>, Arc<AtomicBool>) {
    let counted = Arc::new((AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)));
    let stop = Arc::new(AtomicBool::new(false));
    let room = Spinner {
        cost: Duration::from_millis(2),
        off_cpu,
        cheap_after,
        epoch: Instant::now(),
        ticks: 0,
        counted: counted.clone(),
        stop: stop.clone(),
    };
    let cell = Arc::new(RoomCell::new(name.into(), 1000.0, Box::new(|_| {})));
    executor.place(Box::new(room), cell.clone()).expect("placed");
    (cell, counted, stop)
}

/// Waits (at most 10 s) until the quarantine has taken `cell`'s room.
fn wait_until_quarantined(cell: &RoomCell) {
    let waited = Instant::now();
    while cell.quarantine_report().is_none() {
        assert!(waited.elapsed() < Duration::from_secs(10), "never quarantined: cost {:?}", cell.cost());
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A room that takes 2 ms a tick at 1 kHz is quarantined, and there its ticks take no more than the
/// quarantine's share of a core: the CPU time the room counts itself, over the time since, stays under the
/// cap, while it goes on stepping (in slow motion, its time one period a tick). The executor is started
/// from a thread at SCHED_FIFO (when granted), as a program that measured its timer floor first would,
/// and the quarantine's ticks still run at normal priority.
#[test]
fn a_room_over_budget_is_quarantined_and_its_cpu_share_stays_under_the_cap() {
    let executor = std::thread::spawn(|| {
        drop(kinloop_process::realtime::try_realtime_priority());
        Executor::start(1, false, None, None)
    })
    .join()
    .expect("the starting thread")
    .expect("threads");
    let (cell, counted, stop) = place_spinner(&executor, "slow", false, None);
    wait_until_quarantined(&cell);
    assert!(cell.quarantined());
    assert!(matches!(executor.admit_user(&cell), Err(OverBudget { .. })), "a quarantined room admits a user");
    let (busy_at, ticks_at, since) =
        (counted.0.load(Ordering::Relaxed), counted.1.load(Ordering::Relaxed), Instant::now());
    std::thread::sleep(Duration::from_millis(1500));
    let busy = Duration::from_nanos(counted.0.load(Ordering::Relaxed) - busy_at);
    let ticks = counted.1.load(Ordering::Relaxed) - ticks_at;
    let wall = since.elapsed();
    let report = cell.quarantine_report().expect("quarantined");
    stop.store(true, Ordering::Relaxed);
    executor.shutdown();
    // One tick may straddle the window's start without its rest inside the window.
    let share = busy.saturating_sub(Duration::from_millis(3)).as_secs_f64() / wall.as_secs_f64();
    println!("{ticks} ticks, busy {busy:?} in {wall:?} (share {share:.3}); report {report:?}");
    assert!(ticks >= 10, "the quarantined room stepped {ticks} ticks");
    assert!(share <= quarantine::QUARANTINE_SHARE, "the quarantined room took {share:.3} of a core");
    assert!(report.share_of_core <= quarantine::QUARANTINE_SHARE + 0.01, "{report:?}");
    assert!(report.slowdown > 1.0, "in slow motion: {report:?}");
    assert!(report.behind_real_time_s > 0.1, "behind real time: {report:?}");
    assert_eq!(counted.2.load(Ordering::Relaxed), 0, "quarantined ticks stepped at a real-time priority");
}

/// A room whose ticks each take 2 ms of wall time at 1 kHz but next to no CPU (its thread off the CPU, as
/// when another process preempts it on a busy host) stays on its real-time thread and admits users: the
/// room is charged the CPU time it used, not its neighbours' work.
#[test]
fn a_room_whose_thread_is_preempted_mid_tick_is_not_quarantined() {
    let executor = Executor::start(1, false, None, None).expect("threads");
    let (cell, _, stop) = place_spinner(&executor, "preempted", true, None);
    std::thread::sleep(Duration::from_millis(300));
    let (quarantined, admitted, cost) = (cell.quarantined(), executor.admit_user(&cell), cell.cost());
    stop.store(true, Ordering::Relaxed);
    executor.shutdown();
    assert!(!quarantined, "a room off the CPU for 2 ms a tick was quarantined: cost {cost:?}");
    assert!(admitted.is_ok(), "{admitted:?}");
    assert!(cost < Duration::from_micros(700), "charged {cost:?} a tick");
}

/// A room quarantined for overrunning that then becomes cheap is released after its calm: it leaves the
/// quarantine (no more slow-motion ticks), goes on ticking on its real-time thread, and admits users again,
/// which it refused while quarantined.
#[test]
fn a_quarantined_room_that_becomes_cheap_again_is_released_and_admits_users() {
    let executor = Executor::start(1, false, None, None).expect("threads");
    let (cell, counted, stop) = place_spinner(&executor, "storm", false, Some(20));
    wait_until_quarantined(&cell);
    let refused = executor.admit_user(&cell);
    let waited = Instant::now();
    while cell.quarantined() && waited.elapsed() < quarantine::CALM_TO_RELEASE * 5 {
        std::thread::sleep(Duration::from_millis(20));
    }
    let released = !cell.quarantined();
    let (behind_at, busy_at) = (counted.1.load(Ordering::Relaxed), counted.0.load(Ordering::Relaxed));
    std::thread::sleep(Duration::from_millis(300));
    let (behind, busy) = (counted.1.load(Ordering::Relaxed), counted.0.load(Ordering::Relaxed));
    let (admitted, report, cost) = (executor.admit_user(&cell), cell.quarantine_report(), cell.cost());
    stop.store(true, Ordering::Relaxed);
    executor.shutdown();
    assert!(matches!(refused, Err(OverBudget { .. })), "a quarantined room admitted a user");
    assert!(released, "still quarantined {:?} after the calm began: cost {cost:?}", quarantine::CALM_TO_RELEASE * 5);
    assert_eq!(behind, behind_at, "slow-motion ticks after the release");
    assert!(busy > busy_at, "no ticks on the real-time thread after the release");
    assert!(admitted.is_ok(), "{admitted:?}");
    assert!(report.is_none(), "a released room reports a quarantine: {report:?}");
    assert_eq!(cell.quarantines(), 1, "the quarantine it was released from is counted");
}
