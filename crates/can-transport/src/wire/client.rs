//! The `wire:<socket path>` transport: this process is one node of a bus that the `can-wire`
//! hub runs in its bus model (the `can-bus-model` crate).
//!
//! * `send` stamps the frame with CLOCK_MONOTONIC and hands it to the hub. It refuses with
//!   [`CanError::TxFull`] at once when the node already holds `queue_len` frames not yet off
//!   the wire (sent minus resolved, the hub's counter for this node in shared memory: no
//!   system call and no round trip), like ENOBUFS from a full qdisc.
//! * Received frames carry their end-of-frame time in the model as `rx_monotonic_ns`.
//! * [`CanBus::enable_tx_echo`]: the node's own frames come back marked [`RxFrame::own`] at
//!   their end of frame.
//!
//! Nothing allocates per frame: records are encoded into and decoded from fixed buffers.

use super::proto::{self, Kind, MAX_MESSAGE, RECORD_LEN, Record};
use crate::bus_error::{BusErrorFrame, RxBusError, RxEvent};
use crate::frame::{CanFrame, RxFrame};
use crate::poll::wait_readable;
use crate::{CanBus, CanError, monotonic_ns};
use socket2::{Domain, SockAddr, Socket, Type};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// How long `connect` waits for the hub's answer.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// The hub's counter table, mapped read-only.
struct Counters {
    base: *mut libc::c_void,
    len: usize,
    slot: *const AtomicU64,
}

// SAFETY: the mapping is owned by this value and only read through an atomic; moving it to
// another thread is sound.
unsafe impl Send for Counters {}

impl Counters {
    fn map(fd: OwnedFd, entries: u32, node: u32) -> std::io::Result<Self> {
        if node >= entries {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("node {node} beyond the hub's counter table of {entries}"),
            ));
        }
        let len = entries as usize * 8;
        // SAFETY: mapping `len` bytes of a descriptor we own, read-only and shared; the result
        // is checked against MAP_FAILED before use.
        let base = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ,
                libc::MAP_SHARED,
                fd.as_raw_fd(),
                0,
            )
        };
        if base == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        // The descriptor is closed when `fd` drops; the mapping stays valid.
        Ok(Self {
            base,
            len,
            // SAFETY: node < entries, so the slot lies inside the mapping; page alignment
            // makes every 8-byte slot aligned for AtomicU64.
            slot: unsafe { base.cast::<AtomicU64>().add(node as usize) },
        })
    }

    fn resolved(&self) -> u64 {
        // SAFETY: `slot` points into the live mapping (see `map`); the hub only stores to it
        // atomically.
        unsafe { (*self.slot).load(Ordering::Acquire) }
    }
}

impl Drop for Counters {
    fn drop(&mut self) {
        // SAFETY: unmapping exactly the mapping made in `map`.
        unsafe { libc::munmap(self.base, self.len) };
    }
}

/// One node of a `can-wire` bus.
pub struct WireBus {
    sock: OwnedFd,
    /// The hub's socket (for a second connection: [`CanBus::open_priority_path`]).
    path: std::path::PathBuf,
    /// The hub's bus name (e.g. `can0`): the interface name of candump logs.
    name: String,
    node: u32,
    queue_len: u64,
    bitrate_bps: u32,
    counters: Counters,
    sent: u64,
    /// Frames refused here (queue full), reported to the hub with every record.
    refused: u32,
    echo: bool,
    errors_subscribed: bool,
    buf: Box<[u8; MAX_MESSAGE]>,
    buf_len: usize,
    buf_pos: usize,
    rx_errors: u64,
    bus_errors: u64,
}

fn io_err(iface: &str, op: &'static str) -> impl FnOnce(std::io::Error) -> CanError {
    let iface = iface.to_string();
    move |source| CanError::Io { iface, op, source }
}

