//! The admin command: a connection whose first frame is [`AdminRequest`] instead of a hello creates, removes
//! or lists the server's rooms, and is answered with one [`AdminAnswer`]. The server compares the admin
//! token in constant time and refuses a request without the right one.

use serde::{Deserialize, Serialize};

/// Admin → server: the admin token and what to do.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdminRequest {
    /// The sender's protocol version (a server refuses other versions).
    pub version: u16,
    /// The server's admin token (`--admin-token FILE`).
    pub token: String,
    /// What to do.
    pub command: AdminCommand,
}

/// What an admin asks of the server's rooms.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum AdminCommand {
    /// Open a room; the scene and the token file are read on the server, as a rooms file's entries are.
    CreateRoom {
        /// The room's name, unique on the server.
        name: String,
        /// Scene file on the server, or a built-in scene name.
        scene: String,
        /// Token file on the server; empty: the room is open to any token.
        token_file: String,
        /// Most users at once.
        max_users: u32,
    },
    /// Close a room: its users are told and leave.
    RemoveRoom {
        /// The room's name.
        name: String,
    },
    /// Only list the rooms.
    ListRooms,
}

/// One hosted room, as an admin sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoomSummary {
    /// Its name.
    pub name: String,
    /// Its scene's name.
    pub scene: String,
    /// Users in it now.
    pub users: u32,
    /// Which real-time thread steps it.
    pub thread: u32,
    /// Its measured step cost (EWMA, µs).
    pub cost_us: f64,
}

/// Server → admin.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum AdminAnswer {
    /// Done; the rooms hosted now.
    Done {
        /// Every room after the command.
        rooms: Vec<RoomSummary>,
    },
    /// Not done, and why (bad token, unknown room, a scene that does not load, over budget...).
    Refused {
        /// Why, naming what was wrong.
        what: String,
    },
}
