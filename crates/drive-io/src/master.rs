//! CiA 402 master core: pure logic (frames in, frames out), no I/O, no allocation per cycle.
//! [`crate::runner`] ties it to a bus, the 1 ms SYNC timer and iceoryx2.
//!
//! Sequence: NMT reset-communication (per node) -> wait boot-up of every drive and force
//! sensor -> SDO start-up script of each ([`drive_commissioning::commissioning`]: identity checks first, then
//! PDOs, heartbeats, option codes, mode; read-back) -> NMT start (per node) -> SYNC every
//! period, RPDOs (encoded from each drive's mapping) walk each drive to Operation Enabled
//! holding its actual position -> Ready -> Running on the first new setpoint. TPDOs are
//! decoded from each node's mapping; cable forces come from the drive or its force sensor. Any of: stale setpoints, e-stop event, heartbeat loss,
//! EMCY, drive fault bit, invalid setpoint => quick stop ALL drives and hold (latched until the
//! safety monitor's reset, [`Master::reset`] with a [`ResetGrant`]).

use crate::reset::ResetGrant;
use can_transport::RxFrame;
use crs_ipc::{
    BusState, DriveFeedback, EventKind, FaultCode, JointSetpoint, MAX_CABLES, StateEvent,
};
use drive_bus::canopen::*;
use drive_bus::eds::{Eds, sdo_abort_text};
use drive_bus::mapping::Decoded;
use drive_bus::safety_watch::SafetyWatch;
use drive_bus::sdo::{ClientStep, SdoClient};
pub use drive_commissioning::commissioning::SetupError;
use drive_commissioning::commissioning::{NodeKind, Plan, SdoOp};
use drives_config::{DrivesConfig, WinchConfig};

const SDO_RETRIES: u8 = 3;
/// Drives and force sensors.
const MAX_NODES: usize = 2 * MAX_CABLES;

/// Why a drive's start-up configuration failed (what, where, the drive's answer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommissioningFault {
    /// The drive refused an SDO transfer (CiA 301 abort code).
    Abort {
        node: u8,
        index: u16,
        sub: u8,
        write: bool,
        code: u32,
    },
    /// A value read back differs from the one written.
    Readback {
        node: u8,
        index: u16,
        sub: u8,
        wrote: u32,
        read: u32,
    },
    /// No answer after the retries.
    Timeout { node: u8, index: u16, sub: u8 },
    /// An identity (or unit) check failed before anything was written: a wrong or swapped
    /// device on this node id.
    Check {
        node: u8,
        index: u16,
        sub: u8,
        expected: u32,
        found: u32,
    },
    /// The device name (a string) differs from drives.toml (the found text is in the node's
    /// SDO client).
    CheckText { node: u8, index: u16, sub: u8 },
    /// The node broke the SDO protocol (drive-io aborted with this code).
    Protocol {
        node: u8,
        index: u16,
        sub: u8,
        code: u32,
    },
}

/// What a drive reports wrong while enabled ([`Master::check_drives`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Finding {
    TpdoTimeout,
    ForceTpdoTimeout,
    Fault,
    LeftOperation,
    LeftNmtOperational,
    IgnoresTarget,
    FollowingError,
}

impl Finding {
    fn code(self) -> FaultCode {
        match self {
            Self::TpdoTimeout | Self::ForceTpdoTimeout => FaultCode::PdoTimeout,
            Self::Fault | Self::FollowingError => FaultCode::DriveFaultBit,
            Self::LeftOperation | Self::LeftNmtOperational | Self::IgnoresTarget => {
                FaultCode::UnexpectedState
            }
        }
    }

