//! Drive-side (slave) emulation of a CiA 402 winch drive in cyclic synchronous position mode, for
//! simulated plants and test doubles. The slave handles NMT, SDO (expedited and segmented: the
//! string objects of its EDS such as 0x1008), RPDO/SYNC, produces
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

use can_transport::CanFrame;
use drive_bus::canopen::*;
use drive_bus::eds::{Access, DataType, Eds};
use drive_bus::sdo::{ObjectAccess, SDO_MAX, SdoServer};

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

/// One object dictionary entry held by a drive: EDS metadata + the current value (raw LE bits).
#[derive(Debug, Clone, Copy)]
struct OdSlot {
    index: u16,
    sub: u8,
    data_type: DataType,
    access: Access,
    pdo_mappable: bool,
    low: Option<i64>,
    high: Option<i64>,
    default: u32,
    value: u32,
}

/// A string or domain entry (served by segmented SDO).
#[derive(Debug, Clone)]
struct StringSlot {
    index: u16,
    sub: u8,
    access: Access,
    default: Vec<u8>,
    value: Vec<u8>,
}

/// Up to this many objects per PDO (the EDS may declare more mapping sub-indices; 8 bytes
/// bound any PDO anyway).
const MAX_MAPPED: usize = 8;

/// A PDO as the drive currently runs it (from its 0x14xx/0x16xx or 0x18xx/0x1Axx entries).
#[derive(Debug, Clone, Copy, Default)]
struct PdoRuntime {
    cob_id: u16,
    valid: bool,
    transmission_type: u8,
    count: usize,
    map: [(u16, u8, u8); MAX_MAPPED],
    syncs: u32,
    /// Asynchronous TPDOs: the last data sent (sent again only on change).
    last: [u8; 8],
    last_len: usize,
}

/// One emulated CiA 402 drive (one CANopen node), behaving per its EDS: an object dictionary
/// (values from the EDS defaults; SDO access checked against the EDS types, access and limits),
/// PDOs as mapped in 0x1400-0x1A03, NMT stop and heartbeat-consumer loss handled per 0x6007,
/// quick stop per 0x605A, target clamped to 0x607D, following error per 0x6065/0x6066.
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
    error_code: u16,
    /// Safe-torque path: set while the safety heartbeat is missing/invalid/STOP
    /// ([`drive_bus::safety_watch`]); forces Quick Stop Active and blocks enabling.
    safety_inhibit: bool,
    /// Safe torque off: the STO input (wired from the safety I/O node) is active.
    sto: bool,
    od: Vec<OdSlot>,
    /// String and domain entries of the EDS (0x1008 ...): (index, sub, access, default, value).
    strings: Vec<StringSlot>,
    sdo_server: SdoServer,
    rpdo: [PdoRuntime; 4],
    tpdo: [PdoRuntime; 4],
    sync_cob: u16,
    abort_option: i16,
    quick_stop_option: i16,
    position_limits: (i32, i32),
    following_window: u32,
    following_timeout_ms: u16,
    cycle_period_us: u32,
    /// SYNC periods the following error has exceeded the window.
    following_over: u32,
    /// Heartbeat consumer (0x1016 sub 1): producer node and time; armed by the first heartbeat.
    consumer: Option<(u8, u16)>,
    consumer_last_ns: Option<u64>,
    consumer_lost: bool,
    pdo_length_error_reported: bool,
}

impl DriveSlave {
    /// A drive with node id `node` (1..=127) per the simulated winch's EDS
    /// (`config/eds/crs-winch.eds`), producing heartbeats every `heartbeat_period_ms` (0 = off
    /// until the master writes 0x1017; the EDS default is 0).
    pub fn new(node: u8, heartbeat_period_ms: u16) -> Self {
        Self::with_eds(node, Eds::builtin_winch(), heartbeat_period_ms)
    }

