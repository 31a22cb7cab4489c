//! Many clients' network sides on one tokio runtime: a [`SharedNetwork`] holds a runtime of a few worker
//! threads, one QUIC endpoint (one UDP socket) for every client it is given (quinn serves many connections
//! on one endpoint), and one uplink pump. Each client's session (handshake, snapshot reception, pings,
//! reconnection) is the client's own code ([`super::network`]), run as a task on that runtime instead of on
//! a runtime thread of its own; the clients' haptic loops run on a [`SharedClock`](super::shared_clock),
//! which wakes the pump once a round. The pump ([`pump`]) sends what every client's loop queued on its
//! connection: no thread per client on either side of the rings.
//!
//! A client whose link is emulated (`ClientConfig::link`) keeps an endpoint of its own (the emulation is the
//! socket's), on the same runtime.

use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

use kinloop_process::realtime::{try_fifo_priority, NETWORK_PRIORITY};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::{client_endpoint, Endpoint, EndpointError, EndpointOptions, Trust};
use tokio::sync::Notify;

use super::shared_clock::RoundHook;
use super::uplinks::Outlet;

/// How long the pump waits for a wake before looking at its outlets anyway (the last uplinks of a loop
/// that stopped, a client whose loop is not on the shared clock).
const PUMP_POLL: Duration = Duration::from_millis(5);

/// Longest [`SharedNetwork::finish`] waits for the endpoints' closing connections to tell their servers.
const CLOSE_LINGER: Duration = Duration::from_secs(1);

/// The network side shared by many clients of one process; cloned into each client's
/// [`ClientConfig::network`](super::ClientConfig::network). The runtime stops when the last handle goes (or
/// at [`SharedNetwork::finish`]).
#[derive(Clone)]
pub struct SharedNetwork {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for SharedNetwork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SharedNetwork")
    }
}

struct Inner {
    runtime: Option<tokio::runtime::Runtime>,
    handle: tokio::runtime::Handle,
    /// One endpoint per trust (the endpoint's default client configuration carries it).
    endpoints: Mutex<Vec<(Trust, Endpoint)>>,
    outlets: mpsc::Sender<Outlet>,
    wake: Arc<Notify>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        // Never blocks: the last handle may go on any thread, a runtime's own included.
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_background();
        }
    }
}

impl SharedNetwork {
    /// A runtime of `worker_threads` (at least one) and its uplink pump; with `realtime`, its workers ask
    /// for SCHED_FIFO below the shared clock's priority
    /// ([`NETWORK_PRIORITY`](kinloop_process::realtime::NETWORK_PRIORITY)).
    pub fn start(worker_threads: usize, realtime: bool) -> std::io::Result<Self> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(worker_threads.max(1))
            .thread_name("kinloop-net")
            .on_thread_start(move || {
                if realtime {
                    if let Err(why) = try_fifo_priority(NETWORK_PRIORITY) {
                        tracing::warn!(%why, "a shared network worker runs at normal priority");
                    }
                }
            })
            .enable_all()
            .build()?;
        let (outlets, arrivals) = mpsc::channel();
        let wake = Arc::new(Notify::new());
        runtime.spawn(pump(arrivals, wake.clone()));
        let handle = runtime.handle().clone();
        Ok(SharedNetwork {
            inner: Arc::new(Inner { runtime: Some(runtime), handle, endpoints: Mutex::default(), outlets, wake }),
        })
    }

    /// What the shared clock calls after each round: wakes the pump (once, whatever the number of clients).
    pub fn round_hook(&self) -> RoundHook {
        let wake = self.inner.wake.clone();
        Box::new(move || wake.notify_one())
    }

    /// The endpoint of a client that trusts servers as `trust` says: the shared one for that trust (made on
    /// first use), or `None` when its `link` is emulated (it makes its own, on this runtime).
    pub(super) fn endpoint_for(
        &self,
        trust: &Trust,
        link: Option<&LinkConfig>,
    ) -> Result<Option<Endpoint>, EndpointError> {
        if link.is_some_and(|link| !link.is_transparent()) {
            return Ok(None);
        }
        // A poisoned list is still a list of endpoints.
        let mut endpoints = self.inner.endpoints.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some((_, endpoint)) = endpoints.iter().find(|(known, _)| known == trust) {
            return Ok(Some(endpoint.clone()));
        }
        let _inside = self.inner.handle.enter();
        let endpoint = client_endpoint(trust, &EndpointOptions::default())?;
        endpoints.push((trust.clone(), endpoint.clone()));
        Ok(Some(endpoint))
    }

    /// Runs a client's network side on the runtime.
    pub(super) fn spawn(&self, task: impl std::future::Future<Output = ()> + Send + 'static) {
        self.inner.handle.spawn(task);
    }

    /// Hands the pump a client's uplinks.
    pub(super) fn pump_for(&self, outlet: Outlet) {
        // The pump lives as long as the runtime; when it is gone so are the sessions.
        let _ = self.inner.outlets.send(outlet);
        self.inner.wake.notify_one();
    }

    /// Lets the endpoints' last closing frames leave (at most [`CLOSE_LINGER`]), then stops the runtime;
    /// call it once every client using it has shut down. Other handles still held keep it running.
    pub fn finish(self) {
        let Ok(mut inner) = Arc::try_unwrap(self.inner) else { return };
        let endpoints: Vec<Endpoint> =
            inner.endpoints.get_mut().map(|e| e.drain(..).map(|(_, e)| e).collect()).unwrap_or_default();
        if let Some(runtime) = inner.runtime.take() {
            runtime.block_on(async {
                for endpoint in &endpoints {
                    let _ = tokio::time::timeout(CLOSE_LINGER, endpoint.wait_idle()).await;
                }
            });
            drop(endpoints);
            runtime.shutdown_timeout(CLOSE_LINGER);
        }
    }
}

/// The uplink pump: woken by the shared clock after each round (or every [`PUMP_POLL`]), it takes the
/// outlets of clients that started since, sends what each client's loop queued, and forgets the outlets of
/// loops that stopped once they are empty.
async fn pump(arrivals: mpsc::Receiver<Outlet>, wake: Arc<Notify>) {
    let mut outlets: Vec<Outlet> = Vec::new();
    loop {
        let _ = tokio::time::timeout(PUMP_POLL, wake.notified()).await;
        outlets.extend(arrivals.try_iter());
        outlets.retain_mut(|outlet| !outlet.drain());
    }
}