    fn text(self) -> &'static str {
        match self {
            Self::TpdoTimeout => "TPDO timeout",
            Self::ForceTpdoTimeout => "cable force TPDO timeout",
            Self::Fault => "drive reports a fault (CiA 402 Fault or Fault Reaction Active)",
            Self::LeftOperation => {
                "drive left Operation Enabled without drive-io's command (Switch On Disabled: \
                 its torque off, e.g. its STO input)"
            }
            Self::LeftNmtOperational => "drive left NMT Operational (NMT stop or pre-operational)",
            Self::IgnoresTarget => {
                "drive ignores the target position (statusword bit 12 clear in CSP)"
            }
            Self::FollowingError => "drive reports a following error (statusword bit 13 in CSP)",
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct DriveView {
    node: u8,
    /// The drive's CAN interface (index into `DrivesConfig::interfaces()`).
    iface: u8,
    booted: bool,
    hb_monitored: bool,
    last_hb_ns: u64,
    last_hb_state: u8,
    seen_operational: bool,
    /// Heartbeat timeout already reported (reported once per loss, cleared by a heartbeat).
    hb_lost: bool,
    statusword: u16,
    have_tpdo1: bool,
    position: i32,
    velocity: i32,
    rx_ns: u64,
    /// Next step of the drive's start-up script ([`drive_commissioning::commissioning::plan`]).
    sdo: usize,
    sdo_outstanding: bool,
    sdo_sent_ns: u64,
    sdo_tries: u8,
    /// The next request of a segmented transfer (sent by the next cycle).
    sdo_next: Option<[u8; 8]>,
    /// Last TPDO with the velocity / the cable force, and the force (N).
    vel_rx_ns: u64,
    force_rx_ns: u64,
    force_n: f64,
}

impl DriveView {
    fn new(node: u8, iface: u8) -> Self {
        Self {
            node,
            iface,
            booted: false,
            hb_monitored: false,
            last_hb_ns: 0,
            last_hb_state: 0,
            seen_operational: false,
            hb_lost: false,
            statusword: 0,
            have_tpdo1: false,
            position: 0,
            velocity: 0,
            rx_ns: 0,
            sdo: 0,
            sdo_outstanding: false,
            sdo_sent_ns: 0,
            sdo_tries: 0,
            sdo_next: None,
            vel_rx_ns: 0,
            force_rx_ns: 0,
            force_n: 0.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Boot,
    Configure,
    Enable,
    Ready,
    Running,
    Stopped(BusState),
}

/// The master's per-bus state. Create once (allocates), then call [`Master::on_frame`],
/// [`Master::on_event`] and [`Master::cycle`]; none of these allocate.
pub struct Master {
    /// Per node (the drives in cable order, then the force sensors): start-up script and PDO
    /// mapping.
    plans: Vec<Plan>,
    /// All nodes (drives and force sensors); `drives[..m]` are the drives.
    n: usize,
    sdo_client: [SdoClient; MAX_NODES],
    /// Per cable: the node (index into `drives`) whose TPDO carries its force.
    force_node: [usize; MAX_CABLES],
    /// ((interface, COB-ID), node index) of every used TPDO, sorted.
    tpdo_cobs: Vec<((u8, u16), usize)>,
    commissioning_fault: Option<CommissioningFault>,
    master_node_id: u8,
    master_hb_ns: u64,
    next_master_hb_ns: u64,
    /// Escalation: drive-io's own heartbeat is withheld (the drives act per 0x6007).
    hb_inhibit: bool,
    quick_stop_timeout_ns: u64,
    /// When the current stop was first commanded on the bus (set by the next cycle).
    qs_since_ns: Option<u64>,
    /// Quick stop supervision: 0 waiting, 1 NMT stop sent, 2 heartbeat withheld, 3 acknowledged.
    qs_stage: u8,
    /// The drives were NMT-stopped by an escalation: the next reset starts them again.
    nmt_stopped: bool,
    restart_nmt: bool,
    winches: Vec<WinchConfig>,
    m: usize,
    /// Number of CAN interfaces.
    interfaces: usize,
    sync_period_ns: u64,
    stale_cycles: u32,
    hb_timeout_ns: u64,
    boot_timeout_ns: u64,
    sdo_timeout_ns: u64,
    max_step_counts: [f64; MAX_CABLES],
    /// Largest change of the step per period between consecutive steps (counts per period²).
    max_accel_counts: [f64; MAX_CABLES],
    /// The speed of the last applied step (counts per SYNC period of stream time: the step over
    /// the sequence numbers it covered) and those periods; 0 after enabling, holding or a stop.
    last_vel_counts: [f64; MAX_CABLES],
    last_periods: f64,
    force_limit_n: f64,
    drives: [DriveView; MAX_NODES],
    phase: Phase,
    boot_start_ns: Option<u64>,
    cycle: u64,
    toggle: bool,
    target: [i32; MAX_CABLES],
    last_seq: u64,
    /// Setpoints of the stream never read by a cycle: a newer one was published before the
    /// cycle read the subscriber (sequence numbers skipped between two cycles' reads).
    superseded: u64,
    /// motion-core announced the planned end of its setpoint stream (`MotionState::Stopping`).
    stream_end: bool,
    /// The last applied setpoint commanded rest (every cable speed zero).
    last_at_rest: bool,
    /// drive-io's own clock (the cycle's now) when the last setpoint was applied.
    last_apply_ns: u64,
    setpoint_age: u32,
    applied_seq: u64,
    applied_this_cycle: bool,
    fault_code: FaultCode,
    fault_node: u32,
    last_emcy: u32,
    state_changed: bool,
    overruns: u32,
    feedback: DriveFeedback,
}

impl Master {
    /// A master for `cfg`'s drives and force sensors, each configured from its EDS
    /// (`winch[i].eds`, else `bus.eds`, else the simulated winch's; a force sensor's, else the
    /// simulated load cell's); fails if an EDS cannot be read or lacks what the configuration
    /// needs.
    pub fn new(cfg: &DrivesConfig) -> Result<Self, SetupError> {
        Self::from_plans(
            cfg,
            drive_commissioning::commissioning::plan_all(cfg, None)?,
        )
    }

    /// A master whose drives are all described by `eds` (force sensors by their own).
    pub fn with_eds(cfg: &DrivesConfig, eds: Eds) -> Result<Self, SetupError> {
        Self::from_plans(
            cfg,
            drive_commissioning::commissioning::plan_all(cfg, Some(&eds))?,
        )
    }

    fn from_plans(cfg: &DrivesConfig, plans: Vec<Plan>) -> Result<Self, SetupError> {
        let m = cfg.winches.len().min(MAX_CABLES);
        let n = plans.len().min(MAX_NODES);
        let winches = cfg.winches[..m].to_vec();
        let mut drives = [DriveView::new(0, 0); MAX_NODES];
        let mut max_step_counts = [0.0; MAX_CABLES];
        let mut max_accel_counts = [0.0; MAX_CABLES];
        let period_s = f64::from(cfg.bus.sync_period_us) * 1e-6;
        for (k, (d, p)) in drives.iter_mut().zip(&plans).take(n).enumerate() {
            let iface = if k < m {
                cfg.winch_interface(k)
            } else {
                cfg.sensor_interface(k - m)
            };
            *d = DriveView::new(p.node, iface as u8);
        }
        let mut force_node = [0usize; MAX_CABLES];
        for (i, f) in force_node.iter_mut().enumerate().take(m) {
            *f = cfg.force_sensor_of(i).map_or(i, |j| m + j);
        }
        let mut tpdo_cobs: Vec<((u8, u16), usize)> = plans
            .iter()
            .take(n)
            .enumerate()
            .flat_map(|(k, p)| {
                let iface = drives[k].iface;
                p.mapping
                    .pdos
                    .iter()
                    .filter(|p| p.used && p.direction == drive_bus::mapping::Direction::FromNode)
                    .map(move |p| ((iface, p.cob_id), k))
            })
            .collect();
        tpdo_cobs.sort_unstable();
        if let Some(w) = tpdo_cobs.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(SetupError::CobCollision {
                cob_id: w[0].0.1,
                a: plans[w[0].1].node,
                b: plans[w[1].1].node,
            });
        }
        for i in 0..m {
            // Largest step per SYNC period at max cable speed.
            max_step_counts[i] =
                cfg.bus.max_cable_speed_m_per_s * period_s * winches[i].counts_per_m();
            // Largest change of the step between consecutive periods at max acceleration.
            max_accel_counts[i] = cfg.bus.max_cable_acceleration_m_per_s2
                * period_s
                * period_s
                * winches[i].counts_per_m();
        }
        let feedback = DriveFeedback {
            cable_count: m as u32,
            ..Default::default()
        };
        Ok(Self {
            plans,
            n,
            sdo_client: [SdoClient::default(); MAX_NODES],
            force_node,
            tpdo_cobs,
            commissioning_fault: None,
            master_node_id: cfg.bus.master_node_id,
            master_hb_ns: u64::from(cfg.bus.master_heartbeat_ms) * 1_000_000,
            next_master_hb_ns: 0,
            hb_inhibit: false,
            quick_stop_timeout_ns: u64::from(cfg.bus.quick_stop_timeout_ms) * 1_000_000,
            qs_since_ns: None,
            qs_stage: 0,
            nmt_stopped: false,
            restart_nmt: false,
            winches,
            m,
            interfaces: cfg.interfaces().len(),
            sync_period_ns: cfg.sync_period_ns(),
            stale_cycles: cfg.bus.stale_setpoint_cycles,
            hb_timeout_ns: u64::from(cfg.bus.heartbeat_timeout_ms) * 1_000_000,
            boot_timeout_ns: u64::from(cfg.bus.boot_timeout_ms) * 1_000_000,
            sdo_timeout_ns: u64::from(cfg.bus.sdo_timeout_ms) * 1_000_000,
            max_step_counts,
            max_accel_counts,
            last_vel_counts: [0.0; MAX_CABLES],
            last_periods: 1.0,
            force_limit_n: cfg.bus.force_hard_limit_n,
            drives,
            phase: Phase::Boot,
            boot_start_ns: None,
            cycle: 0,
            toggle: false,
            target: [0; MAX_CABLES],
            last_seq: 0,
            superseded: 0,
            stream_end: false,
            last_at_rest: false,
            last_apply_ns: 0,
            setpoint_age: 0,
            applied_seq: 0,
            applied_this_cycle: false,
            fault_code: FaultCode::None,
            fault_node: 0,
            last_emcy: 0,
            state_changed: true,
            overruns: 0,
            feedback,
        })
    }

    /// The start-up plan of every node: the drives in cable order, then the force sensors.
    pub fn plans(&self) -> &[Plan] {
        &self.plans[..self.n]
    }

    /// The EDS the first drive was configured from (every node's: [`Master::plans`]).
    pub fn eds(&self) -> &Eds {
        &self.plans[0].eds
    }

    /// The first start-up configuration failure, if any (start-up stopped there).
    pub fn commissioning_fault(&self) -> Option<CommissioningFault> {
        self.commissioning_fault
    }

    fn plan_of(&self, node: u8) -> Option<(usize, &Plan)> {
        self.plans.iter().enumerate().find(|(_, p)| p.node == node)
    }

    /// The failure as a sentence naming the node, the object (EDS name) and the CiA 301 abort
    /// text, or for a failed check the expected and the found value and the TOML key.
    pub fn describe_commissioning_fault(&self) -> Option<String> {
        let f = self.commissioning_fault?;
        let node = match f {
            CommissioningFault::Abort { node, .. }
            | CommissioningFault::Readback { node, .. }
            | CommissioningFault::Timeout { node, .. }
            | CommissioningFault::Check { node, .. }
            | CommissioningFault::CheckText { node, .. }
            | CommissioningFault::Protocol { node, .. } => node,
        };
        let (k, plan) = self.plan_of(node)?;
        let (kind, eds) = (plan.kind, &plan.eds);
        Some(match f {
            CommissioningFault::Abort {
                index,
                sub,
                write,
                code,
                ..
            } => format!(
                "{kind} node {node} refused SDO {} of {}: abort code 0x{code:08X} ({}) [EDS {}]",
                if write { "write" } else { "read" },
                eds.describe(index, sub),
                sdo_abort_text(code),
                eds.file
            ),
            CommissioningFault::Readback {
                index,
                sub,
                wrote,
                read,
                ..
            } => format!(
                "{kind} node {node}: {} reads back 0x{read:X} after drive-io wrote 0x{wrote:X}",
                eds.describe(index, sub)
            ),
            CommissioningFault::Timeout { index, sub, .. } => format!(
                "{kind} node {node}: no SDO answer for {} after {SDO_RETRIES} tries",
                eds.describe(index, sub)
            ),
            CommissioningFault::Check {
                index,
                sub,
                expected,
                found,
                ..
            } => format!(
                "{kind} node {node}: {} is 0x{found:08X}, drives.toml {} expects \
                 0x{expected:08X}: a wrong or swapped device on node {node}? Start-up stopped \
                 before anything was written [EDS {}]",
                eds.describe(index, sub),
                plan.check_key(index, sub),
                eds.file
            ),
            CommissioningFault::CheckText { index, sub, .. } => {
                let expected = plan
                    .ops
                    .iter()
                    .find_map(|op| match *op {
                        SdoOp::VerifyBytes {
                            index: i,
                            sub: s,
                            at,
                            len,
                            check: true,
                        } if (i, s) == (index, sub) => Some(plan.bytes(at, len)),
                        _ => None,
                    })
                    .unwrap_or(&[]);
                format!(
                    "{kind} node {node}: {} is {:?}, drives.toml {} expects {:?}: a wrong or \
                     swapped device on node {node}? Start-up stopped before anything was \
                     written [EDS {}]",
                    eds.describe(index, sub),
                    String::from_utf8_lossy(self.sdo_client[k].data()),
                    plan.check_key(index, sub),
                    String::from_utf8_lossy(expected),
                    eds.file
                )
            }
            CommissioningFault::Protocol {
                index, sub, code, ..
            } => format!(
                "{kind} node {node}: SDO transfer of {} broke the protocol; drive-io aborted it \
                 with 0x{code:08X} ({})",
                eds.describe(index, sub),
                sdo_abort_text(code)
            ),
        })
    }

    /// `(index, sub, value)` configured in node `i` (drives first, then force sensors; for
    /// its DCF); empty until it is done.
    pub fn configured_values(&self, i: usize) -> Vec<(u16, u8, drive_bus::eds::DcfValue)> {
        match (self.plans.get(i), self.drives.get(i)) {
            (Some(p), Some(d)) if d.sdo >= p.ops.len() => p.configured_values(),
            _ => Vec::new(),
        }
    }

    /// The DCF of node `i` (drives first, then force sensors) once it is configured: its node
    /// id and the text.
    pub fn dcf(&self, i: usize, baudrate_kbit: u32) -> Option<(u8, String)> {
        let p = self.plans.get(i)?;
        if self.drives[i].sdo < p.ops.len() {
            return None;
        }
        let name = match p.kind {
            NodeKind::Drive { cable } => format!("winch {}", cable + 1),
            NodeKind::ForceSensor { cable } => format!("force sensor of cable {}", cable + 1),
        };
        Some((
            p.node,
            p.eds
                .write_dcf_values(p.node, &name, baudrate_kbit, &p.configured_values()),
        ))
    }

    /// Number of nodes (drives and force sensors).
    pub fn node_count(&self) -> usize {
        self.n
    }

    /// True once every node finished its start-up script.
    pub fn configured(&self) -> bool {
        (0..self.n).all(|i| self.drives[i].sdo >= self.plans[i].ops.len())
    }

    /// Drive node ids in cable order.
    pub fn node_ids(&self) -> impl Iterator<Item = u8> + '_ {
        self.drives[..self.m].iter().map(|d| d.node)
    }

    /// Escalation of a stop the drives did not obey: stop producing drive-io's heartbeat, so
    /// the drives' consumers (0x1016) time out and act per 0x6007.
    pub fn inhibit_heartbeat(&mut self) {
        self.hb_inhibit = true;
    }

    pub fn state(&self) -> BusState {
        match self.phase {
            Phase::Boot | Phase::Configure | Phase::Enable => BusState::Booting,
            Phase::Ready => BusState::Ready,
            Phase::Running => BusState::Running,
            Phase::Stopped(s) => s,
        }
    }

    pub fn sync_period_ns(&self) -> u64 {
        self.sync_period_ns
    }

    /// Feedback of the last cycle.
    pub fn feedback(&self) -> &DriveFeedback {
        &self.feedback
    }

    /// Returns a [`StateEvent`] once after every bus-state change.
    pub fn take_state_event(&mut self, sequence: u64) -> Option<StateEvent> {
        if !self.state_changed {
            return None;
        }
        self.state_changed = false;
        let kind = if self.state() == BusState::Fault {
            EventKind::Fault
        } else {
            EventKind::StateChanged
        };
        let mut ev = StateEvent::new(crs_ipc::ProcessId::DriveIo, kind, sequence);
        ev.state = self.state() as u32;
        ev.detail = u32::from(self.fault_code);
        ev.detail_node = self.fault_node;
        Some(ev)
    }

    fn set_phase(&mut self, p: Phase) {
        let before = self.state();
        self.phase = p;
        // Only bus-state changes are events (Boot/Configure/Enable are all `Booting`).
        self.state_changed |= self.state() != before;
    }

    fn stop(&mut self, state: BusState, code: FaultCode, node: u8) {
        // The first cause is kept: a fault must not be masked by its consequences.
        if matches!(self.phase, Phase::Stopped(BusState::Fault)) {
            return;
        }
        if state == BusState::Fault || !matches!(self.phase, Phase::Stopped(_)) {
            if !matches!(self.phase, Phase::Stopped(_)) {
                self.qs_since_ns = None;
                self.qs_stage = 0;
            }
            self.fault_code = code;
            self.fault_node = u32::from(node);
            if state == BusState::EStop {
                // A commanded stop (the safety heartbeat's trip, the monitor's or an operator's
                // e-stop): its cause is the error line of whoever commanded it; the quick stop
                // that follows is its consequence.
                tracing::warn!(?state, "drive bus stopping: quick stop all drives (e-stop)");
            } else {
                tracing::error!(
                    ?state,
                    ?code,
                    node,
                    "drive bus stopping: quick stop all drives"
                );
            }
            self.set_phase(Phase::Stopped(state));
        }
    }

    fn index_of(&self, iface: usize, node: u8) -> Option<usize> {
        self.drives[..self.n]
            .iter()
            .position(|d| d.node == node && usize::from(d.iface) == iface)
    }

    /// Number of CAN interfaces the master runs.
    pub fn interfaces(&self) -> usize {
        self.interfaces
    }

    /// Node ids and interface (index) of every drive, in cable order.
    pub fn drives_on_interfaces(&self) -> impl Iterator<Item = (usize, u8)> + '_ {
        self.drives[..self.m]
            .iter()
            .map(|d| (usize::from(d.iface), d.node))
    }

    /// Node ids and interface (index) of every node drive-io runs: the drives in cable order,
    /// then the force sensors.
    pub fn nodes_on_interfaces(&self) -> impl Iterator<Item = (usize, u8)> + '_ {
        self.drives[..self.n]
            .iter()
            .map(|d| (usize::from(d.iface), d.node))
    }

