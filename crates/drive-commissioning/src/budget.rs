//! The bus budget: what a configuration puts on each CAN interface, in bits on the wire and
//! time, against a load budget — refused above it, naming the interface and the frames that
//! fill it (`drive-io --print-plan` prints it; [`drive_io::master::Master::new`] and `crs sim`
//! refuse an over-budget configuration before anything starts).
//!
//! Bits are counted with worst-case bit stuffing ([`can_transport::wire::bits`]): a frame of n
//! data bytes with an 11-bit identifier occupies at most 8n + 47 + ⌊(34 + 8n − 1)/4⌋ bit times
//! including the 3-bit intermission (Davis et al. 2007, eq. 4).
//!
//! Per interface and per second: SYNC every period; every PDO of every node at its rate (every
//! SYNC, every n-th SYNC); every node's heartbeat (drives at `heartbeat_producer_ms`, drive-io at
//! `master_heartbeat_ms`); the safety monitor's two doubled frames (heartbeat pair and
//! configuration signature pair) per refresh time where they are sent; and headroom for what
//! is not periodic: one EMCY per node per [`EMCY_RESERVE_PERIOD_MS`] and one expedited SDO
//! exchange per [`SDO_RESERVE_PERIOD_MS`].
//!
//! Two checks per interface:
//! * **load**: Σ bits/s ÷ bit rate ≤ `budget_percent` (≤ 70 %);
//! * **cycle**: in the worst SYNC period (every every-n-th PDO due at once) the synchronous
//!   frames fit the period (with blocking on top they may spill a frame or two into the next
//!   one: reported), and with an isochronous SYNC the cycle's RPDOs — behind one blocking
//!   frame and every higher-priority periodic frame that can be pending then (the safety pairs
//!   where they travel) — are off the wire within `rpdo_guard_us`.

use crate::commissioning::{NodeKind, Plan, SetupError};
use can_transport::wire::bits::worst_case_bits;
use drive_bus::mapping::{Direction, Transmission};
use drives_config::{DrivesConfig, SyncSource};

/// Headroom for EMCY: one 8-byte EMCY per node per this period (a drive's EMCY inhibit time,
/// 0x1015, is typically 10–100 ms; faults are rare, bursts are what matters).
pub const EMCY_RESERVE_PERIOD_MS: f64 = 100.0;
/// Headroom for SDO while running (diagnostics): one expedited request and response per
/// this period on each interface.
pub const SDO_RESERVE_PERIOD_MS: f64 = 10.0;

/// Who sends a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sender {
    /// drive-io (the master).
    Master,
    /// A drive or measuring node (node id).
    Node(u8),
    /// The safety monitor.
    Monitor,
    /// Headroom for aperiodic traffic.
    Reserve,
}

/// When a frame is sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// In every n-th SYNC period (1 = every period): part of the synchronous cycle.
    EverySync(u16),
    /// Periodically with this period, at any phase to the SYNC (heartbeats, the monitor's).
    Every { ms: f64 },
}

/// What a node sends and receives in PDOs, for the budget (COB-ID, data bytes, rate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdoFrame {
    pub cob_id: u16,
    pub dlc: u8,
    /// RPDO (master → node) or TPDO (node → master).
    pub rpdo: bool,
    /// Every n-th SYNC (1 = every SYNC).
    pub every_n_sync: u16,
}

/// One line of an interface's budget.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    pub what: String,
    pub sender: Sender,
    pub cob_id: u16,
    pub dlc: u8,
    pub rate: Rate,
    /// Worst-case bits on the wire per frame (stuffing and intermission included).
    pub bits: u32,
    /// Frames per second.
    pub per_s: f64,
}

impl Line {
    pub fn bits_per_s(&self) -> f64 {
        f64::from(self.bits) * self.per_s
    }
    fn rpdo(&self) -> bool {
        self.what.starts_with("RPDO")
    }
}

