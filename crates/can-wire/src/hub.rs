//! The hub's real-time loop: every bus's model advanced against CLOCK_MONOTONIC, its nodes
//! connected through `wire:` sockets (host) or vcan interfaces (guest).
//!
//! Each pass: for every bus with an event due (a frame's end of frame, or an arbitration whose
//! look-ahead has passed) or input waiting on a quiet bus, read what its nodes sent (submissions
//! carry their send stamps), advance the model (`decide_until = now − lookahead`,
//! `deliver_until = now`), send the deliveries (one message per node and pass), then sleep to
//! the next event: crs-rt's absolute-deadline sleep when every bus has one scheduled, a ppoll on
//! the quiet buses' sockets (with the same deadline) otherwise. Nothing is allocated per frame
//! and nothing is logged per frame.

use crate::config::{BusSpec, Endpoint, HubConfig};
use crate::counters::Counters;
use crate::stats::{HubBusStats, NodeEvent, ToWriter, Writer};
use can_bus_model::{Bus, BusStats, Delivery, SubmitError};
use can_transport::wire::proto::{self, Kind, MAX_MESSAGE, RECORD_LEN, Record};
use can_transport::{CanBus, RxEvent, SocketCanBus};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender};

/// Connections accepted but not registered yet, per bus.
const PENDING_MAX: usize = 16;
/// Messages read from one connection per pass (bounds one pass's work; the rest next pass).
const READ_BURST: usize = 64;
/// Frames read from one vcan port per pass.
const PORT_BURST: usize = 256;

/// Messages one recvmmsg call reads from a connection.
const MMSG: usize = 16;

// epoll tokens: kind << 48 | bus << 32 | index.
const TOKEN_LISTENER: u64 = 1 << 48;
const TOKEN_PENDING: u64 = 2 << 48;
const TOKEN_NODE: u64 = 3 << 48;
const TOKEN_KIND: u64 = 0xFFFF << 48;

#[derive(Debug, thiserror::Error)]
pub enum HubError {
    #[error("bus {bus}: {what}: {source}")]
    Io {
        bus: String,
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error("bus {bus}: {what}")]
    Setup { bus: String, what: String },
    #[error("bus {bus}: port {port}: {source}")]
    Port {
        bus: String,
        port: String,
        #[source]
        source: can_transport::CanError,
    },
}

/// One node's outgoing message (records batched per pass).
struct OutBuf {
    buf: Box<[u8; MAX_MESSAGE]>,
    len: usize,
}

struct NodeRt {
    conn: Option<OwnedFd>,
    echo: bool,
    /// A send-only node (a transmit path that receives nothing, [`Kind::RxOff`]).
    rx_off: bool,
    out: OutBuf,
    /// The node's count of frames it refused itself, as last reported.
    refused_seen: u32,
}

struct HostIo {
    path: PathBuf,
    listener: OwnedFd,
    counters: Counters,
    pending: Vec<Option<OwnedFd>>,
}

enum Io {
    Host(HostIo),
    Ports(Vec<SocketCanBus>),
}

struct BusRt {
    spec: BusSpec,
    model: Bus,
    epfd: OwnedFd,
    ep: Epolls,
    io: Io,
    nodes: Vec<NodeRt>,
    hub: Box<HubBusStats>,
    /// CLOCK_REALTIME − CLOCK_MONOTONIC, ns (vcan: kernel receive stamps are realtime).
    rt_minus_mono: i128,
}

fn io_err(bus: &str, what: &str) -> impl FnOnce(std::io::Error) -> HubError {
    let (bus, what) = (bus.to_string(), what.to_string());
    move |source| HubError::Io { bus, what, source }
}