    /// A TPDO of a node's mapping: decoded as mapped (never by fixed offsets); the cable
    /// force checked against the hard limit. False if `cob` is no configured TPDO.
    fn on_tpdo(&mut self, iface: usize, cob: u16, data: &[u8], rx_ns: u64) -> bool {
        let key = (iface as u8, cob);
        let Ok(k) = self.tpdo_cobs.binary_search_by_key(&key, |&(c, _)| c) else {
            return false;
        };
        let i = self.tpdo_cobs[k].1;
        let Some(pdo) = self.plans[i].mapping.tpdo(cob) else {
            return false;
        };
        let mut got = Decoded::default();
        if !pdo.decode(data, &mut got) {
            // Shorter than its mapping: not processed (CiA 301); the PDO timeout catches a
            // node that only sends such frames.
            return true;
        }
        let scale = self.plans[i].mapping.force_n_per_unit;
        let booting = matches!(self.phase, Phase::Boot | Phase::Configure | Phase::Enable);
        let d = &mut self.drives[i];
        if let Some(sw) = got.statusword {
            d.statusword = sw;
            d.rx_ns = rx_ns;
            d.have_tpdo1 = true;
        }
        if let Some(p) = got.position {
            d.position = p;
        }
        if let Some(v) = got.velocity {
            d.velocity = v;
            d.vel_rx_ns = rx_ns;
        }
        if let Some(f) = got.force {
            let f = f * scale;
            d.force_n = f;
            d.force_rx_ns = rx_ns;
            // Second, independent channel to the monitor's force supervision: beyond the
            // winches' rating (or a sensor reading that large negative) stop at once.
            if (f.is_nan() || f.abs() > self.force_limit_n) && !booting {
                let node = d.node;
                tracing::error!(node, force_n = f, "cable force beyond the hard limit");
                self.stop(BusState::Fault, FaultCode::ForceLimit, node);
            }
        }
        true
    }

