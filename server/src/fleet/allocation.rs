//! From an Agones allocation to a room: a lobby's GameServerAllocation raises the server's `rooms` Counter
//! and names the room it wants in the GameServer's annotations ([`ROOM_ANNOTATION`], [`SCENE_ANNOTATION`];
//! `deploy/agones/allocation.yaml`). The server reads them (`Sdk::watch_gameserver`), creates the room
//! (the run-time admin command of the rooms executor), and, when it cannot, refuses with the reason and
//! lowers the counter again so that the fleet's count stays true.
//!
//! [`room_request`] is the parsing and the checks; [`RoomCreator`] is what the rooms executor implements. A
//! one-room server hosts the room it started with and refuses any other.

use std::collections::HashMap;

/// The annotation naming the room a lobby wants (`metadata.annotations` of the allocation).
pub const ROOM_ANNOTATION: &str = "kinloop.dev/room";
/// The annotation naming its scene (a built-in name or a path inside the server's image).
pub const SCENE_ANNOTATION: &str = "kinloop.dev/scene";
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

/// What creates rooms at run time (the rooms executor); the adapter lowers the `rooms` counter again when
/// it refuses.
pub trait RoomCreator {
    /// Creates `request`'s room, or says why not.
    fn create(&self, request: &RoomRequest) -> Result<(), AllocationRefused>;
}

/// A one-room server: it hosts the room it started with (any allocation for its scene lands there) and
/// refuses rooms of other scenes.
#[derive(Clone, Debug)]
pub struct OneRoom {
    /// The scene it serves, as named on its command line.
    pub scene: String,
}

impl RoomCreator for OneRoom {
    fn create(&self, request: &RoomRequest) -> Result<(), AllocationRefused> {
        if request.scene == self.scene {
            return Ok(());
        }
        Err(AllocationRefused::Unavailable {
            room: request.room.clone(),
            why: format!("this server holds one room, of scene {}, not {}", self.scene, request.scene),
        })
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
    fn a_one_room_server_takes_its_scene_and_refuses_another_with_the_reason() {
        let server = OneRoom { scene: "paper-testbed".into() };
        let ask = |scene: &str| RoomRequest { room: "r".into(), scene: scene.into() };
        assert_eq!(server.create(&ask("paper-testbed")), Ok(()));
        let refused = server.create(&ask("chain50_loops5")).unwrap_err().to_string();
        assert!(refused.contains("paper-testbed") && refused.contains("chain50_loops5"), "{refused}");
    }
}
