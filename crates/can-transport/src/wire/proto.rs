//! The `wire:` protocol between a node process and the `can-wire` hub.
//!
//! One `SOCK_SEQPACKET` unix connection per node (message boundaries kept, in order, reliable;
//! unlike a shared datagram socket it is not limited to `net.unix.max_dgram_qlen` queued
//! datagrams, 10 by default, and the hub sees a node leave). The first message each way is the
//! handshake ([`Hello`], then [`Welcome`] with the bus's counter table passed as a file
//! descriptor, or [`Refusal`]); after it every message is 1..=[`MAX_RECORDS`] records of
//! [`RECORD_LEN`] bytes, little endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0 | kind ([`Kind`]) |
//! | 1 | DLC |
//! | 2 | flags: bit 0 extended, bit 1 remote |
//! | 3 | 0 |
//! | 4..8 | identifier (error class bits for [`Kind::Error`]) |
//! | 8..16 | time stamp, CLOCK_MONOTONIC ns: send time to the hub, end of frame from it |
//! | 16..20 | tag: the sender's frame number ([`Kind::Frame`], [`Kind::Own`]) or the sending node ([`Kind::Rx`]) |
//! | 20..24 | node → hub: how many frames the node has refused itself so far (all kinds) |
//! | 24..32 | data |
//!
//! The counter table (a memfd the hub maps read-write and each client read-only) holds one
//! `u64` per node: how many of its frames the hub has resolved (left the wire, or refused by
//! the model). A client's frames not yet off the wire are the ones it sent minus that count,
//! read without a system call at every send: that is its transmit queue depth.

use crate::bus_error::BusErrorFrame;
use crate::frame::CanFrame;
use std::os::fd::RawFd;

/// "CWIR".
pub const MAGIC: u32 = u32::from_le_bytes(*b"CWIR");
pub const VERSION: u16 = 1;
pub const RECORD_LEN: usize = 32;
/// Records in one message at most.
pub const MAX_RECORDS: usize = 64;
pub const MAX_MESSAGE: usize = RECORD_LEN * MAX_RECORDS;
/// Handshake messages are this long.
pub const HANDSHAKE_LEN: usize = 64;
/// Longest node name in a [`Hello`] and bus name in a [`Welcome`].
pub const NAME_LEN: usize = 40;

/// What a record says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Kind {
    /// Node → hub: a frame handed to the controller at the stamp.
    Frame = 1,
    /// Node → hub: a frame the node refused itself at the stamp (its queue was full).
    Refused = 2,
    /// Node → hub: from now on echo my frames back when they leave the wire.
    EchoOn = 3,
    /// Either way: a CAN error frame (fault injection), passed straight through.
    Error = 4,
    /// Hub → node: another node's frame, complete at the stamp (its end of frame).
    Rx = 5,
    /// Hub → node: the node's own frame, off the wire at the stamp (after [`Kind::EchoOn`]).
    Own = 6,
    /// Node → hub: only the count of refused frames (sent when the node closes).
    Report = 7,
    /// Node → hub: deliver no other node's frames or error frames to me from now on (a
    /// send-only transmit path, SocketCAN's empty receive filter).
    RxOff = 8,
}

impl Kind {
    fn from_u8(b: u8) -> Option<Self> {
        Some(match b {
            1 => Kind::Frame,
            2 => Kind::Refused,
            3 => Kind::EchoOn,
            4 => Kind::Error,
            5 => Kind::Rx,
            6 => Kind::Own,
            7 => Kind::Report,
            8 => Kind::RxOff,
            _ => return None,
        })
    }
}

