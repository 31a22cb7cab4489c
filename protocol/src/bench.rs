//! Measurements `kinloop bench --json` reports for this crate (`codec/snapshot_testbed`,
//! `quic/datagram_oneway_loopback`), kept here so the numbers come from the code that ships.

use std::hint::black_box;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use bytes::Bytes;

use crate::codec::{self, DecodeError, EncodeError};
use crate::messages::{Datagram, PortEnergy, Snapshot};
use crate::quic::{
    client_endpoint, server_endpoint, EndpointError, EndpointOptions, IdentityError, ServerIdentity, Trust,
};
use crate::shape::{SceneKind, SessionShape};

/// The planar testbed's session: a closed-loop planar linkage (k = 3).
pub fn testbed_shape() -> SessionShape {
    SessionShape { kind: SceneKind::Planar, n: 4, nq: 4, m: 2 }
}

/// A realistic snapshot of the planar testbed: k = 3, no contacts, no other user, no configuration terms.
pub fn testbed_snapshot() -> Snapshot {
    Snapshot {
        seq: 123_456,
        server_time_s: 123.456,
        ve_step: 123_456,
        user_id: 1,
        uplink_time_s: 0.0,
        op_pose: vec![0.1734, -0.0421, 0.6912],
        op_twist: vec![0.0123, -0.0456, 0.2977],
        inverse_inertia: vec![2.314, -0.217, 0.081, 1.772, -0.034, 12.81],
        bias_accel: vec![-0.021, 0.173, -1.207],
        directions: vec![0.9806, -0.1961, 0.0, 0.1961, 0.9806, 0.0, 0.0, 0.0, 1.0],
        singular_values: vec![12.83, 2.41, 0.0017],
        constraint_count: 1,
        contacts: Vec::new(),
        other_manipulators: 0,
        config: None,
        energy: PortEnergy::zero(3),
    }
}

/// Encodes and decodes (with validation) the testbed snapshot `iters` times; returns the mean nanoseconds
/// per encode + decode and the encoded size in bytes.
pub fn codec_snapshot_testbed(iters: u64) -> Result<(f64, usize), BenchError> {
    let shape = testbed_shape();
    let message = Datagram::Snapshot(testbed_snapshot());
    let mut buf = Vec::with_capacity(512);
    codec::encode_datagram_into(&message, &mut buf)?;
    let bytes = buf.len();
    let round_trip = |buf: &mut Vec<u8>| -> Result<(), BenchError> {
        codec::encode_datagram_into(black_box(&message), buf)?;
        black_box(codec::decode_datagram(black_box(buf), &shape)?);
        Ok(())
    };
    // Warm caches and the allocator first, as criterion does.
    for _ in 0..iters / 10 {
        round_trip(&mut buf)?;
    }
    let start = Instant::now();
    for _ in 0..iters {
        round_trip(&mut buf)?;
    }
    let ns = start.elapsed().as_nanos() as f64 / iters.max(1) as f64;
    Ok((ns, bytes))
}

/// Datagrams sent before measuring, so connection warm-up (MTU probing, first wake-ups) is not measured.
const WARMUP_SAMPLES: usize = 50;
/// Longest wait for one datagram before counting it lost.
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(1);

/// One-way latency of a QUIC datagram over loopback between two endpoints of this process (one clock, so no
/// synchronization error), with no injected impairment; returns `(p50_us, p99_us)` over `samples` datagrams
/// the size of a testbed snapshot. Datagrams are sent one at a time, each after the previous arrived.
pub async fn quic_datagram_oneway_loopback(samples: usize) -> Result<(f64, f64), BenchError> {
    let identity = ServerIdentity::generate(&["localhost"])?;
    let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
    let opts = EndpointOptions { client_bind: loopback, ..EndpointOptions::default() };
    let server = server_endpoint(loopback, &identity, &opts)?;
    let server_addr = server.local_addr().map_err(|e| BenchError::Setup(e.to_string()))?;
    let client = client_endpoint(&Trust::Fingerprint(identity.fingerprint.clone()), &opts)?;

    let accepting = async {
        let incoming = server.accept().await.ok_or_else(|| BenchError::Setup("server endpoint closed".into()))?;
        incoming.await.map_err(|e| BenchError::Setup(e.to_string()))
    };
    let connecting = async {
        let connecting = client.connect(server_addr, "localhost").map_err(|e| BenchError::Setup(e.to_string()))?;
        connecting.await.map_err(|e| BenchError::Setup(e.to_string()))
    };
    let (receiver, sender) = tokio::try_join!(accepting, connecting)?;

    let payload_len = codec::encode_datagram(&Datagram::Snapshot(testbed_snapshot()))?.len();
    let epoch = Instant::now();
    let mut latencies_us = Vec::with_capacity(samples);
    for i in 0..WARMUP_SAMPLES + samples {
        let mut payload = vec![0u8; payload_len.max(8)];
        payload[..8].copy_from_slice(&(epoch.elapsed().as_nanos() as u64).to_le_bytes());
        sender.send_datagram(Bytes::from(payload)).map_err(|e| BenchError::Setup(e.to_string()))?;
        let Ok(received) = tokio::time::timeout(SAMPLE_TIMEOUT, receiver.read_datagram()).await else {
            continue; // lost on loopback: rare, and not a latency
        };
        let arrived_ns = epoch.elapsed().as_nanos() as u64;
        let received = received.map_err(|e| BenchError::Setup(e.to_string()))?;
        let sent_ns = received.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes).unwrap_or(arrived_ns);
        if i >= WARMUP_SAMPLES {
            latencies_us.push(arrived_ns.saturating_sub(sent_ns) as f64 / 1e3);
        }
    }
    sender.close(0u32.into(), b"done");
    client.wait_idle().await;
    if latencies_us.is_empty() {
        return Err(BenchError::Setup("no datagram arrived".into()));
    }
    latencies_us.sort_by(f64::total_cmp);
    Ok((percentile(&latencies_us, 50.0), percentile(&latencies_us, 99.0)))
}

/// The `p`-th percentile of sorted values (nearest rank).
fn percentile(sorted: &[f64], p: f64) -> f64 {
    let rank = (p / 100.0 * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)]
}

/// Why a measurement could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Encoding failed.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// Decoding failed.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// The certificate could not be made.
    #[error(transparent)]
    Identity(#[from] IdentityError),
    /// An endpoint could not be made.
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    /// The loopback connection failed.
    #[error("loopback QUIC: {0}")]
    Setup(String),
}