    /// A drive implementing the object dictionary of `eds` (entries of the expedited types).
    pub fn with_eds(node: u8, eds: &Eds, heartbeat_period_ms: u16) -> Self {
        let od = eds
            .entries()
            .filter(|e| e.data_type.size().is_some())
            .map(|e| {
                let v = e.default_for(node) as u32;
                OdSlot {
                    index: e.index,
                    sub: e.sub,
                    data_type: e.data_type,
                    access: e.access,
                    pdo_mappable: e.pdo_mappable,
                    low: e.low,
                    high: e.high,
                    default: v,
                    value: v,
                }
            })
            .collect();
        let strings = eds
            .entries()
            .filter(|e| e.data_type.is_string())
            .map(|e| {
                let v = e
                    .default_text
                    .as_deref()
                    .and_then(|t| e.data_type.text_bytes(t))
                    .unwrap_or_default();
                StringSlot {
                    index: e.index,
                    sub: e.sub,
                    access: e.access,
                    default: v.clone(),
                    value: v,
                }
            })
            .collect();
        let mut s = Self {
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
            error_code: 0,
            safety_inhibit: false,
            sto: false,
            od,
            strings,
            sdo_server: SdoServer::default(),
            rpdo: [PdoRuntime::default(); 4],
            tpdo: [PdoRuntime::default(); 4],
            sync_cob: COB_SYNC,
            abort_option: 0,
            quick_stop_option: 2,
            position_limits: (i32::MIN, i32::MAX),
            following_window: u32::MAX,
            following_timeout_ms: 0,
            cycle_period_us: 0,
            following_over: 0,
            consumer: None,
            consumer_last_ns: None,
            consumer_lost: false,
            pdo_length_error_reported: false,
        };
        // The embedder's heartbeat period is this drive's power-on default of 0x1017.
        if let Some(i) = s.slot(OD_PRODUCER_HEARTBEAT_MS, 0) {
            s.od[i].default = u32::from(heartbeat_period_ms);
            s.od[i].value = u32::from(heartbeat_period_ms);
        }
        s.refresh();
        s
    }

    fn slot(&self, index: u16, sub: u8) -> Option<usize> {
        self.od
            .binary_search_by(|o| (o.index, o.sub).cmp(&(index, sub)))
            .ok()
    }
    fn raw(&self, index: u16, sub: u8) -> Option<u32> {
        self.slot(index, sub).map(|i| self.od[i].value)
    }
    fn set_raw(&mut self, index: u16, sub: u8, value: u32) {
        if let Some(i) = self.slot(index, sub) {
            self.od[i].value = value;
        }
    }

    /// Re-reads the configuration objects after a write (no allocation).
    fn refresh(&mut self) {
        let get = |s: &Self, i, sub, d| s.raw(i, sub).unwrap_or(d);
        self.heartbeat_period_ms = get(self, OD_PRODUCER_HEARTBEAT_MS, 0, 0) as u16;
        self.sync_cob = (get(self, OD_COB_ID_SYNC, 0, u32::from(COB_SYNC)) & 0x7FF) as u16;
        self.abort_option = get(self, OD_ABORT_CONNECTION, 0, 0) as u16 as i16;
        self.quick_stop_option = get(self, OD_QUICK_STOP_OPTION, 0, 2) as u16 as i16;
        self.position_limits = (
            get(self, OD_SOFTWARE_POSITION_LIMIT, 1, i32::MIN as u32) as i32,
            get(self, OD_SOFTWARE_POSITION_LIMIT, 2, i32::MAX as u32) as i32,
        );
        self.following_window = get(self, OD_FOLLOWING_ERROR_WINDOW, 0, u32::MAX);
        self.following_timeout_ms = get(self, OD_FOLLOWING_ERROR_TIMEOUT_MS, 0, 0) as u16;
        self.cycle_period_us = get(self, OD_COMM_CYCLE_PERIOD_US, 0, 0);
        let c = get(self, OD_CONSUMER_HEARTBEAT, 1, 0);
        let consumer = (c & 0xFFFF != 0 && (c >> 16) & 0x7F != 0)
            .then_some((((c >> 16) & 0x7F) as u8, (c & 0xFFFF) as u16));
        if consumer != self.consumer {
            self.consumer = consumer;
            self.consumer_last_ns = None;
            self.consumer_lost = false;
        }
        for k in 0..4u16 {
            self.rpdo[k as usize] = self.pdo_from_od(0x1400 + k, 0x1600 + k);
            self.tpdo[k as usize] = self.pdo_from_od(0x1800 + k, 0x1A00 + k);
        }
    }

