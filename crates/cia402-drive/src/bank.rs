//! All drives (and force-measuring nodes) of one plant on one interface: [`DriveBank`], what a
//! coupled plant (all cables stepped together) embeds.

use crate::force_node::ForceNode;
use crate::slave::{DriveSlave, MotionDemand, SlaveEvent};
use can_transport::CanFrame;
use drive_bus::canopen::*;
use drive_bus::eds::Eds;
use drive_bus::safety_watch::{InhibitReason, SafetyWatch, SafetyWatchConfig};

/// All drives of one plant on one bus: what a coupled plant (all cables stepped together)
/// embeds. On every SYNC: read [`DriveBank::demand`] for each cable, step the physics once,
/// [`DriveBank::set_actual`] for each cable, then [`DriveBank::transmit_pdos`]; call
/// [`DriveBank::poll`] regularly for heartbeats and [`DriveBank::flush`] to send.
///
/// ```no_run
/// # use cia402_drive::bank::DriveBank;
/// # use cia402_drive::slave::MotionDemand;
/// # fn main() -> Result<(), can_transport::CanError> {
/// let mut bus = can_transport::open(&"udpbus:239.255.70.1:20000".parse().unwrap())?;
/// let mut bank = DriveBank::new(&[1, 2, 3, 4, 5, 6, 7, 8], 10);
/// bank.start(can_transport::monotonic_ns());
/// loop {
///     bank.flush(&mut bus)?;
///     let now = can_transport::monotonic_ns();
///     if let Some(rx) = bus.recv_timeout(std::time::Duration::from_millis(2))? {
///         if bank.handle_frame(&rx.frame, now) {
///             for i in 0..bank.len() {
///                 let _demand: MotionDemand = bank.demand(i); // Follow / QuickStop / Hold
///             }
///             // ... step the plant by one SYNC period, then per cable:
///             // bank.set_actual(i, position_counts, velocity_counts_per_s, force_mn);
///             bank.transmit_pdos();
///         }
///     }
///     bank.poll(now);
/// }
/// # }
/// ```
pub struct DriveBank {
    slaves: Vec<DriveSlave>,
    /// Force-measuring nodes and the cable (0-based) each measures.
    force_nodes: Vec<(usize, ForceNode)>,
    out: FrameBuf,
    watch: Option<SafetyWatch>,
}

