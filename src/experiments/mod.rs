//! The experiments of `kinloop experiment NAME`: each runs the system in virtual time (or benchmarks the
//! linkage), writes SVG and PNG charts and a `summary.json` into `OUT/NAME/`, and returns a [`Report`].
//!
//! | name | question |
//! |---|---|
//! | [`paper`] | do the paper's two manipulations (Figs 6, 7) come out the same? |
//! | [`speed_accuracy`] | which integrator, VE rate, snapshot rate and local-model form buy accuracy cheapest? |
//! | [`stability`] | where do the joint-constraint gains, the haptic rate, Baumgarte and the coupling fail? |
//! | [`latency`] | how much network delay, jitter and loss does the coupling take, with and without passivity control? (`latency-live`: the goal's real-time matrix) |
//! | [`users`] | do 1 to 16 users on one linkage stay stable, and what does each cost the VE? |
//! | [`scale`] | how do VE step, local-model step and snapshot size grow with links and loops? |
//! | [`pauses`] | what does a VE tick cost after the pause a real-time loop takes between ticks? |
//! | [`capacity`] | how many users does one room carry in real time, beside the machine's timer floor? |
//! | [`renderability`] | does every shipped linkage render with default settings, on every device? (`renderability-live`: the same in real time) |
//! | [`renderability_device`] | the same through a vendor's device: the fake DHD library as omega.3 and Falcon (`renderability-dhd`), the fake OpenHaptics library as a Touch (`renderability-hd`), in real processes (not in `all`: they need the fakes) |
//! | [`robustness`] | do generated linkages of every class, in any units, render with default settings under delay? |
//!
//! Every point of a stability question is labelled by the one criterion of [`verdict`]. Sweeps run points
//! on two threads and keep point order ([`common::sweep`]), so results are deterministic; timings are
//! wall-clock and are the only numbers that vary between runs.

pub mod capacity;
pub mod capacity_rooms;
pub mod common;
pub mod delay_point;
pub mod impedance;
pub mod interleave;
pub mod latency;
pub mod latency_live;
pub mod lead;
pub mod model_update;
pub mod paper;
pub mod pauses;
pub mod programs;
pub mod rate_ratio;
pub mod renderability;
pub mod renderability_device;
pub mod robustness;
pub mod robustness_live;
pub mod scale;
pub mod speed_accuracy;
pub mod stability;
pub mod users;
pub mod verdict;

use anyhow::Result;

pub use common::{Options, Report};
use renderability_device::Vendor;

/// An experiment's name, as given on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Name {
    /// The paper's two manipulations (Figs 6, 7).
    Paper,
    /// Accuracy against cost, with the Pareto front.
    SpeedAccuracy,
    /// Stability maps.
    Stability,
    /// Delay, jitter and loss, with and without passivity control.
    Latency,
    /// 1 to 16 users on one linkage.
    Users,
    /// Cost and snapshot size against links and loops.
    Scale,
    /// A tick's cost after a real-time loop's pause.
    Pauses,
    /// Users per room in real time.
    Capacity,
    /// Every shipped linkage with default settings.
    Renderability,
    /// The same in real time over loopback QUIC.
    RenderabilityLive,
    /// The matrix through a DHD device (the fake library), in real server and client processes.
    RenderabilityDhd,
    /// The matrix through an OpenHaptics device (the fake library as a Touch), in real processes.
    RenderabilityHd,
    /// Delay in real time: three scenes x two devices x four delays.
    LatencyLive,
    /// Generated linkages with default settings.
    Robustness,
    /// A sample of them in real processes, beside virtual time.
    RobustnessLive,
}

impl Name {
    /// Every experiment, in the order `all` runs them.
    pub const ALL: [Name; 12] = [
        Name::Paper,
        Name::SpeedAccuracy,
        Name::Stability,
        Name::Latency,
        Name::Users,
        Name::Scale,
        Name::Pauses,
        Name::Capacity,
        Name::Renderability,
        Name::RenderabilityLive,
        Name::LatencyLive,
        Name::Robustness,
    ];

