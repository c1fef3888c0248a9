//! Drive-side emulation of a force-measuring node: a CiA 404 measuring device with one analog
//! input per pulley load cell (`config/eds/crs-load-cell.eds` or another EDS), for simulated
//! plants and test doubles. It is the same CANopen device core as the drives
//! ([`DriveSlave`]: object dictionary from the EDS, NMT, expedited and segmented SDO, PDO
//! mapping and transmission, heartbeat), with no CiA 402 function behind it; the embedder feeds
//! the measured force ([`ForceNode::set_force_n`]) and the node reports it as its process value
//! in the unit its EDS gives (0x6131 physical unit, CiA 303-2 prefix; 0x6132 decimal digits).

use crate::slave::{DriveSlave, SlaveEvent};
use can_transport::CanFrame;
use drive_bus::canopen::{FrameBuf, NmtState};
use drive_bus::eds::{DataType, Eds};
use drive_bus::force_sensor::{OD_AI_DECIMAL_DIGITS, OD_AI_PHYSICAL_UNIT};

/// The process value objects of CiA 404's analog input, by data type (INTEGER32, INTEGER16,
/// REAL32), in the order a node is searched for its channel.
const PV_OBJECTS: [u16; 3] = [0x9130, 0x7130, 0x6130];

/// One simulated force-measuring node.
#[derive(Debug, Clone)]
pub struct ForceNode {
    dev: DriveSlave,
    index: u16,
    channel: u8,
    data_type: DataType,
}

impl ForceNode {
    /// Node `node` implementing `eds`, measuring on `channel` (1-based) of the first process
    /// value object the EDS has (0x9130, 0x7130 or 0x6130); heartbeat `heartbeat_ms` until the
    /// master writes 0x1017. None if the EDS has no such object.
    pub fn new(node: u8, eds: &Eds, channel: u8, heartbeat_ms: u16) -> Option<Self> {
        let (index, e) = PV_OBJECTS
            .iter()
            .find_map(|&i| eds.entry(i, channel).map(|e| (i, e)))?;
        Some(Self {
            dev: DriveSlave::with_eds(node, eds, heartbeat_ms),
            index,
            channel,
            data_type: e.data_type,
        })
    }

    /// The simulated pulley load cell (`config/eds/crs-load-cell.eds`), channel 1.
    pub fn load_cell(node: u8, heartbeat_ms: u16) -> Self {
        Self::new(node, Eds::builtin_load_cell(), 1, heartbeat_ms)
            .expect("the built-in load cell EDS has 0x9130sub1 (eds unit tests)")
    }

    pub fn node_id(&self) -> u8 {
        self.dev.node_id()
    }
    pub fn nmt_state(&self) -> NmtState {
        self.dev.nmt_state()
    }

    /// Newtons per unit of the process value, from the node's 0x6131 (CiA 303-2: unit in byte
    /// 2, prefix 10^p in byte 3 as a signed exponent) and 0x6132 (decimal digits); 1 N per unit
    /// where the node has neither.
    pub fn n_per_unit(&self) -> f64 {
        let ch = self.channel;
        let prefix = self
            .dev
            .od_value(OD_AI_PHYSICAL_UNIT, ch)
            .map_or(0, |u| i32::from((u >> 24) as u8 as i8));
        let digits = if self.data_type == DataType::Real32 {
            0
        } else {
            self.dev
                .od_value(OD_AI_DECIMAL_DIGITS, ch)
                .map_or(0, |d| d as i32)
        };
        10f64.powi(prefix - digits)
    }

    /// The force the load cell measures now (N), reported from the next TPDO on. Saturates at
    /// the range of the process value's type (a sensor at its end of range).
    pub fn set_force_n(&mut self, force_n: f64) {
        let v = force_n / self.n_per_unit();
        let raw = match self.data_type {
            DataType::Real32 => (v as f32).to_bits(),
            DataType::Integer16 => v.round().clamp(-32768.0, 32767.0) as i16 as u16 as u32,
            _ => v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32 as u32,
        };
        self.dev.set_process_value(self.index, self.channel, raw);
    }

    /// Power-on: boot-up message, pre-operational.
    pub fn start(&mut self, now_ns: u64, out: &mut FrameBuf) {
        self.dev.start(now_ns, out);
    }
    /// Handles one frame; true if it was a SYNC the node acts on (then
    /// [`ForceNode::transmit_pdos`] after the force was set).
    pub fn handle_frame(&mut self, frame: &CanFrame, now_ns: u64, out: &mut FrameBuf) -> bool {
        self.dev.handle_frame(frame, now_ns, out) == SlaveEvent::Sync
    }
    /// TPDOs as mapped (every n-th SYNC or on change).
    pub fn transmit_pdos(&mut self, out: &mut FrameBuf) {
        self.dev.transmit_pdos(out);
    }
    /// Heartbeat when due.
    pub fn poll(&mut self, now_ns: u64, out: &mut FrameBuf) {
        self.dev.poll(now_ns, out);
    }
    /// Test hook: a node with a dead controller stops its heartbeat.
    pub fn set_heartbeat_muted(&mut self, muted: bool) {
        self.dev.set_heartbeat_muted(muted);
    }
    /// Current value of an object (raw bits).
    pub fn od_value(&self, index: u16, sub: u8) -> Option<u32> {
        self.dev.od_value(index, sub)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use drive_bus::canopen::*;

    #[test]
    fn reports_the_force_in_its_eds_unit_on_sync() {
        let mut n = ForceNode::load_cell(33, 10);
        let mut out = FrameBuf::default();
        n.start(0, &mut out);
        assert_eq!(n.n_per_unit(), 0.1);
        n.handle_frame(&nmt(NMT_START, 33), 0, &mut out);
        out.clear();
        assert!(n.handle_frame(&sync(), 1, &mut out));
        n.set_force_n(4321.06);
        n.transmit_pdos(&mut out);
        let f = out.as_slice()[0];
        assert_eq!(f.id(), 0x180 + 33);
        assert_eq!(f.data(), &43211i32.to_le_bytes());
        // Another node id is not addressed by NMT start: no PDO.
        let mut other = ForceNode::load_cell(34, 10);
        other.start(0, &mut out);
        other.handle_frame(&nmt(NMT_START, 33), 0, &mut out);
        out.clear();
        assert!(!other.handle_frame(&sync(), 1, &mut out));
    }
}
