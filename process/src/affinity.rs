//! Which CPU a thread runs on. A thread that wakes another on a different CPU pays for the interrupt that
//! wakes that CPU (on a virtual machine, an exit to the hypervisor); on the same CPU the wake-up is a run-queue
//! insertion. A real-time loop and the network threads it wakes each round can share a CPU for that.

/// Why the calling thread could not be pinned.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AffinityError {
    /// The platform sets no thread affinity through this call.
    #[error("thread affinity is set through sched_setaffinity, not available on this platform")]
    Unsupported,
    /// The CPU index is beyond the set the platform's call takes.
    #[error("CPU {cpu} is beyond the {max} CPUs a CPU set holds")]
    OutOfRange {
        /// The CPU asked for.
        cpu: usize,
        /// How many a set holds.
        max: usize,
    },
    /// The operating system refused (a CPU outside the process's allowed set, for one).
    #[error("the operating system refused to pin the thread to CPU {cpu}: {why}")]
    Refused {
        /// The CPU asked for.
        cpu: usize,
        /// The OS's reason.
        why: String,
    },
}

/// The index of the last CPU this process may use (by `available_parallelism`, at least 0).
pub fn last_cpu() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get()).saturating_sub(1)
}

/// Pins the calling thread to CPU `cpu`.
pub fn pin_current_thread(cpu: usize) -> Result<(), AffinityError> {
    #[cfg(target_os = "linux")]
    {
        let max = libc::CPU_SETSIZE as usize;
        if cpu >= max {
            return Err(AffinityError::OutOfRange { cpu, max });
        }
        // SAFETY: `set` is a zeroed, valid cpu_set_t; CPU_SET writes inside it (cpu < CPU_SETSIZE);
        // sched_setaffinity reads `size_of` bytes of it for the calling thread (pid 0).
        let rc = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(AffinityError::Refused { cpu, why: std::io::Error::last_os_error().to_string() })
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = cpu;
        Err(AffinityError::Unsupported)
    }
}

/// What a server's network worker asks as it starts: CPU `pin`, if given (beside the real-time thread that
/// wakes it each round), and, when `realtime`, SCHED_FIFO at [`NETWORK_PRIORITY`](crate::realtime::NETWORK_PRIORITY).
/// Either may be refused; the worker then runs where and as the OS lets it (the real-time loops say when they
/// are not granted their own priority).
pub fn start_network_worker(pin: Option<usize>, realtime: bool) {
    if let Some(cpu) = pin {
        drop(pin_current_thread(cpu));
    }
    if realtime {
        drop(crate::realtime::try_fifo_priority(crate::realtime::NETWORK_PRIORITY));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_pinned_to_the_last_cpu_runs_there_and_a_cpu_out_of_range_is_refused() {
        let cpu = last_cpu();
        let ran_on = std::thread::spawn(move || {
            pin_current_thread(cpu).expect("the last CPU is the process's");
            // SAFETY: sched_getcpu takes no arguments and returns the calling thread's CPU or -1.
            unsafe { libc::sched_getcpu() }
        })
        .join()
        .expect("joined");
        assert_eq!(ran_on, cpu as i32);
        assert!(matches!(pin_current_thread(1 << 20), Err(AffinityError::OutOfRange { .. })));
    }
}
