//! The drive side of several CAN interfaces: one [`DriveBank`] per interface (a node id is
//! unique only on its own interface), addressed by cable index as one bank is. Used by the
//! simulated plant and the winch emulator.

use crate::bank::DriveBank;
use crate::force_node::ForceNode;
use crate::slave::{DriveSlave, MotionDemand};
use can_transport::{CanBus, CanError, CanFrame};
use drive_bus::eds::{Eds, EdsError};
use drive_bus::safety_watch::{InhibitReason, SafetyWatchConfig, WatchState};
use drives_config::DrivesConfig;

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

    /// The drives of `cfg`, each implementing its own EDS (`winch[i].eds`, `bus.eds` or the
    /// simulated winch's), and its `[[force_sensor]]` nodes (each with its EDS, else the
    /// simulated load cell's) on their interfaces: the pulleys' load cells report the force
    /// [`DriveBanks::set_actual`] gives their cable. Fails if an EDS cannot be read or a
    /// sensor's EDS has no process value of the configured channel.
    pub fn from_config(cfg: &DrivesConfig, heartbeat_ms: u16) -> Result<Self, EdsError> {
        let eds = (0..cfg.winches.len())
            .map(|i| cfg.load_winch_eds(i))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self::from_parts(
            cfg,
            &eds,
            Self::force_nodes(cfg, heartbeat_ms)?,
            heartbeat_ms,
        ))
    }

    /// The simulated force nodes of `cfg`'s `[[force_sensor]]` tables: (interface, cable,
    /// node), each implementing its EDS.
    pub fn force_nodes(
        cfg: &DrivesConfig,
        heartbeat_ms: u16,
    ) -> Result<Vec<(usize, usize, ForceNode)>, EdsError> {
        let mut out = Vec::with_capacity(cfg.force_sensors.len());
        for (j, s) in cfg.force_sensors.iter().enumerate() {
            let eds = cfg.load_sensor_eds(j)?;
            let node = ForceNode::new(s.node_id, &eds, s.object.sub, heartbeat_ms).ok_or_else(
                || EdsError {
                    file: eds.file.clone(),
                    line: 0,
                    reason: format!(
                        "force_sensor[{j}]: no analog input process value (0x9130/0x7130/0x6130) \
                         sub {}",
                        s.object.sub
                    ),
                },
            )?;
            out.push((cfg.sensor_interface(j), s.cable - 1, node));
        }
        Ok(out)
    }

    /// The drives of `cfg` implementing `winch_eds[i]` (cable order) and the force nodes
    /// (interface, cable, node), one bank per interface.
    pub fn from_parts(
        cfg: &DrivesConfig,
        winch_eds: &[Eds],
        force_nodes: Vec<(usize, usize, ForceNode)>,
        heartbeat_ms: u16,
    ) -> Self {
        let n = cfg.interfaces().len().max(1);
        let mut slaves: Vec<Vec<DriveSlave>> = (0..n).map(|_| Vec::new()).collect();
        let mut cells: Vec<Vec<(usize, ForceNode)>> = (0..n).map(|_| Vec::new()).collect();
        let mut cables = Vec::with_capacity(cfg.winches.len());
        for (i, w) in cfg.winches.iter().enumerate() {
            let itf = cfg.winch_interface(i).min(n - 1);
            cables.push((itf, slaves[itf].len()));
            let eds = winch_eds.get(i).unwrap_or_else(|| Eds::builtin_winch());
            slaves[itf].push(DriveSlave::with_eds(w.node_id, eds, heartbeat_ms));
        }
        for (itf, cable, node) in force_nodes {
            cells[itf.min(n - 1)].push((cable, node));
        }
        Self {
            banks: slaves
                .into_iter()
                .zip(cells)
                .map(|(s, c)| DriveBank::from_nodes(s, c))
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
        // The pulley's load cell (on whichever interface) measures the same cable force.
        for b in &mut self.banks {
            b.set_cell_force(i, f64::from(force_mn) * 1e-3);
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
