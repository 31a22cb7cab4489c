//! Snapshot frames in a byte ring: the VE thread commits `[len: u32 LE][bytes]` whole, a session's send task
//! (or the view's socket) reads them and keeps only the newest.

use std::mem::MaybeUninit;

use rtrb::{Consumer, Producer};

use crate::core::prefetch::prefetch_for_write;

/// Bytes of a snapshot frame's length prefix in a user's snapshot ring.
pub const FRAME_HEADER: usize = 4;

/// Appends `[len: u32 LE][bytes]` to a snapshot ring in one commit; false when it has no room. The frame is
/// copied as slices (at most two, where the ring wraps) into the ring's uninitialised slots: each byte is
/// written once (an initialised chunk would first fill them with zeros).
pub fn push_frame(ring: &mut Producer<u8>, bytes: &[u8]) -> bool {
    let total = FRAME_HEADER + bytes.len();
    let Ok(mut chunk) = ring.write_chunk_uninit(total) else { return false };
    let header = (bytes.len() as u32).to_le_bytes();
    let (a, b) = chunk.as_mut_slices();
    write_at(a, b, 0, &header);
    write_at(a, b, FRAME_HEADER, bytes);
    // SAFETY: the two writes above cover the chunk's `total` slots (header then body, across the wrap).
    unsafe { chunk.commit_all() };
    true
}

/// Prefetches, for writing, the slots of a snapshot ring that the next frame of `len` bytes (header
/// included) will fill: lines the consumer's core last read, brought over before the push needs them. Nothing
/// is written or committed (an uncommitted chunk leaves the ring as it was).
pub fn prefetch_next_frame(ring: &mut Producer<u8>, len: usize) {
    if let Ok(mut chunk) = ring.write_chunk_uninit(FRAME_HEADER + len) {
        let (a, b) = chunk.as_mut_slices();
        prefetch_for_write(a);
        prefetch_for_write(b);
    }
}

/// Writes `src` at byte `at` of the concatenation of `a` and `b` (a ring chunk's two halves), which must
/// have room for it.
fn write_at(a: &mut [MaybeUninit<u8>], b: &mut [MaybeUninit<u8>], at: usize, src: &[u8]) {
    let in_a = a.len().saturating_sub(at).min(src.len());
    if in_a > 0 {
        copy_into(&mut a[at..at + in_a], &src[..in_a]);
    }
    let rest = &src[in_a..];
    if !rest.is_empty() {
        let b_at = at + in_a - a.len();
        copy_into(&mut b[b_at..b_at + rest.len()], rest);
    }
}

/// Copies `src` into the equally long `dst` (the compiler makes it one `memcpy`).
fn copy_into(dst: &mut [MaybeUninit<u8>], src: &[u8]) {
    for (d, s) in dst.iter_mut().zip(src) {
        d.write(*s);
    }
}

/// Reads every complete frame from a snapshot ring and keeps the newest in `out` (latest wins); returns
/// how many frames were read.
pub fn take_latest_frame(ring: &mut Consumer<u8>, out: &mut Vec<u8>) -> usize {
    let mut frames = 0;
    loop {
        let len = {
            let Ok(header) = ring.read_chunk(FRAME_HEADER) else { break };
            let (a, b) = header.as_slices();
            let mut bytes = [0u8; FRAME_HEADER];
            for (dst, src) in bytes.iter_mut().zip(a.iter().chain(b)) {
                *dst = *src;
            }
            u32::from_le_bytes(bytes) as usize
        };
        // The writer commits a frame whole, so the body is there whenever its header is.
        let Ok(chunk) = ring.read_chunk(FRAME_HEADER + len) else { break };
        let (a, b) = chunk.as_slices();
        out.clear();
        // Skip the header, which may itself straddle the wrap.
        let skip_a = FRAME_HEADER.min(a.len());
        out.extend_from_slice(&a[skip_a..]);
        out.extend_from_slice(&b[FRAME_HEADER - skip_a..]);
        chunk.commit_all();
        frames += 1;
    }
    frames
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_the_newest_wins() {
        let (mut tx, mut rx) = rtrb::RingBuffer::new(64);
        assert!(push_frame(&mut tx, b"first"));
        assert!(push_frame(&mut tx, b"second frame"));
        assert!(!push_frame(&mut tx, &[0u8; 60]), "no room: refused whole");
        let mut out = Vec::new();
        assert_eq!(take_latest_frame(&mut rx, &mut out), 2);
        assert_eq!(out, b"second frame");
        assert_eq!(take_latest_frame(&mut rx, &mut out), 0);
        // Wrapping around the ring's end.
        for i in 0..20u8 {
            assert!(push_frame(&mut tx, &[i; 13]));
            assert_eq!(take_latest_frame(&mut rx, &mut out), 1);
            assert_eq!(out, [i; 13]);
        }
    }

    #[test]
    fn prefetching_the_next_frame_leaves_the_ring_as_it_was() {
        let (mut tx, mut rx) = rtrb::RingBuffer::new(64);
        assert!(push_frame(&mut tx, b"kept"));
        let free = tx.slots();
        prefetch_next_frame(&mut tx, 20);
        prefetch_next_frame(&mut tx, 1000);
        assert_eq!(tx.slots(), free, "nothing committed");
        let mut out = Vec::new();
        assert_eq!(take_latest_frame(&mut rx, &mut out), 1);
        assert_eq!(out, b"kept");
        // Across the ring's end, the prefetch's two halves.
        for i in 0..20u8 {
            prefetch_next_frame(&mut tx, 13);
            assert!(push_frame(&mut tx, &[i; 13]));
            assert_eq!(take_latest_frame(&mut rx, &mut out), 1);
            assert_eq!(out, [i; 13]);
        }
    }
}
