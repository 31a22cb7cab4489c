//! `kinloop`: run the demo; inspect, simulate and benchmark linkages with kinematic loops; run experiments;
//! replay recordings in a web page.

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
    /// Everything the dynamics core knows at one configuration: q̈, λ, Λ⁻¹, its SVD, the constraint count.
    Inspect(cli::inspect::InspectArgs),
    /// Integrate a scene and report closure error, energy error and cost per step.
    Simulate(cli::simulate::SimulateArgs),
    /// The benchmark suite (median ns per call).
    Bench(cli::bench::BenchArgs),
    /// Run an experiment: charts (SVG, PNG) and summary.json in DIR/NAME/.
    Experiment(cli::experiment::ExperimentArgs),
    /// The lateness of an idle 1 kHz loop timed as the haptic loop is: the machine's floor under real time.
    TimerFloor(cli::timer_floor::TimerFloorArgs),
    /// Replay a recording (a server's or a client's --record CSV) in a web page with a timeline slider.
    View(cli::view::ViewArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    match &cli.command {
        Command::Demo(a) => cli::demo::run(a),
        Command::Inspect(a) => cli::inspect::run(a),
        Command::Simulate(a) => cli::simulate::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Experiment(a) => cli::experiment::run(a),
        Command::TimerFloor(a) => cli::timer_floor::run(a),
        Command::View(a) => cli::view::run(a),
    }
}
