//! A fake Agones SDK sidecar for kinloop's tests: the SDK's gRPC service (the methods kinloop's adapter
//! calls, `proto/`) on a loopback port, answering as a sidecar does and recording every call with the time
//! it arrived, each health ping one record. Counters and Lists keep their values as the sidecar's would. It
//! can be told to fail calls (as a sidecar in trouble does) and stopped and restarted on the same port (as
//! one that disappears and comes back).
//!
//! Like a sidecar, it streams the GameServer to every `WatchGameServer` caller: the current one when the
//! watch opens, then again at each change (its state, its counters, and the annotations and counter raise
//! of an allocation the test makes with [`Journal::allocate`], as a lobby's GameServerAllocation does).

use std::collections::HashMap;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use tokio::sync::{oneshot, watch};
use tokio_stream::wrappers::{ReceiverStream, TcpListenerStream};
use tonic::{Request, Response, Status, Streaming};

/// The SDK's messages and server stubs (package `agones.dev.sdk`).
#[allow(missing_docs, clippy::all)]
pub mod sdk {
    tonic::include_proto!("agones.dev.sdk");
}

/// The beta SDK's messages and server stubs (package `agones.dev.sdk.beta`).
#[allow(missing_docs, clippy::all)]
pub mod beta {
    tonic::include_proto!("agones.dev.sdk.beta");
}

/// One call the server made.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Call {
    /// `Ready`.
    Ready,
    /// `Allocate`.
    Allocate,
    /// `Shutdown`.
    Shutdown,
    /// One message on the `Health` stream.
    Health,
    /// `GetGameServer` (the SDK's connection check).
    GetGameServer,
    /// `WatchGameServer` (the stream opened).
    WatchGameServer,
    /// `SetAnnotation`.
    SetAnnotation { key: String, value: String },
    /// `UpdateCounter` by a difference.
    Counter { name: String, diff: i64 },
    /// `AddListValue`.
    ListAdd { name: String, value: String },
    /// `RemoveListValue`.
    ListRemove { name: String, value: String },
}

/// A call and when it arrived.
#[derive(Clone, Debug)]
pub struct Recorded {
    /// When it arrived.
    pub at: Instant,
    /// What it was.
    pub call: Call,
}

/// What the sidecar saw and holds, shared by its two services and the test.
#[derive(Clone, Debug, Default)]
pub struct Journal {
    calls: Arc<Mutex<Vec<Recorded>>>,
    counters: Arc<Mutex<HashMap<String, i64>>>,
    lists: Arc<Mutex<HashMap<String, Vec<String>>>>,
    /// Calls still to fail (with `UNAVAILABLE`) before answering again; health pings are recorded anyway.
    failing: Arc<Mutex<u32>>,
    /// The GameServer's state (`Ready`, `Allocated`...) and annotations.
    meta: Arc<Mutex<(String, HashMap<String, String>)>>,
    /// The GameServer as the watchers see it, published at each change.
    published: Arc<watch::Sender<sdk::GameServer>>,
}

impl Journal {
    // The error is what the gRPC service's methods return (tonic's `Status`, by value): boxing it here would
    // only be unboxed again at each of them.
    #[allow(clippy::result_large_err)]
    fn record(&self, call: Call) -> Result<(), Status> {
        let fail = {
            let mut failing = self.failing.lock().expect("journal");
            let fail = *failing > 0 && call != Call::Health;
            *failing -= u32::from(fail);
            fail
        };
        self.calls.lock().expect("journal").push(Recorded { at: Instant::now(), call });
        if fail {
            return Err(Status::unavailable("the fake sidecar was told to fail this call"));
        }
        Ok(())
    }

    /// Every call so far, in order.
    pub fn calls(&self) -> Vec<Recorded> {
        self.calls.lock().expect("journal").clone()
    }

    /// A counter's count (0 if never touched).
    pub fn counter(&self, name: &str) -> i64 {
        self.counters.lock().expect("journal").get(name).copied().unwrap_or(0)
    }

    /// A list's values.
    pub fn list(&self, name: &str) -> Vec<String> {
        self.lists.lock().expect("journal").get(name).cloned().unwrap_or_default()
    }

    /// Sets a counter, as an allocation does.
    pub fn set_counter(&self, name: &str, count: i64) {
        self.counters.lock().expect("journal").insert(name.into(), count);
        self.publish();
    }

    /// What a lobby's GameServerAllocation does to the GameServer: it becomes `Allocated`, `counter` rises
    /// by one and the allocation's annotations are written (replacing values of the same keys); every
    /// watcher is sent the new GameServer.
    pub fn allocate(&self, counter: &str, annotations: &[(&str, &str)]) {
        {
            let mut meta = self.meta.lock().expect("journal");
            meta.0 = "Allocated".into();
            meta.1.extend(annotations.iter().map(|(k, v)| (k.to_string(), v.to_string())));
        }
        *self.counters.lock().expect("journal").entry(counter.into()).or_default() += 1;
        self.publish();
    }

