//! CAN error frames (Linux `include/uapi/linux/can/error.h`): what the controller reports about
//! the bus itself. A SocketCAN raw socket receives them only after subscribing
//! (`CAN_RAW_ERR_FILTER`, [`crate::CanBus::subscribe_bus_errors`]); cannelloni forwards them as
//! frames with `CAN_ERR_FLAG` (0x2000_0000) in the id word, so the UDP bus carries them too.
//!
//! Layout: the class bits are the can_id (without the flag); `data[1]` is the controller
//! status (for `CAN_ERR_CRTL`), `data[6..8]` the TX/RX error counters (for `CAN_ERR_CNT`).
//! Decoded here with our own code (tested against the socketcan crate's decoder).

use std::fmt;

/// Error classes (can_id bits of an error frame).
pub mod class {
    pub const TX_TIMEOUT: u32 = 0x0001;
    pub const LOSTARB: u32 = 0x0002;
    pub const CRTL: u32 = 0x0004;
    pub const PROT: u32 = 0x0008;
    pub const TRX: u32 = 0x0010;
    pub const ACK: u32 = 0x0020;
    pub const BUSOFF: u32 = 0x0040;
    pub const BUSERROR: u32 = 0x0080;
    pub const RESTARTED: u32 = 0x0100;
    pub const CNT: u32 = 0x0200;
    /// Every class bit (`CAN_ERR_MASK` is the 29-bit id range).
    pub const MASK: u32 = 0x1FFF_FFFF;
}

/// Controller status in `data[1]` (class `CRTL`).
pub mod crtl {
    pub const RX_OVERFLOW: u8 = 0x01;
    pub const TX_OVERFLOW: u8 = 0x02;
    pub const RX_WARNING: u8 = 0x04;
    pub const TX_WARNING: u8 = 0x08;
    pub const RX_PASSIVE: u8 = 0x10;
    pub const TX_PASSIVE: u8 = 0x20;
    pub const ACTIVE: u8 = 0x40;
}

/// One error frame as the controller (or a test) reported it: class bits and 8 data bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusErrorFrame {
    class: u32,
    data: [u8; 8],
}

/// The condition an error frame reports, most severe first (what a consumer acts on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusCondition {
    /// The controller left the bus (TEC > 255): nothing it sends reaches the drives.
    BusOff,
    /// Error counters ≥ 128: the controller may no longer signal errors actively, frames may be
    /// lost without anyone noticing (CiA 301: treat as a communication fault).
    ErrorPassive,
    /// The controller dropped frames (RX or TX buffer overflow).
    Overflow,
    /// A transmission did not complete in time (the frame was not sent).
    TxTimeout,
    /// Warning level, protocol violation, missing ACK, lost arbitration, transceiver, restart:
    /// reported, not by itself a loss of communication.
    Other,
}

impl BusErrorFrame {
    /// From the class bits (the `CAN_ERR_FLAG` and any flag above the 29-bit range are
    /// dropped) and up to 8 data bytes (zero padded, like the kernel's error frames).
    pub fn new(class: u32, data: &[u8]) -> Self {
        let mut d = [0u8; 8];
        let n = data.len().min(8);
        d[..n].copy_from_slice(&data[..n]);
        Self {
            class: class & class::MASK,
            data: d,
        }
    }

    /// Bus-off as a controller reports it.
    pub fn bus_off() -> Self {
        Self::new(class::BUSOFF, &[])
    }

    /// Error-passive (TX and RX) with the counters, as a controller reports it.
    pub fn error_passive(tx_errors: u8, rx_errors: u8) -> Self {
        Self::new(
            class::CRTL | class::CNT,
            &[
                0,
                crtl::TX_PASSIVE | crtl::RX_PASSIVE,
                0,
                0,
                0,
                0,
                tx_errors,
                rx_errors,
            ],
        )
    }

    pub fn class(&self) -> u32 {
        self.class
    }
    pub fn data(&self) -> &[u8; 8] {
        &self.data
    }
    fn crtl(&self) -> u8 {
        if self.class & class::CRTL != 0 {
            self.data[1]
        } else {
            0
        }
    }
    pub fn is_bus_off(&self) -> bool {
        self.class & class::BUSOFF != 0
    }
    pub fn is_error_passive(&self) -> bool {
        self.crtl() & (crtl::RX_PASSIVE | crtl::TX_PASSIVE) != 0
    }
    pub fn is_overflow(&self) -> bool {
        self.crtl() & (crtl::RX_OVERFLOW | crtl::TX_OVERFLOW) != 0
    }
    pub fn is_tx_timeout(&self) -> bool {
        self.class & class::TX_TIMEOUT != 0
    }
    pub fn is_restarted(&self) -> bool {
        self.class & class::RESTARTED != 0
    }
    /// TX and RX error counters, if the frame carries them (`CAN_ERR_CNT`).
    pub fn counters(&self) -> Option<(u8, u8)> {
        (self.class & class::CNT != 0).then_some((self.data[6], self.data[7]))
    }

