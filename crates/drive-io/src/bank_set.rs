//! The drive side of several CAN interfaces: one [`DriveBank`] per interface (a node id is
//! unique only on its own interface), addressed by cable index as one bank is. Used by the
//! simulated plant and the winch emulator.

use crate::config::DrivesConfig;
use crate::eds::Eds;
use crate::safety_watch::{InhibitReason, SafetyWatchConfig, WatchState};
use crate::slave::{DriveBank, DriveSlave, MotionDemand};
use can_transport::{CanBus, CanError, CanFrame};

/// The drives of every interface, in cable order (see the module docs).
pub struct DriveBanks {
    banks: Vec<DriveBank>,
    /// Per cable: (interface, index in that interface's bank).
    cables: Vec<(usize, usize)>,
}

impl DriveBanks {
    /// One bank per interface of `cfg`, the drives implementing `eds`'s object dictionary,
    /// heartbeat period `heartbeat_ms` until the master configures 0x1017.
    pub fn new(cfg: &DrivesConfig, eds: &Eds, heartbeat_ms: u16) -> Self {
        let n = cfg.interfaces().len().max(1);
        let mut ids: Vec<Vec<u8>> = vec![Vec::new(); n];
        let mut cables = Vec::with_capacity(cfg.winches.len());
        for (i, w) in cfg.winches.iter().enumerate() {
            let itf = cfg.winch_interface(i).min(n - 1);
            cables.push((itf, ids[itf].len()));
            ids[itf].push(w.node_id);
        }
        Self {
            banks: ids
                .iter()
                .map(|ids| DriveBank::with_eds(ids, eds, heartbeat_ms))
                .collect(),
            cables,
        }
    }

    /// Number of interfaces.
    pub fn interfaces(&self) -> usize {
        self.banks.len()
    }
    /// Number of drives (cables).
    pub fn len(&self) -> usize {
        self.cables.len()
    }
    pub fn is_empty(&self) -> bool {
        self.cables.is_empty()
    }
    /// The interface of cable `i`.
    pub fn interface_of(&self, i: usize) -> Option<usize> {
        self.cables.get(i).map(|c| c.0)
    }
    /// Cables on interface `iface`, in cable order.
    pub fn cables_on(&self, iface: usize) -> impl Iterator<Item = usize> + '_ {
        self.cables
            .iter()
            .enumerate()
            .filter(move |(_, c)| c.0 == iface)
            .map(|(i, _)| i)
    }
    /// Every drive validates the safety monitor's doubled heartbeat on its own interface.
    pub fn enable_safety_watch(&mut self, cfg: SafetyWatchConfig) {
        for b in &mut self.banks {
            b.enable_safety_watch(cfg);
        }
    }
    /// Safe torque off of every drive on every interface (the safety I/O node's outputs).
    pub fn set_sto(&mut self, active: bool) {
        for b in &mut self.banks {
            b.set_sto(active);
        }
    }
    /// True while the watch of every interface permits motion (or no watch is enabled).
    pub fn safety_permits(&self) -> bool {
        self.banks.iter().all(|b| {
            b.safety_watch()
                .is_none_or(|w| w.state() == WatchState::Permit)
        })
    }
    /// True if any interface's drives validate the safety heartbeat.
    pub fn has_safety_watch(&self) -> bool {
        self.banks.iter().any(|b| b.safety_watch().is_some())
    }
    /// A trip of any interface's watch not yet reported.
    pub fn take_safety_trip(&mut self) -> Option<(InhibitReason, u64)> {
        self.banks.iter_mut().find_map(DriveBank::take_safety_trip)
    }
    /// Power-on of every drive.
    pub fn start(&mut self, now_ns: u64) {
        for b in &mut self.banks {
            b.start(now_ns);
        }
    }
    /// One frame received on interface `iface`; true if it was a SYNC the drives of that
    /// interface act on.
    pub fn handle_frame(&mut self, iface: usize, frame: &CanFrame, now_ns: u64) -> bool {
        self.banks
            .get_mut(iface)
            .is_some_and(|b| b.handle_frame(frame, now_ns))
    }
    /// Motion demand of cable `i`.
    pub fn demand(&self, i: usize) -> MotionDemand {
        match self.cables.get(i) {
            Some(&(b, k)) => self.banks[b].demand(k),
            None => MotionDemand::Hold,
        }
    }
    /// Measured values of cable `i` for its next TPDOs.
    pub fn set_actual(
        &mut self,
        i: usize,
        position_counts: i32,
        velocity_counts_per_s: i32,
        force_mn: i32,
    ) {
        if let Some(&(b, k)) = self.cables.get(i) {
            self.banks[b].set_actual(k, position_counts, velocity_counts_per_s, force_mn);
        }
    }
    /// TPDOs of the drives on interface `iface` (after the physics step of its SYNC).
    pub fn transmit_pdos_on(&mut self, iface: usize) {
        if let Some(b) = self.banks.get_mut(iface) {
            b.transmit_pdos();
        }
    }
    /// TPDOs of every drive.
    pub fn transmit_pdos(&mut self) {
        for b in &mut self.banks {
            b.transmit_pdos();
        }
    }
    /// Heartbeats when due; the safety watches' validation time.
    pub fn poll(&mut self, now_ns: u64) {
        for b in &mut self.banks {
            b.poll(now_ns);
        }
    }
    /// Sends every interface's queued frames on its bus (`buses[k]` = interface k).
    pub fn flush<B: CanBus>(&mut self, buses: &mut [B]) -> Result<(), CanError> {
        for (b, bus) in self.banks.iter_mut().zip(buses.iter_mut()) {
            b.flush(bus)?;
        }
        Ok(())
    }
    /// Earliest heartbeat due time of every drive.
    pub fn next_heartbeat_ns(&self) -> Option<u64> {
        (0..self.len())
            .filter_map(|i| self.slave(i).and_then(DriveSlave::next_heartbeat_ns))
            .min()
    }
    pub fn slave(&self, i: usize) -> Option<&DriveSlave> {
        let &(b, k) = self.cables.get(i)?;
        self.banks[b].slave(k)
    }
    pub fn slave_mut(&mut self, i: usize) -> Option<&mut DriveSlave> {
        let &(b, k) = self.cables.get(i)?;
        self.banks[b].slave_mut(k)
    }
    /// Drive fault of cable `i` (EMCY + Fault state).
    pub fn raise_fault(&mut self, i: usize, emcy_code: u16) {
        if let Some(&(b, k)) = self.cables.get(i) {
            self.banks[b].raise_fault(k, emcy_code);
        }
    }
    /// The bank of interface `iface` (inspection).
    pub fn bank(&self, iface: usize) -> Option<&DriveBank> {
        self.banks.get(iface)
    }
}
