//! `kinloop experiment NAME [--out DIR] [--quick] [--threads N] [--seconds S]`: runs one experiment (or
//! `all`), writing its charts and `summary.json` into `DIR/NAME/`, and prints where they went and the
//! headline answer.

use std::path::PathBuf;

use anyhow::{ensure, Result};

use crate::experiments::{self, Name, Options};

/// What to run: one experiment or all of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Which {
    /// One experiment.
    One(Name),
    /// Every experiment, one after the other.
    All,
}

const WHICH: [Which; 16] = [
    Which::One(Name::Paper),
    Which::One(Name::SpeedAccuracy),
    Which::One(Name::Stability),
    Which::One(Name::Latency),
    Which::One(Name::Users),
    Which::One(Name::Scale),
    Which::One(Name::Pauses),
    Which::One(Name::Capacity),
    Which::One(Name::Renderability),
    Which::One(Name::RenderabilityLive),
    Which::One(Name::RenderabilityDhd),
    Which::One(Name::RenderabilityHd),
    Which::One(Name::LatencyLive),
    Which::One(Name::Robustness),
    Which::One(Name::RobustnessLive),
    Which::All,
];

impl clap::ValueEnum for Which {
    fn value_variants<'a>() -> &'a [Self] {
        &WHICH
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(match self {
            Which::One(name) => clap::builder::PossibleValue::new(name.as_str()).help(name.about()),
            Which::All => clap::builder::PossibleValue::new("all").help("every experiment, one after the other"),
        })
    }
}

/// Arguments of `kinloop experiment`.
#[derive(clap::Args, Debug)]
pub struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    pub name: Which,
    /// Results go to DIR/NAME/.
    #[arg(long, default_value = "results", value_name = "DIR")]
    pub out: PathBuf,
    /// The small grids (fewer, shorter sessions).
    #[arg(long)]
    pub quick: bool,
    /// Worker threads that run a sweep's independent sessions side by side (1-64); the results are the same
    /// for any number, only the time to get them changes.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Seconds per session instead of the experiment's own (latency 10, renderability 40, the live ones 10
    /// and 4): e.g. `latency --seconds 40` judges every point over its hand's whole tour. The touring
    /// experiments take it, and `capacity` as each point's length (a longer point counts more of the rare
    /// deadline misses, so its ratio to the idle loop's is decided more often).
    #[arg(long, value_name = "S")]
    pub seconds: Option<f64>,
    /// The generator seeds `robustness` and `robustness-live` run, a half-open range `A..B` (default the fixed CI
    /// sample).
    #[arg(long, value_name = "A..B", value_parser = parse_seeds)]
    pub seeds: Option<std::ops::Range<u64>>,
}

/// Parses `A..B` (A < B) into the seeds A to B-1.
fn parse_seeds(text: &str) -> Result<std::ops::Range<u64>, String> {
    let (a, b) = text.split_once("..").ok_or_else(|| format!("expected A..B (e.g. 1..101), got {text:?}"))?;
    let number = |s: &str| s.trim().parse::<u64>().map_err(|e| format!("{s:?} in {text:?}: {e}"));
    let (a, b) = (number(a)?, number(b)?);
    if a >= b {
        return Err(format!("{text:?} holds no seed (A must be below B)"));
    }
    Ok(a..b)
}

/// Longest session `--seconds` accepts (the latency grid's 864 points at this length are hours of simulation).
const MAX_SESSION_SECONDS: f64 = 600.0;

/// Refuses a `--seconds` that is not a length or that the experiment(s) would ignore.
fn check_seconds(seconds: Option<f64>, names: &[Name]) -> Result<()> {
    let Some(seconds) = seconds else { return Ok(()) };
    ensure!(
        seconds.is_finite() && seconds > 0.0 && seconds <= MAX_SESSION_SECONDS,
        "--seconds: must be in (0, {MAX_SESSION_SECONDS}] s per session, got {seconds}"
    );
    if let Some(name) = names.iter().find(|n| !n.takes_seconds()) {
        let takers: Vec<&str> = Name::ALL.iter().filter(|n| n.takes_seconds()).map(|n| n.as_str()).collect();
        anyhow::bail!(
            "--seconds: experiment {} has no session length to set (only {} take it)",
            name.as_str(),
            takers.join(", ")
        );
    }
    Ok(())
}

/// Runs `kinloop experiment`.
pub fn run(args: &ExperimentArgs) -> Result<()> {
    ensure!((1..=64).contains(&args.threads), "--threads: must be between 1 and 64, got {}", args.threads);
    if args.out.exists() {
        ensure!(args.out.is_dir(), "--out: {} exists and is not a directory", args.out.display());
    }
    let names: Vec<Name> = match args.name {
        Which::One(name) => vec![name],
        Which::All => Name::ALL.to_vec(),
    };
    check_seconds(args.seconds, &names)?;
    let options = Options {
        out: args.out.clone(),
        quick: args.quick,
        progress: true,
        threads: args.threads,
        seconds: args.seconds,
    };
    for name in names {
        eprintln!("experiment {}{} ...", name.as_str(), if args.quick { " (quick)" } else { "" });
        let report = match (name, &args.seeds) {
            (Name::Robustness, Some(seeds)) => experiments::robustness::run_seeds(&options, seeds.clone())?,
            (Name::RobustnessLive, seeds) => experiments::robustness_live::run(&options, seeds.clone())?,
            _ => experiments::run(name, &options)?,
        };
        println!(
            "{}: {} files in {} ({:.1} s)",
            report.name,
            report.files.len(),
            report.dir.display(),
            report.runtime_s
        );
        if let Some(answer) = report.summary["results"]["answer"].as_str() {
            println!("  {answer}");
        }
    }
    Ok(())
}
