//! One view address for all of a server's rooms: `/` shows the default room (or the first), `/room/NAME`
//! shows room NAME, and each page's socket is `/ws` or `/room/NAME/ws`; `/rooms` lists the rooms a page's
//! token may watch (so a token learns nothing of rooms it cannot enter, as on the QUIC side). Rooms join
//! and leave the site as they open and close. [`super::ViewSite`] serves it.

use std::sync::{Arc, Mutex};

use kinloop_protocol::Role;
use serde::Serialize;
use tokio::sync::watch;

use super::ViewShared;

/// The room `/` and `/ws` show when the site has it (a `--scene` server's only room).
const FRONT_ROOM: &str = "default";

/// The rooms a site serves, in the order they opened, and its shutdown.
#[derive(Default)]
pub(crate) struct Site {
    rooms: Mutex<Vec<(String, Arc<ViewShared>)>>,
    pub shutdown: watch::Sender<bool>,
}

/// A room as `/rooms` lists it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct RoomLink {
    /// The room's name (its page is `/room/NAME`).
    pub name: String,
    /// Its scene's name.
    pub scene: String,
}

impl Site {
    /// Serves room `name` (a name already served is replaced).
    pub fn add(&self, name: &str, room: Arc<ViewShared>) {
        if let Ok(mut rooms) = self.rooms.lock() {
            rooms.retain(|(n, _)| n != name);
            rooms.push((name.to_owned(), room));
        }
    }

    /// Stops serving room `name` (its pages are closed by its own shutdown).
    pub fn remove(&self, name: &str) {
        if let Ok(mut rooms) = self.rooms.lock() {
            rooms.retain(|(n, _)| n != name);
        }
    }

    /// Room `name`, or (none) the front room: `default` if served, else the first to open.
    pub fn room(&self, name: Option<&str>) -> Option<Arc<ViewShared>> {
        let rooms = self.rooms.lock().ok()?;
        let named = |wanted: &str| rooms.iter().find(|(n, _)| n == wanted).map(|(_, r)| r.clone());
        match name {
            Some(name) => named(name),
            None => named(FRONT_ROOM).or_else(|| rooms.first().map(|(_, r)| r.clone())),
        }
    }

    /// The rooms `token` may watch.
    pub fn links(&self, token: &str) -> Vec<RoomLink> {
        let Ok(rooms) = self.rooms.lock() else { return Vec::new() };
        rooms
            .iter()
            .filter(|(_, room)| room.access.admit(token, Role::Observer).is_ok())
            .map(|(name, room)| RoomLink { name: name.clone(), scene: room.info.name.clone() })
            .collect()
    }
}
