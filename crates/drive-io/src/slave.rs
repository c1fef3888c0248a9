//! Drive-side (slave) emulation of a CiA 402 winch drive in cyclic synchronous position mode, for
//! simulated plants and test doubles. The slave handles NMT, SDO (expedited), RPDO/SYNC, produces
//! heartbeats and TPDOs; the PHYSICS is the embedder's: on every SYNC it reads
//! [`DriveSlave::demand`], integrates its model, feeds back [`DriveSlave::set_actual`] and calls
//! [`DriveSlave::transmit_pdos`].
//!
//! ```ignore
//! let mut out = FrameBuf::default();
//! slave.start(now_ns, &mut out);                        // boot-up message
//! // for every received frame:
//! if slave.handle_frame(&rx.frame, now_ns, &mut out) == SlaveEvent::Sync {
//!     let demand = slave.demand();                       // Follow{target_counts} / QuickStop / Hold
//!     /* plant physics step over one SYNC period */
//!     slave.set_actual(pos_counts, vel_counts_per_s, force_mn);
//!     slave.transmit_pdos(&mut out);
//! }
//! slave.poll(now_ns, &mut out);                         // heartbeat when due
//! // send out.as_slice() on the bus, then out.clear()
//! ```

use crate::canopen::*;
use crate::safety_watch::{InhibitReason, SafetyWatch, SafetyWatchConfig};
use can_transport::CanFrame;

/// What the drive asks its motor/physics to do this SYNC period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionDemand {
    /// Operation Enabled in CSP: track `target_counts` (latched at the last SYNC).
    Follow { target_counts: i32 },
    /// Quick stop active: decelerate at the quick-stop deceleration, then hold.
    QuickStop,
    /// Not enabled, NMT stopped, or fault: brake holds the drum (no motion).
    Hold,
}

/// Result of [`DriveSlave::handle_frame`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlaveEvent {
    None,
    /// A SYNC arrived while operational: step physics, `set_actual`, `transmit_pdos`.
    Sync,
}

/// One emulated CiA 402 drive (one CANopen node).
#[derive(Debug, Clone)]
pub struct DriveSlave {
    node: u8,
    nmt: NmtState,
    state: Ds402State,
    mode: i8,
    heartbeat_period_ms: u16,
    next_heartbeat_ns: u64,
    heartbeat_muted: bool,
    last_controlword: u16,
    /// Target from the last RPDO; becomes active at the next SYNC (CSP semantics).
    pending_target: i32,
    target: i32,
    position: i32,
    velocity: i32,
    force_mn: i32,
    /// Safe-torque path: set while the safety heartbeat is missing/invalid/STOP
    /// ([`crate::safety_watch`]); forces Quick Stop Active and blocks enabling.
    safety_inhibit: bool,
}

impl DriveSlave {
    /// A drive with node id `node` (1..=127) and a default heartbeat producer period (ms; 0 =
    /// off until the master writes 0x1017).
    pub fn new(node: u8, heartbeat_period_ms: u16) -> Self {
        Self {
            node,
            nmt: NmtState::BootUp,
            state: Ds402State::SwitchOnDisabled,
            mode: 0,
            heartbeat_period_ms,
            next_heartbeat_ns: 0,
            heartbeat_muted: false,
            last_controlword: 0,
            pending_target: 0,
            target: 0,
            position: 0,
            velocity: 0,
            force_mn: 0,
            safety_inhibit: false,
        }
    }

    /// Safety inhibit from the safety-heartbeat watch: while set, an enabled drive is put into
    /// Quick Stop Active (decelerate, then the brake holds) and no controlword can enable it.
    /// Clearing it does not re-enable anything (the master must).
    pub fn set_safety_inhibit(&mut self, inhibit: bool) {
        self.safety_inhibit = inhibit;
        if inhibit && self.state == Ds402State::OperationEnabled {
            self.state = Ds402State::QuickStopActive;
        }
    }

    pub fn safety_inhibited(&self) -> bool {
        self.safety_inhibit
    }

