//! Names of operational axes, shared by the CSV recorder and the replay user so a recording replays as is
//! (the record crate owns them, with the rest of the record's columns).

pub use kinloop_record::axes::{pose_names, wrench_names};