fn epoll_add(epfd: RawFd, fd: RawFd, token: u64) -> std::io::Result<()> {
    let mut ev = libc::epoll_event {
        events: libc::EPOLLIN as u32,
        u64: token,
    };
    // SAFETY: epoll_ctl with our descriptors and a valid event.
    if unsafe { libc::epoll_ctl(epfd, libc::EPOLL_CTL_ADD, fd, &mut ev) } < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

fn epoll_del(epfd: RawFd, fd: RawFd) {
    // SAFETY: removing our descriptor from our epoll set (an error only means it was not in).
    unsafe { libc::epoll_ctl(epfd, libc::EPOLL_CTL_DEL, fd, std::ptr::null_mut()) };
}

/// A bus's descriptors are in two epoll sets: the bus's own (a quiet bus's wake-up: the hub
/// waits on it when nothing is scheduled on the bus) and the hub's (one `epoll_wait` per pass
/// finds every connection with input on any bus).
#[derive(Clone, Copy)]
struct Epolls {
    bus: RawFd,
    hub: RawFd,
    index: usize,
}

impl Epolls {
    fn add(&self, fd: RawFd, kind: u64, idx: usize) -> std::io::Result<()> {
        let token = kind | (self.index as u64) << 32 | idx as u64;
        epoll_add(self.bus, fd, token)?;
        epoll_add(self.hub, fd, token).inspect_err(|_| epoll_del(self.bus, fd))
    }
    fn del(&self, fd: RawFd) {
        epoll_del(self.bus, fd);
        epoll_del(self.hub, fd);
    }
}

/// Scratch space for recvmmsg: MMSG messages of up to MAX_MESSAGE bytes.
pub struct RecvScratch {
    bufs: Box<[[u8; MAX_MESSAGE]; MMSG]>,
}

impl RecvScratch {
    pub fn new() -> Self {
        Self {
            bufs: Box::new([[0; MAX_MESSAGE]; MMSG]),
        }
    }
}

impl Default for RecvScratch {
    fn default() -> Self {
        Self::new()
    }
}

/// CLOCK_REALTIME − CLOCK_MONOTONIC, ns.
fn realtime_minus_monotonic() -> i128 {
    let mut rt = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut rt) };
    let mono = crs_rt::monotonic_ns() as i128;
    rt.tv_sec as i128 * 1_000_000_000 + rt.tv_nsec as i128 - mono
}

/// A unix socket address for `path`.
fn unix_addr(bus: &str, path: &Path) -> Result<libc::sockaddr_un, HubError> {
    let bytes = path.as_os_str().as_encoded_bytes();
    // SAFETY: sockaddr_un is plain data; all-zero is valid.
    let mut addr: libc::sockaddr_un = unsafe { std::mem::zeroed() };
    addr.sun_family = libc::AF_UNIX as libc::sa_family_t;
    if bytes.is_empty() || bytes.len() >= addr.sun_path.len() || bytes.contains(&0) {
        return Err(HubError::Setup {
            bus: bus.into(),
            what: format!(
                "socket path {} must be 1..=107 bytes without NUL",
                path.display()
            ),
        });
    }
    for (d, s) in addr.sun_path.iter_mut().zip(bytes) {
        *d = *s as libc::c_char;
    }
    Ok(addr)
}

fn seqpacket_socket(bus: &str) -> Result<OwnedFd, HubError> {
    // SAFETY: socket(2); checked.
    let raw = unsafe {
        libc::socket(
            libc::AF_UNIX,
            libc::SOCK_SEQPACKET | libc::SOCK_NONBLOCK | libc::SOCK_CLOEXEC,
            0,
        )
    };
    if raw < 0 {
        return Err(io_err(bus, "socket")(std::io::Error::last_os_error()));
    }
    // SAFETY: a descriptor socket(2) just returned.
    Ok(unsafe { OwnedFd::from_raw_fd(raw) })
}

const ADDR_LEN: libc::socklen_t = std::mem::size_of::<libc::sockaddr_un>() as libc::socklen_t;

/// True if something accepts SOCK_SEQPACKET connections at `path` (a live hub). The probe
/// connection is closed at once, without a hello: the live hub only counts a failed handshake.
fn seqpacket_connects(bus: &str, path: &Path) -> Result<bool, HubError> {
    let addr = unix_addr(bus, path)?;
    let fd = seqpacket_socket(bus)?;
    // SAFETY: connect our socket to a filled sockaddr_un of its size.
    let rc = unsafe {
        libc::connect(
            fd.as_raw_fd(),
            (&addr as *const libc::sockaddr_un).cast(),
            ADDR_LEN,
        )
    };
    if rc == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error().raw_os_error();
    // EAGAIN: its backlog is full, but it is alive.
    Ok(e == Some(libc::EAGAIN) || e == Some(libc::EINPROGRESS))
}