    pub fn node_id(&self) -> u8 {
        self.node
    }
    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }
    pub fn ds402_state(&self) -> Ds402State {
        self.state
    }
    pub fn statusword(&self) -> u16 {
        self.state.statusword()
    }
    pub fn mode_of_operation(&self) -> i8 {
        self.mode
    }

    /// Power-on: emits the boot-up message and enters pre-operational.
    pub fn start(&mut self, now_ns: u64, out: &mut FrameBuf) {
        self.nmt = NmtState::PreOperational;
        self.state = Ds402State::SwitchOnDisabled;
        out.push(heartbeat(self.node, NmtState::BootUp));
        self.next_heartbeat_ns = now_ns + u64::from(self.heartbeat_period_ms) * 1_000_000;
    }

    /// Test hook: stop (true) or resume producing heartbeats, as a drive with a dead CAN
    /// controller/firmware would.
    pub fn set_heartbeat_muted(&mut self, muted: bool) {
        self.heartbeat_muted = muted;
    }

    /// Internal drive fault (e.g. from the plant: over-current, cable slack): EMCY + Fault state.
    pub fn raise_fault(&mut self, emcy_code: u16, out: &mut FrameBuf) {
        self.state = Ds402State::Fault;
        if self.nmt != NmtState::Stopped {
            out.push(emcy(self.node, emcy_code, 0x01));
        }
    }

    /// Feeds the measured values reported in the next TPDOs.
    pub fn set_actual(&mut self, position_counts: i32, velocity_counts_per_s: i32, force_mn: i32) {
        self.position = position_counts;
        self.velocity = velocity_counts_per_s;
        self.force_mn = force_mn;
    }

    /// What the physics must do now.
    pub fn demand(&self) -> MotionDemand {
        if self.nmt != NmtState::Operational {
            return MotionDemand::Hold;
        }
        match self.state {
            Ds402State::OperationEnabled if self.mode == MODE_CSP => MotionDemand::Follow {
                target_counts: self.target,
            },
            Ds402State::QuickStopActive => MotionDemand::QuickStop,
            _ => MotionDemand::Hold,
        }
    }

    /// Sends TPDO1 (statusword, position) and TPDO2 (velocity, force). Call after a SYNC.
    pub fn transmit_pdos(&mut self, out: &mut FrameBuf) {
        if self.nmt == NmtState::Operational {
            out.push(tpdo1(self.node, self.statusword(), self.position));
            out.push(tpdo2(self.node, self.velocity, self.force_mn));
        }
    }

    /// Produces the heartbeat when due.
    pub fn poll(&mut self, now_ns: u64, out: &mut FrameBuf) {
        if self.heartbeat_period_ms == 0 || self.nmt == NmtState::BootUp {
            return;
        }
        if now_ns >= self.next_heartbeat_ns {
            if !self.heartbeat_muted {
                out.push(heartbeat(self.node, self.nmt));
            }
            let period = u64::from(self.heartbeat_period_ms) * 1_000_000;
            // Re-anchor if we fell far behind (non-real-time host): no burst of heartbeats.
            self.next_heartbeat_ns = if now_ns - self.next_heartbeat_ns > period {
                now_ns + period
            } else {
                self.next_heartbeat_ns + period
            };
        }
    }

    /// Nanoseconds until the next heartbeat is due (for the embedder's wait), if any.
    pub fn next_heartbeat_ns(&self) -> Option<u64> {
        (self.heartbeat_period_ms != 0).then_some(self.next_heartbeat_ns)
    }

    /// Handles one received frame; responses go to `out`.
    pub fn handle_frame(
        &mut self,
        frame: &CanFrame,
        now_ns: u64,
        out: &mut FrameBuf,
    ) -> SlaveEvent {
        match decode(frame) {
            Message::Nmt { command, node } if node == 0 || node == self.node => {
                self.nmt_command(command, now_ns, out);
                SlaveEvent::None
            }
            Message::Sync if self.nmt == NmtState::Operational => {
                self.target = self.pending_target;
                SlaveEvent::Sync
            }
            Message::Rpdo1 {
                node,
                controlword,
                target_counts,
            } if node == self.node => {
                if self.nmt == NmtState::Operational {
                    self.controlword(controlword);
                    self.pending_target = target_counts;
                }
                SlaveEvent::None
            }
            Message::SdoRequest { node, data } if node == self.node => {
                if self.nmt != NmtState::Stopped {
                    self.sdo(&data, out);
                }
                SlaveEvent::None
            }
            _ => SlaveEvent::None,
        }
    }

    fn nmt_command(&mut self, command: u8, now_ns: u64, out: &mut FrameBuf) {
        match command {
            NMT_START => self.nmt = NmtState::Operational,
            NMT_STOP => self.nmt = NmtState::Stopped,
            NMT_ENTER_PREOP => self.nmt = NmtState::PreOperational,
            NMT_RESET_NODE => {
                self.mode = 0;
                self.last_controlword = 0;
                self.start(now_ns, out);
            }
            NMT_RESET_COMM => {
                self.nmt = NmtState::PreOperational;
                out.push(heartbeat(self.node, NmtState::BootUp));
                self.next_heartbeat_ns = now_ns + u64::from(self.heartbeat_period_ms) * 1_000_000;
            }
            _ => {}
        }
    }

    /// CiA 402 device control state machine (transitions 2-16), driven by the controlword.
    fn controlword(&mut self, cw: u16) {
        use Ds402State::*;
        let prev = self.last_controlword;
        self.last_controlword = cw;
        let shutdown = cw & 0x87 == 0x06;
        let switch_on = cw & 0x8F == 0x07;
        let enable_op = cw & 0x8F == 0x0F;
        let disable_voltage = cw & 0x82 == 0x00;
        let quick_stop = cw & 0x86 == 0x02;
        let fault_reset_edge = cw & 0x80 != 0 && prev & 0x80 == 0;
        let before = self.state;
        self.state = match self.state {
            NotReadyToSwitchOn => SwitchOnDisabled,
            SwitchOnDisabled if shutdown => ReadyToSwitchOn,
            ReadyToSwitchOn if switch_on => SwitchedOn,
            ReadyToSwitchOn if enable_op => OperationEnabled,
            ReadyToSwitchOn if disable_voltage || quick_stop => SwitchOnDisabled,
            SwitchedOn if enable_op => OperationEnabled,
            SwitchedOn if shutdown => ReadyToSwitchOn,
            SwitchedOn if disable_voltage || quick_stop => SwitchOnDisabled,
            OperationEnabled if quick_stop => QuickStopActive,
            OperationEnabled if switch_on => SwitchedOn,
            OperationEnabled if shutdown => ReadyToSwitchOn,
            OperationEnabled if disable_voltage => SwitchOnDisabled,
            // Quick stop option code 6 (stop and stay in QSA): leave only by disable voltage,
            // or by enable operation (transition 16).
            QuickStopActive if disable_voltage => SwitchOnDisabled,
            QuickStopActive if enable_op => OperationEnabled,
            FaultReactionActive => Fault,
            Fault if fault_reset_edge => SwitchOnDisabled,
            s => s,
        };
        if self.safety_inhibit && self.state == OperationEnabled {
            // No enabling without a valid safety heartbeat.
            self.state = if before == OperationEnabled {
                QuickStopActive
            } else {
                before
            };
        }
        if self.state == OperationEnabled && !matches!(prev & 0x8F, 0x0F) {
            // Entering Operation Enabled: never jump; start from where the drum is.
            self.pending_target = self.position;
            self.target = self.position;
        }
    }

    fn sdo(&mut self, data: &[u8; 8], out: &mut FrameBuf) {
        let n = self.node;
        match parse_sdo_request(data) {
            SdoRequest::Download {
                index,
                sub,
                value,
                len,
            } => {
                let resp = match (index, sub) {
                    (OD_MODES_OF_OPERATION, 0) if len == 1 => {
                        let m = value as u8 as i8;
                        if m == MODE_CSP {
                            self.mode = m;
                            sdo_download_ok(n, index, sub)
                        } else {
                            sdo_abort(n, index, sub, SDO_ABORT_VALUE_RANGE)
                        }
                    }
                    (OD_PRODUCER_HEARTBEAT_MS, 0) if len == 2 => {
                        self.heartbeat_period_ms = value as u16;
                        sdo_download_ok(n, index, sub)
                    }
                    (OD_MODES_OF_OPERATION, 0) | (OD_PRODUCER_HEARTBEAT_MS, 0) => {
                        sdo_abort(n, index, sub, SDO_ABORT_LENGTH)
                    }
                    (OD_DEVICE_TYPE | OD_MODES_DISPLAY | OD_STATUSWORD | OD_POSITION_ACTUAL, 0) => {
                        sdo_abort(n, index, sub, SDO_ABORT_READ_ONLY)
                    }
                    _ => sdo_abort(n, index, sub, SDO_ABORT_NO_OBJECT),
                };
                out.push(resp);
            }
            SdoRequest::Upload { index, sub } => {
                let resp = match (index, sub) {
                    (OD_DEVICE_TYPE, 0) => sdo_upload_ok(n, index, sub, DEVICE_TYPE_SERVO, 4),
                    (OD_PRODUCER_HEARTBEAT_MS, 0) => {
                        sdo_upload_ok(n, index, sub, u32::from(self.heartbeat_period_ms), 2)
                    }
                    (OD_MODES_OF_OPERATION | OD_MODES_DISPLAY, 0) => {
                        sdo_upload_ok(n, index, sub, u32::from(self.mode as u8), 1)
                    }
                    (OD_STATUSWORD, 0) => {
                        sdo_upload_ok(n, index, sub, u32::from(self.statusword()), 2)
                    }
                    (OD_POSITION_ACTUAL, 0) => {
                        sdo_upload_ok(n, index, sub, self.position as u32, 4)
                    }
                    _ => sdo_abort(n, index, sub, SDO_ABORT_NO_OBJECT),
                };
                out.push(resp);
            }
            SdoRequest::Unsupported { index, sub } => {
                out.push(sdo_abort(n, index, sub, SDO_ABORT_COMMAND))
            }
        }
    }
}

