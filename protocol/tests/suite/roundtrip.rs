//! Every message survives encode → decode unchanged, and encodes to the same bytes again.

use crate::support;

use kinloop_protocol::codec::{decode_control, decode_datagram, encode_control, encode_datagram};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn any_valid_datagram_round_trips((shape, message) in support::shape_and_datagram()) {
        let bytes = encode_datagram(&message).unwrap();
        let decoded = decode_datagram(&bytes, &shape).unwrap();
        prop_assert_eq!(&decoded, &message);
        prop_assert_eq!(encode_datagram(&decoded).unwrap(), bytes);
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
