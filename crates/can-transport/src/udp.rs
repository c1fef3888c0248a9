//! CAN over UDP with cannelloni framing: a loopback multicast "bus" or a point-to-point link.

use crate::bus_error::{BusErrorFrame, RxBusError, RxEvent};
use crate::cannelloni::{self, Item};
use crate::frame::{CanFrame, RxFrame};
use crate::poll::wait_readable;
use crate::{CanBus, CanError, monotonic_ns};
use socket2::{Domain, Protocol, SockAddr, Socket, Type};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::Duration;

/// Frames decoded from one datagram but not yet returned (a cannelloni packet may hold many).
const PENDING: usize = 128;

pub struct UdpBus {
    rx: UdpSocket,
    /// Multicast: a separate socket whose (unique) source address identifies our own frames.
    tx: UdpSocket,
    dest: SocketAddrV4,
    own_src: Option<SocketAddr>,
    name: String,
    seq: u8,
    pending: [Item; PENDING],
    pending_len: usize,
    pending_pos: usize,
    pending_ts: u64,
    rx_errors: u64,
    bus_errors: u64,
    buf: [u8; 2048],
}

/// An I/O error of socket operation `op` on `iface` (shared by the UDP transports).
pub(crate) fn io(iface: &str, op: &'static str) -> impl FnOnce(std::io::Error) -> CanError {
    let iface = iface.to_string();
    move |source| CanError::Io { iface, op, source }
}

