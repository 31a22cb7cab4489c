//! What can be wrong with bytes from the network, said precisely enough to debug a peer.

use std::fmt;

/// Where in a message a problem sits, e.g. `snapshot.inverse_inertia` or `snapshot.contacts[2].normal`.
/// `Copy` and allocation-free, so rejecting garbage costs no heap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Dotted path of the field, or of the list holding the item.
    pub path: &'static str,
    /// Index into that list and the member of the item, when the field is inside a list.
    pub item: Option<(usize, &'static str)>,
}

impl Field {
    /// A field outside any list.
    pub const fn at(path: &'static str) -> Field {
        Field { path, item: None }
    }
    /// `member` of item `index` of the list at `path`.
    pub const fn in_item(path: &'static str, index: usize, member: &'static str) -> Field {
        Field { path, item: Some((index, member)) }
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.item {
            None => f.write_str(self.path),
            Some((index, member)) => write!(f, "{}[{index}].{member}", self.path),
        }
    }
}

/// `[i]` after a field name when the problem is one element of a vector.
#[derive(Clone, Copy, Debug)]
pub struct ElementSuffix(pub Option<usize>);

impl fmt::Display for ElementSuffix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(i) => write!(f, "[{i}]"),
            None => Ok(()),
        }
    }
}

/// Why received bytes were refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The message is (or claims to contain something) larger than its class allows.
    #[error("message exceeds the {limit}-byte limit")]
    TooLarge {
        /// The limit for this message class.
        limit: usize,
    },
    /// Bytes were left over after a complete message.
    #[error("{extra} trailing bytes after the message")]
    Trailing {
        /// How many.
        extra: usize,
    },
    /// The bytes are not a message at all (truncated, bad enum tag, bad UTF-8...).
    #[error("malformed message: {0}")]
    Malformed(String),
    /// A vector has the wrong length for this session.
    #[error("{field} has {got} values, expected {expected}")]
    WrongLength {
        /// Which field.
        field: Field,
        /// Length received.
        got: usize,
        /// Length the session requires.
        expected: usize,
    },
    /// A list has more entries than allowed.
    #[error("{field} has {got} entries, at most {max} allowed")]
    TooMany {
        /// Which field.
        field: Field,
        /// Entries received.
        got: usize,
        /// The maximum.
        max: usize,
    },
    /// A string is longer than allowed.
    #[error("{field} is {bytes} bytes long, at most {max} allowed")]
    TooLong {
        /// Which field.
        field: Field,
        /// Its length in bytes.
        bytes: usize,
        /// The maximum.
        max: usize,
    },
    /// A NaN or infinity.
    #[error("{field}{} is not finite", ElementSuffix(*index))]
    NonFinite {
        /// Which field.
        field: Field,
        /// Element index when the field is a vector.
        index: Option<usize>,
    },
    /// A finite number outside its sane range.
    #[error("{field}{} = {value} is outside [{min}, {max}]", ElementSuffix(*index))]
    OutOfRange {
        /// Which field.
        field: Field,
        /// Element index when the field is a vector.
        index: Option<usize>,
        /// The value received.
        value: f64,
        /// Lowest allowed.
        min: f64,
        /// Highest allowed.
        max: f64,
    },
    /// A vector that must have unit length does not.
    #[error("{field} must have unit length, has norm {norm}")]
    NotUnit {
        /// Which field.
        field: Field,
        /// Its norm.
        norm: f64,
    },
    /// Fields that must agree with each other do not.
    #[error("{field}: {what}")]
    Inconsistent {
        /// Which field.
        field: Field,
        /// The rule that was broken.
        what: &'static str,
    },
    /// Flag bits this protocol version does not define.
    #[error("uplink.flags has unknown bits {bits:#x}")]
    UnknownFlags {
        /// The unknown bits.
        bits: u32,
    },
}

impl DecodeError {
    /// The field the problem sits in, when it is one field's.
    pub fn field(&self) -> Option<Field> {
        match self {
            DecodeError::WrongLength { field, .. }
            | DecodeError::TooMany { field, .. }
            | DecodeError::TooLong { field, .. }
            | DecodeError::NonFinite { field, .. }
            | DecodeError::OutOfRange { field, .. }
            | DecodeError::NotUnit { field, .. }
            | DecodeError::Inconsistent { field, .. } => Some(*field),
            DecodeError::TooLarge { .. }
            | DecodeError::Trailing { .. }
            | DecodeError::Malformed(_)
            | DecodeError::UnknownFlags { .. } => None,
        }
    }
}

/// Why a message could not be encoded (a local bug, never the peer's fault).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// The encoding exceeds the limit the receiver will apply.
    #[error("message encodes to {len} bytes, over the {limit}-byte limit")]
    TooLarge {
        /// Encoded size.
        len: usize,
        /// The limit for this message class.
        limit: usize,
    },
    /// The serializer failed.
    #[error("cannot encode message: {0}")]
    Serializer(String),
}