    /// What the experiment answers, in a line (the command line's help).
    pub fn about(self) -> &'static str {
        match self {
            Name::Paper => "the paper's two manipulations (Figs 6, 7)",
            Name::SpeedAccuracy => "accuracy vs cost for integrators, VE rates, snapshot rates and local-model forms",
            Name::Stability => "stability maps: k_j x b_j, haptic rate, Baumgarte alpha x time step, K_g x B_g",
            Name::Latency => "one-way delay, jitter and loss with and without the passivity controller",
            Name::Users => "1 to 16 users on one linkage",
            Name::Scale => "cost and snapshot size against links and loops",
            Name::Pauses => "a VE tick after the pause a real-time loop takes, against back-to-back ticks",
            Name::Capacity => "users per room against the real-time VE step, misses beside the timer floor",
            Name::Renderability => "every scene x OP x device x network x hand with default settings",
            Name::RenderabilityLive => "the renderability matrix in real time over loopback QUIC (about 20 min)",
            Name::RenderabilityDhd => {
                "the renderability matrix through the fake DHD library as omega.3 and Falcon, real processes"
            }
            Name::RenderabilityHd => {
                "the renderability matrix through the fake OpenHaptics library as a Touch, real processes"
            }
            Name::LatencyLive => {
                "3 scenes x 2 devices x 100-1000 ms one way in real time over loopback QUIC (about 5 min)"
            }
            Name::Robustness => "generated linkages (--seeds A..B) x OPs x devices x hands x 0-1000 ms one way",
            Name::RobustnessLive => {
                "generated linkages (--seeds A..B) x OPs x devices x 0-300 ms in real processes, beside virtual time"
            }
        }
    }

    /// Whether `--seconds` sets its sessions' length: the experiments whose sessions are hands touring a
    /// linkage, and `capacity`, whose points count rare deadline misses (a longer point narrows the interval
    /// of its misses against the idle loop's; the others sweep ticks, rates or sizes, whose lengths are part
    /// of what they measure).
    pub fn takes_seconds(self) -> bool {
        matches!(
            self,
            Name::Capacity
                | Name::Latency
                | Name::LatencyLive
                | Name::Renderability
                | Name::RenderabilityLive
                | Name::RenderabilityDhd
                | Name::RenderabilityHd
                | Name::Robustness
                | Name::RobustnessLive
        )
    }

    /// The name on the command line and of the output directory.
    pub fn as_str(self) -> &'static str {
        match self {
            Name::Paper => "paper",
            Name::SpeedAccuracy => "speed-accuracy",
            Name::Stability => "stability",
            Name::Latency => "latency",
            Name::Users => "users",
            Name::Scale => "scale",
            Name::Pauses => "pauses",
            Name::Capacity => "capacity",
            Name::Renderability => "renderability",
            Name::RenderabilityLive => "renderability-live",
            Name::RenderabilityDhd => "renderability-dhd",
            Name::RenderabilityHd => "renderability-hd",
            Name::LatencyLive => "latency-live",
            Name::Robustness => "robustness",
            Name::RobustnessLive => "robustness-live",
        }
    }
}

/// Runs one experiment.
pub fn run(name: Name, options: &Options) -> Result<Report> {
    match name {
        Name::Paper => paper::run(options),
        Name::SpeedAccuracy => speed_accuracy::run(options),
        Name::Stability => stability::run(options),
        Name::Latency => latency::run(options),
        Name::Users => users::run(options),
        Name::Scale => scale::run(options),
        Name::Pauses => pauses::run(options),
        Name::Capacity => capacity::run(options),
        Name::Renderability => renderability::run(options),
        Name::RenderabilityLive => renderability::run_live(options),
        Name::RenderabilityDhd => renderability_device::run(Vendor::Dhd, options),
        Name::RenderabilityHd => renderability_device::run(Vendor::Hd, options),
        Name::LatencyLive => latency_live::run(options),
        Name::Robustness => robustness::run(options),
        Name::RobustnessLive => robustness_live::run(options, None),
    }
}