    /// Handles one frame received on interface `iface`.
    pub fn on_frame(&mut self, iface: usize, rx: &RxFrame) {
        let f = &rx.frame;
        if !f.is_extended()
            && !f.is_rtr()
            && self.on_tpdo(iface, f.id() as u16, f.data(), rx.rx_monotonic_ns)
        {
            return;
        }
        let msg = decode(&rx.frame);
        let node = match msg {
            Message::Emcy { node, .. }
            | Message::SdoResponse { node, .. }
            | Message::Heartbeat { node, .. } => node,
            _ => return,
        };
        let Some(i) = self.index_of(iface, node) else {
            return;
        };
        let booting = matches!(self.phase, Phase::Boot | Phase::Configure | Phase::Enable);
        let d = &mut self.drives[i];
        match msg {
            Message::Heartbeat { state, .. } => {
                d.last_hb_ns = rx.rx_monotonic_ns;
                d.last_hb_state = state;
                d.hb_lost = false;
                d.seen_operational |= state == NmtState::Operational.code();
                if self.phase == Phase::Boot {
                    d.booted = true;
                } else if state == NmtState::BootUp.code() && !booting {
                    // A node rebooted under us: it lost its configuration and enable state.
                    tracing::error!(
                        node,
                        "node booted mid-run (boot-up message): its configuration is lost; fault"
                    );
                    self.stop(BusState::Fault, FaultCode::UnexpectedState, node);
                }
            }
            // Error code 0 is "error reset / no error": informational.
            Message::Emcy {
                code,
                error_register,
                ..
            } if code != 0 => {
                self.last_emcy = u32::from(code);
                tracing::error!(
                    node,
                    code = format_args!("{code:#06x}"),
                    name = emcy_name(code),
                    error_register = format_args!("{error_register:#04x}"),
                    "EMCY"
                );
                self.stop(BusState::Fault, FaultCode::Emcy, node);
            }
            Message::SdoResponse { data, .. } => self.on_sdo(i, &data),
            _ => {}
        }
    }

    /// The SDO request starting step `op` of node `i`'s script.
    fn start_sdo(&mut self, i: usize, op: SdoOp) -> [u8; 8] {
        let c = &mut self.sdo_client[i];
        match op {
            SdoOp::Write {
                index,
                sub,
                value,
                len,
            } => c
                .download(
                    index,
                    sub,
                    &value.to_le_bytes()[..usize::from(len.clamp(1, 4))],
                )
                .unwrap_or_default(),
            SdoOp::WriteBytes {
                index,
                sub,
                at,
                len,
            } => {
                let (a, l) = (usize::from(at), usize::from(len));
                let bytes = self.plans[i].bytes.get(a..a + l).unwrap_or(&[]);
                c.download(index, sub, bytes).unwrap_or_default()
            }
            SdoOp::Verify { index, sub, .. }
            | SdoOp::Check { index, sub, .. }
            | SdoOp::VerifyBytes { index, sub, .. }
            | SdoOp::Read { index, sub } => c.upload(index, sub),
        }
    }

    /// An SDO response of node `i`: the transfer's next step; once it is done, the answer
    /// checked and the node's start-up script advanced.
    fn on_sdo(&mut self, i: usize, data: &[u8; 8]) {
        let d = self.drives[i];
        let Some(&op) = self.plans[i].ops.get(d.sdo) else {
            return;
        };
        if !d.sdo_outstanding || !self.sdo_transfer_done(i, op, data) {
            return;
        }
        match self.check_answer(i, op) {
            Some(fault) => self.commissioning_failed(fault),
            None => self.next_op(i, op),
        }
    }

    /// The SDO client's step on `data`; true once the transfer of `op` completed. A refused
    /// informational read moves on; any other abort or protocol error fails start-up.
    fn sdo_transfer_done(&mut self, i: usize, op: SdoOp, data: &[u8; 8]) -> bool {
        let node = self.drives[i].node;
        let (index, sub) = op.index_sub();
        match self.sdo_client[i].on_response(data) {
            // Stray or mismatched response: ignore, the timeout handles a silent node.
            ClientStep::Ignored => false,
            ClientStep::Send(next) => {
                // The next segment goes out with the next cycle (a segmented answer is
                // followed to its end, never taken for a timeout).
                self.drives[i].sdo_next = Some(next);
                false
            }
            ClientStep::Aborted(code) if matches!(op, SdoOp::Read { .. }) => {
                // Informational (device name, versions): the node need not have it.
                tracing::warn!(
                    node,
                    object = %self.plans[i].eds.describe(index, sub),
                    code = format_args!("{code:#010x}"),
                    reason = sdo_abort_text(code),
                    "node refused an informational read"
                );
                self.next_op(i, op);
                false
            }
            ClientStep::Aborted(code) => {
                self.commissioning_failed(CommissioningFault::Abort {
                    node,
                    index,
                    sub,
                    write: op.is_write(),
                    code,
                });
                false
            }
            ClientStep::Failed { code, abort } => {
                self.drives[i].sdo_next = Some(abort);
                self.commissioning_failed(CommissioningFault::Protocol {
                    node,
                    index,
                    sub,
                    code,
                });
                false
            }
            ClientStep::Done => true,
        }
    }

    /// What a completed transfer of `op` answered, against what the script expects: the
    /// read-back of a written value, a checked value or text; an informational read is logged.
    fn check_answer(&self, i: usize, op: SdoOp) -> Option<CommissioningFault> {
        let node = self.drives[i].node;
        let (index, sub) = op.index_sub();
        let c = &self.sdo_client[i];
        let masked = |v: u32, len: u8| {
            if len >= 4 {
                v
            } else {
                v & ((1u32 << (8 * u32::from(len))) - 1)
            }
        };
        match op {
            SdoOp::Verify { value, len, .. } => {
                let got = masked(c.data_u32(), len);
                (got != masked(value, len)).then_some(CommissioningFault::Readback {
                    node,
                    index,
                    sub,
                    wrote: masked(value, len),
                    read: got,
                })
            }
            SdoOp::Check { value, len, .. } => {
                let got = masked(c.data_u32(), len);
                (got != masked(value, len)).then_some(CommissioningFault::Check {
                    node,
                    index,
                    sub,
                    expected: masked(value, len),
                    found: got,
                })
            }
            SdoOp::VerifyBytes { at, len, check, .. } => (c.data() != self.plans[i].bytes(at, len))
                .then_some(if check {
                    CommissioningFault::CheckText { node, index, sub }
                } else {
                    CommissioningFault::Readback {
                        node,
                        index,
                        sub,
                        wrote: 0,
                        read: 0,
                    }
                }),
            SdoOp::Read { .. } => {
                tracing::info!(
                    node,
                    object = %self.plans[i].eds.describe(index, sub),
                    value = %String::from_utf8_lossy(c.data()),
                    "node reports"
                );
                None
            }
            SdoOp::Write { .. } | SdoOp::WriteBytes { .. } => None,
        }
    }