    fn pdo_from_od(&self, comm: u16, map: u16) -> PdoRuntime {
        let mut p = PdoRuntime::default();
        let Some(cob) = self.raw(comm, 1) else {
            return p;
        };
        p.cob_id = (cob & 0x7FF) as u16;
        p.valid = cob & 0x8000_0000 == 0;
        p.transmission_type = self.raw(comm, 2).unwrap_or(0xFF) as u8;
        let n = (self.raw(map, 0).unwrap_or(0) as usize).min(MAX_MAPPED);
        for k in 0..n {
            let e = self.raw(map, k as u8 + 1).unwrap_or(0);
            p.map[k] = ((e >> 16) as u16, (e >> 8) as u8, e as u8);
        }
        p.count = n;
        p
    }

    /// Current value of an object (raw little-endian bits), live process data included.
    pub fn od_value(&self, index: u16, sub: u8) -> Option<u32> {
        if sub == 0 {
            match index {
                OD_STATUSWORD => return Some(u32::from(self.statusword())),
                OD_CONTROLWORD => return Some(u32::from(self.last_controlword)),
                OD_POSITION_ACTUAL => return Some(self.position as u32),
                OD_VELOCITY_ACTUAL => return Some(self.velocity as u32),
                OD_PULLEY_FORCE_MN => return Some(self.force_mn as u32),
                OD_TARGET_POSITION => return Some(self.pending_target as u32),
                OD_MODES_OF_OPERATION | OD_MODES_DISPLAY => {
                    return Some(u32::from(self.mode as u8));
                }
                OD_ERROR_CODE => return Some(u32::from(self.error_code)),
                OD_ERROR_REGISTER => return Some(u32::from(self.state == Ds402State::Fault)),
                _ => {}
            }
        }
        self.raw(index, sub)
    }

