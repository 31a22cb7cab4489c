//! Snapshots and uplinks over a connection: QUIC datagrams, latest wins; a message too large for a datagram
//! goes on its own unidirectional stream instead, and is counted, never dropped silently.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use bytes::Bytes;
use quinn::{Connection, ConnectionError, SendDatagramError};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::codec::{self, limits::MAX_DATAGRAM_MESSAGE_BYTES, DecodeError, EncodeError};
use crate::messages::Datagram;
use crate::shape::SessionShape;

/// How a message left.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Route {
    /// As one unreliable datagram.
    Datagram,
    /// On its own unidirectional stream, because it exceeded `max_datagram_size()`.
    Stream,
}

/// Counters of a [`DatagramSender`] or [`DatagramReceiver`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeliveryStats {
    /// Messages that went (or came) as datagrams.
    pub datagrams: u64,
    /// Oversize messages that went (or came) on a stream.
    pub oversize_streams: u64,
    /// Oversize streams that failed to open, write or read (each also logged).
    pub oversize_failed: u64,
    /// Received messages refused by the codec.
    pub rejected: u64,
}

#[derive(Debug, Default)]
struct Counters {
    datagrams: AtomicU64,
    oversize_streams: AtomicU64,
    oversize_failed: AtomicU64,
    rejected: AtomicU64,
}

impl Counters {
    fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    fn snapshot(&self) -> DeliveryStats {
        DeliveryStats {
            datagrams: self.datagrams.load(Ordering::Relaxed),
            oversize_streams: self.oversize_streams.load(Ordering::Relaxed),
            oversize_failed: self.oversize_failed.load(Ordering::Relaxed),
            rejected: self.rejected.load(Ordering::Relaxed),
        }
    }
}