/// The budget of one interface.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceBudget {
    pub name: String,
    pub bitrate_bit_per_s: u32,
    pub budget_percent: f64,
    pub period_us: u32,
    pub lines: Vec<Line>,
    /// Isochronous SYNC: the guard before the SYNC by which the RPDOs must be off the wire, µs.
    pub rpdo_guard_us: Option<u32>,
}

impl InterfaceBudget {
    fn bit_us(&self) -> f64 {
        1e6 / f64::from(self.bitrate_bit_per_s)
    }
    /// Bits per second of every line.
    pub fn bits_per_s(&self) -> f64 {
        self.lines.iter().map(Line::bits_per_s).sum()
    }
    /// Load, percent of the bit rate.
    pub fn load_percent(&self) -> f64 {
        100.0 * self.bits_per_s() / f64::from(self.bitrate_bit_per_s)
    }
    /// The longest frame on the interface (what can block any other), bits.
    fn blocking_bits(&self) -> u32 {
        self.lines.iter().map(|l| l.bits).max().unwrap_or(0)
    }
    /// Bits of the synchronous frames in the worst SYNC period (every every-n-th PDO due).
    pub fn worst_cycle_sync_bits(&self) -> u32 {
        self.lines
            .iter()
            .filter(|l| matches!(l.rate, Rate::EverySync(_)))
            .map(|l| l.bits)
            .sum()
    }
    /// Time of the worst synchronous cycle plus two blocking frames (one delaying the SYNC,
    /// one in the gap before the RPDOs), µs.
    pub fn worst_cycle_us(&self) -> f64 {
        f64::from(self.worst_cycle_sync_bits() + 2 * self.blocking_bits()) * self.bit_us()
    }

