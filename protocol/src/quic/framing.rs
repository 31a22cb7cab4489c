//! Control messages on a QUIC stream: each frame is a 4-byte little-endian body length, then the body.

use quinn::{ReadExactError, RecvStream, SendStream, WriteError};

use crate::codec::{self, limits::MAX_CONTROL_FRAME_BYTES, DecodeError, EncodeError};
use crate::messages::Control;

/// Bytes of the length prefix.
pub const FRAME_HEADER_BYTES: usize = 4;

/// Why a control frame could not be sent or received.
#[derive(Debug, thiserror::Error)]
pub enum ControlStreamError {
    /// The message could not be encoded (a local bug).
    #[error("cannot encode control message: {0}")]
    Encode(#[from] EncodeError),
    /// Writing to the stream failed.
    #[error("cannot write control frame: {0}")]
    Write(#[from] WriteError),
    /// Reading from the stream failed.
    #[error("cannot read control frame: {0}")]
    Read(#[from] ReadExactError),
    /// The peer finished the stream between frames.
    #[error("the peer closed the control stream")]
    Closed,
    /// The length prefix announces more than a control frame may hold; nothing is allocated for it.
    #[error("control frame of {len} bytes exceeds the {limit}-byte limit")]
    TooLarge {
        /// Announced length.
        len: usize,
        /// The limit.
        limit: usize,
    },
    /// The body did not decode or validate.
    #[error("bad control message: {0}")]
    Decode(#[from] DecodeError),
}

/// A whole frame (length prefix and body) for `msg`.
pub fn encode_frame(msg: &Control) -> Result<Vec<u8>, EncodeError> {
    let body = codec::encode_control(msg)?;
    let mut frame = Vec::with_capacity(FRAME_HEADER_BYTES + body.len());
    // The codec already refused bodies over MAX_CONTROL_FRAME_BYTES, so the length fits in u32.
    frame.extend_from_slice(&(body.len() as u32).to_le_bytes());
    frame.extend_from_slice(&body);
    Ok(frame)
}

/// Body length announced by a frame header, refused when over the limit.
pub fn body_len(header: [u8; FRAME_HEADER_BYTES]) -> Result<usize, ControlStreamError> {
    let len = u32::from_le_bytes(header) as usize;
    if len > MAX_CONTROL_FRAME_BYTES {
        return Err(ControlStreamError::TooLarge { len, limit: MAX_CONTROL_FRAME_BYTES });
    }
    Ok(len)
}

/// Sends one control message.
pub async fn send_control(stream: &mut SendStream, msg: &Control) -> Result<(), ControlStreamError> {
    stream.write_all(&encode_frame(msg)?).await?;
    Ok(())
}

/// Receives one frame body without decoding it.
pub async fn recv_frame(stream: &mut RecvStream) -> Result<Vec<u8>, ControlStreamError> {
    let mut header = [0u8; FRAME_HEADER_BYTES];
    match stream.read_exact(&mut header).await {
        Ok(()) => {}
        Err(ReadExactError::FinishedEarly(0)) => return Err(ControlStreamError::Closed),
        Err(e) => return Err(e.into()),
    }
    let mut body = vec![0u8; body_len(header)?];
    stream.read_exact(&mut body).await?;
    Ok(body)
}

/// Receives and validates one control message.
pub async fn recv_control(stream: &mut RecvStream) -> Result<Control, ControlStreamError> {
    let body = recv_frame(stream).await?;
    Ok(codec::decode_control(&body)?)
}
