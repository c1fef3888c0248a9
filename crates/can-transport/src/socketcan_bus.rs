//! SocketCAN raw socket (real CAN or vcan) through the `socketcan` crate.

use crate::bus_error::{BusErrorFrame, RxBusError, RxEvent};
use crate::frame::{CanFrame, RxFrame};
use crate::poll::wait_readable;
use crate::{CanBus, CanError, monotonic_ns};
use socketcan::{CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, SocketOptions, StandardId};
use std::os::fd::AsRawFd;
use std::time::Duration;

pub struct SocketCanBus {
    sock: CanSocket,
    iface: String,
    rx_errors: u64,
    bus_errors: u64,
}

impl SocketCanBus {
    /// Opens `iface`. On a kernel without CAN (ENODEV / EAFNOSUPPORT) returns
    /// [`CanError::NoCanSupport`] naming the UDP alternative.
    pub fn open(iface: &str) -> Result<Self, CanError> {
        let sock = CanSocket::open(iface).map_err(|e| match e.raw_os_error() {
            Some(libc::EAFNOSUPPORT) => CanError::NoCanSupport {
                iface: iface.to_string(),
                errno: libc::EAFNOSUPPORT,
                what: "address family not supported: kernel built without CONFIG_CAN",
            },
            Some(libc::ENODEV) => CanError::NoCanSupport {
                iface: iface.to_string(),
                errno: libc::ENODEV,
                what: "no such CAN device (no CAN support, or the interface is not created/up)",
            },
            _ => CanError::Io {
                iface: iface.to_string(),
                op: "open",
                source: e,
            },
        })?;
        let io = |op| {
            move |source| CanError::Io {
                iface: iface.to_string(),
                op,
                source,
            }
        };
        sock.set_nonblocking(true).map_err(io("nonblocking"))?;
        // Kernel receive timestamps (SO_TIMESTAMP) where available; not fatal if refused.
        if let Err(e) = sock.set_recv_timestamp(true) {
            tracing::info!(iface, error = %e, "no kernel receive timestamps");
        }
        Ok(Self {
            sock,
            iface: iface.to_string(),
            rx_errors: 0,
            bus_errors: 0,
        })
    }
}

fn to_socketcan(f: &CanFrame) -> Option<socketcan::CanFrame> {
    let id: Id = if f.is_extended() {
        Id::Extended(ExtendedId::new(f.id())?)
    } else {
        Id::Standard(StandardId::new(u16::try_from(f.id()).ok()?)?)
    };
    if f.is_rtr() {
        socketcan::CanFrame::new_remote(id, f.len())
    } else {
        socketcan::CanFrame::new(id, f.data())
    }
}

fn from_socketcan(f: &socketcan::CanFrame) -> Option<CanFrame> {
    let (id, ext) = match f.id() {
        Id::Standard(s) => (u32::from(s.as_raw()), false),
        Id::Extended(e) => (e.as_raw(), true),
    };
    if f.is_remote_frame() {
        CanFrame::remote(id, ext, f.dlc() as u8).ok()
    } else {
        CanFrame::with_flags(id, ext, false, f.data()).ok()
    }
}