    /// How far the worst period's frames can reach into the next one, µs (0: they fit).
    pub fn spill_us(&self) -> f64 {
        (self.worst_cycle_us() - f64::from(self.period_us)).max(0.0)
    }
    /// Worst time from queueing the cycle's RPDOs to the last one off the wire, µs: one
    /// blocking frame, every periodic frame of higher priority (lower COB-ID) that may be
    /// pending at any time (the safety pairs where they travel), then the RPDOs. EMCY headroom
    /// is not counted here: an EMCY means a stop, and the cycle it delays is not a normal one.
    pub fn rpdo_window_us(&self) -> f64 {
        let rpdos: Vec<&Line> = self.lines.iter().filter(|l| l.rpdo()).collect();
        let Some(lowest) = rpdos.iter().map(|l| l.cob_id).max() else {
            return 0.0;
        };
        let own: u32 = rpdos.iter().map(|l| l.bits).sum();
        let higher: u32 = self
            .lines
            .iter()
            .filter(|l| {
                matches!(l.rate, Rate::Every { .. })
                    && l.cob_id < lowest
                    && l.sender != Sender::Reserve
            })
            .map(|l| l.bits)
            .sum();
        f64::from(self.blocking_bits() + higher + own) * self.bit_us()
    }
    /// Why this interface's configuration cannot run, if it cannot.
    pub fn check(&self) -> Result<(), BudgetError> {
        let load = self.load_percent();
        if load > self.budget_percent {
            return Err(BudgetError::Load {
                interface: self.name.clone(),
                load_percent: load,
                budget_percent: self.budget_percent,
                top: self.top_frames(4),
            });
        }
        // The synchronous frames of the worst period alone must fit it (else they pile up in
        // every such period); with blocking frames on top they may spill over by a frame or
        // two — reported, see `spill_us`: the lowest-priority frames of that period then
        // arrive in the next one.
        let sync_us = f64::from(self.worst_cycle_sync_bits()) * self.bit_us();
        if sync_us > f64::from(self.period_us) {
            return Err(BudgetError::Cycle {
                interface: self.name.clone(),
                cycle_us: sync_us,
                period_us: self.period_us,
                top: self.top_frames(4),
            });
        }
        if let Some(guard) = self.rpdo_guard_us {
            let w = self.rpdo_window_us();
            if w > f64::from(guard) {
                return Err(BudgetError::RpdoWindow {
                    interface: self.name.clone(),
                    window_us: w,
                    guard_us: guard,
                });
            }
        }
        Ok(())
    }
    /// The `n` kinds of frame that take most of the bus, as "what (share %)".
    fn top_frames(&self, n: usize) -> String {
        // Group by what the frame is, without the node (all RPDO1 together).
        let mut groups: Vec<(String, f64)> = Vec::new();
        for l in &self.lines {
            let key = l.what.split(" node ").next().unwrap_or(&l.what).to_string();
            match groups.iter_mut().find(|g| g.0 == key) {
                Some(g) => g.1 += l.bits_per_s(),
                None => groups.push((key, l.bits_per_s())),
            }
        }
        groups.sort_by(|a, b| b.1.total_cmp(&a.1));
        let total = f64::from(self.bitrate_bit_per_s);
        groups
            .iter()
            .take(n)
            .map(|(k, b)| format!("{k} {:.1} %", 100.0 * b / total))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl std::fmt::Display for InterfaceBudget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "# interface {}: {} kbit/s, SYNC every {} µs, budget {:.0} %",
            self.name,
            self.bitrate_bit_per_s / 1000,
            self.period_us,
            self.budget_percent
        )?;
        writeln!(
            f,
            "#   {:<34} {:>6} {:>4} {:>14} {:>9} {:>10} {:>7}",
            "frame", "COB-ID", "DLC", "rate", "bit/frame", "bit/s", "load %"
        )?;
        let total = f64::from(self.bitrate_bit_per_s);
        for l in &self.lines {
            let rate = match l.rate {
                Rate::EverySync(1) => "every SYNC".to_string(),
                Rate::EverySync(n) => format!("every {n}th SYNC"),
                Rate::Every { ms } => format!("every {ms} ms"),
            };
            writeln!(
                f,
                "#   {:<34} {:>#6x} {:>4} {:>14} {:>9} {:>10.0} {:>7.2}",
                l.what,
                l.cob_id,
                l.dlc,
                rate,
                l.bits,
                l.bits_per_s(),
                100.0 * l.bits_per_s() / total
            )?;
        }
        writeln!(
            f,
            "#   load {:.1} % of {:.0} % budget; worst SYNC period {:.0} µs of {} µs (synchronous \
             frames {} bit + 2 blocking frames){}",
            self.load_percent(),
            self.budget_percent,
            self.worst_cycle_us(),
            self.period_us,
            self.worst_cycle_sync_bits(),
            if self.spill_us() > 0.0 {
                format!(
                    ": the lowest-priority frames of that period may arrive up to {:.0} µs into \
                     the next",
                    self.spill_us()
                )
            } else {
                String::new()
            }
        )?;
        if let Some(g) = self.rpdo_guard_us {
            writeln!(
                f,
                "#   RPDO window (worst case, queued to last RPDO off the wire) {:.0} µs of the \
                 {g} µs guard before the SYNC",
                self.rpdo_window_us()
            )?;
        }
        match self.check() {
            Ok(()) => writeln!(f, "#   fits"),
            Err(e) => writeln!(f, "#   REFUSED: {e}"),
        }
    }
}