/// A unix SOCK_SEQPACKET listener at `path`. A stale socket file (nobody listening) is
/// replaced; a live one, or anything that is not a socket, is refused.
fn listen_at(bus: &str, path: &Path) -> Result<OwnedFd, HubError> {
    use std::os::unix::fs::FileTypeExt;
    let addr = unix_addr(bus, path)?;
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        if !meta.file_type().is_socket() {
            return Err(HubError::Setup {
                bus: bus.into(),
                what: format!("{} exists and is not a socket", path.display()),
            });
        }
        if seqpacket_connects(bus, path)? {
            return Err(HubError::Setup {
                bus: bus.into(),
                what: format!("another process is listening on {}", path.display()),
            });
        }
        std::fs::remove_file(path).map_err(io_err(bus, "removing the stale socket"))?;
    }
    let fd = seqpacket_socket(bus)?;
    // SAFETY: bind our socket to a filled sockaddr_un of its size.
    let rc = unsafe {
        libc::bind(
            fd.as_raw_fd(),
            (&addr as *const libc::sockaddr_un).cast(),
            ADDR_LEN,
        )
    };
    if rc < 0 {
        return Err(io_err(bus, &format!("bind {}", path.display()))(
            std::io::Error::last_os_error(),
        ));
    }
    // SAFETY: listen on our bound socket.
    if unsafe { libc::listen(fd.as_raw_fd(), 64) } < 0 {
        return Err(io_err(bus, "listen")(std::io::Error::last_os_error()));
    }
    Ok(fd)
}

impl BusRt {
    fn open(
        spec: &BusSpec,
        t0: u64,
        writer: &SyncSender<ToWriter>,
        index: usize,
        hub_epfd: RawFd,
    ) -> Result<Self, HubError> {
        let name = spec.name.as_str();
        let mut model = Bus::new(spec.model_config(), t0).map_err(|e| HubError::Setup {
            bus: name.into(),
            what: e.to_string(),
        })?;
        // SAFETY: epoll_create1; checked.
        let raw = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if raw < 0 {
            return Err(io_err(name, "epoll_create1")(
                std::io::Error::last_os_error(),
            ));
        }
        // SAFETY: a descriptor epoll_create1 just returned.
        let epfd = unsafe { OwnedFd::from_raw_fd(raw) };
        let ep = Epolls {
            bus: epfd.as_raw_fd(),
            hub: hub_epfd,
            index,
        };
        let io = match &spec.endpoint {
            Endpoint::Socket(path) => {
                let listener = listen_at(name, path)?;
                ep.add(listener.as_raw_fd(), TOKEN_LISTENER, 0)
                    .map_err(io_err(name, "epoll"))?;
                let counters =
                    Counters::new(name, spec.max_nodes).map_err(io_err(name, "counter table"))?;
                Io::Host(HostIo {
                    path: path.clone(),
                    listener,
                    counters,
                    pending: (0..PENDING_MAX).map(|_| None).collect(),
                })
            }
            Endpoint::Ports(ports) => {
                let mut buses = Vec::with_capacity(ports.len());
                for p in ports {
                    let port_err = |source| HubError::Port {
                        bus: name.into(),
                        port: p.clone(),
                        source,
                    };
                    let mut b = SocketCanBus::open(p).map_err(port_err)?;
                    b.subscribe_bus_errors().map_err(port_err)?;
                    let node = model.add_node().expect("max_nodes = ports");
                    let fd = b.readiness_fd().expect("SocketCAN has a descriptor");
                    ep.add(fd, TOKEN_NODE, node)
                        .map_err(io_err(name, "epoll"))?;
                    let _ = writer.send(ToWriter::Node(NodeEvent {
                        bus: index,
                        node,
                        name: p.clone(),
                        joined: true,
                    }));
                    buses.push(b);
                }
                Io::Ports(buses)
            }
        };
        let nodes = (0..spec.max_nodes)
            .map(|_| NodeRt {
                conn: None,
                echo: false,
                rx_off: false,
                refused_seen: 0,
                out: OutBuf {
                    buf: Box::new([0; MAX_MESSAGE]),
                    len: 0,
                },
            })
            .collect();
        Ok(Self {
            spec: spec.clone(),
            model,
            epfd,
            ep,
            io,
            nodes,
            hub: Box::new(HubBusStats::new(spec.max_nodes)),
            rt_minus_mono: realtime_minus_monotonic(),
        })
    }

    /// When this bus next needs the hub: a delivery, or a decision once the look-ahead passed.
    fn due_at(&self, lookahead: u64) -> Option<u64> {
        let d = self.model.next_delivery_ns();
        let a = self.model.next_decision_ns().map(|t| t + lookahead);
        match (d, a) {
            (Some(d), Some(a)) => Some(d.min(a)),
            (d, a) => d.or(a),
        }
    }

    /// One descriptor of this bus is readable.
    fn on_ready(
        &mut self,
        token: u64,
        now: u64,
        writer: &SyncSender<ToWriter>,
        scratch: &mut RecvScratch,
    ) {
        let idx = (token & 0xFFFF_FFFF) as usize;
        match token & TOKEN_KIND {
            TOKEN_LISTENER => self.accept(),
            TOKEN_PENDING => self.register(idx, writer),
            TOKEN_NODE => match self.io {
                Io::Host(_) => self.read_node(idx, now, writer, scratch),
                Io::Ports(_) => self.read_port(idx, now),
            },
            _ => {}
        }
    }