/// This process's name and pid, for the hub's statistics.
fn own_name() -> String {
    let comm = std::fs::read_to_string("/proc/self/comm").unwrap_or_default();
    format!("{}[{}]", comm.trim(), std::process::id())
}

impl WireBus {
    /// Connects to the hub's socket at `path` and registers as a new node.
    pub fn connect(path: &Path) -> Result<Self, CanError> {
        Self::connect_as(path, own_name())
    }

    /// [`WireBus::connect`] with the name the hub's statistics give the node.
    fn connect_as(path: &Path, name: String) -> Result<Self, CanError> {
        let iface = format!("wire:{}", path.display());
        let sock = Socket::new(Domain::UNIX, Type::SEQPACKET.cloexec(), None)
            .map_err(io_err(&iface, "socket"))?;
        let addr = SockAddr::unix(path).map_err(io_err(&iface, "socket address"))?;
        sock.connect(&addr).map_err(io_err(
            &iface,
            "connect (is the can-wire hub running on this socket?)",
        ))?;
        sock.set_read_timeout(Some(HANDSHAKE_TIMEOUT))
            .map_err(io_err(&iface, "SO_RCVTIMEO"))?;
        let sock: OwnedFd = sock.into();
        let hello = proto::Hello { name }.encode();
        // SAFETY: sending a buffer we own on a descriptor we own.
        let n = unsafe {
            libc::send(
                sock.as_raw_fd(),
                hello.as_ptr().cast(),
                hello.len(),
                libc::MSG_NOSIGNAL,
            )
        };
        if n != hello.len() as isize {
            return Err(CanError::Io {
                iface,
                op: "send hello",
                source: std::io::Error::last_os_error(),
            });
        }
        let mut m = [0u8; proto::HANDSHAKE_LEN];
        let (n, fd) = proto::recv_with_fd(sock.as_raw_fd(), &mut m)
            .map_err(io_err(&iface, "receive the hub's welcome"))?;
        // SAFETY: a descriptor the kernel just installed for us (SCM_RIGHTS); owned from here.
        let fd = fd.map(|fd| unsafe { OwnedFd::from_raw_fd(fd) });
        let bad = |what: String| CanError::Io {
            iface: iface.clone(),
            op: "handshake",
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, what),
        };
        if n != proto::HANDSHAKE_LEN {
            return Err(bad(format!(
                "the hub answered {n} bytes (closed, or not a can-wire hub)"
            )));
        }
        if let Ok(Some(r)) = proto::Refusal::decode(&m) {
            return Err(bad(format!("the hub refused this node: {}", r.reason)));
        }
        let w = proto::Welcome::decode(&m).map_err(|e| bad(e.to_string()))?;
        let fd = fd.ok_or_else(|| bad("welcome without the counter table".into()))?;
        let counters =
            Counters::map(fd, w.counters, w.node).map_err(io_err(&iface, "map counters"))?;
        set_nonblocking(sock.as_raw_fd()).map_err(io_err(&iface, "nonblocking"))?;
        let sent = counters.resolved(); // 0 for a fresh node (slots are never reused)
        Ok(Self {
            sock,
            path: path.to_path_buf(),
            name: w.bus,
            node: w.node,
            queue_len: u64::from(w.queue_len),
            bitrate_bps: w.bitrate_bps,
            counters,
            sent,
            refused: 0,
            echo: false,
            errors_subscribed: false,
            buf: Box::new([0; MAX_MESSAGE]),
            buf_len: 0,
            buf_pos: 0,
            rx_errors: 0,
            bus_errors: 0,
        })
    }

    /// This node's index on the bus (the hub's statistics name nodes by it).
    pub fn node(&self) -> u32 {
        self.node
    }
    /// The bus's bit rate, bit/s.
    pub fn bitrate_bps(&self) -> u32 {
        self.bitrate_bps
    }
    /// Frames sent and not yet off the wire.
    pub fn in_flight(&self) -> u64 {
        self.sent.saturating_sub(self.counters.resolved())
    }

    fn send_record(&self, rec: &mut [u8; RECORD_LEN]) -> std::io::Result<()> {
        proto::set_refused_total(rec, self.refused);
        // SAFETY: sending a buffer we own on a descriptor we own.
        let n = unsafe {
            libc::send(
                self.sock.as_raw_fd(),
                rec.as_ptr().cast(),
                RECORD_LEN,
                libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL,
            )
        };
        if n < 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }

    fn map_send_err(&self, e: std::io::Error, op: &'static str) -> CanError {
        if e.kind() == std::io::ErrorKind::WouldBlock {
            CanError::TxFull {
                iface: self.name.clone(),
            }
        } else {
            CanError::Io {
                iface: self.name.clone(),
                op,
                source: e,
            }
        }
    }

    /// Reads one message from the hub if one is there; Ok(false) when none.
    fn read_message(&mut self) -> Result<bool, CanError> {
        // SAFETY: receiving into a buffer we own, of its length.
        let n = unsafe {
            libc::recv(
                self.sock.as_raw_fd(),
                self.buf.as_mut_ptr().cast(),
                MAX_MESSAGE,
                libc::MSG_DONTWAIT,
            )
        };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            return match e.kind() {
                std::io::ErrorKind::WouldBlock => Ok(false),
                std::io::ErrorKind::Interrupted => Ok(true),
                _ => Err(CanError::Io {
                    iface: self.name.clone(),
                    op: "recv",
                    source: e,
                }),
            };
        }
        if n == 0 {
            return Err(CanError::Io {
                iface: self.name.clone(),
                op: "recv",
                source: std::io::Error::new(
                    std::io::ErrorKind::ConnectionReset,
                    "the can-wire hub closed the connection",
                ),
            });
        }
        let n = n as usize;
        if !n.is_multiple_of(RECORD_LEN) {
            self.rx_errors += 1;
        }
        self.buf_len = n - n % RECORD_LEN;
        self.buf_pos = 0;
        Ok(true)
    }

    /// The next event of the buffered message, skipping what this node does not receive.
    fn next_buffered(&mut self) -> Option<RxEvent> {
        while self.buf_pos < self.buf_len {
            let rec: &[u8; RECORD_LEN] = self.buf[self.buf_pos..self.buf_pos + RECORD_LEN]
                .try_into()
                .expect("RECORD_LEN bytes");
            self.buf_pos += RECORD_LEN;
            match proto::decode(rec) {
                Ok(Record::Frame {
                    kind: kind @ (Kind::Rx | Kind::Own),
                    frame,
                    stamp_ns,
                    ..
                }) => {
                    let own = kind == Kind::Own;
                    if own && !self.echo {
                        continue;
                    }
                    return Some(RxEvent::Frame(RxFrame {
                        frame,
                        rx_monotonic_ns: stamp_ns,
                        kernel_rx_realtime_ns: None,
                        own,
                    }));
                }
                Ok(Record::Error { error, stamp_ns }) => {
                    self.bus_errors += 1;
                    if self.errors_subscribed {
                        return Some(RxEvent::BusError(RxBusError {
                            error,
                            rx_monotonic_ns: stamp_ns,
                        }));
                    }
                }
                Ok(_) | Err(_) => self.rx_errors += 1,
            }
        }
        None
    }
}