impl CanBus for SocketCanBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let f = to_socketcan(frame).ok_or(CanError::Frame(crate::FrameError::IdRange {
            id: frame.id(),
            bits: if frame.is_extended() { 29 } else { 11 },
        }))?;
        match self.sock.write_frame(&f) {
            Ok(()) => Ok(()),
            Err(e)
                if e.kind() == std::io::ErrorKind::WouldBlock
                    || e.raw_os_error() == Some(libc::ENOBUFS) =>
            {
                Err(CanError::TxFull {
                    iface: self.iface.clone(),
                })
            }
            Err(e) => Err(CanError::Io {
                iface: self.iface.clone(),
                op: "write",
                source: e,
            }),
        }
    }

    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        let deadline =
            monotonic_ns().saturating_add(timeout.as_nanos().min(u64::MAX as u128) as u64);
        loop {
            match read_raw(self.sock.as_raw_fd()) {
                Ok(raw) => {
                    let rx_monotonic_ns = monotonic_ns();
                    match socketcan::CanFrame::from(raw.frame) {
                        socketcan::CanFrame::Error(e) => {
                            self.bus_errors += 1;
                            return Ok(Some(RxEvent::BusError(RxBusError {
                                error: BusErrorFrame::new(e.error_bits(), e.data()),
                                rx_monotonic_ns,
                            })));
                        }
                        f => match from_socketcan(&f) {
                            Some(frame) => {
                                return Ok(Some(RxEvent::Frame(RxFrame {
                                    frame,
                                    rx_monotonic_ns,
                                    kernel_rx_realtime_ns: raw.kernel_realtime_ns,
                                    own: raw.own,
                                })));
                            }
                            None => {
                                self.rx_errors += 1;
                                continue;
                            }
                        },
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
                    // Not a classic CAN frame (a CAN FD frame has another size): skipped.
                    self.rx_errors += 1;
                    continue;
                }
                Err(e) => {
                    return Err(CanError::Io {
                        iface: self.iface.clone(),
                        op: "read",
                        source: e,
                    });
                }
            }
            let now = monotonic_ns();
            if now >= deadline {
                return Ok(None);
            }
            wait_readable(self.sock.as_raw_fd(), Duration::from_nanos(deadline - now)).map_err(
                |e| CanError::Io {
                    iface: self.iface.clone(),
                    op: "ppoll",
                    source: e,
                },
            )?;
        }
    }

    /// `CAN_RAW_RECV_OWN_MSGS`: the kernel hands this socket its own frames back once the
    /// controller reports them sent (on vcan: at once), marked `MSG_CONFIRM` in recvmsg's
    /// flags, which [`RxFrame::own`] carries.
    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        self.sock
            .set_recv_own_msgs(true)
            .map_err(|source| CanError::Io {
                iface: self.iface.clone(),
                op: "CAN_RAW_RECV_OWN_MSGS",
                source,
            })
    }

    /// `CAN_RAW_ERR_FILTER` with every class (`CAN_ERR_MASK`): the kernel delivers the
    /// controller's error frames (and, on vcan, any error frame another socket sends).
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        self.sock
            .set_error_filter_accept_all()
            .map_err(|source| CanError::Io {
                iface: self.iface.clone(),
                op: "CAN_RAW_ERR_FILTER",
                source,
            })
    }

    /// Writes a raw frame with `CAN_ERR_FLAG` (what `cansend vcan0 20000040#...` does): a
    /// real controller's driver would not send it onto the wire, vcan forwards it to every
    /// subscribed socket (fault injection).
    fn send_bus_error(&mut self, error: &BusErrorFrame) -> Result<(), CanError> {
        let f = socketcan::CanErrorFrame::new_error(error.class(), error.data()).map_err(|e| {
            CanError::Io {
                iface: self.iface.clone(),
                op: "error frame",
                source: std::io::Error::other(e.to_string()),
            }
        })?;
        match self.sock.write_frame(&socketcan::CanFrame::Error(f)) {
            Ok(()) => Ok(()),
            Err(e)
                if e.kind() == std::io::ErrorKind::WouldBlock
                    || e.raw_os_error() == Some(libc::ENOBUFS) =>
            {
                Err(CanError::TxFull {
                    iface: self.iface.clone(),
                })
            }
            Err(e) => Err(CanError::Io {
                iface: self.iface.clone(),
                op: "write",
                source: e,
            }),
        }
    }

    fn bus_errors(&self) -> u64 {
        self.bus_errors
    }

    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        Some(self.sock.as_raw_fd())
    }
    fn interface(&self) -> &str {
        &self.iface
    }

    /// A second raw socket on the interface: `SO_PRIORITY` 6 puts its frames in pfifo_fast's
    /// band 0, which the qdisc dequeues before band 1 (priority 0, this socket's frames), and
    /// an empty filter receives nothing. Only a priority-aware qdisc (pfifo_fast, prio) honours
    /// it; a frame the driver already took into the controller still goes first.
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        let p = Self::open(&self.iface)?;
        let io = |op| {
            let iface = self.iface.clone();
            move |source| CanError::Io { iface, op, source }
        };
        p.sock.set_filter_drop_all().map_err(io("CAN_RAW_FILTER"))?;
        p.sock
            .set_socket_option_int(
                libc::SOL_SOCKET,
                libc::SO_PRIORITY,
                crate::PRIORITY_PATH_SO_PRIORITY,
            )
            .map_err(io("SO_PRIORITY"))?;
        Ok(Some(Box::new(p)))
    }

    /// `SO_MEMINFO`'s `SK_MEMINFO_WMEM_ALLOC`: send-buffer memory still charged to the socket
    /// (a frame's until the driver has confirmed its transmission and freed it): 1 if any, 0
    /// if none; `None` if the kernel does not answer (before Linux 4.12).
    fn tx_backlog(&self) -> Option<u64> {
        let mut info = [0u32; 9]; // SK_MEMINFO_VARS
        let mut len = std::mem::size_of_val(&info) as libc::socklen_t;
        // SAFETY: getsockopt writes at most `len` bytes into `info`, which is that long.
        let r = unsafe {
            libc::getsockopt(
                self.sock.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_MEMINFO,
                info.as_mut_ptr().cast(),
                &mut len,
            )
        };
        (r == 0).then(|| u64::from(info[libc::SK_MEMINFO_WMEM_ALLOC as usize] > 0))
    }

    fn rx_errors(&self) -> u64 {
        self.rx_errors
    }
}