/// A configuration that does not fit its bus.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BudgetError {
    #[error(
        "CAN interface {interface:?}: the configuration needs {load_percent:.1} % of the bus \
         (worst-case bit stuffing), above its budget of {budget_percent:.0} %; most of it: {top}. \
         Spread the drives over more interfaces, send feedback every n-th SYNC, or map fewer \
         objects (docs/can-protocol.md \"Bus budget\")"
    )]
    Load {
        interface: String,
        load_percent: f64,
        budget_percent: f64,
        top: String,
    },
    #[error(
        "CAN interface {interface:?}: the synchronous frames of the worst SYNC period need \
         {cycle_us:.0} µs on the wire, more than the {period_us} µs period; most of it: {top}"
    )]
    Cycle {
        interface: String,
        cycle_us: f64,
        period_us: u32,
        top: String,
    },
    #[error(
        "CAN interface {interface:?}: the cycle's RPDOs need up to {window_us:.0} µs to leave the \
         wire (behind blocking and higher-priority frames), more than bus.rpdo_guard_us = \
         {guard_us} µs before the SYNC: they would miss it"
    )]
    RpdoWindow {
        interface: String,
        window_us: f64,
        guard_us: u32,
    },
}

/// The budget of every interface of `cfg`, the drives' PDOs given by `pdo_frames(cable)`
/// (from each drive's configured mapping) and the force sensors by `extra_nodes`
/// (interface, node id, its PDOs, heartbeat period ms).
pub fn budget(
    cfg: &DrivesConfig,
    pdo_frames: impl Fn(usize) -> Vec<PdoFrame>,
    extra_nodes: &[(usize, u8, Vec<PdoFrame>, f64)],
) -> Vec<InterfaceBudget> {
    let b = &cfg.bus;
    let mk = LineMaker {
        period_s: f64::from(b.sync_period_us) * 1e-6,
    };
    let safety_itfs = cfg.safety_frame_interfaces();
    let mut out: Vec<InterfaceBudget> = cfg
        .interfaces()
        .iter()
        .enumerate()
        .map(|(k, itf)| {
            let mut ib = InterfaceBudget {
                name: itf.name.clone(),
                bitrate_bit_per_s: itf.bitrate_bit_per_s,
                budget_percent: itf.budget_percent,
                period_us: b.sync_period_us,
                lines: Vec::new(),
                rpdo_guard_us: (b.sync_source == SyncSource::Isochronous)
                    .then_some(b.rpdo_guard_us),
            };
            bus_lines(cfg, mk, safety_itfs.contains(&k), &mut ib.lines);
            ib
        })
        .collect();
    for (i, w) in cfg.winches.iter().enumerate() {
        if let Some(ib) = out.get_mut(cfg.winch_interface(i)) {
            let hb_ms = f64::from(b.heartbeat_producer_ms);
            node_lines(mk, w.node_id, "drive", &pdo_frames(i), hb_ms, &mut ib.lines);
        }
    }
    for (iface, node, pdos, hb_ms) in extra_nodes {
        if let Some(ib) = out.get_mut(*iface) {
            node_lines(mk, *node, "force sensor", pdos, *hb_ms, &mut ib.lines);
        }
    }
    if let (Some(io), Some(iface)) = (&cfg.safety_io, cfg.safety_io_interface())
        && let Some(ib) = out.get_mut(iface)
    {
        safety_io_lines(mk, io, &mut ib.lines);
    }
    // RPDOs and TPDOs of a node were numbered in one sequence: renumber per direction.
    for ib in &mut out {
        renumber(&mut ib.lines);
    }
    out
}

/// Makes the lines of one SYNC period's budget.
#[derive(Clone, Copy)]
struct LineMaker {
    period_s: f64,
}

impl LineMaker {
    fn line(self, what: String, sender: Sender, cob_id: u16, dlc: u8, rate: Rate) -> Line {
        let per_s = match rate {
            Rate::EverySync(n) => 1.0 / (self.period_s * f64::from(n.max(1))),
            Rate::Every { ms } => 1000.0 / ms,
        };
        Line {
            what,
            sender,
            cob_id,
            dlc,
            rate,
            bits: worst_case_bits(false, dlc),
            per_s,
        }
    }
}

