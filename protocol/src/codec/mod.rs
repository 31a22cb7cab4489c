//! Bytes ⇄ messages. The only module that names bincode, so swapping the format touches one file.
//!
//! Format: bincode 2 `config::standard()` (little-endian, varint integers and lengths, enums as a varint
//! variant index, `Option` as a 0/1 byte, `f64` as 8 raw bytes), no framing of its own. Every decode:
//! 1. refuses buffers longer than the message class allows, and runs bincode with the same limit, so a length
//!    field claiming gigabytes is refused instead of allocated (sequences additionally rely on serde's cautious
//!    pre-allocation, capped at 1 MiB, and fail as soon as the buffer runs out);
//! 2. refuses trailing bytes (bincode would silently ignore them);
//! 3. validates the result ([`validate`]): finite numbers, session dimensions, sane magnitudes.

mod error;
pub mod validate;

use bincode::config::{self, Config};
use serde::de::DeserializeOwned;
use serde::Serialize;

pub use error::{DecodeError, ElementSuffix, EncodeError, Field};

use crate::messages::{Control, Datagram};
use crate::shape::SessionShape;

/// Size and magnitude limits the codec enforces. Magnitudes are far beyond anything a real linkage or haptic
/// device produces, in any unit system of [`limits::UNIT_RANGE`]; hitting one means a broken or hostile peer.
pub mod limits {
    /// Largest control frame body (bytes).
    pub const MAX_CONTROL_FRAME_BYTES: usize = 64 * 1024;
    /// Largest datagram message (bytes), whether it travels as a QUIC datagram or on an oversize stream.
    pub const MAX_DATAGRAM_MESSAGE_BYTES: usize = 64 * 1024;
    /// Longest string (names, tokens, messages), bytes.
    pub const MAX_STRING_BYTES: usize = 256;
    /// Most entries of a list (contacts, other users, available operational points).
    pub const MAX_LIST_ENTRIES: usize = 64;
    /// Most device degrees of freedom.
    pub const MAX_DEVICE_DOF: usize = 16;
    /// Most operational axes a device may describe.
    pub const MAX_OP_DIM: usize = 6;
    /// Most generalized coordinates of a scene.
    pub const MAX_COORDINATES: usize = 1024;
    /// Most loop-closure rows of a scene.
    pub const MAX_CLOSURE_ROWS: usize = 1024;
    /// Largest position or angle component (m, rad) of a device.
    pub const MAX_POSITION: f64 = 1e3;
    /// Largest velocity component (m/s, rad/s) of a device.
    pub const MAX_SPEED: f64 = 1e3;
    /// Largest acceleration component (m/s², rad/s²) of a device.
    pub const MAX_ACCEL: f64 = 1e6;
    /// Largest force or torque component (N, N·m) of a device or a hand on it.
    pub const MAX_WRENCH: f64 = 1e4;
    /// Largest stiffness or damping gain of a device.
    pub const MAX_GAIN: f64 = 1e9;
    /// Largest entry of a device's inertia-like matrix.
    pub const MAX_MATRIX_ENTRY: f64 = 1e9;
    /// Largest entry of an orthonormal matrix, allowing for rounding.
    pub const MAX_ORTHONORMAL_ENTRY: f64 = 1.0 + UNIT_TOLERANCE;
    /// How far a unit vector's or quaternion's norm may stray from 1.
    pub const UNIT_TOLERANCE: f64 = 1e-6;
    /// Largest clock reading or age (s): about 31 years.
    pub const MAX_TIME_S: f64 = 1e9;
    /// Lowest loop or device rate (Hz).
    pub const MIN_RATE_HZ: f64 = 1.0;
    /// Highest loop or device rate (Hz).
    pub const MAX_RATE_HZ: f64 = 100_000.0;
    /// Smallest position or force scale of a mapping for an SI scene (device units per VE unit).
    pub const MIN_SCALE: f64 = 1e-4;
    /// Largest position or force scale of a mapping for an SI scene.
    pub const MAX_SCALE: f64 = 1e4;

