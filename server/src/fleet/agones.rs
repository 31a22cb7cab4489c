//! The Agones adapter (`kinloop-server --agones`), with the official SDK (the `agones` crate) talking to the
//! sidecar in the server's pod:
//! - `Ready` once the server listens;
//! - health pings every health period, each only if the executor's heartbeat advanced since the last one, so
//!   a stalled VE stops them within one period (and Agones marks the server Unhealthy after the Fleet's
//!   `health.periodSeconds × failureThreshold`; see `deploy/agones/fleet.yaml` and docs/fleet.md);
//! - rooms as the Counter [`ROOMS_COUNTER`] and users as the List [`USERS_LIST`] (the SDK's beta API), and
//!   `Ready` again when the last room closes while the server serves on (back to the fleet's pool);
//! - `Shutdown` once drained;
//! - the GameServer watched (`WatchGameServer`, [`super::watch`]) from before `Ready`: a new allocation's
//!   annotations ([`super::allocation`]) become a room, created through the server's rooms as the admin
//!   command creates them and counted by the allocation itself; a room refused lowers the count again (and
//!   a server left with no room is `Ready` again).
//!
//! A sidecar that errors or goes away is retried with backoff and reported in the log, never a crash: each
//! call is retried for [`RETRY_FOR`], the health stream is reopened when it ends. Connecting is bounded
//! ([`AgonesConfig::connect_within`]; the SDK's own wait is 30 s), so a server started without a sidecar
//! fails at once with one line.

use std::collections::HashMap;
use std::future::Future;
use std::time::{Duration, Instant};

use agones::Sdk;
use tokio::sync::mpsc::error::TrySendError;
use tokio::sync::watch;
use tokio::task::JoinHandle;

use super::allocation::{
    room_request, AllocationRefused, AllocationTracker, RoomCreator, RoomRequest, MAX_REASON, REFUSED_ANNOTATION,
};
use super::sidecar::{describe, FIRST_BACKOFF, MAX_BACKOFF};
use super::watch::GameServerWatch;
use super::{FleetEvent, FleetEvents, Heartbeat, RoomsSlot};

/// The Counter of rooms on the server (the FleetAutoscaler scales on it; an allocation raises it).
pub const ROOMS_COUNTER: &str = "rooms";
/// The List of users on the server.
pub const USERS_LIST: &str = "users";
/// How long the server waits for the sidecar at start by default.
pub const DEFAULT_CONNECT_WITHIN: Duration = Duration::from_secs(3);
/// How long one call is retried before it is given up (and reported).
pub const RETRY_FOR: Duration = Duration::from_secs(10);
/// The SDK's port when neither the configuration nor `AGONES_SDK_GRPC_PORT` names one.
const DEFAULT_SDK_PORT: u16 = 9357;

/// How the adapter talks to the sidecar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgonesConfig {
    /// The sidecar's gRPC port on localhost (`None`: `AGONES_SDK_GRPC_PORT`, else 9357).
    pub port: Option<u16>,
    /// How often a health ping goes out while the executor ticks.
    pub health_period: Duration,
    /// How long to wait for the sidecar at start.
    pub connect_within: Duration,
}

impl Default for AgonesConfig {
    fn default() -> Self {
        AgonesConfig { port: None, health_period: super::DEFAULT_HEALTH_PERIOD, connect_within: DEFAULT_CONNECT_WITHIN }
    }
}

impl AgonesConfig {
    /// The port the SDK dials.
    pub fn sdk_port(&self) -> u16 {
        self.port
            .or_else(|| std::env::var("AGONES_SDK_GRPC_PORT").ok().and_then(|p| p.parse().ok()))
            .unwrap_or(DEFAULT_SDK_PORT)
    }
}

/// Why the adapter could not start.
#[derive(Debug, thiserror::Error)]
pub enum AgonesError {
    /// Nothing answered in time.
    #[error(
        "no Agones SDK sidecar answered on localhost:{port} within {waited_s:.1} s (--agones runs inside an \
         Agones GameServer pod; AGONES_SDK_GRPC_PORT names the sidecar's port)"
    )]
    NoSidecar {
        /// The port dialled.
        port: u16,
        /// How long it waited.
        waited_s: f64,
    },
    /// The SDK refused to start (a bad port variable, say).
    #[error("the Agones SDK could not start on localhost:{port}: {why}")]
    Sdk {
        /// The port dialled.
        port: u16,
        /// The SDK's error.
        why: String,
    },
}

/// Connects to the sidecar, waiting at most `config.connect_within`.
pub async fn connect(config: &AgonesConfig) -> Result<Sdk, AgonesError> {
    let port = config.sdk_port();
    match tokio::time::timeout(config.connect_within, Sdk::new(Some(port), None)).await {
        Ok(Ok(sdk)) => Ok(sdk),
        Ok(Err(error)) => Err(AgonesError::Sdk { port, why: describe(&error) }),
        Err(_) => Err(AgonesError::NoSidecar { port, waited_s: config.connect_within.as_secs_f64() }),
    }
}