    /// Current value of a string or domain object (0x1008 ...).
    pub fn od_bytes(&self, index: u16, sub: u8) -> Option<&[u8]> {
        self.strings
            .iter()
            .find(|s| (s.index, s.sub) == (index, sub))
            .map(|s| s.value.as_slice())
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

    /// Safe torque off (the drive's STO input, wired from the safety I/O node): while active
    /// the power stage is off — the drive drops to Switch On Disabled at once (no ramp: stop
    /// category 0, the brake closes) and cannot be switched on, whatever the controlword or
    /// the NMT state. Releasing it enables nothing (the master must).
    pub fn set_sto(&mut self, active: bool) {
        self.sto = active;
        if active {
            self.drop_power_stage();
        }
    }

    pub fn sto_active(&self) -> bool {
        self.sto
    }

    fn drop_power_stage(&mut self) {
        use Ds402State::*;
        if matches!(
            self.state,
            ReadyToSwitchOn | SwitchedOn | OperationEnabled | QuickStopActive
        ) {
            self.state = SwitchOnDisabled;
        }
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
    /// 0x607F in counts/s (u32::MAX = unlimited): the embedder's motion limit.
    pub fn max_profile_velocity(&self) -> u32 {
        self.raw(OD_MAX_PROFILE_VELOCITY, 0).unwrap_or(u32::MAX)
    }
    /// 0x607D (min, max) in counts.
    pub fn software_position_limits(&self) -> (i32, i32) {
        self.position_limits
    }
    /// 0x6085 in counts/s² (None if the EDS has no such object): the embedder's quick stop
    /// ramp.
    pub fn quick_stop_deceleration(&self) -> Option<u32> {
        self.raw(0x6085, 0)
    }
    /// Sets a process value the device's own firmware produces (a measured value mapped into
    /// a TPDO, e.g. a load cell's 0x9130sub1); ignored if the object is not there.
    pub fn set_process_value(&mut self, index: u16, sub: u8, raw: u32) {
        self.set_raw(index, sub, raw);
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
        self.error_code = emcy_code;
        if self.nmt != NmtState::Stopped {
            out.push(emcy(self.node, emcy_code, 0x01));
        }
    }

    /// Feeds the measured values reported in the next TPDOs; checks the following error
    /// (0x6065 window for longer than 0x6066 ms => Fault, EMCY 0x8611) and ends a quick stop
    /// per 0x605A once the axis stands still.
    pub fn set_actual(&mut self, position_counts: i32, velocity_counts_per_s: i32, force_mn: i32) {
        self.position = position_counts;
        self.velocity = velocity_counts_per_s;
        self.force_mn = force_mn;
        if self.state == Ds402State::QuickStopActive
            && velocity_counts_per_s == 0
            && matches!(self.quick_stop_option, 1..=4)
        {
            // Option codes 1-4: after the ramp, Switch On Disabled (the brake holds).
            self.state = Ds402State::SwitchOnDisabled;
        }
    }

    fn check_following_error(&mut self, out: &mut FrameBuf) {
        if self.state != Ds402State::OperationEnabled || self.following_window == u32::MAX {
            self.following_over = 0;
            return;
        }
        let err = (i64::from(self.target) - i64::from(self.position)).unsigned_abs();
        if err <= u64::from(self.following_window) {
            self.following_over = 0;
            return;
        }
        self.following_over += 1;
        let period_us = if self.cycle_period_us == 0 {
            1000
        } else {
            self.cycle_period_us
        };
        if u64::from(self.following_over) * u64::from(period_us)
            > u64::from(self.following_timeout_ms) * 1000
        {
            self.raise_fault(EMCY_FOLLOWING_ERROR, out);
        }
    }

    /// What the physics must do now. Operation Enabled in CSP follows the target even in NMT
    /// stopped (0x6007 = 0: the connection loss is not acted on); Quick Stop Active ramps down.
    pub fn demand(&self) -> MotionDemand {
        match self.state {
            Ds402State::OperationEnabled if self.mode == MODE_CSP => MotionDemand::Follow {
                target_counts: self.target,
            },
            Ds402State::QuickStopActive => MotionDemand::QuickStop,
            _ => MotionDemand::Hold,
        }
    }

    /// Sends the TPDOs as mapped (synchronous ones every n-th SYNC, asynchronous ones on
    /// change). Call after a SYNC's physics step.
    pub fn transmit_pdos(&mut self, out: &mut FrameBuf) {
        self.check_following_error(out);
        if self.nmt != NmtState::Operational {
            return;
        }
        for k in 0..self.tpdo.len() {
            let p = self.tpdo[k];
            if !p.valid {
                continue;
            }
            let mut data = [0u8; 8];
            let mut len = 0usize;
            for &(index, sub, bits) in &p.map[..p.count] {
                let n = usize::from(bits / 8);
                if len + n > 8 {
                    break;
                }
                let v = self.od_value(index, sub).unwrap_or(0).to_le_bytes();
                data[len..len + n].copy_from_slice(&v[..n.min(4)]);
                len += n;
            }
            let send = match p.transmission_type {
                0 => data[..len] != p.last[..p.last_len] || p.last_len != len,
                1..=240 => {
                    let t = &mut self.tpdo[k];
                    t.syncs += 1;
                    if t.syncs >= u32::from(p.transmission_type) {
                        t.syncs = 0;
                        true
                    } else {
                        false
                    }
                }
                254 | 255 => data[..len] != p.last[..p.last_len] || p.last_len != len,
                _ => false,
            };
            if send {
                self.tpdo[k].last = data;
                self.tpdo[k].last_len = len;
                out.push(CanFrame::new_std_lossy(p.cob_id, &data[..len]));
            }
        }
    }

    /// Produces the heartbeat when due; watches the consumer heartbeat (0x1016).
    pub fn poll(&mut self, now_ns: u64, out: &mut FrameBuf) {
        if let (Some((_, ms)), Some(last)) = (self.consumer, self.consumer_last_ns)
            && !self.consumer_lost
            && now_ns.saturating_sub(last) > u64::from(ms) * 1_000_000
        {
            // CiA 301 §7.2.8.3.2.2 heartbeat event; the CiA 402 reaction is 0x6007's.
            self.consumer_lost = true;
            if self.nmt != NmtState::Stopped {
                out.push(emcy(self.node, EMCY_HEARTBEAT, 0x11));
            }
            self.abort_connection(out);
        }
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

    /// CiA 402 0x6007 reaction to a connection abort (NMT stopped, heartbeat loss).
    fn abort_connection(&mut self, out: &mut FrameBuf) {
        use Ds402State::*;
        match self.abort_option {
            1 if self.state != Fault => self.raise_fault(EMCY_HEARTBEAT, out),
            2 if matches!(
                self.state,
                OperationEnabled | QuickStopActive | SwitchedOn | ReadyToSwitchOn
            ) =>
            {
                self.state = SwitchOnDisabled
            }
            3 if self.state == OperationEnabled => self.state = QuickStopActive,
            _ => {}
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
        if frame.is_extended() || frame.is_rtr() {
            return SlaveEvent::None;
        }
        let cob = frame.id() as u16;
        let d = frame.data();
        if cob == COB_NMT {
            if d.len() == 2 && (d[1] == 0 || d[1] == self.node) {
                self.nmt_command(d[0], now_ns, out);
            }
            return SlaveEvent::None;
        }
        if cob == self.sync_cob && d.len() <= 1 {
            if self.nmt == NmtState::Operational {
                let (lo, hi) = self.position_limits;
                self.target = self.pending_target.clamp(lo, hi.max(lo));
                return SlaveEvent::Sync;
            }
            return SlaveEvent::None;
        }
        if let Some((producer, _)) = self.consumer
            && cob == COB_HEARTBEAT_BASE + u16::from(producer)
            && d.len() == 1
        {
            self.consumer_last_ns = Some(now_ns);
            self.consumer_lost = false;
            return SlaveEvent::None;
        }
        if cob == COB_SDO_RX_BASE + u16::from(self.node) {
            if d.len() == 8 && self.nmt != NmtState::Stopped && self.nmt != NmtState::BootUp {
                let mut data = [0u8; 8];
                data.copy_from_slice(d);
                self.sdo(&data, out);
            }
            return SlaveEvent::None;
        }
        if self.nmt == NmtState::Operational
            && let Some(k) = self.rpdo.iter().position(|p| p.valid && p.cob_id == cob)
        {
            self.receive_pdo(k, d, out);
        }
        SlaveEvent::None
    }

    fn receive_pdo(&mut self, k: usize, d: &[u8], out: &mut FrameBuf) {
        let p = self.rpdo[k];
        let need: usize = p.map[..p.count].iter().map(|m| usize::from(m.2 / 8)).sum();
        if d.len() < need {
            // CiA 301: a too short RPDO is not processed (EMCY once).
            if !self.pdo_length_error_reported {
                self.pdo_length_error_reported = true;
                out.push(emcy(self.node, EMCY_PDO_LENGTH, 0x11));
            }
            return;
        }
        let mut at = 0usize;
        for &(index, sub, bits) in &p.map[..p.count] {
            let n = usize::from(bits / 8);
            let mut b = [0u8; 4];
            b[..n.min(4)].copy_from_slice(&d[at..at + n.min(4)]);
            at += n;
            let v = u32::from_le_bytes(b);
            match (index, sub) {
                (OD_CONTROLWORD, 0) => self.controlword(v as u16),
                (OD_TARGET_POSITION, 0) => self.pending_target = v as i32,
                _ => self.set_raw(index, sub, v),
            }
        }
    }

    fn nmt_command(&mut self, command: u8, now_ns: u64, out: &mut FrameBuf) {
        match command {
            NMT_START => self.nmt = NmtState::Operational,
            NMT_STOP if self.nmt != NmtState::Stopped => {
                self.nmt = NmtState::Stopped;
                self.abort_connection(out);
            }
            NMT_ENTER_PREOP => self.nmt = NmtState::PreOperational,
            NMT_RESET_NODE => {
                // Application and communication parameters back to the EDS defaults.
                for o in &mut self.od {
                    o.value = o.default;
                }
                for o in &mut self.strings {
                    o.value = o.default.clone();
                }
                self.mode = 0;
                self.last_controlword = 0;
                self.refresh();
                self.start(now_ns, out);
            }
            NMT_RESET_COMM => {
                for o in self
                    .od
                    .iter_mut()
                    .filter(|o| (0x1000..0x2000).contains(&o.index))
                {
                    o.value = o.default;
                }
                self.refresh();
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
        if self.sto {
            // STO: the power stage stays off.
            self.drop_power_stage();
        }
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
        let mut server = std::mem::take(&mut self.sdo_server);
        let resp = server.handle(data, self);
        self.sdo_server = server;
        if let Some(r) = resp {
            out.push(CanFrame::new_std_lossy(
                COB_SDO_TX_BASE + u16::from(self.node),
                &r,
            ));
        }
    }

    /// Abort code for an object/sub-index that is not there.
    fn missing(&self, index: u16) -> u32 {
        if self.od.iter().any(|o| o.index == index) || self.strings.iter().any(|o| o.index == index)
        {
            SDO_ABORT_NO_SUB
        } else {
            SDO_ABORT_NO_OBJECT
        }
    }

    fn read_value(&self, index: u16, sub: u8) -> Result<(u32, u8), u32> {
        let Some(i) = self.slot(index, sub) else {
            return Err(self.missing(index));
        };
        let o = self.od[i];
        if !o.access.readable() {
            return Err(SDO_ABORT_WRITE_ONLY);
        }
        let len = o.data_type.size().unwrap_or(4);
        Ok((self.od_value(index, sub).unwrap_or(o.value), len))
    }

    /// An SDO download checked against the EDS entry (CiA 301 abort codes).
    fn write_value(&mut self, index: u16, sub: u8, value: u32, len: u8) -> Result<(), u32> {
        let Some(i) = self.slot(index, sub) else {
            return Err(self.missing(index));
        };
        let o = self.od[i];
        if !o.access.writable() {
            return Err(SDO_ABORT_READ_ONLY);
        }
        let size = o.data_type.size().unwrap_or(4);
        if len != size {
            return Err(SDO_ABORT_LENGTH);
        }
        let v = o.data_type.to_i64(value);
        if let Some(lo) = o.low
            && v < lo
        {
            return Err(SDO_ABORT_VALUE_LOW);
        }
        if let Some(hi) = o.high
            && v > hi
        {
            return Err(SDO_ABORT_VALUE_HIGH);
        }
        match (index, sub) {
            (OD_MODES_OF_OPERATION, 0) => {
                // This drive implements cyclic synchronous position only.
                if value as u8 as i8 != MODE_CSP {
                    return Err(SDO_ABORT_VALUE_RANGE);
                }
                self.mode = MODE_CSP;
            }
            (OD_CONTROLWORD, 0) => self.controlword(value as u16),
            (OD_TARGET_POSITION, 0) => self.pending_target = value as i32,
            (0x1400..=0x1403 | 0x1800..=0x1803, 1) => {
                let k = usize::from(index & 0x3);
                let p = if index < 0x1800 {
                    self.rpdo[k]
                } else {
                    self.tpdo[k]
                };
                // CiA 301 §7.5.2.35: a valid PDO's COB-ID cannot be changed (disable first).
                if p.valid && value & 0x8000_0000 == 0 && (value & 0x7FF) as u16 != p.cob_id {
                    return Err(SDO_ABORT_VALUE_RANGE);
                }
                if value & 0x8000_0000 == 0 {
                    let cob = (value & 0x7FF) as u16;
                    if cob == 0 || cob == COB_NMT || cob == self.sync_cob {
                        return Err(SDO_ABORT_VALUE_RANGE);
                    }
                }
                self.od[i].value = value;
            }
            (0x1400..=0x1403 | 0x1800..=0x1803, 2) => {
                if (241..=251).contains(&(value as u8)) {
                    return Err(SDO_ABORT_VALUE_RANGE);
                }
                self.od[i].value = value;
            }
            (0x1600..=0x1603 | 0x1A00..=0x1A03, _) => self.write_mapping(index, sub, value)?,
            _ => self.od[i].value = value,
        }
        self.refresh();
        Ok(())
    }

    /// CiA 301 §7.2.2.3.4 mapping procedure: only while the PDO is disabled; entries only with
    /// sub 0 = 0; sub 0 = n checks every entry (mappable, direction, ≤ 64 bits).
    fn write_mapping(&mut self, index: u16, sub: u8, value: u32) -> Result<(), u32> {
        let k = usize::from(index & 0x3);
        let rx = index < 0x1A00;
        let p = if rx { self.rpdo[k] } else { self.tpdo[k] };
        if p.valid {
            return Err(SDO_ABORT_UNSUPPORTED_ACCESS);
        }
        if sub == 0 {
            let n = value as usize;
            let mut bits = 0usize;
            for s in 1..=n {
                let Some(e) = self.raw(index, s as u8) else {
                    return Err(SDO_ABORT_PDO_LENGTH);
                };
                let (i, si, b) = ((e >> 16) as u16, (e >> 8) as u8, e as u8);
                let Some(t) = self.slot(i, si) else {
                    return Err(SDO_ABORT_NOT_MAPPABLE);
                };
                let o = self.od[t];
                let dir_ok = if rx {
                    o.access.writable()
                } else {
                    o.access.readable()
                };
                if !o.pdo_mappable || !dir_ok || o.data_type.size().map(|s| s * 8) != Some(b) {
                    return Err(SDO_ABORT_NOT_MAPPABLE);
                }
                bits += usize::from(b);
            }
            if n > MAX_MAPPED || bits > 64 {
                return Err(SDO_ABORT_PDO_LENGTH);
            }
        } else {
            if self.raw(index, 0).unwrap_or(0) != 0 {
                return Err(SDO_ABORT_UNSUPPORTED_ACCESS);
            }
            if value != 0 {
                let (i, si, b) = ((value >> 16) as u16, (value >> 8) as u8, value as u8);
                let Some(t) = self.slot(i, si) else {
                    return Err(SDO_ABORT_NOT_MAPPABLE);
                };
                let o = self.od[t];
                if !o.pdo_mappable || o.data_type.size().map(|s| s * 8) != Some(b) {
                    return Err(SDO_ABORT_NOT_MAPPABLE);
                }
            }
        }
        self.set_raw(index, sub, value);
        Ok(())
    }
}

impl ObjectAccess for DriveSlave {
    fn sdo_read(&mut self, index: u16, sub: u8, out: &mut [u8; SDO_MAX]) -> Result<usize, u32> {
        if let Some(s) = self
            .strings
            .iter()
            .find(|s| (s.index, s.sub) == (index, sub))
        {
            if !s.access.readable() {
                return Err(SDO_ABORT_WRITE_ONLY);
            }
            let n = s.value.len().min(SDO_MAX);
            out[..n].copy_from_slice(&s.value[..n]);
            return Ok(n);
        }
        let (value, len) = self.read_value(index, sub)?;
        let n = usize::from(len);
        out[..n].copy_from_slice(&value.to_le_bytes()[..n]);
        Ok(n)
    }

    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        if let Some(s) = self
            .strings
            .iter_mut()
            .find(|s| (s.index, s.sub) == (index, sub))
        {
            if !s.access.writable() {
                return Err(SDO_ABORT_READ_ONLY);
            }
            s.value = data.to_vec();
            return Ok(());
        }
        if data.is_empty() || data.len() > 4 {
            // An integer object: the length does not match (an unknown object: not there).
            return Err(match self.slot(index, sub) {
                Some(_) => SDO_ABORT_LENGTH,
                None => self.missing(index),
            });
        }
        let mut b = [0u8; 4];
        b[..data.len()].copy_from_slice(data);
        self.write_value(index, sub, u32::from_le_bytes(b), data.len() as u8)
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