    /// How much smaller than SI the units a scene is written in may be, on every wire bound of a scene-side
    /// quantity: its unit of length may be anything from a metre down to a millimetre and its unit of mass from
    /// a kilogram down to a gram (time is always in seconds). Device and hand quantities are SI whatever the
    /// scene's units (the bounds above). A scene-side bound (the `SCENE_` ones below, and the mapping's
    /// scales, which convert between the two) is the SI bound widened by this range to the power of the
    /// quantity's dimension in length and mass, so it holds the same physical magnitudes in every unit system
    /// of the range and still refuses garbage (a non-finite number, or one no such scene produces). Smaller
    /// units make an inverse inertia's number smaller, so its SI bound holds in every unit system of the range.
    pub const UNIT_RANGE: f64 = 1e3;
    /// Largest scene position or angle component (length units, rad): `MAX_POSITION · UNIT_RANGE`.
    pub const MAX_SCENE_POSITION: f64 = MAX_POSITION * UNIT_RANGE;
    /// Largest scene velocity component (length units/s, rad/s).
    pub const MAX_SCENE_SPEED: f64 = MAX_SPEED * UNIT_RANGE;
    /// Largest scene acceleration component (length units/s², rad/s²).
    pub const MAX_SCENE_ACCEL: f64 = MAX_ACCEL * UNIT_RANGE;
    /// Largest scene force or torque component: a torque is a mass times a length squared (over s²), so
    /// `MAX_WRENCH · UNIT_RANGE³`.
    pub const MAX_SCENE_WRENCH: f64 = MAX_WRENCH * UNIT_RANGE * UNIT_RANGE * UNIT_RANGE;
    /// Largest scene stiffness or damping gain (an angular one is a mass times a length squared):
    /// `MAX_GAIN · UNIT_RANGE³`.
    pub const MAX_SCENE_GAIN: f64 = MAX_GAIN * UNIT_RANGE * UNIT_RANGE * UNIT_RANGE;
    /// Largest entry of a scene's inertia-like matrix or Jacobian (a rotational inertia is a mass times a
    /// length squared): `MAX_MATRIX_ENTRY · UNIT_RANGE³`.
    pub const MAX_SCENE_MATRIX_ENTRY: f64 = MAX_MATRIX_ENTRY * UNIT_RANGE * UNIT_RANGE * UNIT_RANGE;
    /// Largest entry of a scene's inverse inertia (Λ⁻¹, its singular values, a contact's mobility): the SI
    /// bound, which smaller units only move away from.
    pub const MAX_SCENE_INVERSE_INERTIA: f64 = MAX_MATRIX_ENTRY;
    /// Smallest position or force scale of a mapping, asked for or chosen (device metres per scene length
    /// unit, device newtons per scene force unit: a force unit is a mass times a length, so
    /// `MIN_SCALE / UNIT_RANGE²`).
    pub const MIN_MAPPING_SCALE: f64 = MIN_SCALE / (UNIT_RANGE * UNIT_RANGE);
    /// Largest position or force scale of a mapping, asked for or chosen: `MAX_SCALE` (smaller units only make
    /// the scales smaller).
    pub const MAX_MAPPING_SCALE: f64 = MAX_SCALE;
}

use limits::{MAX_CONTROL_FRAME_BYTES, MAX_DATAGRAM_MESSAGE_BYTES};

/// Encodes a control message (frame body, without the length prefix).
pub fn encode_control(msg: &Control) -> Result<Vec<u8>, EncodeError> {
    let mut buf = Vec::new();
    encode_limited::<_, MAX_CONTROL_FRAME_BYTES>(msg, &mut buf)?;
    Ok(buf)
}

/// Decodes and validates a control frame body.
pub fn decode_control(bytes: &[u8]) -> Result<Control, DecodeError> {
    let msg = decode_limited::<Control, MAX_CONTROL_FRAME_BYTES>(bytes)?;
    validate::control(&msg)?;
    Ok(msg)
}

