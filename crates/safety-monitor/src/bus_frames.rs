//! The few CANopen frames the monitor sends and reads on the drive bus, encoded here on purpose
//! (the stop path must not depend on drive-io's code). COB-IDs per docs/can-protocol.md.

use crate::bus_layout::BusLayout;
use can_transport::CanFrame;

pub const COB_NMT: u16 = 0x000;
pub const COB_RPDO1_BASE: u16 = 0x200;
pub const COB_HEARTBEAT_BASE: u16 = 0x700;
pub const NMT_START: u8 = 0x01;
pub const NMT_STOP: u8 = 0x02;
/// CiA 402 controlword "quick stop" (bits 1 = 1, 2 = 0).
pub const CW_QUICK_STOP: u16 = 0x0002;
/// CiA 402 controlword "enable operation": the only RPDOs that command motion.
pub const CW_ENABLE_OPERATION: u16 = 0x000F;
/// True for every controlword that commands CiA 402 "enable operation" (bits 0–3 set, fault
/// reset bit 7 clear; bits 4–6 and 8–15 are mode- or manufacturer-specific and do not prevent
/// the drive from following its target), so the RPDO check covers all of them, not only 0x000F.
pub fn enables_operation(controlword: u16) -> bool {
    controlword & 0x008F == 0x000F
}

/// NMT state "operational" in heartbeats.
pub const NMT_STATE_OPERATIONAL: u8 = 0x05;
/// NMT state "stopped" in heartbeats.
pub const NMT_STATE_STOPPED: u8 = 0x04;

/// NMT command to `node` (0 = all nodes).
pub fn nmt(command: u8, node: u8) -> CanFrame {
    CanFrame::new_std_lossy(COB_NMT, &[command, node])
}

/// RPDO1 (controlword, target position) to `node`.
pub fn rpdo1(node: u8, controlword: u16, target_counts: i32) -> CanFrame {
    let mut d = [0u8; 6];
    d[..2].copy_from_slice(&controlword.to_le_bytes());
    d[2..].copy_from_slice(&target_counts.to_le_bytes());
    CanFrame::new_std_lossy(COB_RPDO1_BASE + u16::from(node & 0x7F), &d)
}

/// What the monitor reads from the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observed {
    /// The RPDO carrying cable `cable`'s controlword and target (in its configured layout).
    Rpdo {
        cable: usize,
        controlword: u16,
        target_counts: i32,
    },
    /// Heartbeat of `node` with its NMT state.
    Heartbeat { node: u8, state: u8 },
    /// Cable `cable`'s measured force (its drive's object or its load cell), N.
    Force { cable: usize, force_n: f64 },
    /// An error frame of the bus controller (the reader's socket subscribes to them).
    BusError(can_transport::BusCondition),
    /// The safety I/O node's TPDO1: inputs (bit 0 e-stop circuit closed, bit 1 reset key) and
    /// outputs (bit 0 STO released).
    SafetyIo { inputs: u8, outputs: u8 },
    /// A frame on one of the monitor's OWN identifiers (its heartbeat and configuration
    /// signature pairs): the process compares it with what it sent.
    OwnId { cob_id: u16, data: [u8; 8], len: u8 },
}

/// A frame on the monitor's own identifiers `cob_id .. cob_id + 3` (any interface), as
/// [`Observed::OwnId`]; None for every other frame.
pub fn own_id(cob_id: u16, f: &CanFrame) -> Option<Observed> {
    let id = f.id() as u16;
    if f.is_extended() || f.is_rtr() || !(cob_id..=cob_id.saturating_add(3)).contains(&id) {
        return None;
    }
    let mut data = [0u8; 8];
    let d = f.data();
    data[..d.len()].copy_from_slice(d);
    Some(Observed::OwnId {
        cob_id: id,
        data,
        len: d.len() as u8,
    })
}