    fn accept(&mut self) {
        let Io::Host(h) = &mut self.io else { return };
        loop {
            // SAFETY: accept4 on our listener; the result is checked.
            let raw = unsafe {
                libc::accept4(
                    h.listener.as_raw_fd(),
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                    libc::SOCK_NONBLOCK | libc::SOCK_CLOEXEC,
                )
            };
            if raw < 0 {
                return; // EAGAIN (or a failed accept: the client sees its connect fail)
            }
            // SAFETY: a descriptor accept4 just returned.
            let fd = unsafe { OwnedFd::from_raw_fd(raw) };
            let Some(slot) = h.pending.iter().position(Option::is_none) else {
                self.hub.refused_connections += 1;
                continue; // dropped: closes the connection
            };
            if self.ep.add(fd.as_raw_fd(), TOKEN_PENDING, slot).is_ok() {
                h.pending[slot] = Some(fd);
            }
        }
    }

    /// A pending connection sent its hello: it becomes a node (or is refused).
    fn register(&mut self, slot: usize, writer: &SyncSender<ToWriter>) {
        let index = self.ep.index;
        let Io::Host(h) = &mut self.io else { return };
        let Some(fd) = h.pending.get_mut(slot).and_then(Option::take) else {
            return;
        };
        let mut m = [0u8; proto::HANDSHAKE_LEN];
        // SAFETY: recv into our buffer on our descriptor.
        let n = unsafe {
            libc::recv(
                fd.as_raw_fd(),
                m.as_mut_ptr().cast(),
                m.len(),
                libc::MSG_DONTWAIT,
            )
        };
        if n < 0 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::WouldBlock {
            h.pending[slot] = Some(fd); // not there yet
            return;
        }
        // Out of the epoll sets as a pending connection (back in below as a node).
        self.ep.del(fd.as_raw_fd());
        if n <= 0 {
            return; // closed before its hello (a probe, e.g. a second hub checking the path)
        }
        let hello = if n == proto::HANDSHAKE_LEN as isize {
            proto::Hello::decode(&m).ok()
        } else {
            None
        };
        let Some(hello) = hello else {
            self.hub.protocol_errors += 1;
            return; // not a can-wire client: closed
        };
        let Some(node) = self.model.add_node() else {
            let r = proto::Refusal {
                reason: format!("all {} node slots used", self.spec.max_nodes),
            }
            .encode();
            // SAFETY: send on our descriptor from our buffer.
            unsafe {
                libc::send(
                    fd.as_raw_fd(),
                    r.as_ptr().cast(),
                    r.len(),
                    libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL,
                )
            };
            self.hub.refused_connections += 1;
            return;
        };
        let w = proto::Welcome {
            node: node as u32,
            queue_len: self.spec.queue_len as u32,
            bitrate_bps: self.spec.bitrate_bps,
            counters: h.counters.entries() as u32,
            bus: self.spec.name.clone(),
        }
        .encode();
        if proto::send_with_fd(fd.as_raw_fd(), &w, h.counters.fd()).is_err()
            || self.ep.add(fd.as_raw_fd(), TOKEN_NODE, node).is_err()
        {
            self.model.remove_node(node);
            return;
        }
        self.nodes[node].conn = Some(fd);
        let _ = writer.send(ToWriter::Node(NodeEvent {
            bus: index,
            node,
            name: hello.name,
            joined: true,
        }));
    }

