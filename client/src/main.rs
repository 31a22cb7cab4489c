//! `kinloop-client`: feel a kinloop server's linkage through a (simulated) haptic device (see [`kinloop_client::cli`]).

fn main() -> std::process::ExitCode {
    kinloop_client::cli::main(std::env::args_os())
}
