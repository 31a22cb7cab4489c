//! `kinloop`: run the demo; inspect, simulate and benchmark linkages with kinematic loops; run experiments;
//! replay recordings in a web page.

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};
use kinloop::cli;

#[derive(Parser, Debug)]
#[command(name = "kinloop", version, about = "Feel virtual linkages with kinematic loops through haptic devices")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The whole system in one process: a VE server and N simulated-device clients over loopback QUIC, in
    /// real time for a few seconds; prints a summary and writes the paper's charts into DIR/demo/.
    #[command(
        after_help = "Both the server and every client apply the link options to what they send (each side with its \
                            own seed derived from --seed), so --delay 20ms makes a 40 ms round trip. Ctrl-C stops early and \
                            still writes the summary and charts."
    )]
    Demo(cli::demo::DemoArgs),
    /// N real client sessions from this process, their haptic loops stepped in turn on one clock thread
    /// (not a real-time thread each), so a server's capacity is measured with its clients off its critical
    /// path; prints each user's lateness, device-local-model RMS, clamped share and uplink loss.
    Load(cli::load::LoadArgs),
    /// Everything the dynamics core knows at one configuration: q̈, λ, Λ⁻¹, its SVD, the constraint count.
    Inspect(cli::inspect::InspectArgs),
    /// Integrate a scene and report closure error, energy error and cost per step.
    Simulate(cli::simulate::SimulateArgs),
    /// The benchmark suite (median ns per call).
    Bench(cli::bench::BenchArgs),
    /// Run an experiment: charts (SVG, PNG) and summary.json in DIR/NAME/.
    Experiment(cli::experiment::ExperimentArgs),
    /// Time an idle 1 kHz loop as the haptic loop times itself: the floor this machine puts under real time.
    ///
    /// Times a loop that does nothing, exactly as the haptic loop times itself (absolute deadlines,
    /// spin_sleep, SCHED_FIFO when permitted), and reports how late its ticks came and how many deadlines it
    /// missed. Run it before trusting real-time figures on a machine: a loop that misses more deadlines than
    /// this floor has a problem of its own; one at the floor is limited by the machine (kernel, hypervisor,
    /// neighbours).
    TimerFloor(cli::timer_floor::TimerFloorArgs),
    /// Write the seeded, reproducible linkage of a seed as a scene file (any class, any unit system).
    Generate(cli::generate::GenerateArgs),
    /// An MJCF model (MuJoCo XML) as a kinloop scene file; what kinloop cannot use is listed in one warning.
    Import(cli::import::ImportArgs),
    /// A scene as an MJCF model (MuJoCo XML) MuJoCo loads and simulates; what it cannot carry is one warning.
    Export(cli::export::ExportArgs),
    /// The haptic devices kinloop can drive here: vendor libraries found (or where it looked), each device's
    /// model and spec; --check reads positions for a second with forces off.
    Devices(cli::devices::DevicesArgs),
    /// Replay a recording (a server's or a client's --record CSV) in a web page with a timeline slider.
    View(cli::view::ViewArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Errors only unless RUST_LOG asks for more; a failure on one line, as kinloop-server and kinloop-client say it.
    kinloop_process::report::run_program("error", || run(&cli))
}

fn run(cli: &Cli) -> Result<()> {
    match &cli.command {
        Command::Demo(a) => cli::demo::run(a),
        Command::Load(a) => cli::load::run(a),
        Command::Inspect(a) => cli::inspect::run(a),
        Command::Simulate(a) => cli::simulate::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Experiment(a) => cli::experiment::run(a),
        Command::TimerFloor(a) => cli::timer_floor::run(a),
        Command::View(a) => cli::view::run(a),
        Command::Generate(a) => cli::generate::run(a),
        Command::Import(a) => cli::import::run(a),
        Command::Export(a) => cli::export::run(a),
        Command::Devices(a) => cli::devices::run(a),
    }
}
