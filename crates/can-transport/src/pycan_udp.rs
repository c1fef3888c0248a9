//! python-can's `udp_multicast` virtual bus (`can.Bus(interface="udp_multicast",
//! channel=GROUP, port=PORT)`), so this project's processes share a bus with python-can and
//! python `canopen` (interoperability tests against a CANopen stack not written here).
//!
//! Wire format (python-can 4.x, `can/interfaces/udp_multicast/utils.py`): one UDP datagram per
//! frame to GROUP:PORT, a msgpack map
//! `{timestamp: float, arbitration_id: int, is_extended_id: bool, is_remote_frame: bool,
//! is_error_frame: bool, channel: nil|str|int, dlc: int, data: bin, is_fd: bool,
//! bitrate_switch: bool, error_state_indicator: bool}` (`packb(use_bin_type=True)`).
//! Sockets as python-can's (`bus.py`): bound to the port on any address with SO_REUSEADDR +
//! SO_REUSEPORT, member of the group on the default interface, TTL/hop limit 1, multicast
//! loop on. python-can members see their own frames; this side filters its own by its
//! separate send socket's port, like [`crate::UdpBus`]. Error and CAN FD frames are counted
//! in [`CanBus::rx_errors`] and dropped (no such frames on this project's bus).

use crate::frame::{CanFrame, RxFrame};
use crate::poll::wait_readable;
use crate::udp::io;
use crate::{CanBus, CanError, monotonic_ns};
use socket2::{Domain, Protocol, SockAddr, Socket, Type};
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::Duration;

/// python-can's defaults (`UdpMulticastBus.DEFAULT_GROUP_IPv4`, port 43113).
pub const DEFAULT_GROUP: Ipv4Addr = Ipv4Addr::new(239, 74, 163, 2);
pub const DEFAULT_PORT: u16 = 43113;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("python-can msgpack message: {0}")]
pub struct MsgError(pub &'static str);

/// A decoded python-can message (what this project's buses carry, plus the flags it drops).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PyCanMessage {
    pub frame: CanFrame,
    pub is_error_frame: bool,
    pub is_fd: bool,
    pub timestamp_s: f64,
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    debug_assert!(s.len() < 32);
    out.push(0xA0 | s.len() as u8);
    out.extend_from_slice(s.as_bytes());
}

fn put_uint(out: &mut Vec<u8>, v: u32) {
    if v < 0x80 {
        out.push(v as u8);
    } else if v <= 0xFF {
        out.extend_from_slice(&[0xCC, v as u8]);
    } else if v <= 0xFFFF {
        out.push(0xCD);
        out.extend_from_slice(&(v as u16).to_be_bytes());
    } else {
        out.push(0xCE);
        out.extend_from_slice(&v.to_be_bytes());
    }
}

fn put_bool(out: &mut Vec<u8>, b: bool) {
    out.push(if b { 0xC3 } else { 0xC2 });
}

/// Encodes `frame` as python-can's `pack_message` does (same keys, same order).
pub fn encode(frame: &CanFrame, timestamp_s: f64, out: &mut Vec<u8>) {
    out.clear();
    out.push(0x8B); // fixmap, 11 entries
    put_str(out, "timestamp");
    out.push(0xCB);
    out.extend_from_slice(&timestamp_s.to_bits().to_be_bytes());
    put_str(out, "arbitration_id");
    put_uint(out, frame.id());
    put_str(out, "is_extended_id");
    put_bool(out, frame.is_extended());
    put_str(out, "is_remote_frame");
    put_bool(out, frame.is_rtr());
    put_str(out, "is_error_frame");
    put_bool(out, false);
    put_str(out, "channel");
    out.push(0xC0);
    put_str(out, "dlc");
    put_uint(out, frame.len() as u32);
    put_str(out, "data");
    let d = if frame.is_rtr() {
        &[][..]
    } else {
        frame.data()
    };
    out.extend_from_slice(&[0xC4, d.len() as u8]);
    out.extend_from_slice(d);
    put_str(out, "is_fd");
    put_bool(out, false);
    put_str(out, "bitrate_switch");
    put_bool(out, false);
    put_str(out, "error_state_indicator");
    put_bool(out, false);
}

