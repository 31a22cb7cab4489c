//! kinloop-process: what kinloop's programs ask of the process they run in, below the server and the
//! client (both use it; it uses no other kinloop crate).
//!
//! - [`report`]: how the programs set up their logs and print an error (one line, each cause once);
//! - [`realtime`]: what the server's and the client's real-time loops ask of the operating system;
//! - [`cpu`]: the CPU time a thread has used, for loops that report what their waiting costs;
//! - [`affinity`]: pinning a thread to a CPU (a loop and the threads it wakes on one CPU).

pub mod affinity;
pub mod cpu;
pub mod realtime;
pub mod report;