/// Decodes a frame received on interface `iface` with the drives' layout: an RPDO, a force,
/// a heartbeat; anything else (or malformed) is `None`. Never panics.
pub fn observe(layout: &BusLayout, iface: usize, f: &CanFrame) -> Option<Observed> {
    if f.is_extended() || f.is_rtr() {
        return None;
    }
    if let Some((cable, controlword, target_counts)) = layout.rpdo_of(iface, f) {
        return Some(Observed::Rpdo {
            cable,
            controlword,
            target_counts,
        });
    }
    if let Some((cable, force_n)) = layout.force_of(iface, f) {
        return Some(Observed::Force { cable, force_n });
    }
    if let Some((io_iface, cob)) = layout.safety_io
        && io_iface == iface
        && f.id() as u16 == cob
    {
        let d = f.data();
        return (d.len() >= 2).then(|| Observed::SafetyIo {
            inputs: d[0],
            outputs: d[1],
        });
    }
    let id = f.id() as u16;
    let node = (id & 0x7F) as u8;
    let d = f.data();
    (id & 0x780 == COB_HEARTBEAT_BASE && node != 0 && d.len() == 1).then(|| Observed::Heartbeat {
        node,
        state: d[0] & 0x7F,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus_layout::{ForceLayout, RpdoLayout, Value};

    #[test]
    fn round_trips() {
        assert_eq!(nmt(NMT_STOP, 0).data(), &[2, 0]);
        assert_eq!(nmt(NMT_STOP, 0).id(), 0);
        let layout = BusLayout {
            rpdo: (1..=6).map(|n| RpdoLayout::default_for(0, n)).collect(),
            force: vec![ForceLayout {
                interface: 0,
                cob_id: 0x286,
                len: 8,
                at: 4,
                value: Value::I32,
                n_per_unit: 0.001,
                node: 6,
            }],
            safety_io: Some((1, 0x1B0)),
        };
        assert_eq!(
            observe(&layout, 0, &rpdo1(5, CW_QUICK_STOP, -7)),
            Some(Observed::Rpdo {
                cable: 4,
                controlword: 2,
                target_counts: -7
            })
        );
        assert_eq!(observe(&layout, 1, &rpdo1(5, CW_QUICK_STOP, -7)), None);
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x703, &[0x85]).unwrap()),
            Some(Observed::Heartbeat { node: 3, state: 5 })
        );
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x203, &[1, 2]).unwrap()),
            None
        );
        for cw in [0x000F, 0x001F, 0x007F, 0x010F, 0xFF0F, 0x004F] {
            assert!(enables_operation(cw), "{cw:#06x}");
        }
        for cw in [0x0000, 0x0002, 0x0006, 0x0007, 0x008F, 0x000B, 0x000E] {
            assert!(!enables_operation(cw), "{cw:#06x}");
        }
        // TPDO2 as drive-io's slave writes it: velocity, then force in mN.
        let mut d = [0u8; 8];
        d[..4].copy_from_slice(&123i32.to_le_bytes());
        d[4..].copy_from_slice(&(-4_500_000i32).to_le_bytes());
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x286, &d).unwrap()),
            Some(Observed::Force {
                cable: 0,
                force_n: -4500.0
            })
        );
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x286, &d[..7]).unwrap()),
            None
        );
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x200, &[0; 6]).unwrap()),
            None
        );
        // The safety I/O node's TPDO1 on its interface only; the monitor's own identifiers.
        assert_eq!(
            observe(&layout, 1, &CanFrame::new(0x1B0, &[0x03, 0x01]).unwrap()),
            Some(Observed::SafetyIo {
                inputs: 3,
                outputs: 1
            })
        );
        assert_eq!(
            observe(&layout, 0, &CanFrame::new(0x1B0, &[0x03, 0x01]).unwrap()),
            None
        );
        assert_eq!(
            observe(&layout, 1, &CanFrame::new(0x1B0, &[0x03]).unwrap()),
            None
        );
        assert!(matches!(
            own_id(0x101, &CanFrame::new(0x104, &[1, 2]).unwrap()),
            Some(Observed::OwnId {
                cob_id: 0x104,
                len: 2,
                ..
            })
        ));
        assert_eq!(own_id(0x101, &CanFrame::new(0x105, &[1]).unwrap()), None);
        assert_eq!(own_id(0x101, &CanFrame::new(0x100, &[1]).unwrap()), None);
        // Empty frames of every kind (SYNC, NMT, a stray heartbeat id) are nothing.
        for id in [0x080, 0x000, 0x705, 0x205, 0x286] {
            assert_eq!(
                observe(&layout, 0, &CanFrame::new(id, &[]).unwrap()),
                None,
                "{id:#x}"
            );
        }
    }
}