/// One frame as recvmsg(2) returned it.
struct RawRead {
    frame: libc::can_frame,
    /// SO_TIMESTAMPNS (CLOCK_REALTIME ns), when the socket delivers it.
    kernel_realtime_ns: Option<u64>,
    /// `MSG_CONFIRM`: our own frame, echoed after transmission (`CAN_RAW_RECV_OWN_MSGS`).
    own: bool,
}

/// Reads one classic frame with its kernel timestamp and flags (the socketcan crate's reader
/// does not return recvmsg's flags, which carry `MSG_CONFIRM`). Non-blocking per the socket;
/// a datagram that is not a classic `can_frame` is `InvalidData`.
fn read_raw(fd: std::os::fd::RawFd) -> std::io::Result<RawRead> {
    // cmsg space for one timespec (SO_TIMESTAMPNS), 8-byte aligned as cmsghdr requires.
    #[repr(C, align(8))]
    struct Ctrl([u8; 64]);
    let mut ctrl = Ctrl([0; 64]);
    // SAFETY: can_frame is plain data; all-zero is a valid value.
    let mut frame: libc::can_frame = unsafe { std::mem::zeroed() };
    let mut iov = libc::iovec {
        iov_base: (&mut frame as *mut libc::can_frame).cast(),
        iov_len: std::mem::size_of::<libc::can_frame>(),
    };
    // SAFETY: msghdr is plain data; all-zero is a valid (empty) header.
    let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl.0.as_mut_ptr().cast();
    msg.msg_controllen = ctrl.0.len() as _;
    // SAFETY: msg points at one iovec over `frame` and at `ctrl`, both live for the call.
    let n = unsafe { libc::recvmsg(fd, &mut msg, libc::MSG_TRUNC) };
    if n < 0 {
        return Err(std::io::Error::last_os_error());
    }
    if n as usize != std::mem::size_of::<libc::can_frame>() {
        return Err(std::io::ErrorKind::InvalidData.into());
    }
    let mut kernel_realtime_ns = None;
    // SAFETY: walking the control messages the kernel wrote into `ctrl` (msg_controllen was
    // updated by recvmsg); each payload is read unaligned and only when long enough.
    unsafe {
        let mut c = libc::CMSG_FIRSTHDR(&msg);
        while !c.is_null() {
            if (*c).cmsg_level == libc::SOL_SOCKET
                && (*c).cmsg_type == libc::SO_TIMESTAMPNS
                && (*c).cmsg_len as usize
                    >= libc::CMSG_LEN(std::mem::size_of::<libc::timespec>() as u32) as usize
            {
                let ts = std::ptr::read_unaligned(libc::CMSG_DATA(c).cast::<libc::timespec>());
                kernel_realtime_ns = Some(ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64);
            }
            c = libc::CMSG_NXTHDR(&msg, c);
        }
    }
    Ok(RawRead {
        frame,
        kernel_realtime_ns,
        own: msg.msg_flags & libc::MSG_CONFIRM != 0,
    })
}