/// Kinematic winch model of the test double: the cable length follows the target within speed
/// and acceleration limits (no elasticity, no load). SI units.
#[derive(Debug, Clone, Copy)]
pub struct WinchAxis {
    pub length_m: f64,
    pub velocity_m_per_s: f64,
    pub max_speed_m_per_s: f64,
    pub max_accel_m_per_s2: f64,
}

impl WinchAxis {
    pub fn new(length_m: f64, max_speed_m_per_s: f64, max_accel_m_per_s2: f64) -> Self {
        Self {
            length_m,
            velocity_m_per_s: 0.0,
            max_speed_m_per_s,
            max_accel_m_per_s2,
        }
    }

    /// Advances by `dt` s towards `target_m` (None = quick stop: decelerate to rest).
    pub fn step(&mut self, target_m: Option<f64>, dt: f64) {
        let a = self.max_accel_m_per_s2;
        let v_des = match target_m {
            Some(t) => {
                let e = t - self.length_m;
                // Largest speed from which we can still stop at the target, and no overshoot in one step.
                let v = (2.0 * a * e.abs())
                    .sqrt()
                    .min(self.max_speed_m_per_s)
                    .min(e.abs() / dt);
                v.copysign(e)
            }
            None => 0.0,
        };
        let dv = (v_des - self.velocity_m_per_s).clamp(-a * dt, a * dt);
        self.velocity_m_per_s += dv;
        self.length_m += self.velocity_m_per_s * dt;
    }

