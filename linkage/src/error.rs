//! Typed errors. Scene errors name the file and the key; dynamics errors say what went wrong and where.

use thiserror::Error;

/// Something wrong with a scene: each variant names the file and the key at fault.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: cannot read: {message}")]
    Io {
        /// The file.
        file: String,
        /// The operating system's message.
        message: String,
    },
    /// The file is not valid TOML or does not fit the scene format.
    #[error("{file}: {message}")]
    Syntax {
        /// The file.
        file: String,
        /// The parser's message (with line and column).
        message: String,
    },
    /// A value is out of range, of the wrong length, or not finite.
    #[error("{file}: {key}: {problem}")]
    Invalid {
        /// The file.
        file: String,
        /// The key, e.g. `body[2] (link3).mass`.
        key: String,
        /// What is wrong.
        problem: String,
    },
    /// A reference to a body (or other item) that does not exist.
    #[error("{file}: {key}: unknown {what} '{name}' (known: {known})")]
    UnknownName {
        /// The file.
        file: String,
        /// The key holding the name.
        key: String,
        /// What kind of item was looked up.
        what: &'static str,
        /// The name given.
        name: String,
        /// The names that exist.
        known: String,
    },
    /// Two items share a name.
    #[error("{file}: {key}: duplicate name '{name}'")]
    Duplicate {
        /// The file.
        file: String,
        /// The key of the second occurrence.
        key: String,
        /// The repeated name.
        name: String,
    },
    /// The tree joints form a cycle instead of a tree rooted at ground.
    #[error("{file}: {key}: the joints form a cycle through body '{body}'; loops must be closed with [[cut]] joints")]
    Cycle {
        /// The file.
        file: String,
        /// The key of a joint on the cycle.
        key: String,
        /// A body on the cycle.
        body: String,
    },
    /// A cut joint is not closed at q0.
    #[error(
        "{file}: {key}: loop '{cut}' is not closed at q0: residual {residual:.3e} exceeds tolerance {tolerance:.1e}; \
         `kinloop inspect --assemble` finds the nearest closed configuration"
    )]
    NotClosed {
        /// The file.
        file: String,
        /// The key of the cut joint.
        key: String,
        /// The cut joint's name.
        cut: String,
        /// Norm of the closure residual (lengths in scene units, angles in length-scale units).
        residual: f64,
        /// The tolerance that was exceeded.
        tolerance: f64,
    },
}

/// A failure while computing dynamics.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum DynamicsError {
    /// An input (state, force) was not finite.
    #[error("non-finite {what} at index {index}")]
    NonFiniteInput {
        /// Which input.
        what: &'static str,
        /// Its first non-finite component.
        index: usize,
    },
    /// An input had the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    WrongLength {
        /// Which input.
        what: &'static str,
        /// Length given.
        got: usize,
        /// Length expected.
        expected: usize,
    },
    /// The mass matrix was not positive definite (a zero pivot at this joint).
    #[error("mass matrix not positive definite at joint {joint} (pivot {pivot:.3e})")]
    MassNotPositive {
        /// Joint index.
        joint: usize,
        /// The offending pivot.
        pivot: f64,
    },
    /// The result was not finite (the state diverged).
    #[error("the solution is not finite ({what})")]
    NonFiniteResult {
        /// Which result.
        what: &'static str,
    },
    /// The loop closure residual exceeded what a closed linkage can show (the state is tearing apart).
    #[error("the loops are torn open: closure residual {residual:.3e} m over the limit {limit:.3e} m")]
    ClosureBroken {
        /// Residual norm ‖h‖, m.
        residual: f64,
        /// The limit it exceeded, m.
        limit: f64,
    },
    /// An operational point index that does not exist.
    #[error("operational point {index} does not exist (the model has {count})")]
    UnknownOp {
        /// Requested index.
        index: usize,
        /// Number of operational points.
        count: usize,
    },
}
