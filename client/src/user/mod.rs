//! Simulated users: what a hand does to the handle. Each computes the hand wrench from the device state and
//! the time (sans-IO); [`crate::device::SimulatedRig`] applies it to a simulated device.
//!
//! On the command line (`--user`):
//! - `constant:FX,FY,TZ` (planar) or `constant:FX,FY,FZ,TX,TY,TZ` (spatial): the paper's user, a constant
//!   wrench in world axes (section VI: `constant:-0.5,0,-0.0025`);
//! - `path:...`: a spring-damper hand whose set-point follows a scripted path, see [`path`];
//! - `replay:FILE`: a recorded hand wrench replayed against time, see [`replay`].

pub mod constant;
pub mod path;
pub mod replay;

use std::path::PathBuf;
use std::time::Duration;

use kinloop_linkage::space::Space;

use crate::device::DeviceState;

pub use constant::ConstantWrench;
pub use path::{HandImpedance, PathFollower, PathSpec};
pub use replay::{ReplayError, ReplayedWrench};

/// A simulated hand.
pub trait SimulatedUser<S: Space>: Send {
    /// The wrench the hand applies to the handle at `now`, given what the device reads.
    fn wrench(&mut self, now: Duration, device: &DeviceState<S>) -> S::OpVec;
}

/// A user as given on the command line, before the scene's space is known.
#[derive(Clone, Debug, PartialEq)]
pub enum UserSpec {
    /// A constant wrench (components in operational order).
    Constant(Vec<f64>),
    /// A spring-damper hand on a path.
    Path(PathSpec),
    /// A wrench replayed from a CSV file.
    Replay(PathBuf),
}

/// A `--user` value that does not parse, or does not fit the scene.
#[derive(Debug, thiserror::Error)]
pub enum UserError {
    /// Unknown kind of user.
    #[error("unknown user {0:?}; expected constant:FX,FY,TZ, path:line|circle|waypoints:..., or replay:FILE")]
    Unknown(String),
    /// A number list that does not parse.
    #[error("{what}: {input:?} is not a comma-separated list of numbers")]
    Numbers {
        /// Which part.
        what: &'static str,
        /// The text.
        input: String,
    },
    /// Wrong number of values.
    #[error("{what} needs {expected} values, got {got}")]
    Count {
        /// Which part.
        what: &'static str,
        /// How many are needed.
        expected: String,
        /// How many were given.
        got: usize,
    },
    /// A path that makes no sense (non-positive duration...).
    #[error("path: {0}")]
    Path(String),
    /// The replay file.
    #[error(transparent)]
    Replay(#[from] ReplayError),
}

/// Parses a comma-separated list of finite numbers.
pub(crate) fn parse_numbers(what: &'static str, s: &str) -> Result<Vec<f64>, UserError> {
    s.split(',')
        .map(|t| t.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| UserError::Numbers { what, input: s.to_owned() })
}

impl std::str::FromStr for UserSpec {
    type Err = UserError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(rest) = s.strip_prefix("constant:") {
            return Ok(UserSpec::Constant(parse_numbers("constant wrench", rest)?));
        }
        if let Some(rest) = s.strip_prefix("path:") {
            return Ok(UserSpec::Path(rest.parse()?));
        }
        if let Some(rest) = s.strip_prefix("replay:") {
            if rest.is_empty() {
                return Err(UserError::Unknown(s.to_owned()));
            }
            return Ok(UserSpec::Replay(PathBuf::from(rest)));
        }
        Err(UserError::Unknown(s.to_owned()))
    }
}

impl UserSpec {
    /// The paper's user: `(−0.5 N, 0 N, −0.0025 N m)`.
    pub fn paper() -> Self {
        UserSpec::Constant(kinloop_linkage::builtin::PAPER_WRENCH.to_vec())
    }

    /// Builds the user for a scene of space `S` (reads the replay file now, not per tick).
    pub fn build<S: Space>(&self) -> Result<Box<dyn SimulatedUser<S>>, UserError> {
        Ok(match self {
            UserSpec::Constant(values) => Box::new(ConstantWrench::<S>::from_values(values)?),
            UserSpec::Path(spec) => Box::new(PathFollower::<S>::new(spec.clone(), HandImpedance::default())?),
            UserSpec::Replay(file) => Box::new(ReplayedWrench::<S>::load(file)?),
        })
    }
}