/// One decoded record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Record {
    Frame {
        kind: Kind,
        frame: CanFrame,
        stamp_ns: u64,
        tag: u32,
    },
    Error {
        error: BusErrorFrame,
        stamp_ns: u64,
    },
    EchoOn,
    /// Deliver nothing to this node ([`Kind::RxOff`]).
    RxOff,
    /// The node's count of frames it refused itself ([`Kind::Report`]).
    Report,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ProtoError {
    #[error("message of {0} bytes is not a whole number of {RECORD_LEN}-byte records")]
    Length(usize),
    #[error("record of unknown kind {0}")]
    Kind(u8),
    #[error("record with an invalid frame (id {id:#x}, dlc {dlc})")]
    Frame { id: u32, dlc: u8 },
    #[error("handshake: bad magic or version (not a can-wire peer of protocol {VERSION})")]
    Handshake,
}

/// Encodes a frame record of `kind` into `out`.
pub fn encode_frame(
    kind: Kind,
    frame: &CanFrame,
    stamp_ns: u64,
    tag: u32,
    out: &mut [u8; RECORD_LEN],
) {
    *out = [0; RECORD_LEN];
    out[0] = kind as u8;
    out[1] = frame.len() as u8;
    out[2] = u8::from(frame.is_extended()) | (u8::from(frame.is_rtr()) << 1);
    out[4..8].copy_from_slice(&frame.id().to_le_bytes());
    out[8..16].copy_from_slice(&stamp_ns.to_le_bytes());
    out[16..20].copy_from_slice(&tag.to_le_bytes());
    out[24..32].copy_from_slice(frame.raw_data());
}

/// Encodes an error-frame record.
pub fn encode_error(error: &BusErrorFrame, stamp_ns: u64, out: &mut [u8; RECORD_LEN]) {
    *out = [0; RECORD_LEN];
    out[0] = Kind::Error as u8;
    out[1] = 8;
    out[4..8].copy_from_slice(&error.class().to_le_bytes());
    out[8..16].copy_from_slice(&stamp_ns.to_le_bytes());
    out[24..32].copy_from_slice(error.data());
}

/// Encodes the echo request.
pub fn encode_echo_on(out: &mut [u8; RECORD_LEN]) {
    *out = [0; RECORD_LEN];
    out[0] = Kind::EchoOn as u8;
}

/// Encodes the request to receive nothing.
pub fn encode_rx_off(out: &mut [u8; RECORD_LEN]) {
    *out = [0; RECORD_LEN];
    out[0] = Kind::RxOff as u8;
}

/// Encodes a report (only the refused count, see [`set_refused_total`]).
pub fn encode_report(out: &mut [u8; RECORD_LEN]) {
    *out = [0; RECORD_LEN];
    out[0] = Kind::Report as u8;
}

/// Node → hub: stamps `out` with the node's count of frames refused so far. Every record
/// carries it, so the hub's count is exact although a single refusal notice may be lost.
pub fn set_refused_total(out: &mut [u8; RECORD_LEN], refused: u32) {
    out[20..24].copy_from_slice(&refused.to_le_bytes());
}

/// The count [`set_refused_total`] wrote.
pub fn refused_total(rec: &[u8; RECORD_LEN]) -> u32 {
    u32::from_le_bytes([rec[20], rec[21], rec[22], rec[23]])
}

/// Decodes one record; never panics on any input.
pub fn decode(rec: &[u8; RECORD_LEN]) -> Result<Record, ProtoError> {
    let kind = Kind::from_u8(rec[0]).ok_or(ProtoError::Kind(rec[0]))?;
    let dlc = rec[1];
    let id = u32::from_le_bytes([rec[4], rec[5], rec[6], rec[7]]);
    let stamp_ns = u64::from_le_bytes(rec[8..16].try_into().expect("8 bytes"));
    let tag = u32::from_le_bytes([rec[16], rec[17], rec[18], rec[19]]);
    let data: &[u8; 8] = rec[24..32].try_into().expect("8 bytes");
    match kind {
        Kind::EchoOn => Ok(Record::EchoOn),
        Kind::RxOff => Ok(Record::RxOff),
        Kind::Report => Ok(Record::Report),
        Kind::Error => Ok(Record::Error {
            error: BusErrorFrame::new(id, data),
            stamp_ns,
        }),
        _ => {
            let ext = rec[2] & 1 != 0;
            let rtr = rec[2] & 2 != 0;
            let frame = if dlc > 8 {
                None
            } else if rtr {
                CanFrame::remote(id, ext, dlc).ok()
            } else {
                CanFrame::with_flags(id, ext, false, &data[..dlc as usize]).ok()
            };
            let frame = frame.ok_or(ProtoError::Frame { id, dlc })?;
            Ok(Record::Frame {
                kind,
                frame,
                stamp_ns,
                tag,
            })
        }
    }
}