    /// The GameServer's annotations.
    pub fn annotations(&self) -> HashMap<String, String> {
        self.meta.lock().expect("journal").1.clone()
    }

    /// The GameServer's state as the sidecar last set it (`""` before `Ready`).
    pub fn state(&self) -> String {
        self.meta.lock().expect("journal").0.clone()
    }

    fn set_state(&self, state: &str) {
        self.meta.lock().expect("journal").0 = state.into();
        self.publish();
    }

    /// The GameServer as it is now.
    fn gameserver(&self) -> sdk::GameServer {
        use sdk::game_server::{status::CounterStatus, ObjectMeta, Status};
        let (state, annotations) = self.meta.lock().expect("journal").clone();
        let counters = self.counters.lock().expect("journal").clone();
        sdk::GameServer {
            object_meta: Some(ObjectMeta { name: "kinloop-fake".into(), annotations, labels: HashMap::new() }),
            status: Some(Status {
                state,
                counters: counters.into_iter().map(|(k, count)| (k, CounterStatus { count, capacity: 1000 })).collect(),
            }),
        }
    }

    /// Sends the GameServer to every watcher.
    fn publish(&self) {
        self.published.send_replace(self.gameserver());
    }

    /// Fails the next `calls` calls (health pings excepted).
    pub fn fail_next(&self, calls: u32) {
        *self.failing.lock().expect("journal") = calls;
    }
}

struct Sdk(Journal, watch::Receiver<bool>);

/// How many GameServer updates may wait for a slow watcher (the newest always arrives).
const WATCH_QUEUE: usize = 16;

#[tonic::async_trait]
impl sdk::sdk_server::Sdk for Sdk {
    async fn ready(&self, _: Request<sdk::Empty>) -> Result<Response<sdk::Empty>, Status> {
        self.0.record(Call::Ready)?;
        self.0.set_state("Ready");
        Ok(Response::new(sdk::Empty {}))
    }

    async fn allocate(&self, _: Request<sdk::Empty>) -> Result<Response<sdk::Empty>, Status> {
        self.0.record(Call::Allocate).map(|()| Response::new(sdk::Empty {}))
    }

    async fn shutdown(&self, _: Request<sdk::Empty>) -> Result<Response<sdk::Empty>, Status> {
        self.0.record(Call::Shutdown)?;
        self.0.set_state("Shutdown");
        Ok(Response::new(sdk::Empty {}))
    }

    async fn health(&self, pings: Request<Streaming<sdk::Empty>>) -> Result<Response<sdk::Empty>, Status> {
        let mut pings = pings.into_inner();
        let mut gone = self.1.clone();
        loop {
            tokio::select! {
                ping = pings.message() => match ping? {
                    Some(_) => self.0.record(Call::Health)?,
                    None => return Ok(Response::new(sdk::Empty {})),
                },
                // A sidecar that goes away ends its streams.
                _ = gone.wait_for(|gone| *gone) => return Err(Status::unavailable("the fake sidecar stopped")),
            }
        }
    }

    async fn get_game_server(&self, _: Request<sdk::Empty>) -> Result<Response<sdk::GameServer>, Status> {
        self.0.record(Call::GetGameServer).map(|()| Response::new(self.0.gameserver()))
    }

    async fn set_annotation(&self, request: Request<sdk::KeyValue>) -> Result<Response<sdk::Empty>, Status> {
        let sdk::KeyValue { key, value } = request.into_inner();
        self.0.record(Call::SetAnnotation { key: key.clone(), value: value.clone() })?;
        self.0.meta.lock().expect("journal").1.insert(key, value);
        self.0.publish();
        Ok(Response::new(sdk::Empty {}))
    }

    type WatchGameServerStream = ReceiverStream<Result<sdk::GameServer, Status>>;