/// A msgpack value of the kinds python-can's messages hold.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Val<'a> {
    Nil,
    Bool(bool),
    Int(i128),
    Float(f64),
    Bytes(&'a [u8]),
    Str(&'a [u8]),
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], MsgError> {
        let end = self.at.checked_add(n).ok_or(MsgError("length overflow"))?;
        let s = self.b.get(self.at..end).ok_or(MsgError("truncated"))?;
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, MsgError> {
        Ok(self.take(1)?[0])
    }
    fn be(&mut self, n: usize) -> Result<u64, MsgError> {
        Ok(self
            .take(n)?
            .iter()
            .fold(0u64, |a, &x| (a << 8) | u64::from(x)))
    }
    fn value(&mut self) -> Result<Val<'a>, MsgError> {
        let t = self.u8()?;
        Ok(match t {
            0x00..=0x7F => Val::Int(i128::from(t)),
            0xE0..=0xFF => Val::Int(i128::from(t as i8)),
            0xA0..=0xBF => Val::Str(self.take(usize::from(t & 0x1F))?),
            0xC0 => Val::Nil,
            0xC2 => Val::Bool(false),
            0xC3 => Val::Bool(true),
            0xC4 | 0xD9 => {
                let n = self.be(1)? as usize;
                let s = self.take(n)?;
                if t == 0xC4 {
                    Val::Bytes(s)
                } else {
                    Val::Str(s)
                }
            }
            0xC5 | 0xDA => {
                let n = self.be(2)? as usize;
                let s = self.take(n)?;
                if t == 0xC5 {
                    Val::Bytes(s)
                } else {
                    Val::Str(s)
                }
            }
            0xCA => Val::Float(f64::from(f32::from_bits(self.be(4)? as u32))),
            0xCB => Val::Float(f64::from_bits(self.be(8)?)),
            0xCC => Val::Int(i128::from(self.be(1)?)),
            0xCD => Val::Int(i128::from(self.be(2)?)),
            0xCE => Val::Int(i128::from(self.be(4)?)),
            0xCF => Val::Int(i128::from(self.be(8)?)),
            0xD0 => Val::Int(i128::from(self.be(1)? as u8 as i8)),
            0xD1 => Val::Int(i128::from(self.be(2)? as u16 as i16)),
            0xD2 => Val::Int(i128::from(self.be(4)? as u32 as i32)),
            0xD3 => Val::Int(i128::from(self.be(8)? as i64)),
            _ => return Err(MsgError("unsupported msgpack type")),
        })
    }
}

/// Decodes one python-can datagram. Never panics; unknown keys are ignored, wrong types and
/// frames this bus cannot carry are errors.
pub fn decode(datagram: &[u8]) -> Result<PyCanMessage, MsgError> {
    let mut r = Reader { b: datagram, at: 0 };
    let t = r.u8()?;
    let n = match t {
        0x80..=0x8F => usize::from(t & 0x0F),
        0xDE => r.be(2)? as usize,
        _ => return Err(MsgError("not a msgpack map")),
    };
    let (mut id, mut ext, mut rtr, mut err, mut fd) = (None, false, false, false, false);
    let (mut dlc, mut data, mut ts) = (None, None, 0.0);
    for _ in 0..n {
        let Val::Str(key) = r.value()? else {
            return Err(MsgError("map key is not a string"));
        };
        let v = r.value()?;
        let flag = |v: Val| match v {
            Val::Bool(b) => Ok(b),
            Val::Nil => Ok(false),
            _ => Err(MsgError("flag is not a bool")),
        };
        match key {
            b"arbitration_id" => match v {
                Val::Int(i) if (0..=0x1FFF_FFFF).contains(&i) => id = Some(i as u32),
                _ => return Err(MsgError("arbitration_id out of range")),
            },
            b"is_extended_id" => ext = flag(v)?,
            b"is_remote_frame" => rtr = flag(v)?,
            b"is_error_frame" => err = flag(v)?,
            b"is_fd" => fd = flag(v)?,
            b"dlc" => match v {
                Val::Int(i) if (0..=64).contains(&i) => dlc = Some(i as u8),
                _ => return Err(MsgError("dlc out of range")),
            },
            b"data" => match v {
                Val::Bytes(b) => data = Some(b),
                Val::Nil => data = Some(&[][..]),
                _ => return Err(MsgError("data is not bytes")),
            },
            b"timestamp" => match v {
                Val::Float(f) => ts = f,
                Val::Int(i) => ts = i as f64,
                _ => return Err(MsgError("timestamp is not a number")),
            },
            _ => {}
        }
    }
    let id = id.ok_or(MsgError("no arbitration_id"))?;
    let data = data.unwrap_or(&[]);
    if err || fd || data.len() > 8 {
        return Ok(PyCanMessage {
            frame: CanFrame::default(),
            is_error_frame: err,
            is_fd: fd || data.len() > 8,
            timestamp_s: ts,
        });
    }
    let frame = if rtr {
        CanFrame::remote(id, ext, dlc.unwrap_or(0).min(8)).map_err(|_| MsgError("bad RTR"))?
    } else {
        CanFrame::with_flags(id, ext, false, data).map_err(|_| MsgError("bad identifier"))?
    };
    Ok(PyCanMessage {
        frame,
        is_error_frame: false,
        is_fd: false,
        timestamp_s: ts,
    })
}