/// The running adapter.
pub struct AgonesAdapter {
    task: JoinHandle<()>,
}

impl AgonesAdapter {
    /// Starts following `events` on the current tokio runtime.
    pub fn spawn(sdk: Sdk, config: &AgonesConfig, events: FleetEvents) -> AgonesAdapter {
        AgonesAdapter { task: tokio::spawn(follow(sdk, config.health_period, events)) }
    }

    /// Waits (at most `limit`) for the adapter to finish: after `Drained` it has called `Shutdown`.
    pub async fn finished(mut self, limit: Duration) {
        if tokio::time::timeout(limit, &mut self.task).await.is_err() {
            tracing::warn!("the Agones adapter did not finish in {limit:?}; leaving without Shutdown");
            self.task.abort();
        }
    }
}

/// Turns the driver's events into SDK calls, in order, and the fleet's allocations into rooms; pings from a
/// task of its own.
async fn follow(sdk: Sdk, health_period: Duration, events: FleetEvents) {
    let FleetEvents { mut events, heartbeat, rooms: server_rooms } = events;
    let (stop_health, health_stopped) = watch::channel(false);
    let health = tokio::spawn(ping_while_beating(sdk.clone(), heartbeat, health_period, health_stopped));
    // Rooms open, and whether the server drains: a server whose last room closed while it serves on goes back
    // to the pool of Ready servers (an allocation had made it Allocated).
    let (mut rooms, mut draining) = (0usize, false);
    // The GameServer watch, open once the server listens with rooms to offer allocations.
    let mut gameserver: Option<GameServerWatch> = None;
    let mut allocations = AllocationTracker::default();
    loop {
        let event = tokio::select! {
            event = events.recv() => match event {
                Some(event) => event,
                None => break,
            },
            annotations = next_update(&mut gameserver) => {
                let refused = allocations.is_new(&annotations) && !take_allocation(&sdk, &server_rooms, &annotations).await;
                if refused && rooms == 0 && !draining {
                    tracing::info!("Agones: no room; Ready again");
                    retried("Ready", &sdk, |mut s| async move { s.ready().await }).await;
                }
                continue;
            }
        };
        match event {
            FleetEvent::Listening { addr } => {
                // The watch opens before Ready: no allocation reaches a Ready server unwatched.
                if gameserver.is_none() && server_rooms.get().is_some() {
                    gameserver = Some(GameServerWatch::open(&sdk).await);
                }
                tracing::info!(%addr, "Agones: Ready");
                retried("Ready", &sdk, |mut s| async move { s.ready().await }).await;
            }
            FleetEvent::RoomOpened { room, allocated } => {
                rooms += 1;
                if allocated {
                    // The allocation raised the count already.
                    tracing::info!(room, "Agones: allocated room open");
                    continue;
                }
                tracing::info!(room, "Agones: rooms + 1");
                let increment = |s: Sdk| async move { s.beta().clone().increment_counter(ROOMS_COUNTER, 1).await };
                retried("UpdateCounter rooms +1", &sdk, increment).await;
            }
            FleetEvent::RoomClosed { room } => {
                tracing::info!(room, "Agones: rooms - 1");
                let decrement = |s: Sdk| async move { s.beta().clone().decrement_counter(ROOMS_COUNTER, 1).await };
                retried("UpdateCounter rooms -1", &sdk, decrement).await;
                rooms = rooms.saturating_sub(1);
                if rooms == 0 && !draining {
                    tracing::info!("Agones: no room left; Ready again");
                    retried("Ready", &sdk, |mut s| async move { s.ready().await }).await;
                }
            }
            FleetEvent::UserJoined { user } => {
                let add = |s: Sdk| {
                    let user = user.clone();
                    async move { s.beta().clone().append_list_value(USERS_LIST, &user).await }
                };
                retried("AddListValue users", &sdk, add).await;
            }
            FleetEvent::UserLeft { user } => {
                let remove = |s: Sdk| {
                    let user = user.clone();
                    async move { s.beta().clone().delete_list_value(USERS_LIST, &user).await }
                };
                retried("RemoveListValue users", &sdk, remove).await;
            }
            FleetEvent::Draining => {
                draining = true;
                tracing::info!("Agones: draining");
            }
            FleetEvent::Drained => {
                stop_health.send_replace(true);
                let _ = health.await;
                tracing::info!("Agones: Shutdown");
                retried("Shutdown", &sdk, |mut s| async move { s.shutdown().await }).await;
                return;
            }
        }
    }
}