/// What every interface carries: the SYNC, drive-io's heartbeat, the SDO headroom, and the
/// monitor's doubled frames where `safety` (the safety frame's interfaces).
fn bus_lines(cfg: &DrivesConfig, mk: LineMaker, safety: bool, lines: &mut Vec<Line>) {
    let b = &cfg.bus;
    lines.push(mk.line("SYNC".into(), Sender::Master, 0x080, 0, Rate::EverySync(1)));
    lines.push(mk.line(
        "heartbeat drive-io".into(),
        Sender::Master,
        0x700 + u16::from(b.master_node_id),
        1,
        Rate::Every {
            ms: f64::from(b.master_heartbeat_ms),
        },
    ));
    lines.push(mk.line(
        "SDO headroom (request + response)".into(),
        Sender::Reserve,
        0x600,
        8,
        Rate::Every {
            ms: SDO_RESERVE_PERIOD_MS / 2.0,
        },
    ));
    if let Some(sh) = cfg.safety_heartbeat.as_ref().filter(|_| safety) {
        // Two doubled frames per refresh time: the configuration signature pair, then the
        // heartbeat pair (docs/safety-monitor.md).
        for (k, what) in [
            "safety heartbeat",
            "safety heartbeat (inverse)",
            "safety signature",
            "safety signature (inverse)",
        ]
        .iter()
        .enumerate()
        {
            lines.push(mk.line(
                (*what).into(),
                Sender::Monitor,
                sh.cob_id + k as u16,
                8,
                Rate::Every {
                    ms: f64::from(sh.refresh_time_ms),
                },
            ));
        }
    }
}

/// One node's PDOs, heartbeat and EMCY headroom.
fn node_lines(
    mk: LineMaker,
    node: u8,
    what: &str,
    pdos: &[PdoFrame],
    hb_ms: f64,
    lines: &mut Vec<Line>,
) {
    for (k, p) in pdos.iter().enumerate() {
        let name = if p.rpdo {
            format!("RPDO{} node {node}", k + 1)
        } else {
            format!("TPDO{} node {node}", k + 1)
        };
        lines.push(mk.line(
            name,
            if p.rpdo {
                Sender::Master
            } else {
                Sender::Node(node)
            },
            p.cob_id,
            p.dlc,
            Rate::EverySync(p.every_n_sync),
        ));
    }
    lines.push(mk.line(
        format!("heartbeat {what} node {node}"),
        Sender::Node(node),
        0x700 + u16::from(node),
        1,
        Rate::Every { ms: hb_ms },
    ));
    lines.push(emcy_headroom(mk, node));
}

/// The safety I/O node's inputs TPDO, heartbeat and EMCY headroom.
fn safety_io_lines(mk: LineMaker, io: &drives_config::SafetyIoConfig, lines: &mut Vec<Line>) {
    lines.push(mk.line(
        format!("safety I/O inputs node {}", io.node_id),
        Sender::Node(io.node_id),
        drives_config::safety_io_tpdo_cob_id(io.node_id),
        2,
        Rate::Every {
            ms: f64::from(io.inputs_period_ms),
        },
    ));
    lines.push(mk.line(
        format!("heartbeat safety I/O node {}", io.node_id),
        Sender::Node(io.node_id),
        0x700 + u16::from(io.node_id),
        1,
        Rate::Every {
            ms: f64::from(io.heartbeat_ms),
        },
    ));
    lines.push(emcy_headroom(mk, io.node_id));
}

/// The EMCY a node may send, reserved at [`EMCY_RESERVE_PERIOD_MS`].
fn emcy_headroom(mk: LineMaker, node: u8) -> Line {
    mk.line(
        format!("EMCY headroom node {node}"),
        Sender::Reserve,
        0x080 + u16::from(node),
        8,
        Rate::Every {
            ms: EMCY_RESERVE_PERIOD_MS,
        },
    )
}

