//! The live view's hub: one tokio task that turns the tap's newest frame into the JSON every page gets.
//!
//! Woken by the tap (or every [`IDLE_REFRESH`] when the VE publishes nothing, so the panel stays current),
//! it decodes only the newest frame in the ring, draws the linkage at its q with its own model, adds what
//! the sessions know of each user (name, device, RTT, clamped fraction, device and model poses) and the
//! pages that grab, serializes once and publishes through a `watch` channel: each page's writer sends the
//! newest frame when it can (latest wins), so a slow page skips frames instead of slowing anyone.

use std::sync::Arc;
use std::time::Duration;

use kinloop_linkage::math::space::SceneKind;
use tokio::sync::watch;

use super::compose::{compose, connected_users, UserInfo};
use super::draw::Geometry;
use super::messages::ToPage;
use super::sample::{take_latest, Sample};
use super::{Counter, FrameText, TapReader, ViewShared};
use crate::gateway::Gateway;

/// Longest wait for the tap before the hub refreshes the last frame's panel anyway.
const IDLE_REFRESH: Duration = Duration::from_millis(250);

pub(crate) struct Hub {
    pub geometry: Box<dyn Geometry>,
    pub reader: TapReader,
    pub kind: SceneKind,
    pub frames: watch::Sender<Option<FrameText>>,
    pub server: Option<Arc<Gateway>>,
}

pub(crate) async fn run(mut hub: Hub, view: Arc<ViewShared>) {
    let mut shutdown = view.shutdown.subscribe();
    let mut last: Option<Sample> = None;
    let mut seq = 0u64;
    let mut users: Vec<UserInfo> = Vec::new();
    loop {
        tokio::select! {
            _ = hub.reader.notify.notified() => {}
            _ = tokio::time::sleep(IDLE_REFRESH) => {}
            _ = shutdown.changed() => break,
        }
        if let Some(sample) = take_latest(&mut hub.reader.ring, hub.kind) {
            last = Some(sample);
        }
        let Some(sample) = &last else { continue };
        users.clear();
        if let Some(server) = &hub.server {
            connected_users(&server.users, &mut users);
        }
        if let Ok(browsers) = view.browsers.lock() {
            users.extend(browsers.iter().cloned());
        }
        seq += 1;
        let frame = compose(seq, sample, hub.geometry.as_mut(), &users);
        match serde_json::to_string(&ToPage::Frame(&frame)) {
            Ok(text) => {
                view.counters.bump(Counter::FramesBuilt);
                hub.frames.send_replace(Some(FrameText { text: text.into() }));
            }
            Err(error) => tracing::error!(%error, "view: a frame did not serialize"),
        }
    }
}
