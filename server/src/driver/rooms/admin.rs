//! The admin command (see [`kinloop_protocol::AdminRequest`]): create, remove or list rooms at run time. The
//! server must have been started with `--admin-token FILE`; the token is compared in constant time (the
//! token file's [`Access`](crate::access::Access) check), and a request without it is refused and logged.

use std::path::Path;

use kinloop_protocol::quic::{answer_admin, AdminSession};
use kinloop_protocol::{AdminAnswer, AdminCommand, Role, PROTOCOL_VERSION};

use super::{load_entry, EntryShape, Host};

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
            let entry = EntryShape {
                name: name.clone(),
                scene: scene.clone(),
                token_file: (!token_file.is_empty()).then(|| token_file.into()),
                max_users: Some(*max_users as usize),
                record: None,
                debug_cost_ms: None,
                debug_panic_after_ticks: None,
            };
            let spec = match load_entry(entry, Path::new("."), "admin command") {
                Ok(spec) => spec,
                Err(error) => return refuse(error.to_string()),
            };
            if let Err(error) = host.open(spec) {
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
