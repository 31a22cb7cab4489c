//! Many clients' haptic loops on one thread: a [`SharedClock`] steps the loop body ([`LoopBody`]) of every
//! client that joins it, once a period each, in the order they joined, instead of each client running a
//! real-time thread of its own. One process can so hold many real sessions (`kinloop load`, the demo's many
//! users) without as many real-time threads as users competing for the machine with the server they load.
//!
//! Each member's tick is the one its own loop would run (same body, rings, core, device); its lateness is
//! measured from the shared deadline to the moment its own step starts, so a member stepped late in a long
//! round says so. The order within a round is the order of joining: the schedule itself ([`Rota`]) is
//! sans-IO (time comes in as arguments) and tested in virtual time.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;
use kinloop_process::realtime::try_realtime_priority;

use super::rt_loop::{Flow, LoopBody};
use super::timing::LatenessHistogram;
use crate::core::CoreStats;
use crate::device::HapticDevice;

/// One loop body on a shared clock, whatever its space and device.
pub trait Member: Send {
    /// One tick at `now` (time since the member joined).
    fn step(&mut self, now: Duration) -> Flow;
    /// Where the member's lateness is recorded.
    fn lateness(&self) -> &LatenessHistogram;
    /// The loop ended: zero commanded, the counters handed to whoever waits for them.
    fn finish(self: Box<Self>, now: Duration);
}

/// A client's loop body and where its final counters go.
struct Body<S: Space, D: HapticDevice<S>> {
    body: LoopBody<S, D>,
    done: mpsc::SyncSender<CoreStats>,
    finished: Arc<AtomicBool>,
}

impl<S: Space, D: HapticDevice<S>> Member for Body<S, D> {
    fn step(&mut self, now: Duration) -> Flow {
        self.body.step(now)
    }

    fn lateness(&self) -> &LatenessHistogram {
        &self.body.shared().lateness
    }

    fn finish(self: Box<Self>, now: Duration) {
        let Body { body, done, finished } = *self;
        let stats = body.finish(now);
        let _ = done.try_send(stats);
        finished.store(true, Ordering::Release);
    }
}

/// The schedule of a shared clock: which members are stepped at which tick, and how late each was. Sans-IO:
/// the caller reads the clock (time since the rota's start) and sleeps until [`Rota::deadline`].
pub struct Rota {
    members: Vec<(Box<dyn Member>, Duration)>,
    period: Duration,
    tick: u64,
}

impl Rota {
    /// An empty rota ticking at `rate_hz`.
    pub fn new(rate_hz: f64) -> Self {
        Rota { members: Vec::new(), period: Duration::from_secs_f64(1.0 / rate_hz), tick: 0 }
    }

    /// Adds `member`, whose own time starts at `now`; it is stepped from the next round on, after those
    /// already here.
    pub fn join(&mut self, member: Box<dyn Member>, now: Duration) {
        self.members.push((member, now));
    }

    /// Members still running.
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// True when no member runs.
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// When the next round is due (time since the rota's start).
    pub fn deadline(&self) -> Duration {
        self.period * u32::try_from(self.tick).unwrap_or(u32::MAX)
    }

    /// Steps every member once, in the order they joined, reading `clock` before each step (its lateness
    /// is that reading minus the round's deadline); members whose loop ended are finished and leave. Then
    /// moves to the next deadline not already past, skipping missed ones rather than running a burst of
    /// late rounds (as the own-thread loop does).
    pub fn round(&mut self, clock: &mut dyn FnMut() -> Duration) {
        let deadline = self.deadline();
        let mut i = 0;
        while i < self.members.len() {
            let now = clock();
            let (member, joined) = &mut self.members[i];
            member.lateness().record(now.saturating_sub(deadline).as_nanos() as u64);
            match member.step(now.saturating_sub(*joined)) {
                Flow::Continue => i += 1,
                Flow::Stop(why) => {
                    if let Some(e) = why {
                        tracing::error!("{e}; this client's loop stops");
                    }
                    let (member, joined) = self.members.remove(i);
                    member.finish(now.saturating_sub(joined));
                }
            }
        }
        let behind = (clock().as_nanos() / self.period.as_nanos()) as u64;
        self.tick = (self.tick + 1).max(behind);
    }

    /// Ends every member (the clock is going away): each commands zero and hands its counters on.
    pub fn finish_all(&mut self, now: Duration) {
        for (member, joined) in self.members.drain(..) {
            member.finish(now.saturating_sub(joined));
        }
    }
}

/// A thread that steps the haptic loops of the clients given to it; cloned into each client's
/// [`ClientConfig`](super::ClientConfig). Its thread ([`ClockThread`]) ends when every handle is dropped and
/// every member's loop has ended.
#[derive(Clone)]
pub struct SharedClock {
    joins: mpsc::Sender<Box<dyn Member>>,
}

impl std::fmt::Debug for SharedClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SharedClock")
    }
}

/// The thread of a [`SharedClock`].
pub struct ClockThread(JoinHandle<()>);