/// The records of a message (1..=MAX_RECORDS whole records).
pub fn records(msg: &[u8]) -> Result<impl Iterator<Item = &[u8; RECORD_LEN]>, ProtoError> {
    if msg.is_empty() || !msg.len().is_multiple_of(RECORD_LEN) || msg.len() > MAX_MESSAGE {
        return Err(ProtoError::Length(msg.len()));
    }
    Ok(msg
        .chunks_exact(RECORD_LEN)
        .map(|c| c.try_into().expect("chunks_exact")))
}

fn put_name(out: &mut [u8], name: &str) {
    let b = name.as_bytes();
    let n = b.len().min(NAME_LEN);
    out[..n].copy_from_slice(&b[..n]);
}

fn get_name(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

fn check_header(m: &[u8; HANDSHAKE_LEN], kind: u8) -> Result<(), ProtoError> {
    let magic = u32::from_le_bytes([m[0], m[1], m[2], m[3]]);
    let version = u16::from_le_bytes([m[4], m[5]]);
    if magic != MAGIC || version != VERSION || m[6] != kind {
        return Err(ProtoError::Handshake);
    }
    Ok(())
}

fn header(kind: u8) -> [u8; HANDSHAKE_LEN] {
    let mut m = [0u8; HANDSHAKE_LEN];
    m[0..4].copy_from_slice(&MAGIC.to_le_bytes());
    m[4..6].copy_from_slice(&VERSION.to_le_bytes());
    m[6] = kind;
    m
}

const HELLO: u8 = 0x10;
const WELCOME: u8 = 0x11;
const REFUSAL: u8 = 0x12;

/// Node → hub, first message: who is connecting (for the statistics).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hello {
    pub name: String,
}

impl Hello {
    pub fn encode(&self) -> [u8; HANDSHAKE_LEN] {
        let mut m = header(HELLO);
        put_name(&mut m[8..8 + NAME_LEN], &self.name);
        m
    }
    pub fn decode(m: &[u8; HANDSHAKE_LEN]) -> Result<Self, ProtoError> {
        check_header(m, HELLO)?;
        Ok(Self {
            name: get_name(&m[8..8 + NAME_LEN]),
        })
    }
}

/// Hub → node: the node's index, its queue length, the bus; the counter table's descriptor
/// travels with it (SCM_RIGHTS).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Welcome {
    pub node: u32,
    pub queue_len: u32,
    pub bitrate_bps: u32,
    /// Entries (nodes) of the counter table.
    pub counters: u32,
    pub bus: String,
}

impl Welcome {
    pub fn encode(&self) -> [u8; HANDSHAKE_LEN] {
        let mut m = header(WELCOME);
        m[8..12].copy_from_slice(&self.node.to_le_bytes());
        m[12..16].copy_from_slice(&self.queue_len.to_le_bytes());
        m[16..20].copy_from_slice(&self.bitrate_bps.to_le_bytes());
        m[20..24].copy_from_slice(&self.counters.to_le_bytes());
        put_name(&mut m[24..24 + NAME_LEN], &self.bus);
        m
    }
    pub fn decode(m: &[u8; HANDSHAKE_LEN]) -> Result<Self, ProtoError> {
        check_header(m, WELCOME)?;
        let u = |i: usize| u32::from_le_bytes([m[i], m[i + 1], m[i + 2], m[i + 3]]);
        Ok(Self {
            node: u(8),
            queue_len: u(12),
            bitrate_bps: u(16),
            counters: u(20),
            bus: get_name(&m[24..24 + NAME_LEN]),
        })
    }
}

