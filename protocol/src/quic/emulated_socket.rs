//! A UDP socket whose outgoing packets cross a [`LinkEmulator`] before they leave, so real QUIC traffic sees
//! the delay, jitter and loss the user asked for. Incoming packets are untouched: each side impairs its own
//! sending direction.

use std::fmt;
use std::io::{self, IoSliceMut};
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Instant;

use quinn::udp::{EcnCodepoint, RecvMeta, Transmit};
use quinn::{AsyncUdpSocket, UdpPoller};
use tokio::sync::Notify;

use crate::emulator::{LinkConfig, LinkConfigError, LinkEmulator, LinkStats, WireSize};

/// An owned copy of one UDP packet waiting on the emulated link.
#[derive(Clone, Debug)]
struct Packet {
    destination: SocketAddr,
    ecn: Option<EcnCodepoint>,
    contents: Vec<u8>,
    src_ip: Option<IpAddr>,
}

impl WireSize for Packet {
    fn wire_bytes(&self) -> usize {
        self.contents.len()
    }
}

impl Packet {
    fn transmit(&self) -> Transmit<'_> {
        Transmit {
            destination: self.destination,
            ecn: self.ecn,
            contents: &self.contents,
            segment_size: None,
            src_ip: self.src_ip,
        }
    }
}

/// State shared by the socket (which enqueues) and its release task (which sends when due).
struct Shared {
    link: Mutex<LinkEmulator<Packet>>,
    epoch: Instant,
    wake: Notify,
    closing: AtomicBool,
    /// Packets the real socket refused at release time (buffer full): lost, like on a congested host.
    refused_by_socket: AtomicU64,
}

/// Counters of an emulated socket.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EmulatedSocketStats {
    /// What the link did.
    pub link: LinkStats,
    /// Packets the operating system refused when they were due.
    pub refused_by_socket: u64,
}

/// Reads the counters of an emulated socket after it has been handed to quinn.
#[derive(Clone)]
pub struct EmulatedSocketStatsHandle(Arc<Shared>);

impl EmulatedSocketStatsHandle {
    /// Counters so far.
    pub fn get(&self) -> EmulatedSocketStats {
        let link = self.0.link.lock().map(|l| l.stats()).unwrap_or_default();
        EmulatedSocketStats { link, refused_by_socket: self.0.refused_by_socket.load(Ordering::Relaxed) }
    }
}

impl fmt::Debug for EmulatedSocketStatsHandle {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.get().fmt(f)
    }
}

/// The socket wrapper handed to quinn.
pub(crate) struct EmulatedSocket {
    inner: Arc<dyn AsyncUdpSocket>,
    shared: Arc<Shared>,
}

impl fmt::Debug for EmulatedSocket {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EmulatedSocket").field("inner", &self.inner).finish_non_exhaustive()
    }
}

impl EmulatedSocket {
    /// Wraps `inner` and spawns the task that releases packets when due (needs a tokio runtime).
    pub(crate) fn wrap(
        inner: Arc<dyn AsyncUdpSocket>,
        config: LinkConfig,
    ) -> Result<(Arc<EmulatedSocket>, EmulatedSocketStatsHandle), LinkConfigError> {
        let shared = Arc::new(Shared {
            link: Mutex::new(LinkEmulator::new(config)?),
            epoch: Instant::now(),
            wake: Notify::new(),
            closing: AtomicBool::new(false),
            refused_by_socket: AtomicU64::new(0),
        });
        tokio::spawn(release_when_due(inner.clone(), shared.clone()));
        let stats = EmulatedSocketStatsHandle(shared.clone());
        Ok((Arc::new(EmulatedSocket { inner, shared }), stats))
    }
}

impl Drop for EmulatedSocket {
    fn drop(&mut self) {
        // The release task drains what is in flight (a CONNECTION_CLOSE, say) and then stops.
        self.shared.closing.store(true, Ordering::Release);
        self.shared.wake.notify_one();
    }
}

/// Sends each packet when the link says it is due; ends once the socket is dropped and the link is empty.
async fn release_when_due(inner: Arc<dyn AsyncUdpSocket>, shared: Arc<Shared>) {
    loop {
        let next_due = {
            let Ok(mut link) = shared.link.lock() else { return };
            let now = shared.epoch.elapsed();
            while let Some(packet) = link.poll(now) {
                if inner.try_send(&packet.transmit()).is_err() {
                    shared.refused_by_socket.fetch_add(1, Ordering::Relaxed);
                }
            }
            link.poll_timeout()
        };
        match next_due {
            Some(due) => {
                tokio::select! {
                    _ = tokio::time::sleep_until((shared.epoch + due).into()) => {}
                    _ = shared.wake.notified() => {}
                }
            }
            None if shared.closing.load(Ordering::Acquire) => return,
            None => shared.wake.notified().await,
        }
    }
}

impl AsyncUdpSocket for EmulatedSocket {
    fn create_io_poller(self: Arc<Self>) -> Pin<Box<dyn UdpPoller>> {
        Box::pin(AlwaysWritable)
    }

    /// Accepts the packet onto the emulated link; it reaches the real socket when due. Never blocks: a
    /// congested link drops instead, as a router would.
    fn try_send(&self, transmit: &Transmit) -> io::Result<()> {
        let segment = transmit.segment_size.unwrap_or(transmit.contents.len()).max(1);
        let now = self.shared.epoch.elapsed();
        {
            let mut link = self.shared.link.lock().map_err(|_| io::Error::other("emulated link poisoned"))?;
            for contents in transmit.contents.chunks(segment) {
                let packet = Packet {
                    destination: transmit.destination,
                    ecn: transmit.ecn,
                    contents: contents.to_vec(),
                    src_ip: transmit.src_ip,
                };
                link.send(now, packet);
            }
        }
        self.shared.wake.notify_one();
        Ok(())
    }

    fn poll_recv(
        &self,
        cx: &mut Context,
        bufs: &mut [IoSliceMut<'_>],
        meta: &mut [RecvMeta],
    ) -> Poll<io::Result<usize>> {
        self.inner.poll_recv(cx, bufs, meta)
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        self.inner.local_addr()
    }

    /// One packet per transmit, so segmentation offload cannot carry packets past the emulator in a batch.
    fn max_transmit_segments(&self) -> usize {
        1
    }

    fn max_receive_segments(&self) -> usize {
        self.inner.max_receive_segments()
    }

    fn may_fragment(&self) -> bool {
        self.inner.may_fragment()
    }
}

/// The emulated link takes every packet at once, so the socket is always writable.
#[derive(Debug)]
struct AlwaysWritable;

impl UdpPoller for AlwaysWritable {
    fn poll_writable(self: Pin<&mut Self>, _cx: &mut Context) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}
