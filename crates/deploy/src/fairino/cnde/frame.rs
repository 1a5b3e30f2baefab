//! CNDE frames: `5A 5A | count u8 | type u8 | len u16 LE | payload | A5 A5` (fairino-cnde.md
//! §2.1), the payloads of the control frames, and a streaming decoder.
//!
//! Written by hand: the format is a few fixed bytes around a payload, and no crate knows it.

use crate::{DeployError, Result};

/// The two head bytes of every frame (0x5A5A little-endian).
pub const HEAD: [u8; 2] = [0x5A, 0x5A];
/// The two tail bytes of every frame (0xA5A5 little-endian).
pub const TAIL: [u8; 2] = [0xA5, 0xA5];
/// Head, count, type and length: the bytes before the payload.
pub const HEADER_LEN: usize = 6;
/// Header plus tail: a frame is its payload length plus this.
pub const OVERHEAD: usize = HEADER_LEN + TAIL.len();
/// The vendor SDK reads with `recv(4096)` and takes what it gets as one frame, so frames
/// for it must not be longer than this.
pub const SDK_RECV_SIZE: usize = 4096;

/// The frame types of the protocol (§2.1). The vendor SDK sends only the output
/// config/start/stop frames and reads only messages and output data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum FrameType {
    InputConfig = 0,
    /// Client → controller: period and state names.
    OutputConfig = 1,
    /// Client → controller: start streaming.
    OutputStart = 2,
    /// Client → controller: stop streaming.
    OutputStop = 3,
    /// Controller → client: one state report.
    OutputData = 4,
    InputData = 5,
    /// Both ways: a status byte (0 = OK) and an optional text.
    Message = 6,
    SetVersion = 7,
    GetVersion = 8,
}

impl FrameType {
    /// The type for a wire byte, `None` for bytes the protocol does not define.
    pub fn from_byte(byte: u8) -> Option<Self> {
        Some(match byte {
            0 => Self::InputConfig,
            1 => Self::OutputConfig,
            2 => Self::OutputStart,
            3 => Self::OutputStop,
            4 => Self::OutputData,
            5 => Self::InputData,
            6 => Self::Message,
            7 => Self::SetVersion,
            8 => Self::GetVersion,
            _ => return None,
        })
    }
}

/// One frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// The sender's frame counter (wraps at 256; nobody checks it).
    pub count: u8,
    pub kind: FrameType,
    pub payload: Vec<u8>,
}

impl Frame {
    pub fn new(count: u8, kind: FrameType, payload: Vec<u8>) -> Self {
        Self {
            count,
            kind,
            payload,
        }
    }

    /// The wire bytes. Errors when the payload does not fit the 16-bit length.
    pub fn encode(&self) -> Result<Vec<u8>> {
        let len = u16::try_from(self.payload.len()).map_err(|_| {
            DeployError::Protocol(format!(
                "CNDE payload of {} bytes does not fit a frame (at most {})",
                self.payload.len(),
                u16::MAX
            ))
        })?;
        let mut bytes = Vec::with_capacity(self.payload.len() + OVERHEAD);
        bytes.extend_from_slice(&HEAD);
        bytes.push(self.count);
        bytes.push(self.kind as u8);
        bytes.extend_from_slice(&len.to_le_bytes());
        bytes.extend_from_slice(&self.payload);
        bytes.extend_from_slice(&TAIL);
        Ok(bytes)
    }

    /// Decodes exactly one frame from `bytes` (no more, no less), naming what is wrong.
    pub fn decode(bytes: &[u8]) -> Result<Frame> {
        match parse_at_start(bytes, usize::from(u16::MAX)) {
            Parse::Frame(frame, used) if used == bytes.len() => Ok(frame),
            Parse::Frame(_, used) => Err(DeployError::Protocol(format!(
                "CNDE: {} bytes after a {used}-byte frame",
                bytes.len() - used
            ))),
            Parse::NeedMore => Err(DeployError::Protocol(format!(
                "CNDE: truncated frame ({} bytes)",
                bytes.len()
            ))),
            Parse::Garbage(why) => Err(DeployError::Protocol(format!("CNDE: {why}"))),
        }
    }

    /// A MESSAGE frame with status 0 (OK), the reply to config, start and stop.
    pub fn message_ok(count: u8) -> Frame {
        Frame::new(count, FrameType::Message, vec![0x00])
    }

