//! The admin command (see [`kinloop_protocol::AdminRequest`]): create, remove or list rooms at run time. The
//! server must have been started with `--admin-token FILE`; the token is compared in constant time (the
//! token file's [`Access`](crate::access::Access) check), and a request without it is refused and logged.
//!
//! [`create_room`] is the one way a room opens at run time: the admin command's `CreateRoom` and a fleet's
//! allocation (the [`RoomCreator`] the host is to the Agones adapter) both come through it.

use std::path::{Path, PathBuf};

use kinloop_protocol::quic::{answer_admin, AdminSession};
use kinloop_protocol::{AdminAnswer, AdminCommand, Role, PROTOCOL_VERSION};

use super::{load_entry, EntryShape, Host, RoomsFileError};
use crate::driver::ServerError;
use crate::fleet::allocation::{AllocationRefused, RoomCreator, RoomRequest};

/// Why a room could not be created at run time.
#[derive(Debug, thiserror::Error)]
pub(crate) enum CreateRoomError {
    /// Its entry (scene, token file, limits) is wrong.
    #[error(transparent)]
    Entry(#[from] RoomsFileError),
    /// It could not open (a name taken, no budget...).
    #[error(transparent)]
    Open(#[from] ServerError),
}

/// How a room created at run time was asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Origin {
    /// The admin command: the room's own token file (none: any token).
    Admin,
    /// A fleet's allocation, which counted the room: the server's own tokens (`--token-file`).
    Allocation,
}

/// Creates a room at run time: checks it as a rooms file's entry (paths relative to the working
/// directory), then opens it on the executor.
pub(crate) fn create_room(host: &Host, entry: EntryShape, origin: Origin) -> Result<(), CreateRoomError> {
    let source = match origin {
        Origin::Admin => "admin command",
        Origin::Allocation => "Agones allocation",
    };
    let mut spec = load_entry(entry, Path::new("."), source)?;
    if origin == Origin::Allocation {
        spec.access = host.template.access.clone();
    }
    host.open(spec, origin == Origin::Allocation)?;
    Ok(())
}

/// A room created at run time, as an entry of a rooms file (no recording, no test knobs).
fn entry(name: &str, scene: &str, token_file: Option<PathBuf>, max_users: usize) -> EntryShape {
    EntryShape {
        name: name.to_owned(),
        scene: scene.to_owned(),
        token_file,
        max_users: Some(max_users),
        record: None,
        debug_cost_ms: None,
        debug_panic_after_ticks: None,
    }
}

/// An allocation's room: the server's own `--token-file` and user limit, refused while the server drains.
impl RoomCreator for Host {
    fn create(&self, request: &RoomRequest) -> Result<(), AllocationRefused> {
        let room = request.room.clone();
        if *self.shutdown.borrow() {
            return Err(AllocationRefused::Unavailable { room, why: "the server is draining".into() });
        }
        let asked = entry(&request.room, &request.scene, None, self.template.ve.max_users);
        let refused = match create_room(self, asked, Origin::Allocation) {
            Ok(()) => return Ok(()),
            Err(refused) => refused,
        };
        Err(match refused {
            CreateRoomError::Entry(RoomsFileError::Entry { key: "scene", message, .. }) => {
                AllocationRefused::Scene { room, scene: request.scene.clone(), why: message }
            }
            other => AllocationRefused::Unavailable { room, why: other.to_string() },
        })
    }
}

/// Decides an admin request and answers it.
pub(crate) async fn serve_admin(session: AdminSession, host: &Host) {
    let remote = session.connection.remote_address();
    let answer = decide(&session.request, host).await;
    match &answer {
        AdminAnswer::Done { .. } => tracing::info!(%remote, command = ?session.request.command, "admin command done"),
        AdminAnswer::Refused { what } => tracing::warn!(%remote, %what, "admin command refused"),
    }
    answer_admin(session, answer).await;
}

async fn decide(request: &kinloop_protocol::AdminRequest, host: &Host) -> AdminAnswer {
    let refuse = |what: String| AdminAnswer::Refused { what };
    let Some(admin) = &host.admin else {
        return refuse("this server takes no admin commands (started without --admin-token)".into());
    };
    if admin.admit(&request.token, Role::Manipulator).is_err() {
        return refuse("the admin token was not accepted".into());
    }
    if request.version != PROTOCOL_VERSION {
        return refuse(format!("protocol version {} is not {PROTOCOL_VERSION}", request.version));
    }
    match &request.command {
        AdminCommand::CreateRoom { name, scene, token_file, max_users } => {
            let token_file = (!token_file.is_empty()).then(|| token_file.into());
            let asked = entry(name, scene, token_file, *max_users as usize);
            if let Err(error) = create_room(host, asked, Origin::Admin) {
                return refuse(error.to_string());
            }
        }
        AdminCommand::RemoveRoom { name } => match host.take(name) {
            Some(room) => {
                room.begin_close("the room was closed by the server's admin");
                if let Err(error) = room.finish().await {
                    tracing::warn!(room = %name, %error, "the removed room did not close cleanly");
                }
            }
            None => return refuse(format!("no room {name:?}")),
        },
        AdminCommand::ListRooms => {}
    }
    AdminAnswer::Done { rooms: host.summaries() }
}