    /// Node `i`'s script moves past `op`.
    fn next_op(&mut self, i: usize, op: SdoOp) {
        let d = &mut self.drives[i];
        d.sdo_outstanding = false;
        d.sdo_tries = 0;
        d.sdo += 1;
        if op.index_sub() == (OD_PRODUCER_HEARTBEAT_MS, 0) && op.is_write() {
            // The node produces heartbeats at the configured period from now on.
            d.hb_monitored = true;
        }
    }

    /// Handles an error frame of the bus controller (the runner subscribes to them): bus-off
    /// and error-passive mean that RPDOs and SYNC may no longer reach the drives (and their
    /// TPDOs no longer reach us), so every drive is stopped (quick stop; latched `Fault`,
    /// `FaultCode::BusError`, reset only through the monitor). Other conditions are logged.
    pub fn on_bus_error(&mut self, error: &can_transport::BusErrorFrame) {
        let c = error.condition();
        if c.is_loss_of_communication() {
            tracing::error!(%error, "CAN bus {}: stopping every drive", c.name());
            self.stop(BusState::Fault, FaultCode::BusError, 0);
        } else {
            tracing::warn!(%error, "CAN error frame");
        }
    }

    fn commissioning_failed(&mut self, f: CommissioningFault) {
        if self.commissioning_fault.is_none() {
            self.commissioning_fault = Some(f);
            if let Some(msg) = self.describe_commissioning_fault() {
                tracing::error!("start-up configuration failed: {msg}");
            }
        }
        let node = match f {
            CommissioningFault::Abort { node, .. }
            | CommissioningFault::Readback { node, .. }
            | CommissioningFault::Timeout { node, .. }
            | CommissioningFault::Check { node, .. }
            | CommissioningFault::CheckText { node, .. }
            | CommissioningFault::Protocol { node, .. } => node,
        };
        self.stop(BusState::Fault, FaultCode::BootTimeout, node);
    }

    /// Handles an e-stop event from the process bus (anyone may stop). A Reset event does
    /// nothing here: leaving the latch needs a [`ResetGrant`] ([`Master::reset`]).
    /// motion-core's announced end of its stream (`MotionState::Stopping`, published after
    /// its last setpoint) makes the silence that follows a planned end, not a stale stream —
    /// provided that last setpoint commanded rest (see the Running phase).
    pub fn on_event(&mut self, ev: &StateEvent, _now_ns: u64) {
        if ev.kind == EventKind::EStop as u32 {
            self.stop(BusState::EStop, FaultCode::None, 0);
        } else if ev.kind == EventKind::StateChanged as u32
            && ev.source == crs_ipc::ProcessId::MotionCore as u32
            && ev.motion_state() == Ok(crs_ipc::MotionState::Stopping)
        {
            self.stream_end = true;
        }
    }

    /// Setpoints superseded before a cycle read them (skipped sequence numbers of the stream).
    pub fn superseded_setpoints(&self) -> u64 {
        self.superseded
    }

    /// True while a stop is latched (e-stop, stale stop, fault).
    pub fn is_latched(&self) -> bool {
        matches!(self.phase, Phase::Stopped(_))
    }

    /// Leaves the latch with the safety monitor's reset ([`ResetGrant`], made only by
    /// [`crate::reset::ResetGate`], consumed here): re-runs the enable sequence (holding the
    /// actual positions) if every drive's heartbeat is fresh, and returns the grant's epoch.
    /// Nothing changes when not latched or a heartbeat is stale: the grant comes back
    /// (`Err`), to be retried or dropped.
    pub fn reset(&mut self, grant: ResetGrant, now_ns: u64) -> Result<u32, ResetGrant> {
        if !self.is_latched() || !self.heartbeats_fresh(now_ns) {
            return Err(grant);
        }
        let epoch = grant.epoch();
        tracing::info!(epoch, "reset: re-enabling drives");
        self.hb_inhibit = false;
        self.restart_nmt = std::mem::take(&mut self.nmt_stopped);
        self.fault_code = FaultCode::None;
        self.fault_node = 0;
        // The drives were NMT-stopped: their velocity and force TPDOs restart with the NMT
        // start. Enable waits for fresh ones as at start-up; the stamps from before the stop
        // would let Ready judge them stale in its first cycle (TPDO timeout right after the
        // reset when the drives answer a few ms late).
        for d in &mut self.drives[..self.n] {
            d.vel_rx_ns = 0;
            d.force_rx_ns = 0;
        }
        self.set_phase(Phase::Enable);
        self.boot_start_ns = Some(now_ns);
        Ok(epoch)
    }

    fn heartbeats_fresh(&self, now_ns: u64) -> bool {
        self.drives[..self.n]
            .iter()
            .all(|d| !d.hb_monitored || now_ns.saturating_sub(d.last_hb_ns) <= self.hb_timeout_ns)
    }

    /// One SYNC cycle at time `now_ns`: consumes the newest setpoint (if any), writes RPDOs and
    /// the SYNC into `out`, updates the feedback.
    pub fn cycle(&mut self, now_ns: u64, setpoint: Option<&JointSetpoint>, out: &mut BusFrames) {
        self.cycle += 1;
        self.toggle = !self.toggle;
        self.applied_this_cycle = false;
        let boot_start = *self.boot_start_ns.get_or_insert(now_ns);
        self.send_own_heartbeat(now_ns, out);
        self.consume_heartbeats(now_ns);
        self.check_boot_timeout(now_ns, boot_start);
        match self.phase {
            Phase::Boot => self.cycle_boot(now_ns, out),
            Phase::Configure => self.cycle_configure(now_ns, out),
            Phase::Enable => self.cycle_enable(out),
            Phase::Ready | Phase::Running => self.cycle_follow(now_ns, setpoint, out),
            Phase::Stopped(_) => {
                self.push_quick_stop(out);
                self.supervise_quick_stop(now_ns, out);
            }
        }
        self.update_feedback(now_ns);
    }

    /// drive-io's own heartbeat (the drives' 0x1016 consumer watches it), unless withheld
    /// as the last escalation of a stop.
    fn send_own_heartbeat(&mut self, now_ns: u64, out: &mut BusFrames) {
        if !self.hb_inhibit && now_ns >= self.next_master_hb_ns {
            out.push_all(heartbeat(self.master_node_id, NmtState::Operational));
            self.next_master_hb_ns = if now_ns - self.next_master_hb_ns > self.master_hb_ns {
                now_ns + self.master_hb_ns
            } else {
                self.next_master_hb_ns + self.master_hb_ns
            };
        }
    }

    /// Heartbeat consumer (CiA 301 §7.2.8.3.2.2), active per node once its producer time is
    /// set; every loss of one cycle is one line (the first node and how many).
    fn consume_heartbeats(&mut self, now_ns: u64) {
        let mut lost: Option<u8> = None;
        let mut n_lost = 0usize;
        for i in 0..self.n {
            let d = &mut self.drives[i];
            if d.hb_monitored
                && !d.hb_lost
                && now_ns.saturating_sub(d.last_hb_ns) > self.hb_timeout_ns
            {
                d.hb_lost = true;
                n_lost += 1;
                lost.get_or_insert(d.node);
            }
        }
        if let Some(node) = lost {
            tracing::error!(node, nodes = n_lost, "heartbeat lost");
            self.stop(BusState::Fault, FaultCode::HeartbeatLost, node);
        }
    }

