//! cannelloni CAN-over-UDP framing (protocol version 2, as in cannelloni's `parser.cpp`), so a
//! `udp:` transport can be bridged to a real bus by a stock `cannelloni` instance.
//!
//! Packet: `version:u8 = 2 | op_code:u8 (0 = DATA) | seq_no:u8 | count:u16 BE` then `count`
//! frames, each `can_id:u32 BE (Linux can_id with EFF 0x8000_0000 / RTR 0x4000_0000 / ERR
//! 0x2000_0000 flags) | len:u8 (bit 0x80 = CAN FD, followed by a flags byte) | data[len]`
//! (no data bytes for RTR frames).
//!
//! Error frames (`CAN_ERR_FLAG`, as cannelloni forwards a subscribed SocketCAN's error frames:
//! class bits in the id, 8 data bytes) are refused by [`decode`] (data frames only) and
//! delivered by [`decode_items`] as [`Item::BusError`].

use crate::bus_error::BusErrorFrame;
use crate::frame::{CanFrame, EFF_MAX, SFF_MAX};

pub const VERSION: u8 = 2;
pub const OP_DATA: u8 = 0;
pub const HEADER_LEN: usize = 5;
const EFF_FLAG: u32 = 0x8000_0000;
const RTR_FLAG: u32 = 0x4000_0000;
const ERR_FLAG: u32 = 0x2000_0000;
const CANFD_FRAME: u8 = 0x80;
/// Largest encoded classic frame: id 4 + len 1 + data 8.
pub const MAX_FRAME_LEN: usize = 13;

#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("packet of {0} bytes is shorter than the 5-byte cannelloni header")]
    ShortHeader(usize),
    #[error("unsupported cannelloni version {0} (expected 2)")]
    Version(u8),
    #[error("unsupported cannelloni op code {0} (only DATA = 0)")]
    OpCode(u8),
    #[error("frame {index}: packet truncated at byte {offset}")]
    Truncated { index: u16, offset: usize },
    #[error("frame {index}: CAN FD frames are not supported on this bus")]
    CanFd { index: u16 },
    #[error("frame {index}: data length {len} > 8")]
    Length { index: u16, len: u8 },
    #[error("frame {index}: error frame (flag 0x20000000) on a data-frame-only decode")]
    ErrorFrame { index: u16 },
    #[error("frame {index}: id {id:#x} out of range")]
    Id { index: u16, id: u32 },
    #[error("{extra} trailing bytes after {count} frames")]
    Trailing { count: u16, extra: usize },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("output buffer too small ({have} bytes, need {need})")]
pub struct EncodeError {
    pub have: usize,
    pub need: usize,
}

/// Encodes `frames` into `out`; returns the packet length. No allocation.
pub fn encode(seq: u8, frames: &[CanFrame], out: &mut [u8]) -> Result<usize, EncodeError> {
    let need = HEADER_LEN
        + frames
            .iter()
            .map(|f| 5 + if f.is_rtr() { 0 } else { f.len() })
            .sum::<usize>();
    if out.len() < need || frames.len() > u16::MAX as usize {
        return Err(EncodeError {
            have: out.len(),
            need,
        });
    }
    out[0] = VERSION;
    out[1] = OP_DATA;
    out[2] = seq;
    out[3..5].copy_from_slice(&(frames.len() as u16).to_be_bytes());
    let mut p = HEADER_LEN;
    for f in frames {
        let mut id = f.id();
        if f.is_extended() {
            id |= EFF_FLAG;
        }
        if f.is_rtr() {
            id |= RTR_FLAG;
        }
        out[p..p + 4].copy_from_slice(&id.to_be_bytes());
        out[p + 4] = f.len() as u8;
        p += 5;
        if !f.is_rtr() {
            out[p..p + f.len()].copy_from_slice(f.data());
            p += f.len();
        }
    }
    Ok(p)
}

/// One frame of a packet: a data/remote frame or an error frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    Frame(CanFrame),
    BusError(BusErrorFrame),
}