    fn read_node(
        &mut self,
        node: usize,
        now: u64,
        writer: &SyncSender<ToWriter>,
        scratch: &mut RecvScratch,
    ) {
        for _ in 0..READ_BURST / MMSG {
            let Some(conn) = self.nodes[node].conn.as_ref() else {
                return;
            };
            let fd = conn.as_raw_fd();
            // SAFETY: iovec, mmsghdr are plain data; all-zero is valid.
            let mut iov: [libc::iovec; MMSG] = unsafe { std::mem::zeroed() };
            // SAFETY: as above.
            let mut hdrs: [libc::mmsghdr; MMSG] = unsafe { std::mem::zeroed() };
            for (i, (v, h)) in iov.iter_mut().zip(hdrs.iter_mut()).enumerate() {
                v.iov_base = scratch.bufs[i].as_mut_ptr().cast();
                v.iov_len = MAX_MESSAGE;
                h.msg_hdr.msg_iov = v;
                h.msg_hdr.msg_iovlen = 1;
            }
            // SAFETY: MMSG headers each pointing at one iovec over its own scratch buffer, all
            // live for the call.
            let n = unsafe {
                libc::recvmmsg(
                    fd,
                    hdrs.as_mut_ptr(),
                    MMSG as libc::c_uint,
                    libc::MSG_DONTWAIT,
                    std::ptr::null_mut(),
                )
            };
            let left = if n < 0 {
                match std::io::Error::last_os_error().kind() {
                    std::io::ErrorKind::WouldBlock => return,
                    std::io::ErrorKind::Interrupted => continue,
                    _ => true, // the connection failed
                }
            } else {
                false
            };
            let count = n.max(0) as usize;
            let mut closed = left;
            for (i, h) in hdrs.iter().take(count).enumerate() {
                let len = h.msg_len as usize;
                if len == 0 {
                    closed = true; // end of stream: the node closed its connection
                    break;
                }
                self.handle_message(node, &scratch.bufs[i][..len], now);
            }
            if closed {
                self.leave(node, writer);
                return;
            }
            if count < MMSG {
                return;
            }
        }
    }

    /// The node left (closed, or its connection failed).
    fn leave(&mut self, node: usize, writer: &SyncSender<ToWriter>) {
        self.nodes[node].conn = None; // closing removes it from both epoll sets
        self.nodes[node].echo = false;
        self.nodes[node].rx_off = false;
        self.nodes[node].out.len = 0;
        self.model.remove_node(node);
        let _ = writer.send(ToWriter::Node(NodeEvent {
            bus: self.ep.index,
            node,
            name: String::new(),
            joined: false,
        }));
    }

    /// One message from a node: its records.
    fn handle_message(&mut self, node: usize, msg: &[u8], now: u64) {
        let Ok(recs) = proto::records(msg) else {
            self.hub.protocol_errors += 1;
            return;
        };
        for r in recs {
            let Ok(rec) = proto::decode(r) else {
                self.hub.protocol_errors += 1;
                continue;
            };
            // Frames the node refused itself: the count every record carries keeps the
            // node's total exact when a notice was lost.
            let total = proto::refused_total(r);
            let new = total.wrapping_sub(self.nodes[node].refused_seen);
            self.nodes[node].refused_seen = total;
            let notices = u32::from(matches!(
                rec,
                Record::Frame {
                    kind: Kind::Refused,
                    ..
                }
            ));
            if new < notices {
                self.hub.protocol_errors += 1;
                continue;
            }
            self.model
                .record_refused_count(node, u64::from(new - notices));
            self.handle(node, rec, now);
        }
    }

    fn read_port(&mut self, node: usize, now: u64) {
        for _ in 0..PORT_BURST {
            let Io::Ports(ports) = &mut self.io else {
                return;
            };
            let ev = match ports[node].try_recv_event() {
                Ok(Some(ev)) => ev,
                Ok(None) => return,
                Err(_) => {
                    self.hub.protocol_errors += 1;
                    return;
                }
            };
            match ev {
                RxEvent::Frame(rx) => {
                    // The kernel's receive stamp is the node's send time on vcan (its write
                    // loops back at once); without one, our read time.
                    let stamp = rx
                        .kernel_rx_realtime_ns
                        .map(|rt| (rt as i128 - self.rt_minus_mono).max(0) as u64)
                        .unwrap_or(rx.rx_monotonic_ns);
                    self.handle(
                        node,
                        Record::Frame {
                            kind: Kind::Frame,
                            frame: rx.frame,
                            stamp_ns: stamp,
                            tag: 0,
                        },
                        now,
                    );
                }
                RxEvent::BusError(e) => self.handle(
                    node,
                    Record::Error {
                        error: e.error,
                        stamp_ns: e.rx_monotonic_ns,
                    },
                    now,
                ),
            }
        }
    }

