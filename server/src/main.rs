//! `kinloop-server`: hosts one linkage for many haptic users over QUIC (see [`kinloop_server::cli`]).

fn main() -> std::process::ExitCode {
    kinloop_server::cli::main(std::env::args_os())
}
