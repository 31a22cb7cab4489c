//! What goes wrong reading a `--user` value, and the number lists it is made of.

use super::replay::ReplayError;

/// A `--user` value that does not parse, or does not fit the scene.
#[derive(Debug, thiserror::Error)]
pub enum UserError {
    /// Unknown kind of user.
    #[error("unknown user {0:?}; expected soft|firm|release|poke[:PATH|:hold], path:line|circle|waypoints:..., constant:FX,FY,TZ (spatial: FX,FY,FZ,TX,TY,TZ), paper, or replay:FILE")]
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