    /// Brake: stop immediately.
    pub fn hold(&mut self) {
        self.velocity_m_per_s = 0.0;
    }
}

/// All drives of one plant on one bus: what a coupled plant (all cables stepped together)
/// embeds. On every SYNC: read [`DriveBank::demand`] for each cable, step the physics once,
/// [`DriveBank::set_actual`] for each cable, then [`DriveBank::transmit_pdos`]; call
/// [`DriveBank::poll`] regularly for heartbeats and [`DriveBank::flush`] to send.
///
/// ```no_run
/// # use drive_io::slave::{DriveBank, MotionDemand};
/// # fn main() -> Result<(), can_transport::CanError> {
/// let mut bus = can_transport::open(&"udpbus:239.255.70.1:20000".parse().unwrap())?;
/// let mut bank = DriveBank::new(&[1, 2, 3, 4, 5, 6, 7, 8], 10);
/// bank.start(crs_ipc::monotonic_ns());
/// loop {
///     bank.flush(&mut bus)?;
///     let now = crs_ipc::monotonic_ns();
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
    out: FrameBuf,
    watch: Option<SafetyWatch>,
}

impl DriveBank {
    /// One [`DriveSlave`] per node id (cable order), default heartbeat period `heartbeat_ms`.
    pub fn new(node_ids: &[u8], heartbeat_ms: u16) -> Self {
        Self {
            slaves: node_ids
                .iter()
                .map(|&n| DriveSlave::new(n, heartbeat_ms))
                .collect(),
            out: FrameBuf::default(),
            watch: None,
        }
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
    /// Power-on of all drives (boot-up messages).
    pub fn start(&mut self, now_ns: u64) {
        for s in &mut self.slaves {
            s.start(now_ns, &mut self.out);
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
    /// TPDOs of all drives (after the physics step of a SYNC).
    pub fn transmit_pdos(&mut self) {
        for s in &mut self.slaves {
            s.transmit_pdos(&mut self.out);
        }
    }
    /// Heartbeats when due; applies the safety-heartbeat validation time if the watch is on.
    pub fn poll(&mut self, now_ns: u64) {
        self.apply_safety_watch(now_ns);
        for s in &mut self.slaves {
            s.poll(now_ns, &mut self.out);
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