    /// Boot, configuration and enabling must end within the boot timeout; the error names the
    /// first node not there yet.
    fn check_boot_timeout(&mut self, now_ns: u64, boot_start: u64) {
        if matches!(self.phase, Phase::Boot | Phase::Configure | Phase::Enable)
            && now_ns.saturating_sub(boot_start) > self.boot_timeout_ns
        {
            let m = self.m;
            let node = self.drives[..self.n]
                .iter()
                .zip(&self.plans)
                .enumerate()
                .find(|(k, (d, plan))| {
                    !d.booted
                        || d.sdo < plan.ops.len()
                        || (*k < m
                            && Ds402State::from_statusword(d.statusword)
                                != Ds402State::OperationEnabled)
                })
                .map_or(0, |(_, (d, _))| d.node);
            tracing::error!(node, phase = ?self.phase, "boot timeout");
            self.stop(BusState::Fault, FaultCode::BootTimeout, node);
        }
    }

    /// Boot: reset every node's communication once, wait for every boot-up message.
    fn cycle_boot(&mut self, now_ns: u64, out: &mut BusFrames) {
        if self.cycle == 1 {
            // Addressed per node: other devices on the bus (the safety monitor's I/O,
            // another master's nodes) are not drive-io's to reset.
            for d in &self.drives[..self.n] {
                out.push(usize::from(d.iface), nmt(NMT_RESET_COMM, d.node));
            }
        }
        if self.drives[..self.n].iter().all(|d| d.booted) {
            for d in &mut self.drives[..self.n] {
                d.last_hb_ns = now_ns;
            }
            self.set_phase(Phase::Configure);
        }
    }

    /// Configure: each node's start-up script, one SDO transfer at a time per node (retried
    /// on timeout); NMT start once every node is configured and verified.
    fn cycle_configure(&mut self, now_ns: u64, out: &mut BusFrames) {
        let sdo_timeout = self.sdo_timeout_ns;
        let mut timed_out = None;
        for i in 0..self.n {
            let d = self.drives[i];
            let Some(&op) = self.plans[i].ops.get(d.sdo) else {
                continue;
            };
            let rx_cob = COB_SDO_RX_BASE + u16::from(d.node);
            if let Some(next) = self.drives[i].sdo_next.take() {
                // The next segment of a segmented transfer.
                let f = can_transport::CanFrame::new_std_lossy(rx_cob, &next);
                out.push(usize::from(d.iface), f);
                self.drives[i].sdo_sent_ns = now_ns;
                continue;
            }
            if d.sdo_outstanding && now_ns.saturating_sub(d.sdo_sent_ns) < sdo_timeout {
                continue;
            }
            if d.sdo_outstanding && d.sdo_tries >= SDO_RETRIES {
                let (index, sub) = op.index_sub();
                timed_out = Some(CommissioningFault::Timeout {
                    node: d.node,
                    index,
                    sub,
                });
                continue;
            }
            // A new transfer, or the whole transfer again after a timeout.
            let req = self.start_sdo(i, op);
            let f = can_transport::CanFrame::new_std_lossy(rx_cob, &req);
            out.push(usize::from(d.iface), f);
            let d = &mut self.drives[i];
            d.sdo_outstanding = true;
            d.sdo_sent_ns = now_ns;
            d.sdo_tries += 1;
        }
        if let Some(f) = timed_out {
            self.commissioning_failed(f);
        } else if self.configured() {
            tracing::info!(
                nodes = self.n,
                "all drives and force sensors identified, configured and verified"
            );
            for d in &self.drives[..self.n] {
                out.push(usize::from(d.iface), nmt(NMT_START, d.node));
            }
            self.set_phase(Phase::Enable);
        }
    }

    /// Enable: walk every drive's CiA 402 state machine to Operation Enabled, holding its
    /// actual position; Ready once every drive follows and every supervised TPDO arrived.
    fn cycle_enable(&mut self, out: &mut BusFrames) {
        if std::mem::take(&mut self.restart_nmt) {
            for d in &self.drives[..self.m] {
                out.push(usize::from(d.iface), nmt(NMT_START, d.node));
            }
        }
        let mut all_enabled = true;
        for i in 0..self.m {
            let d = self.drives[i];
            let st = Ds402State::from_statusword(d.statusword);
            // After an NMT restart, wait for the heartbeat to say operational too; in
            // CSP, wait for statusword bit 12 (the drive follows the target).
            all_enabled &= d.have_tpdo1
                && st == Ds402State::OperationEnabled
                && d.statusword & SW_FOLLOWS_TARGET != 0
                && (!d.seen_operational || d.last_hb_state == NmtState::Operational.code());
            if d.have_tpdo1 {
                // Enable while holding the actual position: the drive must not jump.
                self.target[i] = d.position;
                self.push_rpdos(i, enable_step(st, self.toggle), d.position, out);
            }
        }
        // Every TPDO drive-io supervises has arrived (the velocity may come every n-th
        // SYNC only; the forces from the drives or their force sensors).
        all_enabled &= self.drives[..self.m].iter().all(|d| d.vel_rx_ns > 0)
            && self.force_node[..self.m]
                .iter()
                .all(|&k| self.drives[k].force_rx_ns > 0);
        out.request_sync();
        if all_enabled {
            self.setpoint_age = 0;
            self.set_phase(Phase::Ready);
        }
    }

    /// Ready / Running: the drives' checks, the newest setpoint (or its absence), then the
    /// targets (or the quick stop a finding latched) to every drive.
    fn cycle_follow(&mut self, now_ns: u64, setpoint: Option<&JointSetpoint>, out: &mut BusFrames) {
        self.check_drives(now_ns);
        // A finding stopped the bus: this cycle's setpoint must not re-enter Running
        // (the stop is latched; the quick stop goes out below).
        if !self.is_latched()
            && let Some(sp) = setpoint.filter(|sp| sp.sequence > self.last_seq)
        {
            self.take_setpoint(sp, now_ns);
        } else if self.phase == Phase::Running {
            self.age_setpoint();
        }
        if matches!(self.phase, Phase::Ready | Phase::Running) {
            for i in 0..self.m {
                self.push_rpdos(i, CW_ENABLE_OPERATION, self.target[i], out);
            }
            out.request_sync();
        } else {
            self.push_quick_stop(out);
        }
    }

    /// A setpoint newer than the last one: counted (superseded ones too), applied if it passes
    /// the checks, and the bus is Running.
    fn take_setpoint(&mut self, sp: &JointSetpoint, now_ns: u64) {
        if self.last_seq > 0 {
            self.superseded += sp.sequence - self.last_seq - 1;
        }
        self.last_seq = sp.sequence;
        if self.apply_setpoint(sp, now_ns) {
            if self.phase == Phase::Ready {
                // A new stream: an old end announcement does not cover it.
                self.stream_end = false;
            }
            self.last_at_rest = sp.cable_velocity_m_per_s[..self.m]
                .iter()
                .all(|v| *v == 0.0);
            self.setpoint_age = 0;
            self.set_phase(Phase::Running);
        }
    }

