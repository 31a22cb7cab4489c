//! The `--record` CSV files, owned in one place: the client's (one row per haptic tick) and the server's (one
//! row per VE step). [`schema`] names their columns and how each is printed, [`write`] is the one writer
//! both drivers use, [`read`] the one reader every tool and test uses.

pub mod axes;
pub mod read;
pub mod rows;
pub mod schema;
pub mod write;

pub use read::{parse, read, ReadError, Recording};
pub use rows::{TickRecord, VeRow, VeUserRow};
pub use schema::{ClientSchema, VeSchema};
pub use write::{RecordError, RecordFile};
