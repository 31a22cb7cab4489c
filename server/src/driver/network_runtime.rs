//! The runtime a server's QUIC side runs on, built one way wherever a server is started (`kinloop-server`,
//! the demo, the capacity experiment): two workers, each asking on start for SCHED_FIFO below the executor's
//! real-time threads and above the machine's other work, and optionally a CPU. At normal priority, a loaded
//! machine leaves them waiting while datagrams pile up in the socket (docs/benchmarks.md, "Rooms per
//! server"), and what a server then measures is its network side starved, not what it carries.

/// Builds the runtime: `realtime` asks SCHED_FIFO at
/// [`NETWORK_PRIORITY`](kinloop_process::realtime::NETWORK_PRIORITY) for each worker, `cpu` pins them.
pub fn network_runtime(name: &str, cpu: Option<usize>, realtime: bool) -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name(name)
        .on_thread_start(move || kinloop_process::affinity::start_network_worker(cpu, realtime))
        .enable_all()
        .build()
}
