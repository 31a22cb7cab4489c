//! What the two real-time loops (the server's VE thread and the client's haptic thread) ask of the operating
//! system, asked the same way by both.

/// Why the calling thread could not be switched to SCHED_FIFO.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RealtimePriorityError {
    /// The platform has no POSIX real-time policies.
    #[error("SCHED_FIFO is a POSIX policy, not available on this platform")]
    NotPosix,
    /// The operating system refused (usually: neither root nor CAP_SYS_NICE, or no real-time budget).
    #[error("the operating system refused SCHED_FIFO (needs root or CAP_SYS_NICE): {0}")]
    Refused(String),
}

/// Priority asked for: high among real-time threads, below the kernel's own (99).
pub const REALTIME_PRIORITY: u8 = 80;

/// Priority asked for the network runtime's workers of a process that runs real-time loops (a server's
/// executor, a load's shared clock): below the loops, so that a loop never waits for them, and above every
/// normal thread, so that on a machine busy with other work the datagrams of a thousand-hertz session are
/// still read and sent every millisecond (tokio's workers park when they have nothing to do).
pub const NETWORK_PRIORITY: u8 = 40;

/// Runs the calling thread under SCHED_FIFO at [`REALTIME_PRIORITY`].
pub fn try_realtime_priority() -> Result<(), RealtimePriorityError> {
    try_fifo_priority(REALTIME_PRIORITY)
}

/// Runs the calling thread under SCHED_FIFO at `priority` (1-99).
pub fn try_fifo_priority(priority: u8) -> Result<(), RealtimePriorityError> {
    #[cfg(unix)]
    {
        use thread_priority::unix::{RealtimeThreadSchedulePolicy, ThreadSchedulePolicy};
        use thread_priority::{ThreadPriority, ThreadPriorityValue};
        let value = ThreadPriorityValue::try_from(priority)
            .map_err(|e| RealtimePriorityError::Refused(format!("priority {priority}: {e:?}")))?;
        set_own_policy(
            ThreadPriority::Crossplatform(value),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
    }
    #[cfg(not(unix))]
    {
        Err(RealtimePriorityError::NotPosix)
    }
}

/// Runs the calling thread under the normal time-sharing policy (SCHED_OTHER). A thread inherits its
/// creator's policy, so a thread meant to yield to the real-time loops (the rooms' quarantine) sets it
/// itself rather than run at SCHED_FIFO because a real-time thread happened to spawn it.
pub fn normal_priority() -> Result<(), RealtimePriorityError> {
    #[cfg(unix)]
    {
        use thread_priority::unix::{NormalThreadSchedulePolicy, ThreadSchedulePolicy};
        set_own_policy(
            thread_priority::ThreadPriority::Min,
            ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other),
        )
    }
    #[cfg(not(unix))]
    {
        Err(RealtimePriorityError::NotPosix)
    }
}

/// Sets the calling thread's scheduling policy and priority; the operating system's refusal, typed.
#[cfg(unix)]
fn set_own_policy(
    priority: thread_priority::ThreadPriority,
    policy: thread_priority::unix::ThreadSchedulePolicy,
) -> Result<(), RealtimePriorityError> {
    use thread_priority::unix::{set_thread_priority_and_policy, thread_native_id};
    set_thread_priority_and_policy(thread_native_id(), priority, policy)
        .map_err(|e| RealtimePriorityError::Refused(format!("{e:?}")))
}

/// Whether the calling thread runs under a real-time policy (SCHED_FIFO or SCHED_RR).
pub fn runs_realtime() -> bool {
    #[cfg(unix)]
    {
        use thread_priority::unix::{thread_schedule_policy, ThreadSchedulePolicy};
        matches!(thread_schedule_policy(), Ok(ThreadSchedulePolicy::Realtime(_)))
    }
    #[cfg(not(unix))]
    {
        false
    }
}

/// Tells the stalls apart among a loop's deadline misses: a host stall makes every tick it spans late, and a
/// loaded loop stays late for as long as it takes to catch up, so misses come in runs; each run is one stall.
/// Stalls, unlike misses, come one at a time, which is what a rate's interval assumes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StallRuns {
    last_missed: bool,
}

impl StallRuns {
    /// Notes whether this wake-up missed its deadline; true when it begins a stall (a miss after an on-time
    /// wake-up, or the first wake-up missing).
    pub fn begins_stall(&mut self, missed: bool) -> bool {
        let begins = missed && !self.last_missed;
        self.last_missed = missed;
        begins
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Granted or refused, the answer is one of the typed ones: when granted, the policy the operating system
    /// reports back for the thread is SCHED_FIFO; a refusal says why.
    #[test]
    fn the_thread_gets_fifo_or_a_reason() {
        std::thread::spawn(|| match try_realtime_priority() {
            Ok(()) => {
                #[cfg(unix)]
                {
                    let policy = thread_priority::unix::thread_schedule_policy().expect("policy");
                    assert_eq!(
                        policy,
                        thread_priority::unix::ThreadSchedulePolicy::Realtime(
                            thread_priority::unix::RealtimeThreadSchedulePolicy::Fifo
                        )
                    );
                }
            }
            Err(RealtimePriorityError::Refused(why)) => assert!(!why.is_empty()),
            Err(RealtimePriorityError::NotPosix) => {
                if cfg!(unix) {
                    panic!("a POSIX platform answered NotPosix")
                }
            }
        })
        .join()
        .expect("the probe thread");
    }

    /// A thread that was raised to SCHED_FIFO goes back to SCHED_OTHER when asked.
    #[cfg(unix)]
    #[test]
    fn a_raised_thread_returns_to_the_normal_policy() {
        use thread_priority::unix::{thread_schedule_policy, NormalThreadSchedulePolicy, ThreadSchedulePolicy};
        std::thread::spawn(|| {
            let raised = try_realtime_priority().is_ok();
            assert_eq!(runs_realtime(), raised);
            normal_priority().expect("a thread may always lower its own policy");
            assert!(!runs_realtime());
            assert_eq!(
                thread_schedule_policy().expect("policy"),
                ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other),
                "raised first: {raised}"
            );
        })
        .join()
        .expect("the probe thread");
    }

    /// A run of late wake-ups is one stall; an on-time one ends it.
    #[test]
    fn runs_of_misses_are_one_stall_each() {
        let mut runs = StallRuns::default();
        let misses = [false, true, true, true, false, true, false, false, true, true];
        let stalls = misses.iter().filter(|m| runs.begins_stall(**m)).count();
        assert_eq!(stalls, 3);
        let mut first = StallRuns::default();
        assert!(first.begins_stall(true), "a first wake-up that misses begins a stall");
    }
}