impl Drop for WireBus {
    /// Reports the final refused count (waiting up to 100 ms for room in the socket).
    fn drop(&mut self) {
        let tv = libc::timeval {
            tv_sec: 0,
            tv_usec: 100_000,
        };
        let fd = self.sock.as_raw_fd();
        // SAFETY: fcntl/setsockopt on our descriptor with a valid timeval.
        unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
            libc::setsockopt(
                fd,
                libc::SOL_SOCKET,
                libc::SO_SNDTIMEO,
                (&tv as *const libc::timeval).cast(),
                std::mem::size_of::<libc::timeval>() as libc::socklen_t,
            );
        }
        let mut rec = [0u8; RECORD_LEN];
        proto::encode_report(&mut rec);
        proto::set_refused_total(&mut rec, self.refused);
        // SAFETY: sending our buffer on our descriptor (blocking up to SO_SNDTIMEO).
        unsafe { libc::send(fd, rec.as_ptr().cast(), RECORD_LEN, libc::MSG_NOSIGNAL) };
    }
}

fn set_nonblocking(fd: RawFd) -> std::io::Result<()> {
    // SAFETY: fcntl on a descriptor we own.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    // SAFETY: as above.
    if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) } < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

impl CanBus for WireBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let stamp = monotonic_ns();
        let mut rec = [0u8; RECORD_LEN];
        if self.sent.saturating_sub(self.counters.resolved()) >= self.queue_len {
            // Tell the hub, so its statistics count the drop (best effort: when the notice
            // cannot be sent, the next record's refused count still tells the hub).
            self.refused = self.refused.wrapping_add(1);
            proto::encode_frame(Kind::Refused, frame, stamp, 0, &mut rec);
            let _ = self.send_record(&mut rec);
            return Err(CanError::TxFull {
                iface: self.name.clone(),
            });
        }
        proto::encode_frame(Kind::Frame, frame, stamp, self.sent as u32, &mut rec);
        self.send_record(&mut rec)
            .map_err(|e| self.map_send_err(e, "send"))?;
        self.sent += 1;
        Ok(())
    }

    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        let deadline =
            monotonic_ns().saturating_add(timeout.as_nanos().min(u64::MAX as u128) as u64);
        loop {
            if let Some(ev) = self.next_buffered() {
                return Ok(Some(ev));
            }
            if self.read_message()? {
                continue;
            }
            let now = monotonic_ns();
            if now >= deadline {
                return Ok(None);
            }
            wait_readable(self.sock.as_raw_fd(), Duration::from_nanos(deadline - now)).map_err(
                |e| CanError::Io {
                    iface: self.name.clone(),
                    op: "ppoll",
                    source: e,
                },
            )?;
        }
    }

    fn interface(&self) -> &str {
        &self.name
    }

    fn rx_errors(&self) -> u64 {
        self.rx_errors
    }

    /// The hub passes every error frame to every node; this node returns them from now on.
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        self.errors_subscribed = true;
        Ok(())
    }

    /// Error frames pass straight through the hub to every other node (no bus time).
    fn send_bus_error(&mut self, error: &BusErrorFrame) -> Result<(), CanError> {
        let mut rec = [0u8; RECORD_LEN];
        proto::encode_error(error, monotonic_ns(), &mut rec);
        self.send_record(&mut rec)
            .map_err(|e| self.map_send_err(e, "send"))
    }

    fn bus_errors(&self) -> u64 {
        self.bus_errors
    }

    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        let mut rec = [0u8; RECORD_LEN];
        proto::encode_echo_on(&mut rec);
        self.send_record(&mut rec)
            .map_err(|e| self.map_send_err(e, "send echo request"))?;
        self.echo = true;
        Ok(())
    }

    fn readiness_fd(&self) -> Option<RawFd> {
        Some(self.sock.as_raw_fd())
    }

    /// A second node of the same bus that receives nothing: its frames compete by identifier
    /// with every other node's queue heads, this node's included, so they never wait behind
    /// this node's queued frames (a controller's high-priority mailbox, or pfifo_fast's band 0
    /// in front of a controller that sends its lowest identifier first).
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        let p = Self::connect_as(&self.path, format!("prio {}", own_name()))?;
        let mut rec = [0u8; RECORD_LEN];
        proto::encode_rx_off(&mut rec);
        p.send_record(&mut rec)
            .map_err(|e| p.map_send_err(e, "send receive-off request"))?;
        Ok(Some(Box::new(p)))
    }

    fn tx_backlog(&self) -> Option<u64> {
        Some(self.in_flight())
    }
}