fn realtime_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

pub struct PyCanUdpBus {
    rx: UdpSocket,
    tx: UdpSocket,
    dest: SocketAddrV4,
    own_port: u16,
    name: String,
    rx_errors: u64,
    buf: [u8; 4096],
    out: Vec<u8>,
}

impl PyCanUdpBus {
    /// Joins python-can's `udp_multicast` bus `group:port` (IPv4).
    pub fn open(group: Ipv4Addr, port: u16) -> Result<Self, CanError> {
        let name = format!("pycan{port}");
        let rx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(&name, "socket"))?;
        rx.set_reuse_address(true)
            .map_err(io(&name, "SO_REUSEADDR"))?;
        rx.set_reuse_port(true).map_err(io(&name, "SO_REUSEPORT"))?;
        rx.bind(&SockAddr::from(SocketAddrV4::new(
            Ipv4Addr::UNSPECIFIED,
            port,
        )))
        .map_err(io(&name, "bind"))?;
        rx.join_multicast_v4(&group, &Ipv4Addr::UNSPECIFIED)
            .map_err(io(
                &name,
                "join multicast (python-can joins on the default interface)",
            ))?;
        rx.set_recv_buffer_size(1 << 20)
            .map_err(io(&name, "SO_RCVBUF"))?;
        rx.set_nonblocking(true).map_err(io(&name, "nonblocking"))?;
        let tx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(&name, "socket"))?;
        tx.set_multicast_loop_v4(true)
            .map_err(io(&name, "IP_MULTICAST_LOOP"))?;
        tx.set_multicast_ttl_v4(1)
            .map_err(io(&name, "IP_MULTICAST_TTL"))?;
        tx.bind(&SockAddr::from(SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, 0)))
            .map_err(io(&name, "bind"))?;
        tx.set_nonblocking(true).map_err(io(&name, "nonblocking"))?;
        let tx: UdpSocket = tx.into();
        let own_port = tx.local_addr().map_err(io(&name, "local_addr"))?.port();
        Ok(Self {
            rx: rx.into(),
            tx,
            dest: SocketAddrV4::new(group, port),
            own_port,
            name,
            rx_errors: 0,
            buf: [0; 4096],
            out: Vec::with_capacity(160),
        })
    }
}