impl DriveBank {
    /// One [`DriveSlave`] per node id (cable order), default heartbeat period `heartbeat_ms`.
    pub fn new(node_ids: &[u8], heartbeat_ms: u16) -> Self {
        Self::with_eds(node_ids, Eds::builtin_winch(), heartbeat_ms)
    }
    /// Drives implementing the object dictionary of `eds` (drives.toml `bus.eds`).
    pub fn with_eds(node_ids: &[u8], eds: &Eds, heartbeat_ms: u16) -> Self {
        Self {
            slaves: node_ids
                .iter()
                .map(|&n| DriveSlave::with_eds(n, eds, heartbeat_ms))
                .collect(),
            force_nodes: Vec::new(),
            out: FrameBuf::default(),
            watch: None,
        }
    }
    /// A bank of these drives and force nodes (drives in cable order; each force node with the
    /// cable it measures, as [`DriveBank::set_cell_force`] names it).
    pub fn from_nodes(slaves: Vec<DriveSlave>, force_nodes: Vec<(usize, ForceNode)>) -> Self {
        Self {
            slaves,
            force_nodes,
            out: FrameBuf::default(),
            watch: None,
        }
    }
    /// The force-measuring nodes and the cable (0-based) each measures.
    pub fn force_nodes(&self) -> &[(usize, ForceNode)] {
        &self.force_nodes
    }
    pub fn force_nodes_mut(&mut self) -> &mut [(usize, ForceNode)] {
        &mut self.force_nodes
    }
    /// Makes every drive validate the safety monitor's doubled heartbeat (drives.toml
    /// `[safety_heartbeat]`): without a valid RUN pair within the validation time, or on an
    /// invalid pair, all drives quick-stop and cannot be enabled. Starts inhibited.
    pub fn enable_safety_watch(&mut self, cfg: SafetyWatchConfig) {
        self.watch = Some(SafetyWatch::new(cfg));
        for s in &mut self.slaves {
            s.set_safety_inhibit(true);
        }
    }
    /// Safe torque off of every drive (their STO inputs, wired from the safety I/O node).
    pub fn set_sto(&mut self, active: bool) {
        for s in &mut self.slaves {
            s.set_sto(active);
        }
    }
    /// The safety-heartbeat watch, if enabled.
    pub fn safety_watch(&self) -> Option<&SafetyWatch> {
        self.watch.as_ref()
    }
    /// Trip of the watch not yet reported (reason, CLOCK_MONOTONIC ns), for logging.
    pub fn take_safety_trip(&mut self) -> Option<(InhibitReason, u64)> {
        self.watch.as_mut().and_then(SafetyWatch::take_trip)
    }
    fn apply_safety_watch(&mut self, now_ns: u64) {
        if let Some(w) = self.watch.as_mut() {
            let inhibit = !w.permits(now_ns);
            for s in &mut self.slaves {
                s.set_safety_inhibit(inhibit);
            }
        }
    }
    pub fn len(&self) -> usize {
        self.slaves.len()
    }
    pub fn is_empty(&self) -> bool {
        self.slaves.is_empty()
    }
    /// Power-on of all drives and force nodes (boot-up messages).
    pub fn start(&mut self, now_ns: u64) {
        for s in &mut self.slaves {
            s.start(now_ns, &mut self.out);
        }
        for (_, f) in &mut self.force_nodes {
            f.start(now_ns, &mut self.out);
        }
    }
    /// Handles one frame for every drive; true if it was a SYNC that the drives act on (step the
    /// physics now).
    pub fn handle_frame(&mut self, frame: &CanFrame, now_ns: u64) -> bool {
        if let Some(w) = self.watch.as_mut() {
            w.on_frame(frame, now_ns);
            self.apply_safety_watch(now_ns);
        }
        let mut sync = false;
        for s in &mut self.slaves {
            sync |= s.handle_frame(frame, now_ns, &mut self.out) == SlaveEvent::Sync;
        }
        for (_, f) in &mut self.force_nodes {
            sync |= f.handle_frame(frame, now_ns, &mut self.out);
        }
        sync
    }
    /// Motion demand of cable `i` (Hold for an out-of-range index).
    pub fn demand(&self, i: usize) -> MotionDemand {
        self.slaves
            .get(i)
            .map_or(MotionDemand::Hold, DriveSlave::demand)
    }
    /// Measured values of cable `i` for the next TPDOs (ignored for an out-of-range index).
    pub fn set_actual(
        &mut self,
        i: usize,
        position_counts: i32,
        velocity_counts_per_s: i32,
        force_mn: i32,
    ) {
        if let Some(s) = self.slaves.get_mut(i) {
            s.set_actual(position_counts, velocity_counts_per_s, force_mn);
        }
    }
    /// The force the load cells of `cable` measure (N), reported in their next TPDOs.
    pub fn set_cell_force(&mut self, cable: usize, force_n: f64) {
        for (_, f) in self.force_nodes.iter_mut().filter(|(c, _)| *c == cable) {
            f.set_force_n(force_n);
        }
    }
    /// TPDOs of all drives and force nodes (after the physics step of a SYNC).
    pub fn transmit_pdos(&mut self) {
        for s in &mut self.slaves {
            s.transmit_pdos(&mut self.out);
        }
        for (_, f) in &mut self.force_nodes {
            f.transmit_pdos(&mut self.out);
        }
    }
    /// Heartbeats when due; applies the safety-heartbeat validation time if the watch is on.
    pub fn poll(&mut self, now_ns: u64) {
        self.apply_safety_watch(now_ns);
        for s in &mut self.slaves {
            s.poll(now_ns, &mut self.out);
        }
        for (_, f) in &mut self.force_nodes {
            f.poll(now_ns, &mut self.out);
        }
    }
    /// Sends queued frames; a full TX queue drops the frame (as a CAN controller would).
    pub fn flush(
        &mut self,
        bus: &mut impl can_transport::CanBus,
    ) -> Result<(), can_transport::CanError> {
        let r = self
            .out
            .as_slice()
            .iter()
            .try_for_each(|f| match bus.send(f) {
                Ok(()) | Err(can_transport::CanError::TxFull { .. }) => Ok(()),
                Err(e) => Err(e),
            });
        self.out.clear();
        r
    }
    /// Direct access, e.g. for fault injection ([`DriveSlave::raise_fault`] via
    /// [`DriveBank::raise_fault`]) or [`DriveSlave::set_heartbeat_muted`].
    pub fn slave(&self, i: usize) -> Option<&DriveSlave> {
        self.slaves.get(i)
    }
    pub fn slave_mut(&mut self, i: usize) -> Option<&mut DriveSlave> {
        self.slaves.get_mut(i)
    }
    /// Drive fault of cable `i` (EMCY + Fault state).
    pub fn raise_fault(&mut self, i: usize, emcy_code: u16) {
        if let Some(s) = self.slaves.get_mut(i) {
            s.raise_fault(emcy_code, &mut self.out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::safety_frame::{
        ConfigSignature, DEFAULT_COB_ID, SafetyHeartbeat, SafetyState, encode,
    };

    const MS: u64 = 1_000_000;

    /// One monitor cycle with reset epoch `epoch`: the configuration signature pair (matching
    /// the default configuration), then the heartbeat pair.
    fn pair_e(counter: u16, state: SafetyState, epoch: u32) -> [CanFrame; 4] {
        let [s1, s2] = ConfigSignature {
            srdo_crc: SafetyWatchConfig::default().srdo_crc(),
            safety_params_crc: 0x1234_5678,
        }
        .encode(DEFAULT_COB_ID);
        let [a, b] = encode(
            &SafetyHeartbeat {
                state,
                cause: if state == SafetyState::Stop { 1 } else { 0 },
                counter,
                epoch,
            },
            DEFAULT_COB_ID,
        );
        [s1, s2, a, b]
    }

    fn pair(counter: u16, state: SafetyState) -> [CanFrame; 4] {
        pair_e(counter, state, 1)
    }

    /// The drive side: no enable without the heartbeat; a lost heartbeat quick-stops an enabled
    /// drive within the validation time; the release does not re-enable by itself.
    #[test]
    fn drive_bank_with_watch_blocks_enable_and_quick_stops() {
        let mut bank = DriveBank::new(&[1, 2], 10);
        bank.enable_safety_watch(SafetyWatchConfig::default());
        bank.start(0);
        bank.handle_frame(&nmt(NMT_START, 0), 0);
        for node in [1, 2] {
            bank.handle_frame(&sdo_download(node, OD_MODES_OF_OPERATION, 0, 8, 1), 0);
        }
        let enable = |bank: &mut DriveBank, t: u64| {
            for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
                for node in [1, 2] {
                    bank.handle_frame(&rpdo1(node, cw, 0), t);
                }
            }
        };
        enable(&mut bank, MS);
        for i in 0..2 {
            assert_eq!(bank.slave(i).unwrap().ds402_state(), Ds402State::SwitchedOn);
            assert_eq!(bank.demand(i), MotionDemand::Hold);
        }
        // Valid heartbeats: the watch releases, now the master can enable.
        for k in 0..3u16 {
            for f in pair(k, SafetyState::Run) {
                bank.handle_frame(&f, (2 + u64::from(k)) * MS);
            }
        }
        enable(&mut bank, 5 * MS);
        for i in 0..2 {
            assert_eq!(
                bank.slave(i).unwrap().ds402_state(),
                Ds402State::OperationEnabled
            );
        }
        // Silence: still permitted at the validation time, quick stop right after it.
        let last = 4 * MS;
        bank.poll(last + 50 * MS);
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::OperationEnabled
        );
        bank.poll(last + 50 * MS + 1);
        for i in 0..2 {
            assert_eq!(
                bank.slave(i).unwrap().ds402_state(),
                Ds402State::QuickStopActive
            );
            assert_eq!(bank.demand(i), MotionDemand::QuickStop);
        }
        assert!(matches!(
            bank.take_safety_trip(),
            Some((InhibitReason::Timeout, _))
        ));
        // A master trying to re-enable (transition 16) is refused while inhibited.
        for node in [1, 2] {
            bank.handle_frame(&rpdo1(node, CW_ENABLE_OPERATION, 0), 60 * MS);
        }
        assert_eq!(
            bank.slave(1).unwrap().ds402_state(),
            Ds402State::QuickStopActive
        );
        // The same epoch back (a replay, or the monitor's frames resuming without a reset):
        // no self-release.
        for k in 10..13u16 {
            for f in pair(k, SafetyState::Run) {
                bank.handle_frame(&f, (60 + u64::from(k)) * MS);
            }
        }
        for node in [1, 2] {
            bank.handle_frame(&rpdo1(node, CW_ENABLE_OPERATION, 0), 74 * MS);
        }
        assert_eq!(
            bank.slave(1).unwrap().ds402_state(),
            Ds402State::QuickStopActive
        );
        // A newer epoch (the monitor accepted a reset): released, but the drives stay stopped
        // until the master enables.
        for k in 13..16u16 {
            for f in pair_e(k, SafetyState::Run, 2) {
                bank.handle_frame(&f, (62 + u64::from(k)) * MS);
            }
        }
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::QuickStopActive
        );
        for node in [1, 2] {
            bank.handle_frame(&rpdo1(node, CW_ENABLE_OPERATION, 0), 78 * MS);
        }
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::OperationEnabled
        );
    }
}