    /// One record from `node`.
    fn handle(&mut self, node: usize, rec: Record, now: u64) {
        match rec {
            Record::Frame {
                kind: Kind::Frame,
                frame,
                stamp_ns,
                tag,
            } => {
                // No node sends after now: a stamp from the future is taken as now (read
                // again: the pass's `now` may predate a send read in this pass).
                let stamp_ns = if stamp_ns > now {
                    stamp_ns.min(crs_rt::monotonic_ns())
                } else {
                    stamp_ns
                };
                match self.model.submit(node, frame, stamp_ns, tag) {
                    Ok(()) => {}
                    Err(SubmitError::QueueFull { .. }) => {
                        if let Io::Host(h) = &self.io {
                            h.counters.resolve(node);
                        }
                    }
                    Err(SubmitError::NoNode(_)) => self.hub.protocol_errors += 1,
                }
            }
            Record::Frame {
                kind: Kind::Refused,
                frame,
                ..
            } => self.model.record_refused(node, &frame),
            Record::EchoOn => self.nodes[node].echo = true,
            Record::RxOff => self.nodes[node].rx_off = true,
            Record::Report => {}
            Record::Error { error, stamp_ns } => {
                self.hub.error_frames += 1;
                match &mut self.io {
                    Io::Host(_) => {
                        let mut r = [0u8; RECORD_LEN];
                        proto::encode_error(&error, stamp_ns.min(crs_rt::monotonic_ns()), &mut r);
                        for (n, nd) in self.nodes.iter_mut().enumerate() {
                            if n != node && nd.conn.is_some() && !nd.rx_off {
                                push(nd, &r, &mut self.hub.rx_dropped[n]);
                            }
                        }
                    }
                    Io::Ports(ports) => {
                        for (n, p) in ports.iter_mut().enumerate() {
                            if n != node && p.send_bus_error(&error).is_err() {
                                self.hub.rx_dropped[n] += 1;
                            }
                        }
                    }
                }
            }
            Record::Frame { .. } => self.hub.protocol_errors += 1,
        }
    }

    /// Advances the model to `now` and hands out what left the wire.
    fn advance(&mut self, now: u64, lookahead: u64) {
        let Self {
            model,
            io,
            nodes,
            hub,
            ..
        } = self;
        model.poll(now.saturating_sub(lookahead), now, &mut |d: &Delivery| {
            let late = now.saturating_sub(d.eof_ns);
            hub.lateness.saturating_record(late.max(1));
            hub.lateness_max_ns = hub.lateness_max_ns.max(late);
            match io {
                Io::Host(h) => {
                    let mut r = [0u8; RECORD_LEN];
                    proto::encode_frame(Kind::Rx, &d.frame, d.eof_ns, d.node as u32, &mut r);
                    for (n, nd) in nodes.iter_mut().enumerate() {
                        if n != d.node && nd.conn.is_some() && !nd.rx_off {
                            push(nd, &r, &mut hub.rx_dropped[n]);
                        }
                    }
                    h.counters.resolve(d.node);
                    let sender = &mut nodes[d.node];
                    if sender.echo && sender.conn.is_some() {
                        proto::encode_frame(Kind::Own, &d.frame, d.eof_ns, d.tag, &mut r);
                        push(sender, &r, &mut hub.rx_dropped[d.node]);
                    }
                }
                Io::Ports(ports) => {
                    for (n, p) in ports.iter_mut().enumerate() {
                        if n != d.node && p.send(&d.frame).is_err() {
                            hub.rx_dropped[n] += 1;
                        }
                    }
                }
            }
        });
    }

    /// Sends every node's batched records.
    fn flush(&mut self) {
        for (n, nd) in self.nodes.iter_mut().enumerate() {
            if nd.out.len > 0 {
                flush_node(nd, &mut self.hub.rx_dropped[n]);
            }
        }
    }
}

/// Appends a record to a node's message, sending it first when full.
fn push(nd: &mut NodeRt, r: &[u8; RECORD_LEN], dropped: &mut u64) {
    if nd.out.len == MAX_MESSAGE {
        flush_node(nd, dropped);
    }
    nd.out.buf[nd.out.len..nd.out.len + RECORD_LEN].copy_from_slice(r);
    nd.out.len += RECORD_LEN;
}

fn flush_node(nd: &mut NodeRt, dropped: &mut u64) {
    let len = std::mem::take(&mut nd.out.len);
    let Some(conn) = nd.conn.as_ref() else { return };
    // SAFETY: send from our buffer on our descriptor.
    let n = unsafe {
        libc::send(
            conn.as_raw_fd(),
            nd.out.buf.as_ptr().cast(),
            len,
            libc::MSG_DONTWAIT | libc::MSG_NOSIGNAL,
        )
    };
    if n < 0 {
        // The node does not read (its socket buffer is full) or is gone (noticed at its next
        // read): what it would have received is lost, like a full SocketCAN receive queue.
        *dropped += (len / RECORD_LEN) as u64;
    }
}

/// When to wake for `deadlines`: `window` after the earliest one, so that one wake-up handles
/// everything that falls due within the window (on every bus, and a bus's consecutive frames);
/// no event is handled more than `window` late. `None` without deadlines.
pub fn coalesced_wake(deadlines: &[u64], window: u64) -> Option<u64> {
    deadlines.iter().min().map(|d| d.saturating_add(window))
}

