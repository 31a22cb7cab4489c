//! The hooks `kinloop bench --json` calls work and report sane shapes; the timing goals are for the bench
//! report to show, not for tests to race against.

use kinloop_protocol::bench::{codec_snapshot_testbed, quic_datagram_oneway_loopback};

#[test]
fn testbed_snapshot_fits_the_400_byte_budget() {
    let (ns, bytes) = codec_snapshot_testbed(10_000).unwrap();
    eprintln!("codec/snapshot_testbed: {ns:.0} ns per encode + decode, {bytes} bytes");
    assert!(bytes <= 400, "{bytes} bytes");
    assert!(ns > 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loopback_latency_percentiles_are_ordered() {
    let (p50_us, p99_us) =
        tokio::time::timeout(std::time::Duration::from_secs(60), quic_datagram_oneway_loopback(2000))
            .await
            .expect("bounded")
            .unwrap();
    eprintln!("quic/datagram_oneway_loopback: p50 {p50_us:.1} µs, p99 {p99_us:.1} µs");
    assert!(0.0 < p50_us && p50_us <= p99_us, "p50 {p50_us} p99 {p99_us}");
}