/// Creates the room a new allocation asks for through the server's rooms; whether it was.
async fn take_allocation(sdk: &Sdk, server_rooms: &RoomsSlot, annotations: &HashMap<String, String>) -> bool {
    let Some(creator) = server_rooms.get() else {
        tracing::warn!("Agones: an allocation arrived as the server stopped; no room created");
        return false;
    };
    match create_allocated_room(sdk, creator.as_ref(), annotations).await {
        Ok(request) => {
            tracing::info!(room = request.room, scene = request.scene, "Agones: allocation: room created");
            true
        }
        Err(_) => false,
    }
}

/// The next GameServer update's annotations, or never without a watch.
async fn next_update(watch: &mut Option<GameServerWatch>) -> HashMap<String, String> {
    match watch {
        Some(watch) => watch.next().await,
        None => std::future::pending().await,
    }
}

/// Calls `call` until it succeeds or [`RETRY_FOR`] has passed, waiting with exponential backoff between
/// tries; each failure is reported, and a call given up is said in the log (never a panic).
async fn retried<F, Fut>(what: &str, sdk: &Sdk, call: F) -> bool
where
    F: Fn(Sdk) -> Fut,
    Fut: Future<Output = agones::errors::Result<()>>,
{
    let started = Instant::now();
    let mut backoff = FIRST_BACKOFF;
    for attempt in 1u32.. {
        match call(sdk.clone()).await {
            Ok(()) => return true,
            Err(error) if started.elapsed() + backoff > RETRY_FOR => {
                let error = describe(&error);
                tracing::error!(call = what, attempt, error, "the Agones sidecar failed the call; giving it up");
                return false;
            }
            Err(error) => {
                let error = describe(&error);
                tracing::warn!(call = what, attempt, error, retry_in = ?backoff, "the Agones sidecar failed the call");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(MAX_BACKOFF);
            }
        }
    }
    false
}

/// Pings every `period` while `heartbeat` advances; reopens the health stream (with backoff) when it ends.
async fn ping_while_beating(sdk: Sdk, heartbeat: Heartbeat, period: Duration, mut stop: watch::Receiver<bool>) {
    let mut pings = sdk.health_check();
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last = heartbeat.count();
    let mut stalled = false;
    let mut failures = 0u32;
    let mut reopen_at = Instant::now();
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = stop.wait_for(|stop| *stop) => return,
        }
        let beats = heartbeat.count();
        if beats == 0 {
            // The VE has not started yet (Agones' initialDelaySeconds covers the start).
            continue;
        }
        if beats == last {
            if !stalled {
                tracing::warn!("the VE has not ticked for a health period: health pings withheld");
                stalled = true;
            }
            continue;
        }
        if stalled {
            tracing::info!("the VE ticks again: health pings resume");
            stalled = false;
        }
        last = beats;
        match pings.try_send(()) {
            Ok(()) => failures = 0,
            // The SDK's stream is behind (a sidecar slow to take pings): this one is skipped.
            Err(TrySendError::Full(())) => {}
            Err(TrySendError::Closed(())) => {
                failures += 1;
                if failures.is_power_of_two() {
                    tracing::warn!(failures, "the health stream to the Agones sidecar ended; reopening it");
                }
                if Instant::now() >= reopen_at {
                    pings = sdk.health_check();
                    let _ = pings.try_send(());
                    let backoff = (FIRST_BACKOFF * failures.min(20)).min(MAX_BACKOFF);
                    reopen_at = Instant::now() + backoff;
                }
            }
        }
    }
}

/// The allocation → room path, taken when the GameServer watch shows a new allocation: the room the
/// annotations ask for is created by `creator` (the server's rooms, as the admin command creates them);
/// when it cannot be (a scene the server cannot load, a name taken, a draining server), the refusal is
/// reported (in the log, and in the GameServer's [`REFUSED_ANNOTATION`] for the lobby) and the `rooms` count
/// the allocation raised is lowered again.
pub async fn create_allocated_room(
    sdk: &Sdk,
    creator: &dyn RoomCreator,
    annotations: &HashMap<String, String>,
) -> Result<RoomRequest, AllocationRefused> {
    let created = room_request(annotations).and_then(|request| creator.create(&request).map(|()| request));
    if let Err(refusal) = &created {
        tracing::warn!(%refusal, "Agones: allocation refused; rooms - 1");
        let decrement = |s: Sdk| async move { s.beta().clone().decrement_counter(ROOMS_COUNTER, 1).await };
        retried("UpdateCounter rooms -1 (allocation refused)", sdk, decrement).await;
        let reason: String = refusal.to_string().chars().take(MAX_REASON).collect();
        let annotate = |mut s: Sdk| {
            let reason = reason.clone();
            async move { s.set_annotation(REFUSED_ANNOTATION, reason).await }
        };
        retried("SetAnnotation kinloop.dev/refused", sdk, annotate).await;
    }
    created
}
