//! Every message survives encode → decode unchanged, and encodes to the same bytes again.

use crate::support;

use kinloop_protocol::codec::{
    decode_control, decode_datagram, encode_control, encode_datagram, encode_datagram_into_slice, EncodeError,
};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn any_valid_datagram_round_trips((shape, message) in support::shape_and_datagram()) {
        let bytes = encode_datagram(&message).unwrap();
        let decoded = decode_datagram(&bytes, &shape).unwrap();
        prop_assert_eq!(&decoded, &message);
        prop_assert_eq!(encode_datagram(&decoded).unwrap(), bytes.clone());
        // The slice writer the VE thread uses writes the same bytes.
        let mut out = vec![0u8; bytes.len() + 7];
        let len = encode_datagram_into_slice(&message, &mut out).unwrap();
        prop_assert_eq!(&out[..len], &bytes[..]);
    }

    #[test]
    fn any_valid_control_message_round_trips(message in support::control()) {
        let bytes = encode_control(&message).unwrap();
        let decoded = decode_control(&bytes).unwrap();
        prop_assert_eq!(&decoded, &message);
        prop_assert_eq!(encode_control(&decoded).unwrap(), bytes);
    }
}

#[test]
fn snapshot_with_every_optional_part_round_trips() {
    let (shape, snapshot) = support::full_spatial_snapshot();
    let message = kinloop_protocol::Datagram::Snapshot(snapshot);
    let bytes = encode_datagram(&message).unwrap();
    assert_eq!(decode_datagram(&bytes, &shape).unwrap(), message);
}

/// A slice too short for the encoding is refused as too large, naming the encoding's length and the slice's.
#[test]
fn a_slice_too_short_for_the_snapshot_is_refused_with_both_sizes() {
    let (_, snapshot) = support::full_spatial_snapshot();
    let message = kinloop_protocol::Datagram::Snapshot(snapshot);
    let bytes = encode_datagram(&message).unwrap();
    let mut out = vec![0u8; bytes.len() - 1];
    let refused = encode_datagram_into_slice(&message, &mut out);
    assert_eq!(refused, Err(EncodeError::TooLarge { len: bytes.len(), limit: bytes.len() - 1 }));
}
