//! CAN frame transport for the CRS drive bus.
//!
//! Two implementations of [`CanBus`], chosen explicitly by a transport string (never silently):
//! * `socketcan:<iface>`: Linux SocketCAN raw socket (e.g. `socketcan:can0`, `socketcan:vcan0`).
//!   On a kernel without CAN support the open fails with [`CanError::NoCanSupport`], which names
//!   the alternative below.
//! * `udpbus:<group>:<port>`: CAN-over-UDP multicast on loopback with cannelloni framing. Every
//!   process that opens the same group/port sees every other member's frames (but not its own,
//!   like a SocketCAN raw socket), so drive-io, the plant and the safety monitor share one "bus".
//! * `udp:<local ip:port>-><remote ip:port>`: point-to-point cannelloni, to bridge a real bus
//!   through a `cannelloni` instance.
//! * `wire:<socket path>`: a node of a bus with physics (bit time, arbitration, transmit
//!   queues) that the `can-wire` hub runs; see [`wire`].
//!
//! [`candump`] formats/parses can-utils log lines and [`LoggingBus`] logs every frame.

pub mod bus_error;
pub mod candump;
pub mod cannelloni;
mod frame;
pub mod multi;
mod poll;
pub use poll::wait_readable_any;
pub mod pycan_udp;
pub mod safety_frame;
mod socketcan_bus;
mod spec;
mod udp;
pub mod wire;

pub use bus_error::{BusCondition, BusErrorFrame, RxBusError, RxEvent};
pub use candump::LoggingBus;
pub use frame::{CanFrame, FrameError, RxFrame};
pub use multi::recv_any;
pub use socketcan_bus::SocketCanBus;
pub use spec::{SpecError, TransportSpec};
pub use udp::UdpBus;

use std::time::Duration;

/// Transport errors. Never a panic on bus input.
#[derive(Debug, thiserror::Error)]
pub enum CanError {
    #[error(
        "this kernel has no SocketCAN support for {iface:?} (os error {errno}: {what}); \
         use a CAN-over-UDP transport instead, e.g. transport = \"udpbus:239.255.70.1:20000\" \
         (all processes on this host share it), or run the HIL tests in the vcan VM (tools/hil-run.sh)"
    )]
    NoCanSupport {
        iface: String,
        errno: i32,
        what: &'static str,
    },
    #[error("{op} on {iface:?} failed: {source}")]
    Io {
        iface: String,
        op: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("transmit queue of {iface:?} full (frame dropped)")]
    TxFull { iface: String },
    #[error("{iface:?} cannot carry CAN error frames")]
    NoErrorFrames { iface: String },
    #[error(
        "{iface:?} cannot echo transmitted frames (transmit confirmation needs socketcan: or wire:)"
    )]
    NoTxEcho { iface: String },
    #[error("invalid frame: {0}")]
    Frame(#[from] FrameError),
}