/// What [`Hub::pass`] keeps between passes (preallocated).
pub struct LoopState {
    next_stats: u64,
    dues: Vec<u64>,
    pfds: Vec<libc::pollfd>,
    to_writer: SyncSender<ToWriter>,
}

/// The running hub.
pub struct Hub {
    cfg: HubConfig,
    buses: Vec<BusRt>,
    /// Every bus's descriptors: one epoll_wait per pass finds all input.
    epfd: OwnedFd,
    scratch: RecvScratch,
    writer: Writer,
    spare_rx: Receiver<(usize, Box<BusStats>, Box<HubBusStats>)>,
    spares: Vec<Vec<(Box<BusStats>, Box<HubBusStats>)>>,
    pub wakeups: u64,
}

impl Hub {
    /// Opens every bus (sockets, interfaces) and starts the statistics writer. Once this
    /// returns, clients can connect.
    pub fn open(cfg: HubConfig, scheduler: String) -> Result<Self, HubError> {
        let t0 = crs_rt::monotonic_ns();
        // SAFETY: epoll_create1; checked.
        let raw = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if raw < 0 {
            return Err(io_err("*", "epoll_create1")(std::io::Error::last_os_error()));
        }
        // SAFETY: a descriptor epoll_create1 just returned.
        let epfd = unsafe { OwnedFd::from_raw_fd(raw) };
        let (writer, to_writer, spare_rx) = Writer::start(&cfg, t0, scheduler);
        let mut buses: Vec<BusRt> = Vec::with_capacity(cfg.buses.len());
        let mut spares = Vec::with_capacity(cfg.buses.len());
        for (i, spec) in cfg.buses.iter().enumerate() {
            let b = match BusRt::open(spec, t0, &to_writer, i, epfd.as_raw_fd()) {
                Ok(b) => b,
                Err(e) => {
                    // Nothing half-applied: the sockets of the buses opened so far go too.
                    for b in &buses {
                        if let Io::Host(h) = &b.io {
                            let _ = std::fs::remove_file(&h.path);
                        }
                    }
                    return Err(e);
                }
            };
            let cfgm = b.model.config();
            spares.push(
                (0..2)
                    .map(|_| {
                        (
                            Box::new(BusStats::new(cfgm)),
                            Box::new(HubBusStats::new(spec.max_nodes)),
                        )
                    })
                    .collect(),
            );
            buses.push(b);
        }
        Ok(Self {
            cfg,
            buses,
            epfd,
            scratch: RecvScratch::new(),
            writer,
            spare_rx,
            spares,
            wakeups: 0,
        })
    }

    /// Runs until `stop` is set (SIGTERM/SIGINT), then writes the final statistics.
    pub fn run(mut self, stop: &AtomicBool) -> Result<(), HubError> {
        let mut st = self.loop_state();
        while !stop.load(Ordering::Relaxed) {
            self.pass(&mut st);
        }
        self.finish(&st);
        Ok(())
    }

    /// The state of [`Hub::run`]'s loop, for driving it pass by pass ([`Hub::pass`]).
    pub fn loop_state(&self) -> LoopState {
        let nb = self.buses.len();
        LoopState {
            next_stats: crs_rt::monotonic_ns() + self.cfg.stats_period_ns,
            dues: Vec::with_capacity(nb),
            pfds: Vec::with_capacity(nb),
            to_writer: self.writer.sender(),
        }
    }

