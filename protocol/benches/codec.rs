//! Codec cost of the testbed snapshot: encode, decode (with validation), and both.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use kinloop_protocol::bench::{testbed_shape, testbed_snapshot};
use kinloop_protocol::codec::{decode_datagram, encode_datagram_into};
use kinloop_protocol::Datagram;

fn codec(c: &mut Criterion) {
    let shape = testbed_shape();
    let message = Datagram::Snapshot(testbed_snapshot());
    let mut buf = Vec::with_capacity(512);
    let encoded = {
        encode_datagram_into(&message, &mut buf).expect("testbed snapshot encodes");
        buf.clone()
    };
    c.bench_function("codec/snapshot_testbed/encode", |b| {
        b.iter(|| encode_datagram_into(black_box(&message), &mut buf).expect("encodes"))
    });
    c.bench_function("codec/snapshot_testbed/decode", |b| {
        b.iter(|| decode_datagram(black_box(&encoded), &shape).expect("decodes"))
    });
    c.bench_function("codec/snapshot_testbed/encode_decode", |b| {
        b.iter(|| {
            encode_datagram_into(black_box(&message), &mut buf).expect("encodes");
            decode_datagram(black_box(&buf), &shape).expect("decodes")
        })
    });
}

criterion_group!(benches, codec);
criterion_main!(benches);