impl CanBus for PyCanUdpBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        encode(frame, realtime_s(), &mut self.out);
        match self.tx.send_to(&self.out, self.dest) {
            Ok(_) => Ok(()),
            Err(e)
                if e.kind() == std::io::ErrorKind::WouldBlock
                    || e.raw_os_error() == Some(libc::ENOBUFS) =>
            {
                Err(CanError::TxFull {
                    iface: self.name.clone(),
                })
            }
            Err(e) => Err(CanError::Io {
                iface: self.name.clone(),
                op: "send",
                source: e,
            }),
        }
    }

    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        let deadline =
            monotonic_ns().saturating_add(timeout.as_nanos().min(u64::MAX as u128) as u64);
        loop {
            match self.rx.recv_from(&mut self.buf) {
                Ok((n, src)) => {
                    if src.port() == self.own_port {
                        continue; // our own frame looped back
                    }
                    match decode(&self.buf[..n]) {
                        Ok(m) if !m.is_error_frame && !m.is_fd => {
                            return Ok(Some(RxFrame {
                                frame: m.frame,
                                rx_monotonic_ns: monotonic_ns(),
                                kernel_rx_realtime_ns: None,
                                own: false,
                            }));
                        }
                        Ok(_) => self.rx_errors += 1,
                        Err(e) => {
                            self.rx_errors += 1;
                            tracing::warn!(iface = %self.name, error = %e, "dropping malformed python-can datagram");
                        }
                    }
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => {
                    return Err(CanError::Io {
                        iface: self.name.clone(),
                        op: "recv",
                        source: e,
                    });
                }
            }
            let now = monotonic_ns();
            if now >= deadline {
                return Ok(None);
            }
            wait_readable(self.rx.as_raw_fd(), Duration::from_nanos(deadline - now)).map_err(
                |e| CanError::Io {
                    iface: self.name.clone(),
                    op: "ppoll",
                    source: e,
                },
            )?;
        }
    }

    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        Some(self.rx.as_raw_fd())
    }
    fn interface(&self) -> &str {
        &self.name
    }

    fn rx_errors(&self) -> u64 {
        self.rx_errors
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bytes of python-can 4.6.1's `pack_message` for id 0x123, data 01 02 03, timestamp 1.5
    /// (`msgpack.packb(as_dict, use_bin_type=True)`, captured with python-can).
    const PYTHON_CAN: &str = "8ba974696d657374616d70cb3ff8000000000000ae6172626974726174696f6e5f6964cd0123ae69735f657874656e6465645f6964c2af69735f72656d6f74655f6672616d65c2ae69735f6572726f725f6672616d65c2a76368616e6e656cc0a3646c6303a464617461c403010203a569735f6664c2ae626974726174655f737769746368c2b56572726f725f73746174655f696e64696361746f72c2";

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    #[test]
    fn encodes_byte_for_byte_like_python_can() {
        let mut out = Vec::new();
        encode(&CanFrame::new(0x123, &[1, 2, 3]).unwrap(), 1.5, &mut out);
        assert_eq!(out, hex(PYTHON_CAN));
    }

    #[test]
    fn decodes_python_can_and_round_trips() {
        let m = decode(&hex(PYTHON_CAN)).unwrap();
        assert_eq!(m.frame, CanFrame::new(0x123, &[1, 2, 3]).unwrap());
        assert_eq!(m.timestamp_s, 1.5);
        let mut out = Vec::new();
        for f in [
            CanFrame::with_flags(0x1ABC_DEF0, true, false, &[9; 8]).unwrap(),
            CanFrame::new(0x7FF, &[]).unwrap(),
            CanFrame::remote(0x701, false, 1).unwrap(),
        ] {
            encode(&f, 2.0, &mut out);
            assert_eq!(decode(&out).unwrap().frame, f);
        }
    }

    #[test]
    fn error_and_fd_frames_are_flagged_and_garbage_is_an_error() {
        let mut e = hex(PYTHON_CAN);
        // is_error_frame: true
        let pos = e.windows(14).position(|w| w == b"is_error_frame").unwrap() + 14;
        e[pos] = 0xC3;
        assert!(decode(&e).unwrap().is_error_frame);
        assert!(decode(&[]).is_err());
        assert!(decode(&[0x81, 0xA1, b'x']).is_err());
        assert!(decode(&hex(&PYTHON_CAN[..60])).is_err());
    }

    proptest::proptest! {
        #[test]
        fn decode_never_panics(d in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200)) {
            let _ = decode(&d);
        }
    }
}