/// Encodes a datagram message into a fresh buffer.
pub fn encode_datagram(msg: &Datagram) -> Result<Vec<u8>, EncodeError> {
    let mut buf = Vec::new();
    encode_datagram_into(msg, &mut buf)?;
    Ok(buf)
}

/// Encodes a datagram message into `buf` (cleared first), reusing its allocation in hot loops.
pub fn encode_datagram_into(msg: &Datagram, buf: &mut Vec<u8>) -> Result<(), EncodeError> {
    encode_limited::<_, MAX_DATAGRAM_MESSAGE_BYTES>(msg, buf)
}

/// Encodes a datagram message into the start of `out`, returning its length: bincode's slice writer, without
/// a `Vec`'s growth checks at every field (the VE encodes a snapshot per user each round). An `out` shorter than
/// the datagram limit refuses what would not fit in it as too large.
pub fn encode_datagram_into_slice(msg: &Datagram, out: &mut [u8]) -> Result<usize, EncodeError> {
    let limit = out.len().min(MAX_DATAGRAM_MESSAGE_BYTES);
    match bincode::serde::encode_into_slice(msg, &mut out[..limit], config::standard()) {
        Ok(len) => Ok(len),
        Err(bincode::error::EncodeError::UnexpectedEnd) => {
            // Rare: the full encoding says how large it was.
            let mut whole = Vec::new();
            encode_datagram_into(msg, &mut whole)?;
            Err(EncodeError::TooLarge { len: whole.len(), limit })
        }
        Err(e) => Err(EncodeError::Serializer(e.to_string())),
    }
}

/// Decodes a datagram message and validates it against the session's dimensions.
pub fn decode_datagram(bytes: &[u8], shape: &SessionShape) -> Result<Datagram, DecodeError> {
    let msg = decode_limited::<Datagram, MAX_DATAGRAM_MESSAGE_BYTES>(bytes)?;
    validate::datagram(&msg, shape)?;
    Ok(msg)
}

/// Variant index of `Control::Hello` on the wire (first variant; frozen by the golden tests).
const HELLO_VARIANT: u32 = 0;

/// The version in a control frame that starts like a `Hello`, even when the rest is not this version's
/// `Hello`: lets a server refuse another version with that precise reason instead of "malformed".
pub fn peek_hello_version(body: &[u8]) -> Option<u16> {
    let config = limited_config::<MAX_CONTROL_FRAME_BYTES>();
    let ((variant, version), _read): ((u32, u16), usize) = bincode::serde::decode_from_slice(body, config).ok()?;
    (variant == HELLO_VARIANT).then_some(version)
}

fn encode_limited<T: Serialize, const LIMIT: usize>(msg: &T, buf: &mut Vec<u8>) -> Result<(), EncodeError> {
    buf.clear();
    bincode::serde::encode_into_std_write(msg, buf, config::standard())
        .map_err(|e| EncodeError::Serializer(e.to_string()))?;
    if buf.len() > LIMIT {
        return Err(EncodeError::TooLarge { len: buf.len(), limit: LIMIT });
    }
    Ok(())
}

fn decode_limited<T: DeserializeOwned, const LIMIT: usize>(bytes: &[u8]) -> Result<T, DecodeError> {
    if bytes.len() > LIMIT {
        return Err(DecodeError::TooLarge { limit: LIMIT });
    }
    let (msg, read) = bincode::serde::decode_from_slice(bytes, limited_config::<LIMIT>()).map_err(|e| match e {
        bincode::error::DecodeError::LimitExceeded => DecodeError::TooLarge { limit: LIMIT },
        other => DecodeError::Malformed(other.to_string()),
    })?;
    if read != bytes.len() {
        return Err(DecodeError::Trailing { extra: bytes.len() - read });
    }
    Ok(msg)
}

fn limited_config<const LIMIT: usize>() -> impl Config {
    config::standard().with_limit::<LIMIT>()
}