/// "RPDO1, RPDO2 …" and "TPDO1 …" per node, counted per direction.
fn renumber(lines: &mut [Line]) {
    let mut counts: Vec<(String, u32)> = Vec::new();
    for l in lines.iter_mut() {
        let (kind, rest) = match l.what.split_once("PDO") {
            Some((k, r)) if k == "R" || k == "T" => (k.to_string(), r.to_string()),
            _ => continue,
        };
        let node = rest.split_once(" node ").map_or("", |x| x.1).to_string();
        let key = format!("{kind}{node}");
        let n = match counts.iter_mut().find(|c| c.0 == key) {
            Some(c) => {
                c.1 += 1;
                c.1
            }
            None => {
                counts.push((key, 1));
                1
            }
        };
        l.what = format!("{kind}PDO{n} node {node}");
    }
}

/// The PDO layout drive-io configures today (docs/can-protocol.md): RPDO1 = controlword +
/// target position (6 B), TPDO1 = statusword + position actual (6 B), TPDO2 = velocity actual +
/// force (8 B), every SYNC.
pub fn fixed_layout(node: u8) -> Vec<PdoFrame> {
    let n = u16::from(node);
    vec![
        PdoFrame {
            cob_id: 0x200 + n,
            dlc: 6,
            rpdo: true,
            every_n_sync: 1,
        },
        PdoFrame {
            cob_id: 0x180 + n,
            dlc: 6,
            rpdo: false,
            every_n_sync: 1,
        },
        PdoFrame {
            cob_id: 0x280 + n,
            dlc: 8,
            rpdo: false,
            every_n_sync: 1,
        },
    ]
}

/// The budget of `cfg` for the nodes' plans (their configured PDO frames,
/// [`crate::commissioning::plan_all`]).
pub fn of_plans(cfg: &DrivesConfig, plans: &[Plan]) -> Vec<InterfaceBudget> {
    let (drives, extra) = budget_frames(cfg, plans);
    budget(cfg, |i| drives.get(i).cloned().unwrap_or_default(), &extra)
}

/// The budget of `cfg` with the PDO frames every node will be configured with (reads the
/// EDS files), every interface checked: the first one that does not fit is the error.
pub fn check(cfg: &DrivesConfig) -> Result<Vec<InterfaceBudget>, CheckError> {
    let plans = crate::commissioning::plan_all(cfg, None)?;
    let all = of_plans(cfg, &plans);
    for ib in &all {
        ib.check()?;
    }
    Ok(all)
}

/// The plans' PDO frames in the bus budget's terms ([`budget`]): per cable its
/// drive's frames, and every force sensor as an extra node (interface, node id, frames,
/// heartbeat period ms). An event-driven TPDO counts as one frame every
/// max(1, ⌊inhibit time / SYNC period⌋) SYNCs — its worst case when the inhibit time is at least
/// one period; with a shorter inhibit time it may come more often than that.
#[allow(clippy::type_complexity)]
pub fn budget_frames(
    cfg: &DrivesConfig,
    plans: &[Plan],
) -> (Vec<Vec<PdoFrame>>, Vec<(usize, u8, Vec<PdoFrame>, f64)>) {
    let period_us = cfg.bus.sync_period_us.max(1);
    let convert = |p: &Plan| -> Vec<PdoFrame> {
        p.pdo_frames()
            .iter()
            .map(|f| PdoFrame {
                cob_id: f.cob_id,
                dlc: f.dlc,
                rpdo: f.direction == Direction::ToNode,
                every_n_sync: match f.transmission {
                    Transmission::Sync { every } => u16::from(every.max(1)),
                    Transmission::Event { inhibit_us, .. } => {
                        u16::try_from((inhibit_us / period_us).max(1)).unwrap_or(u16::MAX)
                    }
                },
            })
            .collect()
    };
    let mut drives = Vec::new();
    let mut extra = Vec::new();
    // plan_all: the drives in cable order, then the force sensors in their order.
    let mut j = 0;
    for p in plans {
        match p.kind {
            NodeKind::Drive { .. } => drives.push(convert(p)),
            NodeKind::ForceSensor { .. } => {
                j += 1;
                let j = j - 1;
                extra.push((
                    cfg.sensor_interface(j),
                    p.node,
                    convert(p),
                    f64::from(cfg.bus.heartbeat_producer_ms),
                ));
            }
        }
    }
    (drives, extra)
}