    /// A MESSAGE frame refusing a request: status 1 and a text such as `NOT_FOUND name`.
    pub fn message_error(count: u8, text: &str) -> Frame {
        let mut payload = vec![0x01];
        payload.extend_from_slice(text.as_bytes());
        Frame::new(count, FrameType::Message, payload)
    }

    /// For a MESSAGE frame: `Ok(())` for status 0, else `Err(text)`.
    pub fn message_status(&self) -> std::result::Result<(), String> {
        match self.payload.split_first() {
            Some((0, _)) => Ok(()),
            Some((status, text)) => Err(format!(
                "status {status}: {}",
                String::from_utf8_lossy(text).trim()
            )),
            None => Err("empty message".to_string()),
        }
    }
}

/// The OUTPUT_CONFIG payload: the period (u16 LE, ms) and the names joined by commas.
pub fn encode_output_config(period_ms: u16, names: &[String]) -> Vec<u8> {
    let mut payload = period_ms.to_le_bytes().to_vec();
    payload.extend_from_slice(names.join(",").as_bytes());
    payload
}

/// Reads an OUTPUT_CONFIG payload back into its period (ms) and names.
pub fn parse_output_config(payload: &[u8]) -> Result<(u16, Vec<String>)> {
    let Some((period, names)) = payload.split_first_chunk::<2>() else {
        return Err(DeployError::Protocol(format!(
            "CNDE output config of {} bytes has no period",
            payload.len()
        )));
    };
    let names = std::str::from_utf8(names)
        .map_err(|_| DeployError::Protocol("CNDE output config names are not UTF-8".into()))?;
    let names = if names.is_empty() {
        Vec::new()
    } else {
        names.split(',').map(str::to_string).collect()
    };
    Ok((u16::from_le_bytes(*period), names))
}

enum Parse {
    Frame(Frame, usize),
    NeedMore,
    Garbage(String),
}

/// Parses a frame that starts at `bytes[0]`.
fn parse_at_start(bytes: &[u8], max_payload: usize) -> Parse {
    if bytes.len() < HEADER_LEN {
        return if HEAD.starts_with(&bytes[..bytes.len().min(2)]) {
            Parse::NeedMore
        } else {
            Parse::Garbage("frame does not start with 5A 5A".into())
        };
    }
    if bytes[..2] != HEAD {
        return Parse::Garbage("frame does not start with 5A 5A".into());
    }
    let Some(kind) = FrameType::from_byte(bytes[3]) else {
        return Parse::Garbage(format!("unknown frame type {}", bytes[3]));
    };
    let len = usize::from(u16::from_le_bytes([bytes[4], bytes[5]]));
    if len > max_payload {
        return Parse::Garbage(format!(
            "frame announces {len} payload bytes, more than {max_payload}"
        ));
    }
    let end = HEADER_LEN + len;
    if bytes.len() < end + TAIL.len() {
        return Parse::NeedMore;
    }
    if bytes[end..end + TAIL.len()] != TAIL {
        return Parse::Garbage(format!("no A5 A5 tail after {len} payload bytes"));
    }
    let frame = Frame::new(bytes[2], kind, bytes[HEADER_LEN..end].to_vec());
    Parse::Frame(frame, end + TAIL.len())
}

/// Reassembles frames from a byte stream, whatever the reads cut or join, and resyncs on
/// garbage by skipping to the next `5A 5A` (the vendor SDK instead drops anything that
/// is not exactly one frame per read).
#[derive(Debug)]
pub struct FrameDecoder {
    buffer: Vec<u8>,
    max_payload: usize,
    discarded: u64,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new(usize::from(u16::MAX))
    }
}

impl FrameDecoder {
    /// A decoder that treats a header announcing more than `max_payload` bytes as garbage,
    /// so a corrupted length cannot make it wait for 64 KiB that never come.
    pub fn new(max_payload: usize) -> Self {
        Self {
            buffer: Vec::new(),
            max_payload: max_payload.min(usize::from(u16::MAX)),
            discarded: 0,
        }
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buffer.extend_from_slice(bytes);
    }