impl UdpBus {
    /// Joins the loopback multicast bus `group:port`. Every member receives every other member's
    /// frames; TTL 0 keeps the traffic on this host.
    pub fn multicast(group: Ipv4Addr, port: u16) -> Result<Self, CanError> {
        let name = format!("udpbus{port}");
        let rx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(&name, "socket"))?;
        rx.set_reuse_address(true)
            .map_err(io(&name, "SO_REUSEADDR"))?;
        rx.bind(&SockAddr::from(SocketAddrV4::new(group, port)))
            .map_err(io(&name, "bind"))?;
        rx.join_multicast_v4(&group, &Ipv4Addr::LOCALHOST)
            .map_err(io(&name, "join multicast"))?;
        rx.set_recv_buffer_size(1 << 20)
            .map_err(io(&name, "SO_RCVBUF"))?;
        rx.set_nonblocking(true).map_err(io(&name, "nonblocking"))?;
        let tx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
            .map_err(io(&name, "socket"))?;
        tx.set_multicast_if_v4(&Ipv4Addr::LOCALHOST)
            .map_err(io(&name, "IP_MULTICAST_IF"))?;
        tx.set_multicast_loop_v4(true)
            .map_err(io(&name, "IP_MULTICAST_LOOP"))?;
        tx.set_multicast_ttl_v4(0)
            .map_err(io(&name, "IP_MULTICAST_TTL"))?;
        tx.bind(&SockAddr::from(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0)))
            .map_err(io(&name, "bind"))?;
        tx.set_nonblocking(true).map_err(io(&name, "nonblocking"))?;
        let tx: UdpSocket = tx.into();
        let own_src = Some(tx.local_addr().map_err(io(&name, "local_addr"))?);
        Ok(Self::build(
            rx.into(),
            tx,
            SocketAddrV4::new(group, port),
            own_src,
            name,
        ))
    }

    /// Point-to-point cannelloni link: receives on `local`, sends to `remote`.
    pub fn peer(local: SocketAddrV4, remote: SocketAddrV4) -> Result<Self, CanError> {
        let name = format!("udp{}", local.port());
        let s = UdpSocket::bind(local).map_err(io(&name, "bind"))?;
        s.set_nonblocking(true).map_err(io(&name, "nonblocking"))?;
        let tx = s.try_clone().map_err(io(&name, "dup"))?;
        Ok(Self::build(s, tx, remote, None, name))
    }

    fn build(
        rx: UdpSocket,
        tx: UdpSocket,
        dest: SocketAddrV4,
        own_src: Option<SocketAddr>,
        name: String,
    ) -> Self {
        Self {
            rx,
            tx,
            dest,
            own_src,
            name,
            seq: 0,
            pending: [Item::Frame(CanFrame::default()); PENDING],
            pending_len: 0,
            pending_pos: 0,
            pending_ts: 0,
            rx_errors: 0,
            bus_errors: 0,
            buf: [0; 2048],
        }
    }

    fn send_datagram(&mut self, packet: &[u8]) -> Result<(), CanError> {
        match self.tx.send_to(packet, self.dest) {
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

    /// Reads one datagram if available; fills `pending`. Returns false if nothing was readable.
    fn read_datagram(&mut self) -> Result<bool, CanError> {
        let (n, src) = match self.rx.recv_from(&mut self.buf) {
            Ok(v) => v,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(false),
            Err(e) => {
                return Err(CanError::Io {
                    iface: self.name.clone(),
                    op: "recv",
                    source: e,
                });
            }
        };
        if Some(src) == self.own_src {
            return Ok(true); // our own frame looped back: a CAN raw socket does not see it either
        }
        let ts = monotonic_ns();
        let mut len = 0;
        let pending = &mut self.pending;
        let r = cannelloni::decode_items(&self.buf[..n], |f| {
            if len < PENDING {
                pending[len] = f;
                len += 1;
            }
        });
        match r {
            Ok((_, count)) => {
                if count as usize > PENDING {
                    self.rx_errors += 1; // frames beyond our queue are dropped, and counted
                }
                self.pending_len = len;
                self.pending_pos = 0;
                self.pending_ts = ts;
            }
            Err(e) => {
                self.rx_errors += 1;
                tracing::warn!(iface = %self.name, error = %e, "dropping malformed cannelloni packet");
            }
        }
        Ok(true)
    }
}

impl CanBus for UdpBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let mut out = [0u8; cannelloni::HEADER_LEN + cannelloni::MAX_FRAME_LEN];
        let n =
            cannelloni::encode(self.seq, std::slice::from_ref(frame), &mut out).map_err(|e| {
                CanError::Io {
                    iface: self.name.clone(),
                    op: "encode",
                    source: std::io::Error::other(e),
                }
            })?;
        self.seq = self.seq.wrapping_add(1);
        self.send_datagram(&out[..n])
    }

    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        let deadline =
            monotonic_ns().saturating_add(timeout.as_nanos().min(u64::MAX as u128) as u64);
        loop {
            if self.pending_pos < self.pending_len {
                let item = self.pending[self.pending_pos];
                self.pending_pos += 1;
                let rx_monotonic_ns = self.pending_ts;
                return Ok(Some(match item {
                    Item::Frame(frame) => RxEvent::Frame(RxFrame {
                        frame,
                        rx_monotonic_ns,
                        kernel_rx_realtime_ns: None,
                        own: false,
                    }),
                    Item::BusError(error) => {
                        self.bus_errors += 1;
                        RxEvent::BusError(RxBusError {
                            error,
                            rx_monotonic_ns,
                        })
                    }
                }));
            }
            if self.read_datagram()? {
                continue;
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

    /// Error frames travel on the UDP bus like any other frame: always "subscribed".
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        Ok(())
    }

    fn send_bus_error(&mut self, error: &BusErrorFrame) -> Result<(), CanError> {
        let mut out = [0u8; cannelloni::HEADER_LEN + cannelloni::MAX_FRAME_LEN];
        let n =
            cannelloni::encode_bus_error(self.seq, error, &mut out).map_err(|e| CanError::Io {
                iface: self.name.clone(),
                op: "encode",
                source: std::io::Error::other(e),
            })?;
        self.seq = self.seq.wrapping_add(1);
        self.send_datagram(&out[..n])
    }

    fn bus_errors(&self) -> u64 {
        self.bus_errors
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
