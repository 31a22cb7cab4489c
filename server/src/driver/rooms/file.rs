//! The rooms file (`--rooms rooms.toml`): one `[[room]]` table per hosted linkage.
//!
//! ```toml
//! [[room]]
//! name = "bench-a"            # unique; clients pick it with --room
//! scene = "paper-testbed"     # scene file (relative to this file) or built-in name
//! token_file = "a.tokens"     # optional; without it the room takes any token
//! max_users = 4               # optional (default 16)
//! record = "bench-a.csv"      # optional: one CSV row per VE step
//! debug_cost_ms = 2.0         # test knob: each tick takes this much CPU time
//! debug_panic_after_ticks = 0 # test knob: the VE panics at this tick
//! ```
//! Each entry is checked at start: a scene that does not load, a name used twice or a token file that
//! cannot be read is refused naming the file, the room and the key.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

use kinloop_linkage::model::scene::Scene;
use serde::Deserialize;

use crate::access::Access;

/// One room as the file (or an admin command) gives it, checked and loaded.
#[derive(Clone, Debug)]
pub struct RoomSpec {
    /// Unique name.
    pub name: String,
    /// The linkage.
    pub scene: Scene,
    /// Where the scene came from, for messages.
    pub scene_label: String,
    /// Who may join.
    pub access: Access,
    /// Most users at once.
    pub max_users: usize,
    /// CSV file for one row per VE step.
    pub record: Option<PathBuf>,
    /// Test knobs (never set in production files).
    pub knobs: TestKnobs,
}

/// Test knobs: make one room overrun or fail, to show the others do not.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TestKnobs {
    /// Each tick takes at least this much CPU time.
    pub cost: Option<Duration>,
    /// The VE panics at this tick.
    pub panic_after_ticks: Option<u64>,
}

/// A rooms file that cannot be used, naming the file, the room and the key.
#[derive(Debug, thiserror::Error)]
pub enum RoomsFileError {
    /// The file could not be read.
    #[error("cannot read rooms file {file}: {message}")]
    Read {
        /// The file.
        file: String,
        /// Why.
        message: String,
    },
    /// The file is not TOML of the expected shape (an unknown key, a missing name...).
    #[error("rooms file {file}: {message}")]
    Format {
        /// The file.
        file: String,
        /// What the TOML reader said.
        message: String,
    },
    /// The file lists no room.
    #[error("rooms file {file}: no [[room]] entries")]
    Empty {
        /// The file.
        file: String,
    },
    /// A value of one room is wrong.
    #[error("rooms file {file}, room {room:?}, key `{key}`: {message}")]
    Entry {
        /// The file.
        file: String,
        /// The room's name.
        room: String,
        /// The key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileShape {
    room: Vec<EntryShape>,
}

/// One `[[room]]` table, as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntryShape {
    /// See the module documentation.
    pub name: String,
    /// Scene file or built-in name.
    pub scene: String,
    /// Token file.
    pub token_file: Option<PathBuf>,
    /// Most users at once.
    pub max_users: Option<usize>,
    /// CSV recording.
    pub record: Option<PathBuf>,
    /// Test knob.
    pub debug_cost_ms: Option<f64>,
    /// Test knob.
    pub debug_panic_after_ticks: Option<u64>,
}

/// Default most users of a room.
pub const DEFAULT_MAX_USERS: usize = 16;

/// Reads and checks a rooms file.
pub fn load_rooms_file(path: &Path) -> Result<Vec<RoomSpec>, RoomsFileError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| RoomsFileError::Read { file: file.clone(), message: e.to_string() })?;
    let shape: FileShape =
        toml::from_str(&text).map_err(|e| RoomsFileError::Format { file: file.clone(), message: e.to_string() })?;
    if shape.room.is_empty() {
        return Err(RoomsFileError::Empty { file });
    }
    let base = path.parent().unwrap_or(Path::new("."));
    let mut names = HashSet::new();
    let mut specs = Vec::with_capacity(shape.room.len());
    for entry in shape.room {
        if !names.insert(entry.name.clone()) {
            let message = "this name is used by an earlier room".to_string();
            return Err(RoomsFileError::Entry { file, room: entry.name, key: "name", message });
        }
        specs.push(load_entry(entry, base, &file)?);
    }
    Ok(specs)
}

/// Loads one entry: its scene, its token file, its limits; `base` resolves relative paths, `file` names the
/// source in errors (a rooms file, or "admin command").
pub fn load_entry(entry: EntryShape, base: &Path, file: &str) -> Result<RoomSpec, RoomsFileError> {
    let fail = |key: &'static str, message: String| RoomsFileError::Entry {
        file: file.to_owned(),
        room: entry.name.clone(),
        key,
        message,
    };
    if entry.name.is_empty() || entry.name.len() > 64 || entry.name.chars().any(|c| c.is_whitespace() || c == '/') {
        return Err(fail("name", "a room's name is 1-64 characters without spaces or '/'".into()));
    }
    let relative = |p: &Path| if p.is_relative() && base.join(p).exists() { base.join(p) } else { p.to_owned() };
    let scene_arg = relative(Path::new(&entry.scene)).display().to_string();
    let (scene, scene_label) = crate::driver::load_scene(&scene_arg).map_err(|e| fail("scene", e.to_string()))?;
    compiles(&scene, &scene_label).map_err(|e| fail("scene", e.to_string()))?;
    let access = match &entry.token_file {
        Some(path) => Access::from_file(&relative(path)).map_err(|e| fail("token_file", e.to_string()))?,
        None => Access::open(),
    };
    let max_users = entry.max_users.unwrap_or(DEFAULT_MAX_USERS);
    if max_users == 0 {
        return Err(fail("max_users", "a room admits at least one user".into()));
    }
    let cost = match entry.debug_cost_ms {
        Some(ms) => Some(
            Duration::try_from_secs_f64(ms * 1e-3)
                .map_err(|_| fail("debug_cost_ms", format!("{ms} ms is not a duration")))?,
        ),
        None => None,
    };
    Ok(RoomSpec {
        name: entry.name.clone(),
        scene,
        scene_label,
        access,
        max_users,
        record: entry.record.as_deref().map(|p| if p.is_relative() { base.join(p) } else { p.to_owned() }),
        knobs: TestKnobs { cost, panic_after_ticks: entry.debug_panic_after_ticks },
    })
}

/// Whether the scene compiles into a model (what the room will do when it opens).
fn compiles(scene: &Scene, label: &str) -> Result<(), kinloop_linkage::error::SceneError> {
    use kinloop_linkage::math::space::{Planar, SceneKind, Spatial};
    use kinloop_linkage::model::Model;
    match scene.kind {
        SceneKind::Planar => Model::<Planar>::compile(scene, label).map(drop),
        SceneKind::Spatial => Model::<Spatial>::compile(scene, label).map(drop),
    }
}
