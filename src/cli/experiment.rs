//! `kinloop experiment NAME [--out DIR] [--quick]`: runs one experiment (or `all`), writing its charts and
//! `summary.json` into `DIR/NAME/`, and prints where they went and the headline answer.

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

const WHICH: [Which; 11] = [
    Which::One(Name::Paper),
    Which::One(Name::SpeedAccuracy),
    Which::One(Name::Stability),
    Which::One(Name::Latency),
    Which::One(Name::Users),
    Which::One(Name::Scale),
    Which::One(Name::Pauses),
    Which::One(Name::Renderability),
    Which::One(Name::RenderabilityLive),
    Which::One(Name::LatencyLive),
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
    /// The small grids (each experiment under a minute on two cores).
    #[arg(long)]
    pub quick: bool,
    /// Worker threads that run a sweep's independent sessions side by side (1-64); the results are the same
    /// for any number, only the time to get them changes.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

/// Runs `kinloop experiment`.
pub fn run(args: &ExperimentArgs) -> Result<()> {
    ensure!((1..=64).contains(&args.threads), "--threads: must be between 1 and 64, got {}", args.threads);
    if args.out.exists() {
        ensure!(args.out.is_dir(), "--out: {} exists and is not a directory", args.out.display());
    }
    let options = Options { out: args.out.clone(), quick: args.quick, progress: true, threads: args.threads };
    let names: Vec<Name> = match args.name {
        Which::One(name) => vec![name],
        Which::All => Name::ALL.to_vec(),
    };
    for name in names {
        eprintln!("experiment {}{} ...", name.as_str(), if args.quick { " (quick)" } else { "" });
        let report = experiments::run(name, &options)?;
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