/// A CAN bus endpoint. Implementations deliver frames sent by OTHER endpoints only.
///
/// Receiving: a transport implements ONE of the two receive methods. One that carries error
/// frames implements [`CanBus::recv_event_timeout`] and inherits [`CanBus::recv_timeout`] (the
/// same wait with error frames filtered out); a frames-only transport implements
/// [`CanBus::recv_timeout`] and inherits [`CanBus::recv_event_timeout`]. Each default calls the
/// other, so an implementation that overrides neither recurses without end.
pub trait CanBus: Send {
    /// Queues one frame for transmission (non-blocking; [`CanError::TxFull`] if the queue is full).
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError>;
    /// Waits up to `timeout` for a frame; `Ok(None)` on timeout. Malformed datagrams are skipped
    /// (counted in [`CanBus::rx_errors`]), never returned as frames. The default waits on
    /// [`CanBus::recv_event_timeout`] until the same deadline, skipping error frames.
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        let deadline =
            monotonic_ns().saturating_add(timeout.as_nanos().min(u64::MAX as u128) as u64);
        loop {
            let left = Duration::from_nanos(deadline.saturating_sub(monotonic_ns()));
            match self.recv_event_timeout(left)? {
                Some(RxEvent::Frame(f)) => return Ok(Some(f)),
                Some(RxEvent::BusError(_)) => continue,
                None => return Ok(None),
            }
        }
    }
    /// Non-blocking receive.
    fn try_recv(&mut self) -> Result<Option<RxFrame>, CanError> {
        self.recv_timeout(Duration::ZERO)
    }
    /// Human-readable interface name (used in candump logs), e.g. `vcan0` or `udpbus20000`.
    fn interface(&self) -> &str;
    /// Number of malformed packets/frames dropped so far.
    fn rx_errors(&self) -> u64 {
        0
    }
    /// Subscribes to the bus's error frames (SocketCAN: `CAN_RAW_ERR_FILTER` = every class;
    /// the UDP bus carries them as cannelloni frames with `CAN_ERR_FLAG`). They are delivered
    /// by [`CanBus::recv_event_timeout`] only; [`CanBus::recv_timeout`] never returns them.
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        Err(CanError::NoErrorFrames {
            iface: self.interface().to_string(),
        })
    }
    /// Like [`CanBus::recv_timeout`], but also delivers error frames (after
    /// [`CanBus::subscribe_bus_errors`]). The default (a frames-only transport) is
    /// [`CanBus::recv_timeout`]'s frame.
    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        Ok(self.recv_timeout(timeout)?.map(RxEvent::Frame))
    }
    /// Non-blocking [`CanBus::recv_event_timeout`].
    fn try_recv_event(&mut self) -> Result<Option<RxEvent>, CanError> {
        self.recv_event_timeout(Duration::ZERO)
    }
    /// Sends an error frame (fault injection: vcan and the UDP bus forward it to every
    /// subscribed member, as a controller's report would arrive).
    fn send_bus_error(&mut self, _error: &BusErrorFrame) -> Result<(), CanError> {
        Err(CanError::NoErrorFrames {
            iface: self.interface().to_string(),
        })
    }
    /// Error frames received so far (subscribed or not).
    fn bus_errors(&self) -> u64 {
        0
    }
    /// Transmit confirmation: from now on this endpoint's own frames come back through the
    /// receive calls once they have left the wire, with [`RxFrame::own`] set (SocketCAN:
    /// `CAN_RAW_RECV_OWN_MSGS`; `wire:`: at the frame's end-of-frame time in the bus model).
    /// Transports without it refuse ([`CanError::NoTxEcho`]).
    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        Err(CanError::NoTxEcho {
            iface: self.interface().to_string(),
        })
    }
    /// A descriptor that becomes readable when a receive may return something, for waiting
    /// on the bus and other sources in one poll ([`wait_readable_any`]); drain it with
    /// [`CanBus::try_recv_event`] (which may still return `None`: a filtered or malformed
    /// frame). `None`: the transport has no such descriptor; wait with
    /// [`CanBus::recv_event_timeout`].
    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        None
    }
    /// Opens a second, send-only transmit path on the same interface for frames that must not
    /// wait behind this endpoint's own queued frames (drive-io's SYNC): SocketCAN: a second raw
    /// socket with `SO_PRIORITY` [`PRIORITY_PATH_SO_PRIORITY`] (pfifo_fast's band 0, dequeued
    /// before band 1 where the default priority 0 goes) and an empty receive filter; `wire:`: a
    /// second node of the hub's bus that receives nothing (a controller's high-priority
    /// mailbox: it competes by identifier, never behind this node's queue). Its frames still
    /// wait for a frame already on the wire and lose arbitration to lower identifiers.
    /// `Ok(None)`: the transport has no transmit queue to overtake (the UDP transports put
    /// every frame on the network at `send`); send through this endpoint.
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        Ok(None)
    }
    /// Frames this endpoint sent that have not left the wire yet, where the transport knows:
    /// `wire:` exactly (sent minus resolved by the hub); SocketCAN 1 or 0 (whether the socket
    /// still holds send-buffer memory, `SIOCOUTQ`: a frame is charged to its socket until the
    /// driver confirms its transmission); `None` for the UDP transports (no transmit queue).
    fn tx_backlog(&self) -> Option<u64> {
        None
    }
}

/// `SO_PRIORITY` of a [`CanBus::open_priority_path`] socket: `TC_PRIO_INTERACTIVE` (6), the
/// highest a process may set without `CAP_NET_ADMIN`; pfifo_fast maps it to band 0.
pub const PRIORITY_PATH_SO_PRIORITY: i32 = 6;

impl<B: CanBus + ?Sized> CanBus for Box<B> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        (**self).send(frame)
    }
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        (**self).recv_timeout(timeout)
    }
    fn try_recv(&mut self) -> Result<Option<RxFrame>, CanError> {
        (**self).try_recv()
    }
    fn interface(&self) -> &str {
        (**self).interface()
    }
    fn rx_errors(&self) -> u64 {
        (**self).rx_errors()
    }
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        (**self).subscribe_bus_errors()
    }
    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        (**self).recv_event_timeout(timeout)
    }
    fn send_bus_error(&mut self, error: &BusErrorFrame) -> Result<(), CanError> {
        (**self).send_bus_error(error)
    }
    fn bus_errors(&self) -> u64 {
        (**self).bus_errors()
    }
    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        (**self).enable_tx_echo()
    }
    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        (**self).readiness_fd()
    }
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        (**self).open_priority_path()
    }
    fn tx_backlog(&self) -> Option<u64> {
        (**self).tx_backlog()
    }
}

/// Opens the transport named by `spec`.
pub fn open(spec: &TransportSpec) -> Result<Box<dyn CanBus>, CanError> {
    Ok(match spec {
        TransportSpec::SocketCan { iface } => Box::new(SocketCanBus::open(iface)?),
        TransportSpec::UdpMulticast { group, port } => Box::new(UdpBus::multicast(*group, *port)?),
        TransportSpec::UdpPeer { local, remote } => Box::new(UdpBus::peer(*local, *remote)?),
        TransportSpec::PyCanUdp { group, port } => {
            Box::new(pycan_udp::PyCanUdpBus::open(*group, *port)?)
        }
        TransportSpec::Wire { path } => Box::new(wire::WireBus::connect(path)?),
    })
}

/// The stack's one clock (CLOCK_MONOTONIC ns, defined in crs-rt): the receive-timestamp clock
/// of [`RxFrame`], the same as the process bus's payload stamps.
pub use crs_rt::monotonic_ns;