impl ClockThread {
    /// Waits for the thread: call it once every handle of the clock (and every client holding one) is gone.
    pub fn join(self) {
        let _ = self.0.join();
    }
}

/// What a shared clock calls after each round, once whatever the number of members: the shared network's
/// wake of its uplink pump ([`super::shared_network::SharedNetwork::round_hook`]), so that the uplinks of
/// every member leave with one wake-up rather than one per member.
pub type RoundHook = Box<dyn FnMut() + Send>;

/// How long an idle clock waits for a member before looking again.
const IDLE_WAIT: Duration = Duration::from_millis(20);

impl SharedClock {
    /// Starts the clock's thread at `rate_hz`; with `realtime`, it asks for SCHED_FIFO (one real-time
    /// thread for every member). It sleeps to each deadline without spinning, so its CPU use is its work.
    /// `after_round` is called after each round.
    pub fn start(rate_hz: f64, realtime: bool, after_round: Option<RoundHook>) -> std::io::Result<(Self, ClockThread)> {
        let (joins, arrivals) = mpsc::channel::<Box<dyn Member>>();
        let thread = std::thread::Builder::new()
            .name("kinloop-shared-clock".into())
            .spawn(move || run_clock(rate_hz, realtime, &arrivals, after_round))?;
        Ok((SharedClock { joins }, ClockThread(thread)))
    }

    /// Hands a client's loop body to the clock; what the client keeps to learn when it ended. When the
    /// clock's thread is gone the body is finished at once (zero commanded) and `None` returned.
    pub(super) fn join<S: Space, D: HapticDevice<S> + 'static>(&self, body: LoopBody<S, D>) -> Option<SharedEnd> {
        let (done, stats) = mpsc::sync_channel(1);
        let finished = Arc::new(AtomicBool::new(false));
        let member: Box<dyn Member> = Box::new(Body { body, done, finished: finished.clone() });
        match self.joins.send(member) {
            Ok(()) => Some(SharedEnd { stats, finished }),
            Err(mpsc::SendError(member)) => {
                member.finish(Duration::ZERO);
                None
            }
        }
    }
}

/// The clock's thread: takes members as they come, sleeps to each deadline (no spin), steps a round.
fn run_clock(
    rate_hz: f64,
    realtime: bool,
    arrivals: &mpsc::Receiver<Box<dyn Member>>,
    mut after_round: Option<RoundHook>,
) {
    if realtime {
        if let Err(why) = try_realtime_priority() {
            tracing::warn!(%why, "could not switch the shared haptic clock to SCHED_FIFO");
        }
    }
    let sleeper = spin_sleep::SpinSleeper::new(0);
    let start = Instant::now();
    let mut rota = Rota::new(rate_hz);
    let mut open = true;
    loop {
        loop {
            let arrival = if rota.is_empty() && open {
                arrivals.recv_timeout(IDLE_WAIT).map_err(|e| e == mpsc::RecvTimeoutError::Disconnected)
            } else {
                arrivals.try_recv().map_err(|e| e == mpsc::TryRecvError::Disconnected)
            };
            match arrival {
                Ok(member) => rota.join(member, start.elapsed()),
                Err(disconnected) => {
                    open &= !disconnected;
                    break;
                }
            }
        }
        if rota.is_empty() {
            if open {
                continue;
            }
            break;
        }
        sleeper.sleep_until(start + rota.deadline());
        rota.round(&mut || start.elapsed());
        if let Some(hook) = after_round.as_mut() {
            hook();
        }
    }
    rota.finish_all(start.elapsed());
}

/// Where a client's haptic loop runs: a thread of its own, or a clock shared with other clients.
pub(super) enum LoopEnd {
    Own(JoinHandle<CoreStats>),
    Shared(SharedEnd),
}

impl LoopEnd {
    pub(super) fn is_finished(&self) -> bool {
        match self {
            LoopEnd::Own(thread) => thread.is_finished(),
            LoopEnd::Shared(end) => end.is_finished(),
        }
    }

    /// The loop's last counters, once it has ended (it was asked to stop).
    pub(super) fn join(self) -> Option<CoreStats> {
        match self {
            LoopEnd::Own(thread) => thread.join().ok(),
            LoopEnd::Shared(end) => end.join(),
        }
    }
}

/// What a client on a shared clock keeps of its loop: whether it ended, and its last counters.
pub(super) struct SharedEnd {
    stats: mpsc::Receiver<CoreStats>,
    finished: Arc<AtomicBool>,
}

/// Longest a client waits for the shared clock to end its loop after asking it to stop (one round, unless
/// the clock's thread is gone).
const END_PATIENCE: Duration = Duration::from_secs(5);

impl SharedEnd {
    /// True once the clock has ended this client's loop.
    pub(super) fn is_finished(&self) -> bool {
        self.finished.load(Ordering::Acquire)
    }

