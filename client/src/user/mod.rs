//! Simulated users: what a hand does to the handle. Each computes the hand wrench from the device state and
//! the time (sans-IO); [`crate::device::SimulatedRig`] applies it to a simulated device.
//!
//! On the command line (`--user`):
//! - `soft`, `firm`, `release`, `poke` (default `soft`): a hand that pushes and yields, a mass-spring-damper
//!   grasp on an intended motion, touring the operational point's reach; `KIND:PATH` gives it a scripted
//!   path instead (`soft:circle:0.01,2`), `KIND:hold` holds still. See [`hand`];
//! - `path:...`: the `soft` hand on a scripted path, see [`path`];
//! - `constant:FX,FY,TZ` (planar) or `constant:FX,FY,FZ,TX,TY,TZ` (spatial; forces then torques, world
//!   axes): a constant wrench, which never yields; `paper` is the paper's (section VI:
//!   `constant:-0.5,0,-0.0025` at the testbed's link 2);
//! - `replay:FILE`: a recorded hand wrench replayed against time, see [`replay`].

pub mod constant;
mod error;
pub mod hand;
pub mod path;
pub mod replay;

use std::path::PathBuf;

use kinloop_linkage::math::space::Space;

pub use crate::device::SimulatedUser;

pub use constant::ConstantWrench;
pub(crate) use error::parse_numbers;
pub use error::UserError;
pub use hand::{Hand, HandImpedance, HandKind, HandSpec, Intent, UserContext};
pub use path::PathSpec;
pub use replay::{ReplayError, ReplayedWrench};

/// A user as given on the command line, before the scene's space is known.
#[derive(Clone, Debug, PartialEq)]
pub enum UserSpec {
    /// A constant wrench (components in operational order).
    Constant(Vec<f64>),
    /// A hand.
    Hand(HandSpec),
    /// A wrench replayed from a CSV file.
    Replay(PathBuf),
}

impl std::str::FromStr for UserSpec {
    type Err = UserError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(rest) = s.strip_prefix("constant:") {
            return Ok(UserSpec::Constant(parse_numbers("constant wrench", rest)?));
        }
        if s == "paper" {
            return Ok(UserSpec::paper());
        }
        if let Some(rest) = s.strip_prefix("path:") {
            return Ok(UserSpec::Hand(HandSpec { kind: HandKind::Soft, intent: Intent::Path(rest.parse()?) }));
        }
        let (kind, rest) = s.split_once(':').map_or((s, None), |(k, r)| (k, Some(r)));
        if let Some(kind) = HandKind::parse(kind) {
            let intent = match rest {
                None | Some("tour") => Intent::Tour,
                Some("hold") => Intent::Hold,
                Some(path) => Intent::Path(path.parse()?),
            };
            return Ok(UserSpec::Hand(HandSpec { kind, intent }));
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
        UserSpec::Constant(kinloop_linkage::model::builtin::PAPER_WRENCH.to_vec())
    }

    /// The default user: a relaxed hand touring the operational point's reach.
    pub fn soft_hand() -> Self {
        UserSpec::Hand(HandSpec::touring(HandKind::Soft))
    }

    /// The name as written on the command line (the path, for a hand on one, is summarized).
    pub fn label(&self) -> String {
        match self {
            UserSpec::Constant(values) => {
                format!("constant:{}", values.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(","))
            }
            UserSpec::Hand(HandSpec { kind, intent }) => match intent {
                Intent::Tour => format!("{} (touring the reach)", kind.name()),
                Intent::Hold => format!("{}:hold", kind.name()),
                Intent::Path(_) => format!("{}:path", kind.name()),
            },
            UserSpec::Replay(file) => format!("replay:{}", file.display()),
        }
    }

    /// Builds the user for a scene of space `S` (reads the replay file now, not per tick); a touring hand
    /// tours `context`'s waypoints.
    pub fn build<S: Space>(&self, context: &UserContext<S>) -> Result<Box<dyn SimulatedUser<S>>, UserError> {
        Ok(match self {
            UserSpec::Constant(values) => Box::new(ConstantWrench::<S>::from_values(values)?),
            UserSpec::Hand(spec) => Box::new(Hand::<S>::new(spec, context)?),
            UserSpec::Replay(file) => Box::new(ReplayedWrench::<S>::load(file)?),
        })
    }
}