    /// The most severe condition this frame reports.
    pub fn condition(&self) -> BusCondition {
        if self.is_bus_off() {
            BusCondition::BusOff
        } else if self.is_error_passive() {
            BusCondition::ErrorPassive
        } else if self.is_overflow() {
            BusCondition::Overflow
        } else if self.is_tx_timeout() {
            BusCondition::TxTimeout
        } else {
            BusCondition::Other
        }
    }
}

impl BusCondition {
    /// Bus-off and error-passive: communication with the drives can no longer be relied on.
    pub fn is_loss_of_communication(self) -> bool {
        matches!(self, BusCondition::BusOff | BusCondition::ErrorPassive)
    }
    /// Stable code (trip logs, the monitor's fault value).
    pub fn code(self) -> u8 {
        match self {
            BusCondition::BusOff => 1,
            BusCondition::ErrorPassive => 2,
            BusCondition::Overflow => 3,
            BusCondition::TxTimeout => 4,
            BusCondition::Other => 5,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            BusCondition::BusOff => "bus-off",
            BusCondition::ErrorPassive => "error-passive",
            BusCondition::Overflow => "controller overflow",
            BusCondition::TxTimeout => "tx timeout",
            BusCondition::Other => "bus error",
        }
    }
}

impl fmt::Display for BusErrorFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (class {:#x}", self.condition().name(), self.class)?;
        if let Some((tx, rx)) = self.counters() {
            write!(f, ", tec {tx} rec {rx}")?;
        }
        write!(f, ")")
    }
}

/// A received error frame with its receive time (CLOCK_MONOTONIC ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxBusError {
    pub error: BusErrorFrame,
    pub rx_monotonic_ns: u64,
}

/// What a subscribed receive delivers: a data/remote frame or an error frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxEvent {
    Frame(crate::RxFrame),
    BusError(RxBusError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use socketcan::errors::{ControllerProblems, ErrorCause};

    /// Our decoder against the socketcan crate's (code not written here) on the kernel layout.
    fn theirs(class_bits: u32, data: [u8; 8]) -> Vec<ErrorCause> {
        socketcan::CanErrorFrame::new_error(class_bits, &data)
            .unwrap()
            .into_error()
            .into_iter()
            .collect()
    }

    #[test]
    fn conditions_agree_with_the_socketcan_decoder() {
        let cases: [(u32, [u8; 8]); 6] = [
            (class::BUSOFF, [0; 8]),
            (class::CRTL | class::CNT, [0, 0x30, 0, 0, 0, 0, 130, 5]),
            (class::CRTL, [0, crtl::RX_OVERFLOW, 0, 0, 0, 0, 0, 0]),
            (class::TX_TIMEOUT, [0; 8]),
            (class::CRTL, [0, crtl::TX_WARNING, 0, 0, 0, 0, 0, 0]),
            (class::ACK | class::BUSERROR, [0; 8]),
        ];
        for (c, d) in cases {
            let ours = BusErrorFrame::new(c | 0x2000_0000, &d);
            let causes = theirs(c, d);
            let has = |p: &dyn Fn(&ErrorCause) -> bool| causes.iter().any(p);
            assert_eq!(
                ours.is_bus_off(),
                has(&|e| matches!(e, ErrorCause::BusOff)),
                "{c:#x}"
            );
            let passive = has(&|e| match e {
                ErrorCause::Controller(p) => {
                    p.contains(ControllerProblems::RX_PASSIVE)
                        || p.contains(ControllerProblems::TX_PASSIVE)
                }
                _ => false,
            });
            assert_eq!(ours.is_error_passive(), passive, "{c:#x}");
            assert_eq!(
                ours.is_tx_timeout(),
                has(&|e| matches!(e, ErrorCause::TransmitTimeout)),
                "{c:#x}"
            );
            let counters = causes.iter().find_map(|e| match e {
                ErrorCause::Counters { tx, rx } => Some((*tx, *rx)),
                _ => None,
            });
            assert_eq!(ours.counters(), counters, "{c:#x}");
        }
        assert_eq!(BusErrorFrame::bus_off().condition(), BusCondition::BusOff);
        assert_eq!(
            BusErrorFrame::error_passive(128, 0).condition(),
            BusCondition::ErrorPassive
        );
        assert!(BusCondition::ErrorPassive.is_loss_of_communication());
        assert!(!BusCondition::Overflow.is_loss_of_communication());
        // The flag is not a class bit.
        assert_eq!(BusErrorFrame::new(0x2000_0040, &[]).class(), 0x40);
    }
}