    /// The loop's last counters, once the clock has ended it (the caller has asked it to stop).
    pub(super) fn join(self) -> Option<CoreStats> {
        self.stats.recv_timeout(END_PATIENCE).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// A member that notes each step's time and stops after `ticks` steps.
    struct Noted {
        name: char,
        ticks: usize,
        seen: Arc<Mutex<Vec<(char, Duration)>>>,
        lateness: LatenessHistogram,
        ended: Arc<Mutex<Option<Duration>>>,
    }

    impl Member for Noted {
        fn step(&mut self, now: Duration) -> Flow {
            if self.ticks == 0 {
                return Flow::Stop(None);
            }
            self.ticks -= 1;
            self.seen.lock().unwrap().push((self.name, now));
            Flow::Continue
        }
        fn lateness(&self) -> &LatenessHistogram {
            &self.lateness
        }
        fn finish(self: Box<Self>, now: Duration) {
            *self.ended.lock().unwrap() = Some(now);
        }
    }

    fn noted(
        name: char,
        ticks: usize,
        seen: &Arc<Mutex<Vec<(char, Duration)>>>,
    ) -> (Box<Noted>, Arc<Mutex<Option<Duration>>>) {
        let ended = Arc::new(Mutex::new(None));
        let member =
            Noted { name, ticks, seen: seen.clone(), lateness: LatenessHistogram::default(), ended: ended.clone() };
        (Box::new(member), ended)
    }

    const MS: Duration = Duration::from_millis(1);
    const US: Duration = Duration::from_micros(1);

    /// Every member is stepped once a round in the order it joined, with its own time since joining; one that
    /// stops leaves and is finished, the others go on; a round that runs past deadlines skips them.
    #[test]
    fn members_step_in_turn_on_their_own_time_and_leave_when_done() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut rota = Rota::new(1000.0);
        let (a, a_ended) = noted('a', 2, &seen);
        let (b, b_ended) = noted('b', 10, &seen);
        rota.join(a, Duration::ZERO);
        rota.join(b, 3 * US);
        // Virtual clock: each reading is 10 µs after the last, from the round's deadline.
        for round in 0..3u32 {
            let mut t = rota.deadline();
            assert_eq!(t, MS * round, "round {round} is due on its tick");
            rota.round(&mut || {
                t += 10 * US;
                t
            });
        }
        let seen = seen.lock().unwrap().clone();
        let expected = vec![
            ('a', 10 * US),
            ('b', 20 * US - 3 * US),
            ('a', MS + 10 * US),
            ('b', MS + 20 * US - 3 * US),
            ('b', 2 * MS + 20 * US - 3 * US),
        ];
        assert_eq!(seen, expected);
        assert_eq!(rota.len(), 1, "a stopped after its two ticks");
        assert_eq!(*a_ended.lock().unwrap(), Some(2 * MS + 10 * US), "a was finished on its own time");
        assert_eq!(*b_ended.lock().unwrap(), None);
        // A round that overruns six periods (its step at 6.1 ms, done at 9.2 ms) is followed by one round
        // at once, not by the six it missed.
        let mut t = rota.deadline();
        rota.round(&mut || {
            t += 3 * MS + 100 * US;
            t
        });
        assert_eq!(rota.deadline(), 9 * MS, "the missed deadlines were skipped");
        rota.finish_all(7 * MS);
        assert_eq!(*b_ended.lock().unwrap(), Some(7 * MS - 3 * US));
        assert!(rota.is_empty());
    }

    /// Each member's lateness is how long after the round's deadline its own step began: the last in a long
    /// round is the latest.
    #[test]
    fn the_round_hook_runs_once_a_round_whatever_the_members() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let (joins, arrivals) = mpsc::channel::<Box<dyn Member>>();
        for name in ['a', 'b', 'c'] {
            joins.send(noted(name, 5, &seen).0).unwrap();
        }
        drop(joins);
        let rounds = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let counted = rounds.clone();
        let hook: RoundHook = Box::new(move || {
            counted.fetch_add(1, Ordering::Relaxed);
        });
        run_clock(10_000.0, false, &arrivals, Some(hook));
        assert_eq!(seen.lock().unwrap().len(), 15, "every member stepped its 5 ticks");
        // Five rounds that step the three members, and the sixth in which they stop.
        assert_eq!(rounds.load(Ordering::Relaxed), 6);
    }

    #[test]
    fn lateness_is_measured_per_member_from_the_rounds_deadline() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut rota = Rota::new(1000.0);
        let (a, _) = noted('a', 5, &seen);
        let (b, _) = noted('b', 5, &seen);
        rota.join(a, Duration::ZERO);
        rota.join(b, Duration::ZERO);
        let mut t = rota.deadline();
        rota.round(&mut || {
            t += 300 * US;
            t
        });
        let summaries: Vec<_> = rota.members.iter().map(|(m, _)| m.lateness().summary()).collect();
        assert_eq!(summaries[0].ticks, 1);
        assert!((summaries[0].max_us - 300.0).abs() < 1.0, "{:?}", summaries[0]);
        assert!((summaries[1].max_us - 600.0).abs() < 1.0, "{:?}", summaries[1]);
        assert_eq!(summaries[1].misses, 1, "600 µs after the deadline is a miss");
        assert_eq!(summaries[0].misses, 0);
    }
}