    /// Running without a new setpoint: past the stale limit, the announced end of a stream at
    /// rest returns to Ready; anything else stops the bus.
    fn age_setpoint(&mut self) {
        self.setpoint_age = self.setpoint_age.saturating_add(1);
        if self.setpoint_age > self.stale_cycles && self.stream_end && self.last_at_rest {
            // The planned end of the stream, at rest: a normal state. The drives
            // stay enabled holding the last target; a new stream (sequence numbers
            // from 1 again) is followed from here.
            tracing::info!(
                sequence = self.last_seq,
                "motion-core ended its stream at rest: drives holding position"
            );
            self.stream_end = false;
            self.last_seq = 0;
            self.applied_seq = 0;
            self.setpoint_age = 0;
            self.set_phase(Phase::Ready);
        } else if self.setpoint_age > self.stale_cycles {
            tracing::warn!(cycles = self.setpoint_age, "setpoints stale");
            self.stop(BusState::StaleStop, FaultCode::None, 0);
        }
    }

    /// CiA 402 quick stop supervision: every drive must acknowledge the stop in a TPDO sent
    /// after it was commanded (Quick Stop Active, or a state in which the brake holds:
    /// switched on and below, Fault) with velocity actual 0, within `bus.quick_stop_timeout_ms`.
    /// Otherwise escalate: NMT stop all (the drives act per 0x6007: disable voltage, the brake
    /// holds), and if the heartbeats do not report NMT stopped within another timeout, withhold
    /// drive-io's heartbeat (their 0x1016 consumers time out and act per 0x6007 again).
    fn supervise_quick_stop(&mut self, now_ns: u64, out: &mut BusFrames) {
        if self.qs_stage == 3 || self.m == 0 {
            return;
        }
        let since = *self.qs_since_ns.get_or_insert(now_ns);
        let at_rest = |d: &DriveView| {
            use Ds402State::*;
            d.have_tpdo1
                && d.rx_ns > since
                && d.vel_rx_ns > since
                && d.velocity == 0
                && matches!(
                    Ds402State::from_statusword(d.statusword),
                    QuickStopActive
                        | SwitchOnDisabled
                        | ReadyToSwitchOn
                        | SwitchedOn
                        | Fault
                        | NotReadyToSwitchOn
                )
        };
        let elapsed = now_ns.saturating_sub(since);
        if self.qs_stage == 0 && self.drives[..self.m].iter().all(at_rest) {
            tracing::info!(
                ms = elapsed as f64 * 1e-6,
                "quick stop acknowledged: every drive stopped (statusword) at velocity 0"
            );
            self.qs_stage = 3;
            return;
        }
        if self.qs_stage == 0 && elapsed > self.quick_stop_timeout_ns {
            // One line for the event: the first drive that did not acknowledge, and how many.
            let mut late = self.drives[..self.m].iter().filter(|d| !at_rest(d));
            let drives = late.clone().count();
            if let Some(d) = late.next() {
                tracing::error!(
                    node = d.node,
                    statusword = format_args!("{:#06x}", d.statusword),
                    velocity_counts_per_s = d.velocity,
                    drives,
                    "quick stop not acknowledged in time: escalating to NMT stop (0x6007 action)"
                );
            }
            for d in &self.drives[..self.m] {
                out.push(usize::from(d.iface), nmt(NMT_STOP, d.node));
            }
            self.nmt_stopped = true;
            self.qs_stage = 1;
        } else if self.qs_stage == 1 && elapsed > 2 * self.quick_stop_timeout_ns {
            let all_stopped = self.drives[..self.m]
                .iter()
                .all(|d| d.last_hb_state == NmtState::Stopped.code() && d.last_hb_ns > since);
            if all_stopped {
                self.qs_stage = 3;
            } else {
                tracing::error!(
                    "drives do not report NMT stopped: withholding drive-io's heartbeat \
                     (the drives' consumer timeout acts per 0x6007)"
                );
                self.hb_inhibit = true;
                self.qs_stage = 2;
            }
        }
    }

    /// Stage of the quick stop supervision (0 waiting, 1 NMT stop sent, 2 heartbeat withheld,
    /// 3 done), for tests and diagnostics.
    pub fn quick_stop_stage(&self) -> u8 {
        self.qs_stage
    }

    /// Drive `i`'s RPDOs carrying `controlword` and `target_counts`, as its mapping says.
    fn push_rpdos(&self, i: usize, controlword: u16, target_counts: i32, out: &mut BusFrames) {
        let iface = usize::from(self.drives[i].iface);
        for p in self.plans[i].mapping.rpdos() {
            out.push_rpdo(iface, p.encode(controlword, target_counts));
        }
    }

    fn push_quick_stop(&mut self, out: &mut BusFrames) {
        // Keep SYNC running so the drives keep reporting; hold the last target.
        if self.drives[..self.m].iter().any(|d| d.have_tpdo1) {
            for i in 0..self.m {
                self.push_rpdos(i, CW_QUICK_STOP, self.target[i], out);
            }
            out.request_sync();
        }
    }

    /// What a drive (or the force node of its cable) reports wrong while drive-io runs it
    /// enabled, or None. A stale TPDO first: a statusword not refreshed is no report.
    fn finding(&self, i: usize, now_ns: u64) -> Option<(Finding, u8)> {
        let d = &self.drives[i];
        let stale = |t: u64| now_ns.saturating_sub(t) > self.hb_timeout_ns;
        let f = if stale(d.rx_ns) || stale(d.vel_rx_ns) {
            Some(Finding::TpdoTimeout)
        } else {
            match Ds402State::from_statusword(d.statusword) {
                Ds402State::Fault | Ds402State::FaultReactionActive => Some(Finding::Fault),
                Ds402State::OperationEnabled
                    if d.seen_operational && d.last_hb_state != NmtState::Operational.code() =>
                {
                    Some(Finding::LeftNmtOperational)
                }
                // CSP (CiA 402 statusword bits 12/13, defined in Operation Enabled only): the
                // drive must follow the target and report no following error.
                Ds402State::OperationEnabled if d.statusword & SW_FOLLOWS_TARGET == 0 => {
                    Some(Finding::IgnoresTarget)
                }
                Ds402State::OperationEnabled if d.statusword & SW_FOLLOWING_ERROR != 0 => {
                    Some(Finding::FollowingError)
                }
                Ds402State::OperationEnabled => None,
                _ => Some(Finding::LeftOperation),
            }
        };
        if let Some(f) = f {
            return Some((f, d.node));
        }
        // Every cable's force, from its drive or its force sensor.
        let fnode = &self.drives[self.force_node[i]];
        stale(fnode.force_rx_ns).then_some((Finding::ForceTpdoTimeout, fnode.node))
    }

    /// The drives' reports while enabled: any finding stops every drive (latched `Fault`).
    /// One event is one error line: the first drive's finding is the cause (its node,
    /// statusword and state), with the number of drives reporting something that cycle (eight
    /// drives losing their TPDOs in one host stall are one timeout, not eight).
    fn check_drives(&mut self, now_ns: u64) {
        let mut first = None;
        let mut drives = 0usize;
        for i in 0..self.m {
            if let Some(f) = self.finding(i, now_ns) {
                drives += 1;
                first.get_or_insert((i, f));
            }
        }
        let Some((i, (finding, node))) = first else {
            return;
        };
        let d = &self.drives[i];
        tracing::error!(
            node,
            cable = i + 1,
            statusword = format_args!("{:#06x}", d.statusword),
            state = ?Ds402State::from_statusword(d.statusword),
            drives,
            "{}",
            finding.text()
        );
        self.stop(BusState::Fault, finding.code(), node);
    }

    /// Drives drive-io runs enabled (Ready or Running) whose last statusword reports Switch On
    /// Disabled: their power stage off (the STO input) without drive-io commanding it.
    pub fn drives_torque_off(&self) -> usize {
        if !matches!(self.phase, Phase::Ready | Phase::Running) {
            return 0;
        }
        self.drives[..self.m]
            .iter()
            .filter(|d| {
                d.have_tpdo1
                    && Ds402State::from_statusword(d.statusword) == Ds402State::SwitchOnDisabled
            })
            .count()
    }