    /// The next complete frame, if the buffer holds one; skips garbage before it.
    pub fn next_frame(&mut self) -> Option<Frame> {
        loop {
            match parse_at_start(&self.buffer, self.max_payload) {
                Parse::Frame(frame, used) => {
                    self.buffer.drain(..used);
                    return Some(frame);
                }
                Parse::NeedMore => return None,
                Parse::Garbage(_) => {
                    // Skip at least one byte, then up to the next possible head.
                    let skip = self.buffer[1..]
                        .windows(2)
                        .position(|w| w == HEAD)
                        .map_or_else(
                            // Keep a trailing 5A: it may be half of the next head.
                            || self.buffer.len() - usize::from(self.buffer.last() == Some(&0x5A)),
                            |p| p + 1,
                        )
                        .max(1);
                    self.buffer.drain(..skip);
                    self.discarded += skip as u64;
                }
            }
        }
    }

    /// Bytes thrown away as garbage so far.
    pub fn discarded(&self) -> u64 {
        self.discarded
    }

    /// Bytes waiting for the rest of their frame.
    pub fn buffered(&self) -> usize {
        self.buffer.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_every_type() {
        for byte in 0..=8u8 {
            let kind = FrameType::from_byte(byte).unwrap();
            let frame = Frame::new(byte.wrapping_mul(37), kind, vec![byte; byte as usize * 3]);
            let bytes = frame.encode().unwrap();
            assert_eq!(bytes.len(), frame.payload.len() + OVERHEAD);
            assert_eq!(Frame::decode(&bytes).unwrap(), frame);
        }
        assert_eq!(FrameType::from_byte(9), None);
    }

    #[test]
    fn decode_names_the_problem() {
        let good = Frame::message_ok(0).encode().unwrap();
        let err = Frame::decode(&good[..good.len() - 1]).unwrap_err();
        assert!(err.to_string().contains("truncated"), "{err}");
        let mut bad_tail = good.clone();
        *bad_tail.last_mut().unwrap() = 0;
        assert!(
            Frame::decode(&bad_tail)
                .unwrap_err()
                .to_string()
                .contains("tail")
        );
        let mut extra = good.clone();
        extra.push(1);
        assert!(
            Frame::decode(&extra)
                .unwrap_err()
                .to_string()
                .contains("after")
        );
        let mut bad_type = good;
        bad_type[3] = 42;
        assert!(
            Frame::decode(&bad_type)
                .unwrap_err()
                .to_string()
                .contains("type 42")
        );
    }

    #[test]
    fn oversized_payload_is_an_error() {
        let frame = Frame::new(0, FrameType::OutputData, vec![0; 70_000]);
        assert!(frame.encode().is_err());
    }

    #[test]
    fn messages() {
        assert_eq!(Frame::message_ok(3).message_status(), Ok(()));
        let err = Frame::message_error(0, "NOT_FOUND foo")
            .message_status()
            .unwrap_err();
        assert!(err.contains("NOT_FOUND foo"), "{err}");
        assert!(
            Frame::new(0, FrameType::Message, vec![])
                .message_status()
                .is_err()
        );
    }

    #[test]
    fn output_config_round_trip() {
        let names = vec!["robot_state".to_string(), "actual_joint_pos".to_string()];
        let payload = encode_output_config(8, &names);
        assert_eq!(&payload[..2], &[8, 0]);
        assert_eq!(parse_output_config(&payload).unwrap(), (8, names));
        assert_eq!(parse_output_config(&[0xE8, 0x03]).unwrap(), (1000, vec![]));
        assert!(parse_output_config(&[1]).is_err());
        assert!(parse_output_config(&[8, 0, 0xFF, 0xFE]).is_err());
    }

    #[test]
    fn decoder_skips_garbage_and_keeps_half_heads() {
        let frame = Frame::new(1, FrameType::OutputData, vec![9, 8, 7]);
        let bytes = frame.encode().unwrap();
        let mut decoder = FrameDecoder::default();
        decoder.push(&[1, 2, 3, 0x5A]);
        assert_eq!(decoder.next_frame(), None);
        decoder.push(&bytes[1..]);
        // The trailing 5A of the garbage and the pushed rest form the frame.
        assert_eq!(decoder.next_frame(), Some(frame));
        assert_eq!(decoder.discarded(), 3);
        assert_eq!(decoder.buffered(), 0);
    }

    #[test]
    fn decoder_rejects_absurd_lengths() {
        let mut decoder = FrameDecoder::new(100);
        decoder.push(&[0x5A, 0x5A, 0, 4, 0xFF, 0xFF, 0, 0]);
        let good = Frame::message_ok(2);
        decoder.push(&good.encode().unwrap());
        assert_eq!(decoder.next_frame(), Some(good));
        assert_eq!(decoder.discarded(), 8);
    }
}