/// Hub → node instead of a [`Welcome`]: why not (e.g. all node slots used).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    pub reason: String,
}

impl Refusal {
    pub fn encode(&self) -> [u8; HANDSHAKE_LEN] {
        let mut m = header(REFUSAL);
        put_name(&mut m[8..8 + NAME_LEN], &self.reason);
        m
    }
    /// `Ok(Some)` for a refusal, `Ok(None)` for another valid handshake message.
    pub fn decode(m: &[u8; HANDSHAKE_LEN]) -> Result<Option<Self>, ProtoError> {
        if check_header(m, REFUSAL).is_ok() {
            return Ok(Some(Self {
                reason: get_name(&m[8..8 + NAME_LEN]),
            }));
        }
        check_header(m, WELCOME).map(|_| None)
    }
}

/// Sends `msg` with `fd` attached (SCM_RIGHTS), non-blocking.
pub fn send_with_fd(sock: RawFd, msg: &[u8], fd: RawFd) -> std::io::Result<()> {
    #[repr(C, align(8))]
    struct Ctrl([u8; 64]);
    let mut ctrl = Ctrl([0; 64]);
    let mut iov = libc::iovec {
        iov_base: msg.as_ptr() as *mut libc::c_void,
        iov_len: msg.len(),
    };
    // SAFETY: msghdr is plain data; all-zero is a valid (empty) header.
    let mut hdr: libc::msghdr = unsafe { std::mem::zeroed() };
    hdr.msg_iov = &mut iov;
    hdr.msg_iovlen = 1;
    hdr.msg_control = ctrl.0.as_mut_ptr().cast();
    // SAFETY: CMSG_SPACE/CMSG_LEN are pure size computations.
    let (space, len) = unsafe {
        (
            libc::CMSG_SPACE(std::mem::size_of::<RawFd>() as u32),
            libc::CMSG_LEN(std::mem::size_of::<RawFd>() as u32),
        )
    };
    hdr.msg_controllen = space as _;
    // SAFETY: the control buffer is 64 bytes, more than CMSG_SPACE(4); the header points
    // into it and the data is written unaligned.
    let n = unsafe {
        let c = libc::CMSG_FIRSTHDR(&hdr);
        (*c).cmsg_level = libc::SOL_SOCKET;
        (*c).cmsg_type = libc::SCM_RIGHTS;
        (*c).cmsg_len = len as _;
        std::ptr::write_unaligned(libc::CMSG_DATA(c).cast::<RawFd>(), fd);
        libc::sendmsg(sock, &hdr, libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL)
    };
    if n < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Receives one message into `buf`, with a descriptor if one was attached (SCM_RIGHTS;
/// close-on-exec). Returns (bytes, descriptor).
pub fn recv_with_fd(sock: RawFd, buf: &mut [u8]) -> std::io::Result<(usize, Option<RawFd>)> {
    #[repr(C, align(8))]
    struct Ctrl([u8; 64]);
    let mut ctrl = Ctrl([0; 64]);
    let mut iov = libc::iovec {
        iov_base: buf.as_mut_ptr().cast(),
        iov_len: buf.len(),
    };
    // SAFETY: msghdr is plain data; all-zero is a valid (empty) header.
    let mut hdr: libc::msghdr = unsafe { std::mem::zeroed() };
    hdr.msg_iov = &mut iov;
    hdr.msg_iovlen = 1;
    hdr.msg_control = ctrl.0.as_mut_ptr().cast();
    hdr.msg_controllen = ctrl.0.len() as _;
    // SAFETY: the header points at `buf` and `ctrl`, both live for the call.
    let n = unsafe { libc::recvmsg(sock, &mut hdr, libc::MSG_CMSG_CLOEXEC) };
    if n < 0 {
        return Err(std::io::Error::last_os_error());
    }
    let mut fd = None;
    // SAFETY: walking the control messages the kernel wrote; the descriptor is read unaligned
    // and only from an SCM_RIGHTS message long enough to hold one.
    unsafe {
        let mut c = libc::CMSG_FIRSTHDR(&hdr);
        while !c.is_null() {
            if (*c).cmsg_level == libc::SOL_SOCKET
                && (*c).cmsg_type == libc::SCM_RIGHTS
                && (*c).cmsg_len as usize
                    >= libc::CMSG_LEN(std::mem::size_of::<RawFd>() as u32) as usize
            {
                fd = Some(std::ptr::read_unaligned(libc::CMSG_DATA(c).cast::<RawFd>()));
            }
            c = libc::CMSG_NXTHDR(&hdr, c);
        }
    }
    Ok((n as usize, fd))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_garbage_is_an_error_not_a_panic() {
        let frames = [
            CanFrame::new(0x201, &[1, 2, 3, 4, 5, 6]).unwrap(),
            CanFrame::with_flags(0x1ABC_DEF0, true, false, &[9; 8]).unwrap(),
            CanFrame::remote(0x701, false, 1).unwrap(),
            CanFrame::new(0x080, &[]).unwrap(),
        ];
        let mut r = [0u8; RECORD_LEN];
        for f in frames {
            encode_frame(Kind::Rx, &f, 123_456_789, 42, &mut r);
            assert_eq!(
                decode(&r).unwrap(),
                Record::Frame {
                    kind: Kind::Rx,
                    frame: f,
                    stamp_ns: 123_456_789,
                    tag: 42
                }
            );
        }
        let e = BusErrorFrame::error_passive(128, 3);
        encode_error(&e, 7, &mut r);
        assert_eq!(
            decode(&r).unwrap(),
            Record::Error {
                error: e,
                stamp_ns: 7
            }
        );
        encode_echo_on(&mut r);
        assert_eq!(decode(&r).unwrap(), Record::EchoOn);
        r[0] = 99;
        assert_eq!(decode(&r), Err(ProtoError::Kind(99)));
        encode_frame(Kind::Frame, &frames[0], 0, 0, &mut r);
        r[1] = 9;
        assert!(matches!(decode(&r), Err(ProtoError::Frame { .. })));
        r[1] = 2;
        r[2] = 0;
        r[4..8].copy_from_slice(&0x800u32.to_le_bytes()); // beyond 11 bits
        assert!(matches!(decode(&r), Err(ProtoError::Frame { .. })));
        assert!(records(&[0u8; 33]).is_err());
        assert!(records(&[]).is_err());
        assert_eq!(records(&[0u8; 64]).unwrap().count(), 2);
    }

    proptest::proptest! {
        #[test]
        fn decode_never_panics(b: [u8; RECORD_LEN]) {
            let _ = decode(&b);
        }
    }

    #[test]
    fn handshake_round_trips() {
        let h = Hello {
            name: "drive-io[1234]".into(),
        };
        assert_eq!(Hello::decode(&h.encode()).unwrap(), h);
        let w = Welcome {
            node: 3,
            queue_len: 10,
            bitrate_bps: 1_000_000,
            counters: 32,
            bus: "can0".into(),
        };
        assert_eq!(Welcome::decode(&w.encode()).unwrap(), w);
        assert_eq!(Refusal::decode(&w.encode()).unwrap(), None);
        let r = Refusal {
            reason: "all 32 node slots used".into(),
        };
        assert_eq!(Refusal::decode(&r.encode()).unwrap(), Some(r));
        assert!(Hello::decode(&w.encode()).is_err());
        assert!(Welcome::decode(&[0; HANDSHAKE_LEN]).is_err());
    }
}