    /// The safety monitor's heartbeat for this cycle (the runner calls it once per cycle,
    /// after the bus was drained, before the cycle): true if it permits motion.
    ///
    /// Drives that report their torque off while the heartbeat is overdue are the safety I/O
    /// node's STO on the same missing heartbeat, i.e. the stop the watch is about to command:
    /// the watch trips now ([`SafetyWatch::inhibit_on_torque_off`]), so the stop is one
    /// e-stop with its cause, not eight drive faults. While the heartbeat is on time such a
    /// drive stays the master's fault ([`Master::cycle`]). A trip is logged once (the error
    /// line of the event); without a permit (and past the start-up grace) an enabled bus is
    /// e-stopped (quick stop all, latched).
    pub fn supervise_safety_heartbeat(&mut self, watch: &mut SafetyWatch, now_ns: u64) -> bool {
        watch.inhibit_on_torque_off(now_ns, self.drives_torque_off());
        let permit = watch.permits(now_ns);
        let grace = watch.in_startup_grace(now_ns);
        if let Some((reason, at_ns)) = watch.take_trip() {
            tracing::error!(
                ?reason,
                at_ns,
                "safety heartbeat invalid or missing: e-stop"
            );
        }
        if !permit && !grace && matches!(self.phase, Phase::Ready | Phase::Running) {
            self.stop(BusState::EStop, FaultCode::None, 0);
        }
        permit
    }

    /// Converts and checks a setpoint; on any invalid entry nothing is applied and the bus faults.
    fn apply_setpoint(&mut self, sp: &JointSetpoint, now_ns: u64) -> bool {
        if sp.version != crs_ipc::CONTRACT_VERSION || sp.cable_count as usize != self.m {
            tracing::error!(
                count = sp.cable_count,
                expected = self.m,
                "setpoint cable count/version mismatch"
            );
            self.stop(BusState::Fault, FaultCode::SetpointInvalid, 0);
            return false;
        }
        let mut counts = [0i32; MAX_CABLES];
        // The implied cable speed is judged on drive-io's OWN clock, not on the sender's
        // timestamps (a faulty producer could claim any interval): the stream advances one
        // sequence number per period, so the step may cover as many periods as sequence numbers
        // passed, but never more than drive-io's own time since it applied the previous
        // setpoint plus one period (the phase slip of two unsynchronised 1 kHz loops: two
        // setpoints may arrive within one SYNC) — and never more than the stale limit, beyond
        // which the drives are quick-stopped anyway. The first setpoint after enabling must
        // start at the held position (one period of motion).
        let running = self.phase == Phase::Running;
        // `periods` bounds the step (speed); `v_periods` is the time base of the step's speed for
        // the acceleration check: the sequence numbers, bounded by drive-io's own time plus two
        // periods — one more than the speed bound, because a setpoint superseded before
        // drive-io read it leaves a gap of two sequence numbers that may arrive a fraction of a
        // period after the previous one (a stalled, then catching-up producer); judged over
        // own + 1 such a step would look like a speed jump it is not. A producer claiming many
        // skipped periods still gets at most own + 2 (and its step at most the speed bound).
        let (periods, v_periods) = if running {
            let own = now_ns.saturating_sub(self.last_apply_ns) as f64 / self.sync_period_ns as f64;
            let by_sequence = sp.sequence.saturating_sub(self.applied_seq) as f64;
            let max = f64::from(self.stale_cycles) + 2.0;
            (
                by_sequence.min(own + 1.0).clamp(1.0, max),
                by_sequence.min(own + 2.0).clamp(1.0, max),
            )
        } else {
            (1.0, 1.0)
        };
        // A hold is zero speed: out of Ready (enabled, holding) the previous step is rest, so the
        // first moving step is acceleration-checked like every other one.
        if !running {
            self.last_vel_counts = [0.0; MAX_CABLES];
            self.last_periods = 1.0;
        }
        // Between the midpoints of the previous step and this one.
        let dt_mid = 0.5 * (v_periods + self.last_periods);
        let mut vel = [0.0f64; MAX_CABLES];
        for (i, count) in counts.iter_mut().enumerate().take(self.m) {
            let node = self.drives[i].node;
            let Some(c) = self.winches[i].length_to_counts(sp.cable_length_m[i]) else {
                tracing::error!(
                    node,
                    length = sp.cable_length_m[i],
                    "setpoint cable length out of range"
                );
                self.stop(BusState::Fault, FaultCode::SetpointInvalid, node);
                return false;
            };
            // +2 counts: rounding of the commanded and the measured position.
            if (f64::from(c) - f64::from(self.target[i])).abs()
                > self.max_step_counts[i] * periods + 2.0
            {
                tracing::error!(
                    node,
                    length = sp.cable_length_m[i],
                    target_counts = c,
                    previous_counts = self.target[i],
                    periods,
                    "setpoint step exceeds max cable speed"
                );
                self.stop(BusState::Fault, FaultCode::SetpointStep, node);
                return false;
            }
            // Acceleration: the step's speed may change by at most max_accel × Δt from the
            // previous step's (+2 counts of rounding); braking towards zero without reversing is
            // never limited (the safe direction: a hold after an e-stop).
            let v = (f64::from(c) - f64::from(self.target[i])) / v_periods;
            let pv = self.last_vel_counts[i];
            let braking = v * pv >= 0.0 && v.abs() <= pv.abs();
            if !braking && (v - pv).abs() > self.max_accel_counts[i] * dt_mid + 2.0 {
                tracing::error!(
                    node,
                    length = sp.cable_length_m[i],
                    step_counts_per_period = v,
                    previous_counts_per_period = pv,
                    periods,
                    "setpoint step accelerates the cable beyond max_cable_acceleration"
                );
                self.stop(BusState::Fault, FaultCode::SetpointStep, node);
                return false;
            }
            vel[i] = v;
            *count = c;
        }
        self.last_vel_counts[..self.m].copy_from_slice(&vel[..self.m]);
        self.last_periods = v_periods;
        self.target[..self.m].copy_from_slice(&counts[..self.m]);
        self.applied_seq = sp.sequence;
        self.last_apply_ns = now_ns;
        self.applied_this_cycle = true;
        true
    }

    /// The runner reports missed SYNC ticks here (published in the feedback).
    pub fn add_overruns(&mut self, n: u32) {
        self.overruns = self.overruns.saturating_add(n);
    }

    /// Call right after the cycle's frames were written to the bus.
    pub fn mark_written(&mut self, now_ns: u64) {
        if self.applied_this_cycle {
            self.feedback.applied_setpoint_sequence = self.applied_seq;
            self.feedback.applied_setpoint_write_ns = now_ns;
        }
    }

    fn update_feedback(&mut self, now_ns: u64) {
        let f = &mut self.feedback;
        f.cycle = self.cycle;
        f.timestamp_ns = now_ns;
        f.bus_state = match self.phase {
            Phase::Boot | Phase::Configure | Phase::Enable => BusState::Booting,
            Phase::Ready => BusState::Ready,
            Phase::Running => BusState::Running,
            Phase::Stopped(s) => s,
        } as u32;
        f.fault_code = u32::from(self.fault_code);
        f.fault_node = self.fault_node;
        f.last_emcy_code = self.last_emcy;
        f.setpoint_age_cycles = self.setpoint_age;
        f.overruns = self.overruns;
        for i in 0..self.m {
            let d = &self.drives[i];
            let w = &self.winches[i];
            f.cable_length_m[i] = w.counts_to_length(d.position);
            f.cable_velocity_m_per_s[i] = w.counts_per_s_to_m_per_s(d.velocity);
            f.cable_force_n[i] = self.drives[self.force_node[i]].force_n;
            f.rx_timestamp_ns[i] = d.rx_ns;
            f.statusword[i] = d.statusword;
        }
    }
}
