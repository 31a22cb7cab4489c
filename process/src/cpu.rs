//! CPU clocks: the calling thread's (a real-time loop that waits with a hybrid sleep, sleeping then spinning
//! to its deadline, reports it beside its timing, so a figure bought by spinning shows its cost) and the
//! whole process's (a load generator reports it beside what it drove).

use std::time::{Duration, Instant};

/// CPU time the calling thread has used since it started (user and system), or `None` where the platform
/// has no per-thread CPU clock. A system call rather than a vDSO read, an order of magnitude dearer than
/// `Instant::now`: the rooms' executor reads it once per tick, not more.
pub fn thread_cpu_time() -> Option<Duration> {
    #[cfg(unix)]
    {
        cpu_clock(libc::CLOCK_THREAD_CPUTIME_ID)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Spins the calling thread until it has used `cost` of CPU time since `cpu_at_start` (its reading of
/// [`thread_cpu_time`] taken at `wall_at_start`), or, without a thread CPU clock, until `cost` of wall time
/// has passed: a test load that costs what it says on a busy host, where a preempted spin takes longer in
/// wall time rather than less of the CPU.
pub fn spin_until_spent(cpu_at_start: Option<Duration>, wall_at_start: Instant, cost: Duration) {
    let spent = || match (cpu_at_start, thread_cpu_time()) {
        (Some(before), Some(now)) => now.saturating_sub(before),
        _ => wall_at_start.elapsed(),
    };
    while spent() < cost {
        std::hint::spin_loop();
    }
}

/// CPU time every thread of this process has used (user and system), or `None` where the platform has no
/// process CPU clock: what a process that drives many loops costs the machine it shares.
pub fn process_cpu_time() -> Option<Duration> {
    #[cfg(unix)]
    {
        cpu_clock(libc::CLOCK_PROCESS_CPUTIME_ID)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

#[cfg(unix)]
fn cpu_clock(id: libc::clockid_t) -> Option<Duration> {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { libc::clock_gettime(id, &mut t) };
    (rc == 0).then(|| Duration::new(t.tv_sec as u64, t.tv_nsec as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// A thread that spins has used CPU; one that sleeps has used next to none of it while asleep.
    #[cfg(unix)]
    #[test]
    fn spinning_costs_cpu_and_sleeping_does_not() {
        let start = thread_cpu_time().expect("a unix thread has a CPU clock");
        let until = Instant::now() + Duration::from_millis(30);
        while Instant::now() < until {
            std::hint::spin_loop();
        }
        let spun = thread_cpu_time().expect("clock") - start;
        std::thread::sleep(Duration::from_millis(30));
        let slept = thread_cpu_time().expect("clock") - start - spun;
        assert!(spun > Duration::ZERO, "spun {spun:?}");
        assert!(slept < Duration::from_millis(5), "slept {slept:?}");
    }
}