    /// One pass of the loop: read every bus's input, advance the buses that are due, send
    /// what left the wire, hand the statistics over when their period is up, then sleep to
    /// the next event. Allocates nothing (but when a node joins or leaves).
    pub fn pass(&mut self, st: &mut LoopState) {
        let lookahead = self.cfg.lookahead_ns;
        let period = self.cfg.stats_period_ns;
        let now = crs_rt::monotonic_ns();
        self.drain_all(now, &st.to_writer);
        for b in &mut self.buses {
            if b.due_at(lookahead).is_some_and(|t| t <= now) {
                b.advance(now, lookahead);
            }
            b.flush(); // deliveries, and error frames passed through while draining
        }
        if now >= st.next_stats {
            self.exchange_stats(now, false);
            st.next_stats += period.max(1);
            if st.next_stats <= now {
                st.next_stats = now + period;
            }
        }
        // Next wake-up: the buses' deadlines (coalesced) and the statistics tick.
        st.dues.clear();
        st.pfds.clear();
        for b in &self.buses {
            match b.due_at(lookahead) {
                Some(t) => st.dues.push(t),
                None => st.pfds.push(libc::pollfd {
                    fd: b.epfd.as_raw_fd(),
                    events: libc::POLLIN,
                    revents: 0,
                }),
            }
        }
        let wake = coalesced_wake(&st.dues, self.cfg.coalesce_ns)
            .map_or(st.next_stats, |t| t.min(st.next_stats));
        self.wakeups += 1;
        // Input on a quiet bus is stamped ≥ now, so its arbitration is due ≥ now + lookahead:
        // when the hub wakes anyway by then (plus the coalescing allowance), it need not wake
        // for the input itself.
        let horizon = crs_rt::monotonic_ns() + lookahead + self.cfg.coalesce_ns;
        if st.pfds.is_empty() || wake <= horizon {
            crs_rt::sleep_until(wake);
        } else {
            let left = wake.saturating_sub(crs_rt::monotonic_ns());
            let ts = libc::timespec {
                tv_sec: (left / 1_000_000_000) as libc::time_t,
                tv_nsec: (left % 1_000_000_000) as libc::c_long,
            };
            // SAFETY: ppoll over our pollfd array with a valid timespec; EINTR (a signal) just
            // ends the wait. Whatever became readable is read by the next pass.
            unsafe {
                libc::ppoll(
                    st.pfds.as_mut_ptr(),
                    st.pfds.len() as libc::nfds_t,
                    &ts,
                    std::ptr::null(),
                )
            };
        }
    }

    /// Reads what the nodes sent last, delivers what is complete by now, writes the final
    /// statistics (and the summary lines), removes the sockets.
    pub fn finish(mut self, st: &LoopState) {
        let now = crs_rt::monotonic_ns();
        self.drain_all(now, &st.to_writer);
        for b in &mut self.buses {
            b.advance(now, self.cfg.lookahead_ns);
            b.flush();
        }
        self.exchange_stats(now, true);
        for b in &self.buses {
            if let Io::Host(h) = &b.io {
                let _ = std::fs::remove_file(&h.path);
            }
        }
        self.writer.finish();
    }

    /// Nodes on bus `bus` now (host: connected clients).
    pub fn connected(&self, bus: usize) -> usize {
        self.buses
            .get(bus)
            .map_or(0, |b| b.nodes.iter().filter(|n| n.conn.is_some()).count())
    }

    /// Reads what arrived on every bus (new connections, hellos, submissions).
    fn drain_all(&mut self, now: u64, writer: &SyncSender<ToWriter>) {
        let mut events = [libc::epoll_event { events: 0, u64: 0 }; 128];
        loop {
            // SAFETY: epoll_wait into our array, no timeout.
            let n = unsafe { libc::epoll_wait(self.epfd.as_raw_fd(), events.as_mut_ptr(), 128, 0) };
            for ev in events.iter().take(n.max(0) as usize) {
                let token = ev.u64;
                let bus = ((token >> 32) & 0xFFFF) as usize;
                if let Some(b) = self.buses.get_mut(bus) {
                    b.on_ready(token, now, writer, &mut self.scratch);
                }
            }
            if n < 128 {
                return;
            }
        }
    }

    /// Hands each bus's statistics block to the writer and continues in a spare one.
    fn exchange_stats(&mut self, now: u64, last: bool) {
        while let Ok((i, mut m, mut h)) = self.spare_rx.try_recv() {
            m.reset();
            h.reset();
            self.spares[i].push((m, h));
        }
        let to_writer = self.writer.sender();
        for (i, b) in self.buses.iter_mut().enumerate() {
            if let Some((mut m, mut h)) = self.spares[i].pop() {
                b.model.swap_stats(&mut m);
                std::mem::swap(&mut b.hub, &mut h);
                b.rt_minus_mono = realtime_minus_monotonic();
                let _ = to_writer.send(ToWriter::Interval {
                    bus: i,
                    model: m,
                    hub: h,
                });
            }
            // No spare (the writer is behind): this block keeps accumulating until next time.
        }
        let _ = to_writer.send(ToWriter::Tick {
            now_ns: now,
            wakeups: self.wakeups,
            cpu_ns: thread_cpu_ns(),
            last,
        });
    }
}

/// CPU time of the calling thread, ns.
pub fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coalescing_wakes_a_window_after_the_earliest_deadline() {
        assert_eq!(coalesced_wake(&[], 10), None);
        assert_eq!(coalesced_wake(&[130, 100, 105], 0), Some(100));
        assert_eq!(coalesced_wake(&[130, 100, 105], 50), Some(150));
    }
}
