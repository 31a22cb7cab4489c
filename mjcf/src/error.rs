//! Typed errors of the MJCF reader and writer: each names the file and, where the model has one, the line.

use thiserror::Error;

/// What went wrong reading or writing an MJCF model.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum MjcfError {
    /// A file could not be read or written.
    #[error("{file}: cannot read: {message}")]
    Io {
        /// The file.
        file: String,
        /// The operating system's message.
        message: String,
    },
    /// The text is not well-formed XML (the parser's message carries the line and column).
    #[error("{file}:{line}: not well-formed XML: {message}")]
    Xml {
        /// The file.
        file: String,
        /// The line of the fault.
        line: u32,
        /// The parser's message.
        message: String,
    },
    /// An element or attribute that is well-formed XML but not a model kinloop can build.
    #[error("{file}:{line}: <{element}>: {problem}")]
    Invalid {
        /// The file the element is in.
        file: String,
        /// The element's line.
        line: u32,
        /// The element's tag (and name when it has one).
        element: String,
        /// What is wrong.
        problem: String,
    },
    /// The model was read, but the scene made from it does not compile (the scene's own error, which names
    /// the item by the model's names).
    #[error("{file}: the scene made from this model does not compile: {message}")]
    Scene {
        /// The model file.
        file: String,
        /// The scene compiler's message.
        message: String,
    },
}
