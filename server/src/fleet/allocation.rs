//! From an Agones allocation to a room: a lobby's GameServerAllocation raises the server's `rooms` Counter
//! and names the room it wants in the GameServer's annotations ([`ROOM_ANNOTATION`], [`SCENE_ANNOTATION`];
//! `deploy/agones/allocation.yaml`). The server reads them (`Sdk::watch_gameserver`), creates the room
//! (the run-time admin command of the rooms executor), and, when it cannot, refuses with the reason (in the
//! log and in the [`REFUSED_ANNOTATION`], where the lobby reads it) and lowers the counter again so that the
//! fleet's count stays true.
//!
//! [`AllocationTracker`] tells a new allocation from an update that repeats it; [`room_request`] is the
//! parsing and the checks; [`RoomCreator`] is what the server's rooms implement (through the admin
//! command's path).

use std::collections::HashMap;

/// The annotation naming the room a lobby wants (`metadata.annotations` of the allocation).
pub const ROOM_ANNOTATION: &str = "kinloop.dev/room";
/// The annotation naming its scene (a built-in name or a path inside the server's image).
pub const SCENE_ANNOTATION: &str = "kinloop.dev/scene";
/// The annotation the server writes when it refuses an allocation: the reason, for the lobby.
pub const REFUSED_ANNOTATION: &str = "kinloop.dev/refused";
/// Longest reason written there.
pub const MAX_REASON: usize = 1024;
/// Longest room or scene name taken from an annotation.
pub const MAX_NAME: usize = 128;

/// A room an allocation asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RoomRequest {
    /// The room's name (unique on the server).
    pub room: String,
    /// The scene to load.
    pub scene: String,
}

/// Why an allocation's room was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum AllocationRefused {
    /// An annotation is missing.
    #[error("the allocation has no {annotation} annotation")]
    Missing {
        /// Which.
        annotation: &'static str,
    },
    /// An annotation's value is empty, too long or not printable.
    #[error("the allocation's {annotation} annotation {value:?} is not a name (1 to {MAX_NAME} printable characters)")]
    BadName {
        /// Which.
        annotation: &'static str,
        /// Its value.
        value: String,
    },
    /// The scene cannot be loaded.
    #[error("room {room}: cannot load scene {scene}: {why}")]
    Scene {
        /// The room.
        room: String,
        /// The scene.
        scene: String,
        /// Why.
        why: String,
    },
    /// The server already holds a room of that name, or holds only its own.
    #[error("room {room}: {why}")]
    Unavailable {
        /// The room.
        room: String,
        /// Why.
        why: String,
    },
}

/// The room an allocation's annotations ask for.
pub fn room_request(annotations: &HashMap<String, String>) -> Result<RoomRequest, AllocationRefused> {
    let name = |annotation: &'static str| {
        let value = annotations.get(annotation).ok_or(AllocationRefused::Missing { annotation })?;
        let printable = !value.is_empty() && value.len() <= MAX_NAME && value.chars().all(|c| !c.is_control());
        if !printable {
            return Err(AllocationRefused::BadName { annotation, value: value.chars().take(MAX_NAME).collect() });
        }
        Ok(value.clone())
    };
    Ok(RoomRequest { room: name(ROOM_ANNOTATION)?, scene: name(SCENE_ANNOTATION)? })
}

/// What creates rooms at run time (the server's rooms, as the admin command does); the adapter lowers the
/// `rooms` counter again when it refuses.
pub trait RoomCreator: Send + Sync {
    /// Creates `request`'s room, or says why not.
    fn create(&self, request: &RoomRequest) -> Result<(), AllocationRefused>;
}

/// Tells a new allocation from a GameServer update that only repeats the last one. The sidecar streams the
/// whole GameServer at every change (a counter moved, a list grew, the state changed), so an update is an
/// allocation only when the allocation annotations differ from the last update's: each allocation names
/// its own room (a lobby names rooms uniquely), and one whose annotations repeat the last room's is not
/// seen. Updates without either annotation (a GameServer never allocated) are none.
#[derive(Clone, Debug, Default)]
pub struct AllocationTracker {
    last: Option<(Option<String>, Option<String>)>,
}

impl AllocationTracker {
    /// Whether `annotations` (of the newest GameServer update) carry an allocation not seen before.
    pub fn is_new(&mut self, annotations: &HashMap<String, String>) -> bool {
        let names = (annotations.get(ROOM_ANNOTATION).cloned(), annotations.get(SCENE_ANNOTATION).cloned());
        if names == (None, None) || self.last.as_ref() == Some(&names) {
            return false;
        }
        self.last = Some(names);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn annotations(pairs: &[(&str, &str)]) -> HashMap<String, String> {
        pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
    }

    #[test]
    fn an_allocation_names_its_room_and_scene_or_is_refused_saying_which_is_wrong() {
        let good = annotations(&[(ROOM_ANNOTATION, "lab-3"), (SCENE_ANNOTATION, "paper-testbed")]);
        assert_eq!(room_request(&good), Ok(RoomRequest { room: "lab-3".into(), scene: "paper-testbed".into() }));
        let missing = annotations(&[(ROOM_ANNOTATION, "lab-3")]);
        assert_eq!(room_request(&missing), Err(AllocationRefused::Missing { annotation: SCENE_ANNOTATION }));
        let long = "x".repeat(MAX_NAME + 1);
        for bad in ["", "a\nb", long.as_str()] {
            let refused = room_request(&annotations(&[(ROOM_ANNOTATION, bad), (SCENE_ANNOTATION, "s")])).unwrap_err();
            assert!(matches!(refused, AllocationRefused::BadName { annotation: ROOM_ANNOTATION, .. }), "{bad:?}");
            assert!(refused.to_string().contains(ROOM_ANNOTATION));
        }
    }

    #[test]
    fn an_allocation_is_new_when_its_annotations_change_and_repeats_are_not() {
        let mut tracker = AllocationTracker::default();
        assert!(!tracker.is_new(&annotations(&[("other", "x")])), "a GameServer never allocated");
        let lab3 = annotations(&[(ROOM_ANNOTATION, "lab-3"), (SCENE_ANNOTATION, "paper-testbed")]);
        assert!(tracker.is_new(&lab3));
        assert!(!tracker.is_new(&lab3), "the same allocation streamed again (a counter moved)");
        let lab4 = annotations(&[(ROOM_ANNOTATION, "lab-4"), (SCENE_ANNOTATION, "paper-testbed")]);
        assert!(tracker.is_new(&lab4));
        let half = annotations(&[(ROOM_ANNOTATION, "lab-5")]);
        assert!(tracker.is_new(&half), "an allocation missing its scene is new (and refused)");
        assert!(tracker.is_new(&lab3), "an earlier room's name again, after another: new");
    }
}