/// Why [`check`] refused a configuration.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The nodes' configuration could not be planned (EDS, mapping).
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error(transparent)]
    Budget(#[from] BudgetError),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drives(per_interface: &[usize], extra: &str) -> DrivesConfig {
        let mut t = String::from("[bus]\n");
        t.push_str(extra);
        for (k, _) in per_interface.iter().enumerate() {
            t.push_str(&format!(
                "[[bus.interface]]\nname = \"can{k}\"\ntransport = \"udpbus:239.255.70.1:{}\"\n",
                21000 + k
            ));
        }
        let mut node = 0;
        for (k, n) in per_interface.iter().enumerate() {
            for _ in 0..*n {
                node += 1;
                t.push_str(&format!(
                    "[[winch]]\ninterface = \"can{k}\"\nnode_id = {node}\ndrum_diameter_m = 0.305\n\
                     gear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = 1\n"
                ));
            }
        }
        t.push_str(
            "[safety_heartbeat]\ncob_id = 0x101\nvalidation_time_ms = 50\npair_window_ms = 10\n\
             release_pairs = 3\nrefresh_time_ms = 15\n",
        );
        DrivesConfig::parse(&t).unwrap()
    }

    /// The figures: 8 drives with today's three PDOs on one 1 Mbit/s bus need about
    /// three buses' worth (the cyclic frames alone: 2975 bit per 1 ms cycle).
    #[test]
    fn eight_drives_with_three_pdos_on_one_bus_are_refused_naming_the_frames() {
        let cfg = drives(&[8], "");
        let all = budget(&cfg, |i| fixed_layout(cfg.winches[i].node_id), &[]);
        let ib = &all[0];
        assert_eq!(ib.worst_cycle_sync_bits(), 2975);
        assert!(ib.load_percent() > 297.0, "{}", ib.load_percent());
        let e = ib.check().unwrap_err().to_string();
        assert!(
            e.contains("\"can0\"") && e.contains("TPDO2") && e.contains("RPDO1"),
            "{e}"
        );
        assert!(matches!(check(&cfg), Err(CheckError::Budget(_))));
    }

    #[test]
    fn two_drives_with_three_pdos_are_still_above_the_budget() {
        let cfg = drives(&[2, 2, 2, 2], "");
        let b = budget(&cfg, |i| fixed_layout(cfg.winches[i].node_id), &[]);
        let e = b[0].check().unwrap_err();
        assert!(matches!(e, BudgetError::Load { .. }), "{e}");
        // 55 + 2 × (115 + 115 + 135) = 785 bit of synchronous frames per 1 ms.
        assert_eq!(b[0].worst_cycle_sync_bits(), 785);
        assert!(
            (78.0..90.0).contains(&b[0].load_percent()),
            "{}",
            b[0].load_percent()
        );
    }

    #[test]
    fn a_lean_layout_fits_and_a_budget_set_lower_refuses_it() {
        // RPDO 6 B + TPDO 6 B every SYNC, velocity 4 B every 10th.
        let lean = |node: u8| {
            let n = u16::from(node);
            vec![
                PdoFrame {
                    cob_id: 0x200 + n,
                    dlc: 6,
                    rpdo: true,
                    every_n_sync: 1,
                },
                PdoFrame {
                    cob_id: 0x180 + n,
                    dlc: 6,
                    rpdo: false,
                    every_n_sync: 1,
                },
                PdoFrame {
                    cob_id: 0x280 + n,
                    dlc: 4,
                    rpdo: false,
                    every_n_sync: 10,
                },
            ]
        };
        // With the monitor's pairs on every drive interface the RPDOs can wait behind them.
        let cfg = drives(&[2, 2, 2, 2], "");
        let b = budget(&cfg, |i| lean(cfg.winches[i].node_id), &[]);
        assert!(
            matches!(b[0].check(), Err(BudgetError::RpdoWindow { .. })),
            "{}",
            b[0]
        );
        // With a safety I/O node on its own interface they travel there only.
        let cfg = drives(&[2, 2, 2, 2, 0], "");
        let mut cfg = cfg;
        cfg.safety_io = Some(drives_config::SafetyIoConfig {
            interface: "can4".into(),
            node_id: 0x30,
            inputs_period_ms: 10,
            heartbeat_ms: 10,
        });
        cfg.validate().unwrap();
        let b = budget(&cfg, |i| lean(cfg.winches[i].node_id), &[]);
        assert!(b[4].lines.iter().any(|l| l.sender == Sender::Monitor));
        assert!(
            b[..4]
                .iter()
                .all(|ib| ib.lines.iter().all(|l| l.sender != Sender::Monitor))
        );
        for ib in &b {
            ib.check().unwrap_or_else(|e| panic!("{e}\n{ib}"));
            assert!(ib.load_percent() < 70.0);
        }
        let text = b[0].to_string();
        assert!(
            text.contains("fits") && text.contains("RPDO window"),
            "{text}"
        );
        let mut tight = cfg.clone();
        for itf in &mut tight.bus.interfaces {
            itf.budget_percent = 40.0;
        }
        let b = budget(&tight, |i| lean(tight.winches[i].node_id), &[]);
        assert!(matches!(b[0].check(), Err(BudgetError::Load { .. })));
        // An RPDO guard too short for two RPDOs behind a blocking frame.
        let mut short = cfg.clone();
        short.bus.rpdo_guard_us = 300;
        let b = budget(&short, |i| lean(short.winches[i].node_id), &[]);
        assert!(
            matches!(b[0].check(), Err(BudgetError::RpdoWindow { .. })),
            "{}",
            b[0]
        );
    }

    /// The simulated winch's default mapping is the layout the budget assumes today; a vendor
    /// drive with a load cell has 6 + 6 B every SYNC, 4 B every 10th, and the cell's 4 B.
    #[test]
    fn budget_frames_are_the_configured_mappings() {
        let c = DrivesConfig::parse(
            "[bus]\ntransport = \"udpbus:239.255.70.1:20000\"\n[[winch]]\nnode_id = 3\n\
             drum_diameter_m = 0.305\ngear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = -1\n\
             max_cable_length_m = 20.0\n",
        )
        .unwrap();
        let plans = crate::commissioning::plan_all(&c, None).unwrap();
        let (drives, extra) = budget_frames(&c, &plans);
        assert_eq!(drives, vec![fixed_layout(3)]);
        assert!(extra.is_empty());
        let vendor = format!(
            "{}/../../config/eds/vendor-csp-drive.eds",
            env!("CARGO_MANIFEST_DIR")
        );
        let c = DrivesConfig::parse(&format!(
            "[bus]\ntransport = \"udpbus:239.255.70.1:20000\"\neds = \"{vendor}\"\n\
             [[winch]]\nnode_id = 3\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = 1\n\
             [[force_sensor]]\nnode_id = 40\ncable = 1\nn_per_unit = 0.1\nevery_n_syncs = 2\n"
        ))
        .unwrap();
        let plans = crate::commissioning::plan_all(&c, None).unwrap();
        let (drives, extra) = budget_frames(&c, &plans);
        let f = |cob_id, dlc, rpdo, every_n_sync| PdoFrame {
            cob_id,
            dlc,
            rpdo,
            every_n_sync,
        };
        assert_eq!(
            drives[0],
            vec![
                f(0x203, 6, true, 1),
                f(0x183, 6, false, 1),
                f(0x283, 4, false, 10)
            ]
        );
        assert_eq!(extra, vec![(0, 40, vec![f(0x1A8, 4, false, 2)], 10.0)]);
    }
}
