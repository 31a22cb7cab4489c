//! A million random and mutated datagrams through the decoders: no panic, and no allocation beyond a small
//! bound, even when a length field claims gigabytes.
//!
//! This binary installs an allocator that records the largest single allocation, so its tests measure
//! memory rather than trust it.

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use kinloop_protocol::codec::limits::MAX_CONTROL_FRAME_BYTES;
use kinloop_protocol::codec::{decode_control, decode_datagram, encode_control, encode_datagram, peek_hello_version};
use kinloop_protocol::quic::body_len;
use kinloop_protocol::*;
use proptest::strategy::{Strategy, ValueTree};
use proptest::test_runner::TestRunner;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct LargestAllocation;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded unchanged to the system allocator; we only record sizes.
unsafe impl GlobalAlloc for LargestAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: LargestAllocation = LargestAllocation;

/// serde pre-allocates at most 1 MiB for a sequence whatever its length claims; nothing else comes close.
const ALLOCATION_BOUND: usize = 1024 * 1024 + 64 * 1024;

const SHAPES: [SessionShape; 3] = [
    SessionShape { kind: SceneKind::Planar, n: 4, nq: 4, m: 2 },
    SessionShape { kind: SceneKind::Spatial, n: 3, nq: 3, m: 1 },
    SessionShape { kind: SceneKind::Planar, n: 0, nq: 0, m: 0 },
];

/// Valid encodings of many messages of every kind, the seeds of the mutations.
fn corpus() -> Vec<Vec<u8>> {
    let mut runner = TestRunner::deterministic();
    let mut corpus = Vec::new();
    for _ in 0..150 {
        let (_, datagram) = support::shape_and_datagram().new_tree(&mut runner).expect("strategy").current();
        corpus.push(encode_datagram(&datagram).expect("encodes"));
        let control = support::control().new_tree(&mut runner).expect("strategy").current();
        corpus.push(encode_control(&control).expect("encodes"));
    }
    let (_, full) = support::full_spatial_snapshot();
    corpus.push(encode_datagram(&Datagram::Snapshot(full)).expect("encodes"));
    corpus
}

/// A varint (bincode standard) claiming an absurd length: u16, u32 or u64 form.
fn huge_varint(rng: &mut ChaCha8Rng) -> Vec<u8> {
    match rng.random_range(0..3) {
        0 => [&[0xfb][..], &u16::MAX.to_le_bytes()].concat(),
        1 => [&[0xfc][..], &rng.random_range(1u32 << 20..=u32::MAX).to_le_bytes()].concat(),
        _ => [&[0xfd][..], &rng.random_range(1u64 << 30..=u64::MAX).to_le_bytes()].concat(),
    }
}

fn mutate(rng: &mut ChaCha8Rng, corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut bytes = corpus[rng.random_range(0..corpus.len())].clone();
    let at = |rng: &mut ChaCha8Rng, len: usize| rng.random_range(0..=len);
    match rng.random_range(0..7) {
        0 => (0..rng.random_range(0..400)).map(|_| rng.random()).collect(),
        1 => {
            for _ in 0..rng.random_range(1..=8) {
                let bit = rng.random_range(0..bytes.len() * 8);
                bytes[bit / 8] ^= 1 << (bit % 8);
            }
            bytes
        }
        2 => {
            bytes.truncate(rng.random_range(0..bytes.len()));
            bytes
        }
        3 => {
            // Length-field inflation: an absurd length claim where a length (or anything) was.
            let position = at(rng, bytes.len());
            let claim = huge_varint(rng);
            let replace = rng.random_range(0..=1).min(bytes.len() - position);
            bytes.splice(position..position + replace, claim);
            bytes
        }
        4 => {
            for _ in 0..rng.random_range(1..=4) {
                let i = rng.random_range(0..bytes.len());
                bytes[i] = rng.random();
            }
            bytes
        }
        5 => {
            let other = &corpus[rng.random_range(0..corpus.len())];
            let cut = at(rng, bytes.len());
            let from = at(rng, other.len());
            bytes.truncate(cut);
            bytes.extend_from_slice(&other[from..]);
            bytes
        }
        _ => {
            bytes.extend((0..rng.random_range(1..16)).map(|_| rng.random::<u8>()));
            bytes
        }
    }
}

#[test]
fn a_million_random_and_mutated_datagrams_neither_panic_nor_allocate_much() {
    const INPUTS: usize = 1_000_000;
    let corpus = corpus();
    assert!(corpus.iter().all(|c| !c.is_empty()));
    let mut rng = ChaCha8Rng::seed_from_u64(0x006b_696e_6c6f_6f70);
    let (mut accepted, mut refused) = (0usize, 0usize);
    for i in 0..INPUTS {
        let bytes = mutate(&mut rng, &corpus);
        match decode_datagram(&bytes, &SHAPES[i % SHAPES.len()]) {
            Ok(_) => accepted += 1,
            Err(_) => refused += 1,
        }
        match decode_control(&bytes) {
            Ok(_) => accepted += 1,
            Err(_) => refused += 1,
        }
        peek_hello_version(&bytes);
        if let Some(header) = bytes.first_chunk::<4>() {
            if let Ok(len) = body_len(*header) {
                assert!(len <= MAX_CONTROL_FRAME_BYTES);
            }
        }
    }
    assert_eq!(accepted + refused, 2 * INPUTS);
    assert!(refused > INPUTS, "most mutations must be refused, got {refused} refusals");
    assert!(accepted > 1000, "some mutations (e.g. flipped mantissa bits) stay valid, got {accepted}");
    let largest = LARGEST.load(Ordering::Relaxed);
    eprintln!("{accepted} accepted, {refused} refused, largest allocation {largest} bytes");
    assert!(largest <= ALLOCATION_BOUND, "largest allocation {largest} bytes");
}

#[test]
fn length_fields_claiming_gigabytes_are_refused_without_allocating_them() {
    let eight_gib = 1u64 << 33;
    let claim = [&[0xfd][..], &eight_gib.to_le_bytes()].concat();

    // A Hello whose token claims 8 GiB: refused by the codec's size limit.
    let hello = [&[0x00, 0x01][..], &claim].concat();
    assert!(matches!(decode_control(&hello), Err(codec::DecodeError::TooLarge { .. })));

    // A snapshot whose op_pose claims 2^33 doubles: refused when the bytes run out.
    let snapshot = [&[0x00, 0x01, 0, 0, 0, 0, 0, 0, 0, 0, 0x01, 0x01][..], &claim].concat();
    assert!(decode_datagram(&snapshot, &SHAPES[0]).is_err());

    // An uplink whose hand_wrench claims u64::MAX values.
    let uplink = [&[0x01, 0x01, 0, 0, 0, 0, 0, 0, 0, 0, 0x01, 0, 0, 0, 0, 0, 0, 0, 0, 0xfd][..], &[0xff; 8]].concat();
    assert!(decode_datagram(&uplink, &SHAPES[0]).is_err());

    let largest = LARGEST.load(Ordering::Relaxed);
    assert!(largest <= ALLOCATION_BOUND, "largest allocation {largest} bytes");
}