    async fn watch_game_server(&self, _: Request<sdk::Empty>) -> Result<Response<Self::WatchGameServerStream>, Status> {
        self.0.record(Call::WatchGameServer)?;
        let (tx, rx) = tokio::sync::mpsc::channel(WATCH_QUEUE);
        let (mut changes, mut gone) = (self.0.published.subscribe(), self.1.clone());
        tokio::spawn(async move {
            loop {
                let current = changes.borrow_and_update().clone();
                if tx.send(Ok(current)).await.is_err() {
                    return;
                }
                let stopped = tokio::select! {
                    changed = changes.changed() => changed.is_err(),
                    // A sidecar that goes away ends its streams.
                    _ = gone.wait_for(|gone| *gone) => true,
                };
                if stopped {
                    let _ = tx.send(Err(Status::unavailable("the fake sidecar stopped"))).await;
                    return;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }
}

struct Beta(Journal);

#[tonic::async_trait]
impl beta::sdk_server::Sdk for Beta {
    async fn update_counter(
        &self,
        request: Request<beta::UpdateCounterRequest>,
    ) -> Result<Response<beta::Counter>, Status> {
        let update =
            request.into_inner().counter_update_request.ok_or_else(|| Status::invalid_argument("no update"))?;
        self.0.record(Call::Counter { name: update.name.clone(), diff: update.count_diff })?;
        let mut counters = self.0.counters.lock().expect("journal");
        let count = counters.entry(update.name.clone()).or_default();
        if *count + update.count_diff < 0 {
            return Err(Status::out_of_range(format!("counter {} would go below zero", update.name)));
        }
        *count += update.count_diff;
        let count = *count;
        drop(counters);
        self.0.publish();
        Ok(Response::new(beta::Counter { name: update.name, count, capacity: 1000 }))
    }

    async fn add_list_value(
        &self,
        request: Request<beta::AddListValueRequest>,
    ) -> Result<Response<beta::List>, Status> {
        let add = request.into_inner();
        self.0.record(Call::ListAdd { name: add.name.clone(), value: add.value.clone() })?;
        let mut lists = self.0.lists.lock().expect("journal");
        let values = lists.entry(add.name.clone()).or_default();
        if values.contains(&add.value) {
            return Err(Status::already_exists(format!("{} is in list {}", add.value, add.name)));
        }
        values.push(add.value);
        Ok(Response::new(beta::List { name: add.name, capacity: 1000, values: values.clone() }))
    }

    async fn remove_list_value(
        &self,
        request: Request<beta::RemoveListValueRequest>,
    ) -> Result<Response<beta::List>, Status> {
        let remove = request.into_inner();
        self.0.record(Call::ListRemove { name: remove.name.clone(), value: remove.value.clone() })?;
        let mut lists = self.0.lists.lock().expect("journal");
        let values = lists.entry(remove.name.clone()).or_default();
        let Some(at) = values.iter().position(|v| *v == remove.value) else {
            return Err(Status::not_found(format!("{} is not in list {}", remove.value, remove.name)));
        };
        values.remove(at);
        Ok(Response::new(beta::List { name: remove.name, capacity: 1000, values: values.clone() }))
    }
}

/// A running fake sidecar.
pub struct FakeSidecar {
    addr: SocketAddr,
    journal: Journal,
    stop: Option<oneshot::Sender<()>>,
    gone: watch::Sender<bool>,
    task: tokio::task::JoinHandle<()>,
}

type ServeFuture = Pin<Box<dyn std::future::Future<Output = ()> + Send>>;

impl FakeSidecar {
    /// Serves on a free loopback port with an empty journal. Call inside a tokio runtime.
    pub async fn start() -> std::io::Result<FakeSidecar> {
        Self::start_on(SocketAddr::from(([127, 0, 0, 1], 0)), Journal::default()).await
    }

    /// Serves on `addr` with `journal` (a restart keeps what the sidecar saw before).
    pub async fn start_on(addr: SocketAddr, journal: Journal) -> std::io::Result<FakeSidecar> {
        let listener = tokio::net::TcpListener::bind(addr).await?;
        let addr = listener.local_addr()?;
        let (stop, stopped) = oneshot::channel::<()>();
        let (gone, gone_rx) = watch::channel(false);
        let serve: ServeFuture = Box::pin({
            let journal = journal.clone();
            async move {
                let _ = tonic::transport::Server::builder()
                    .add_service(sdk::sdk_server::SdkServer::new(Sdk(journal.clone(), gone_rx)))
                    .add_service(beta::sdk_server::SdkServer::new(Beta(journal)))
                    .serve_with_incoming_shutdown(TcpListenerStream::new(listener), async {
                        let _ = stopped.await;
                    })
                    .await;
            }
        });
        Ok(FakeSidecar { addr, journal, stop: Some(stop), gone, task: tokio::spawn(serve) })
    }

    /// The gRPC port (what `AGONES_SDK_GRPC_PORT` names).
    pub fn port(&self) -> u16 {
        self.addr.port()
    }

    /// What it saw and holds.
    pub fn journal(&self) -> &Journal {
        &self.journal
    }

    /// Stops serving (its port closes, its streams end); the journal stays readable.
    pub async fn stop(mut self) -> Journal {
        self.gone.send_replace(true);
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if tokio::time::timeout(std::time::Duration::from_secs(2), &mut self.task).await.is_err() {
            self.task.abort();
        }
        self.journal.clone()
    }
}