/// Encodes one error frame (class bits | `CAN_ERR_FLAG`, len 8) into `out`; returns the
/// packet length.
pub fn encode_bus_error(
    seq: u8,
    error: &BusErrorFrame,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let need = HEADER_LEN + MAX_FRAME_LEN;
    if out.len() < need {
        return Err(EncodeError {
            have: out.len(),
            need,
        });
    }
    out[0] = VERSION;
    out[1] = OP_DATA;
    out[2] = seq;
    out[3..5].copy_from_slice(&1u16.to_be_bytes());
    out[5..9].copy_from_slice(&(error.class() | ERR_FLAG).to_be_bytes());
    out[9] = 8;
    out[10..18].copy_from_slice(error.data());
    Ok(need)
}

/// Like [`decode`], but error frames are delivered as [`Item::BusError`] instead of refusing
/// the packet. Validates the whole packet before delivering anything.
pub fn decode_items(packet: &[u8], mut sink: impl FnMut(Item)) -> Result<(u8, u16), DecodeError> {
    let count = header(packet)?;
    walk(packet, count, true, &mut |_| {})?;
    walk(packet, count, true, &mut |i| sink(i)).map(|_| (packet[2], count))
}

/// Decodes a packet, calling `sink` for every frame in order. Validates the WHOLE packet before
/// delivering anything, so a malformed packet delivers no frame (nothing half-applied).
/// Returns `(seq_no, frame count)`.
pub fn decode(packet: &[u8], mut sink: impl FnMut(CanFrame)) -> Result<(u8, u16), DecodeError> {
    let count = header(packet)?;
    walk(packet, count, false, &mut |_| {})?;
    walk(packet, count, false, &mut |i| {
        if let Item::Frame(f) = i {
            sink(f)
        }
    })
    .map(|_| (packet[2], count))
}

fn header(packet: &[u8]) -> Result<u16, DecodeError> {
    if packet.len() < HEADER_LEN {
        return Err(DecodeError::ShortHeader(packet.len()));
    }
    if packet[0] != VERSION {
        return Err(DecodeError::Version(packet[0]));
    }
    if packet[1] != OP_DATA {
        return Err(DecodeError::OpCode(packet[1]));
    }
    Ok(u16::from_be_bytes([packet[3], packet[4]]))
}

fn walk(
    packet: &[u8],
    count: u16,
    errors: bool,
    sink: &mut dyn FnMut(Item),
) -> Result<(), DecodeError> {
    let mut p = HEADER_LEN;
    for index in 0..count {
        let Some(hdr) = packet.get(p..p + 5) else {
            return Err(DecodeError::Truncated {
                index,
                offset: packet.len(),
            });
        };
        let raw = u32::from_be_bytes([hdr[0], hdr[1], hdr[2], hdr[3]]);
        let len_byte = hdr[4];
        p += 5;
        if len_byte & CANFD_FRAME != 0 {
            return Err(DecodeError::CanFd { index });
        }
        if len_byte > 8 {
            return Err(DecodeError::Length {
                index,
                len: len_byte,
            });
        }
        if raw & ERR_FLAG != 0 {
            if !errors || raw & RTR_FLAG != 0 {
                return Err(DecodeError::ErrorFrame { index });
            }
            let Some(d) = packet.get(p..p + len_byte as usize) else {
                return Err(DecodeError::Truncated {
                    index,
                    offset: packet.len(),
                });
            };
            p += len_byte as usize;
            sink(Item::BusError(BusErrorFrame::new(raw & EFF_MAX, d)));
            continue;
        }
        let extended = raw & EFF_FLAG != 0;
        let rtr = raw & RTR_FLAG != 0;
        let id = raw & EFF_MAX;
        if !extended && id > SFF_MAX {
            return Err(DecodeError::Id { index, id });
        }
        let frame = if rtr {
            CanFrame::remote(id, extended, len_byte)
        } else {
            let Some(d) = packet.get(p..p + len_byte as usize) else {
                return Err(DecodeError::Truncated {
                    index,
                    offset: packet.len(),
                });
            };
            p += len_byte as usize;
            CanFrame::with_flags(id, extended, false, d)
        };
        // Ranges were checked above, so construction cannot fail; map defensively anyway.
        let frame = frame.map_err(|_| DecodeError::Id { index, id })?;
        sink(Item::Frame(frame));
    }
    if p != packet.len() {
        return Err(DecodeError::Trailing {
            count,
            extra: packet.len() - p,
        });
    }
    Ok(())
}