/// Why a message could not be sent.
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// The message could not be encoded (a local bug).
    #[error("cannot encode datagram: {0}")]
    Encode(#[from] EncodeError),
    /// The connection cannot carry datagrams (closed, or the peer disabled them).
    #[error("cannot send datagram: {0}")]
    Datagram(#[from] SendDatagramError),
    /// An oversize message needs a tokio runtime to write its stream.
    #[error("an oversize message needs a tokio runtime to send its stream")]
    NoRuntime,
}

/// Sends snapshots or uplinks on one connection. Never waits: datagrams queue in quinn's small send buffer
/// (oldest dropped first), oversize messages are written by a spawned task.
#[derive(Debug)]
pub struct DatagramSender {
    connection: Connection,
    counters: Arc<Counters>,
}

impl DatagramSender {
    /// A sender on `connection`.
    pub fn new(connection: Connection) -> Self {
        DatagramSender { connection, counters: Arc::default() }
    }

    /// Encodes and sends `msg`, choosing the route by the connection's current datagram size limit.
    pub fn send(&self, msg: &Datagram) -> Result<Route, SendError> {
        self.send_encoded(Bytes::from(codec::encode_datagram(msg)?))
    }

    /// Sends a message already encoded with [`codec::encode_datagram_into`] (by a thread that must not hand
    /// messages across, for instance), choosing the route as [`DatagramSender::send`] does.
    pub fn send_encoded(&self, bytes: Bytes) -> Result<Route, SendError> {
        let fits = self.connection.max_datagram_size().is_some_and(|max| bytes.len() <= max);
        if fits {
            match self.connection.send_datagram(bytes.clone()) {
                Ok(()) => {
                    Counters::bump(&self.counters.datagrams);
                    return Ok(Route::Datagram);
                }
                // The path MTU shrank since we asked: fall through to the stream.
                Err(SendDatagramError::TooLarge) => {}
                Err(e) => return Err(e.into()),
            }
        }
        self.send_on_stream(bytes)?;
        Ok(Route::Stream)
    }

    /// Counters so far (oversize failures are counted when the spawned write fails).
    pub fn stats(&self) -> DeliveryStats {
        self.counters.snapshot()
    }

    fn send_on_stream(&self, bytes: Bytes) -> Result<(), SendError> {
        let runtime = tokio::runtime::Handle::try_current().map_err(|_| SendError::NoRuntime)?;
        Counters::bump(&self.counters.oversize_streams);
        let connection = self.connection.clone();
        let counters = self.counters.clone();
        let len = bytes.len();
        runtime.spawn(async move {
            let written = async {
                let mut stream = connection.open_uni().await.map_err(|e| e.to_string())?;
                stream.write_all(&bytes).await.map_err(|e| e.to_string())?;
                stream.finish().map_err(|e| e.to_string())
            };
            if let Err(why) = written.await {
                Counters::bump(&counters.oversize_failed);
                tracing::warn!(len, %why, "oversize datagram message could not be sent on a stream");
            }
        });
        Ok(())
    }
}

/// Why receiving failed.
#[derive(Debug, thiserror::Error)]
pub enum RecvError {
    /// The connection is gone: stop receiving.
    #[error("connection lost: {0}")]
    Connection(#[from] ConnectionError),
    /// One message was refused; the next may be fine.
    #[error("refused a {route:?} message: {error}")]
    Decode {
        /// How it came.
        route: Route,
        /// Why it was refused.
        error: DecodeError,
    },
}

impl RecvError {
    /// True when the connection is gone and no more messages will come.
    pub fn is_fatal(&self) -> bool {
        matches!(self, RecvError::Connection(_))
    }
}

/// Oversize messages read completely but not yet handed out.
const OVERSIZE_BACKLOG: usize = 16;

/// Receives snapshots or uplinks on one connection, from datagrams and oversize streams alike, and checks
/// them against the session's shape.
#[derive(Debug)]
pub struct DatagramReceiver {
    connection: Connection,
    shape: SessionShape,
    oversize: mpsc::Receiver<Bytes>,
    oversize_reader: JoinHandle<()>,
    counters: Arc<Counters>,
}

impl DatagramReceiver {
    /// A receiver on `connection` for a session of `shape`; spawns the oversize-stream reader (needs tokio).
    pub fn new(connection: Connection, shape: SessionShape) -> Self {
        let counters = Arc::<Counters>::default();
        let (tx, oversize) = mpsc::channel(OVERSIZE_BACKLOG);
        let oversize_reader = tokio::spawn(read_oversize_streams(connection.clone(), tx, counters.clone()));
        DatagramReceiver { connection, shape, oversize, oversize_reader, counters }
    }

    /// The next message. Cancel-safe: a message is never lost when the future is dropped.
    pub async fn recv(&mut self) -> Result<Datagram, RecvError> {
        let (bytes, route) = tokio::select! {
            datagram = self.connection.read_datagram() => (datagram?, Route::Datagram),
            Some(bytes) = self.oversize.recv() => (bytes, Route::Stream),
        };
        let counter = match route {
            Route::Datagram => &self.counters.datagrams,
            Route::Stream => &self.counters.oversize_streams,
        };
        Counters::bump(counter);
        codec::decode_datagram(&bytes, &self.shape).map_err(|error| {
            Counters::bump(&self.counters.rejected);
            RecvError::Decode { route, error }
        })
    }

    /// Counters so far.
    pub fn stats(&self) -> DeliveryStats {
        self.counters.snapshot()
    }
}

impl Drop for DatagramReceiver {
    fn drop(&mut self) {
        self.oversize_reader.abort();
    }
}

/// Accepts the peer's unidirectional streams and reads each (concurrently, so one slow stream does not hold
/// up the next) into the receiver's channel.
async fn read_oversize_streams(connection: Connection, tx: mpsc::Sender<Bytes>, counters: Arc<Counters>) {
    while let Ok(mut stream) = connection.accept_uni().await {
        let tx = tx.clone();
        let counters = counters.clone();
        tokio::spawn(async move {
            match stream.read_to_end(MAX_DATAGRAM_MESSAGE_BYTES).await {
                Ok(bytes) => {
                    // A closed channel means the receiver is gone; nothing left to deliver to.
                    let _ = tx.send(Bytes::from(bytes)).await;
                }
                Err(why) => {
                    Counters::bump(&counters.oversize_failed);
                    tracing::warn!(%why, "oversize datagram stream could not be read");
                }
            }
        });
    }
}
