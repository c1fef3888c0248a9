//! TEST DOUBLE: `winch-emulator` answers as m CiA 402 drives on the bus and moves each cable
//! kinematically ([`WinchAxis`]) toward its target. It is not the plant (that is crates/sim-plant);
//! it exists so drive-io can be tested without the physics.

use can_transport::{CanBus, RxEvent};
use cia402_drive::bank_set::DriveBanks;
use cia402_drive::force_node::ForceNode;
use cia402_drive::safety_io::SafetyIoNode;
use cia402_drive::slave::{MotionDemand, WinchAxis};
use crs_ipc::MAX_CABLES;
use drive_bus::canopen::FrameBuf;
use drive_bus::canopen::{Ds402State, NmtState};
use drive_bus::eds::{Eds, EdsError};
use drive_bus::safety_watch::SafetyWatchConfig;
use drives_config::{DrivesConfig, WinchConfig};
use std::sync::Arc;
use std::sync::atomic::{
    AtomicBool, AtomicI32, AtomicU8, AtomicU16, AtomicU32, AtomicU64, Ordering,
};
use std::time::Duration;

/// Emulator parameters (SI).
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// The drives configuration (interfaces, node ids, scaling).
    pub drives: DrivesConfig,
    pub winches: Vec<WinchConfig>,
    pub initial_length_m: Vec<f64>,
    /// Physics step per SYNC (s): the drive interpolates over one SYNC period (CSP).
    pub sync_period_s: f64,
    pub max_speed_m_per_s: f64,
    pub max_accel_m_per_s2: f64,
    /// Heartbeat period before the master configures 0x1017 (ms).
    pub default_heartbeat_ms: u16,
    /// Reported pulley force: pretension + damping * cable speed (a stand-in, not physics).
    pub pretension_n: f64,
    pub damping_n_per_m_per_s: f64,
    /// Validate the safety monitor's heartbeat (drives.toml `[safety_heartbeat]`); None = off.
    pub safety_watch: Option<SafetyWatchConfig>,
    /// The drives' EDS (drives.toml `bus.eds`, else the simulated winch's).
    pub eds: Eds,
    /// Per winch: its own EDS (`winch[i].eds`); a winch without one uses `eds`.
    pub winch_eds: Vec<Eds>,
    /// The `[[force_sensor]]` nodes (simulated load cells): interface, cable (0-based) and
    /// node; they report the emulator's force stand-in of that cable.
    pub force_nodes: Vec<(usize, usize, ForceNode)>,
    /// The safety I/O node (drives.toml `[safety_io]`) the emulator plays too: with it the
    /// drives ignore the monitor's frames and the node drives their STO inputs.
    pub safety_io: Option<drives_config::SafetyIoConfig>,
}

impl EmulatorConfig {
    /// Fails only if an EDS cannot be read (or a force sensor's has no process value).
    pub fn from_drives(cfg: &DrivesConfig, initial_length_m: f64) -> Result<Self, EdsError> {
        Ok(Self {
            drives: cfg.clone(),
            winch_eds: (0..cfg.winches.len())
                .map(|i| cfg.load_winch_eds(i))
                .collect::<Result<_, _>>()?,
            force_nodes: DriveBanks::force_nodes(cfg, cfg.bus.heartbeat_producer_ms)?,
            winches: cfg.winches.clone(),
            initial_length_m: vec![initial_length_m; cfg.winches.len()],
            sync_period_s: f64::from(cfg.bus.sync_period_us) * 1e-6,
            max_speed_m_per_s: 5.0,
            max_accel_m_per_s2: 14.0,
            default_heartbeat_ms: cfg.bus.heartbeat_producer_ms,
            pretension_n: 2000.0,
            damping_n_per_m_per_s: 100.0,
            safety_watch: cfg.safety_heartbeat,
            eds: cfg.load_eds()?,
            safety_io: cfg.safety_io.clone(),
        })
    }
}

/// Shared view/control of a running emulator (lock-free, for tests).
#[derive(Default)]
pub struct EmulatorControl {
    pub stop: AtomicBool,
    /// Bit i set = winch i stops producing heartbeats.
    pub heartbeat_mute_mask: AtomicU32,
    /// Number of SYNCs processed (by winch 0).
    pub syncs: AtomicU64,
    length_bits: [AtomicU64; MAX_CABLES],
    velocity_bits: [AtomicU64; MAX_CABLES],
    statusword: [AtomicU16; MAX_CABLES],
    nmt: [AtomicU16; MAX_CABLES],
    demand: [AtomicU8; MAX_CABLES],
    left_follow_ns: [AtomicU64; MAX_CABLES],
    /// Safety-heartbeat watch (if enabled): inhibiting now, trips so far, time of the last trip.
    pub safety_inhibit: AtomicBool,
    pub safety_trips: AtomicU64,
    pub safety_tripped_ns: AtomicU64,
    /// Fault injection: bit i set = winch i reports `force_override_mn[i]` as its measured
    /// force (TPDO2) instead of the pretension stand-in (a slack or overloaded cable, as the
    /// safety HIL matrix needs; the emulator has no physics).
    force_override_mask: AtomicU32,
    force_override_mn: [AtomicI32; MAX_CABLES],
    /// When the emulation loop first reported winch i's current override (CLOCK_MONOTONIC ns,
    /// 0: not yet, or no override): the instant the injected force exists for the load cell,
    /// which a harness measures detection from (the control file's polling is the rig's
    /// latency, not the system's).
    force_override_applied_ns: [AtomicU64; MAX_CABLES],
    /// Safety I/O node inputs: bit 0 e-stop circuit OPEN (button pressed), bit 1 reset key
    /// turned (0 = released button, key at rest: the default).
    pub io_inputs: AtomicU8,
    /// Safety I/O node: STO released (torque permitted) now.
    pub sto_released: AtomicBool,
    /// Sequence lock over the per-winch state (length, velocity, statusword, NMT, demand,
    /// left-follow time): odd while the loop publishes a pass, so a reader on another thread
    /// ([`EmulatorControl::read_consistent`]) never pairs one pass's demand with another
    /// pass's length (a torn read once showed a drive braked at the length before its last
    /// step, so the step looked like motion after the stop).
    publish_seq: AtomicU64,
}

/// Motion demand codes in [`EmulatorControl::demand_code`].
pub const DEMAND_HOLD: u8 = 0;
pub const DEMAND_QUICK_STOP: u8 = 1;
pub const DEMAND_FOLLOW: u8 = 2;

impl EmulatorControl {
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }
    /// Runs `read` over a state the loop published as a whole (one pass): retried while the
    /// loop is publishing or published meanwhile. The loop never waits for a reader.
    pub fn read_consistent<R>(&self, mut read: impl FnMut(&Self) -> R) -> R {
        loop {
            let before = self.publish_seq.load(Ordering::Acquire);
            if before % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let r = read(self);
            // Orders the reads above before the check below (seqlock reader).
            std::sync::atomic::fence(Ordering::Acquire);
            if self.publish_seq.load(Ordering::Relaxed) == before {
                return r;
            }
        }
    }
    /// True cable length of winch `i` (m).
    pub fn length_m(&self, i: usize) -> f64 {
        f64::from_bits(self.length_bits[i].load(Ordering::Acquire))
    }
    pub fn velocity_m_per_s(&self, i: usize) -> f64 {
        f64::from_bits(self.velocity_bits[i].load(Ordering::Acquire))
    }
    pub fn ds402_state(&self, i: usize) -> Ds402State {
        Ds402State::from_statusword(self.statusword[i].load(Ordering::Acquire))
    }
    pub fn nmt_state(&self, i: usize) -> Option<NmtState> {
        NmtState::from_code(self.nmt[i].load(Ordering::Acquire) as u8)
    }
    /// Motion demand of winch `i`: [`DEMAND_HOLD`], [`DEMAND_QUICK_STOP`] or [`DEMAND_FOLLOW`].
    pub fn demand_code(&self, i: usize) -> u8 {
        self.demand[i].load(Ordering::Acquire)
    }
    /// CLOCK_MONOTONIC ns when winch `i` last stopped following (0 = never).
    pub fn left_follow_ns(&self, i: usize) -> u64 {
        self.left_follow_ns[i].load(Ordering::Acquire)
    }
    /// When the loop first reported winch `i`'s current force override (0: not yet / none).
    pub fn force_override_applied_ns(&self, i: usize) -> u64 {
        self.force_override_applied_ns
            .get(i)
            .map_or(0, |t| t.load(Ordering::Acquire))
    }
    /// Makes winch `i` report `force_n` (None: the normal stand-in) from its next SYNC on.
    pub fn set_force_override(&self, i: usize, force_n: Option<f64>) {
        if i >= MAX_CABLES {
            return;
        }
        self.force_override_applied_ns[i].store(0, Ordering::Release);
        match force_n {
            Some(f) => {
                let mn = (f * 1000.0).clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
                self.force_override_mn[i].store(mn, Ordering::Release);
                self.force_override_mask.fetch_or(1 << i, Ordering::AcqRel);
            }
            None => {
                self.force_override_mask
                    .fetch_and(!(1 << i), Ordering::AcqRel);
            }
        }
    }
    /// The measured force winch `i` reports (mN), given the stand-in's.
    fn reported_force_mn(&self, i: usize, stand_in_mn: i32) -> i32 {
        if self.force_override_mask.load(Ordering::Acquire) & (1 << i) != 0 {
            let applied = &self.force_override_applied_ns[i];
            if applied.load(Ordering::Acquire) == 0 {
                let _ = applied.compare_exchange(
                    0,
                    crs_ipc::monotonic_ns(),
                    Ordering::AcqRel,
                    Ordering::Relaxed,
                );
            }
            self.force_override_mn[i].load(Ordering::Acquire)
        } else {
            stand_in_mn
        }
    }
    pub fn mute_heartbeat(&self, i: usize) {
        self.heartbeat_mute_mask.fetch_or(1 << i, Ordering::AcqRel);
    }
}

/// Runs the emulator until `control.stop` is set, answering as the drives of every interface
/// (`buses[k]` = interface k of `cfg.drives`). Bus errors other than a full TX queue end it.
pub fn run<B: CanBus>(
    buses: Vec<B>,
    cfg: &EmulatorConfig,
    control: &EmulatorControl,
) -> Result<(), can_transport::CanError> {
    let mut em = Emulator::configure(buses, cfg, control);
    em.activate();
    while !control.stop.load(Ordering::Acquire) {
        em.pass()?;
    }
    Ok(())
}

/// The safety I/O node with its interface and its outgoing frames.
type IoNode = (usize, SafetyIoNode, FrameBuf);

/// The emulator's state between passes of its loop.
struct Emulator<'a, B: CanBus> {
    buses: Vec<B>,
    cfg: &'a EmulatorConfig,
    control: &'a EmulatorControl,
    /// Winches emulated (at most `MAX_CABLES`).
    m: usize,
    bank: DriveBanks,
    /// With a safety I/O node the drives are real CiA 402 drives: they ignore the monitor's
    /// frames, the node drives their STO inputs; otherwise they validate the heartbeat.
    io: Option<IoNode>,
    axes: Vec<WinchAxis>,
    /// Interval between the SYNCs of each interface: a CSP drive interpolates over the time
    /// that really passed (on the wire model, SYNC jitter shows as motion).
    last_sync: Vec<Option<u64>>,
    /// Round-robin position of `recv_any` over the interfaces.
    cursor: usize,
    last_pass_ns: u64,
    last_stall_log_ns: u64,
}

impl<'a, B: CanBus> Emulator<'a, B> {
    /// The drives, the safety I/O node and the winch axes at their initial lengths and the
    /// pretension, nothing sent yet.
    fn configure(buses: Vec<B>, cfg: &'a EmulatorConfig, control: &'a EmulatorControl) -> Self {
        let m = cfg.winches.len().min(MAX_CABLES);
        let mut bank = DriveBanks::from_parts(
            &cfg.drives,
            &cfg.winch_eds,
            cfg.force_nodes.clone(),
            cfg.default_heartbeat_ms,
        );
        let last_sync: Vec<Option<u64>> = vec![None; bank.interfaces()];
        let io = match (&cfg.safety_io, cfg.safety_watch) {
            (Some(io_cfg), Some(sw)) => cfg
                .drives
                .safety_io_interface()
                .map(|iface| (iface, SafetyIoNode::new(io_cfg, sw), FrameBuf::default())),
            _ => None,
        };
        match (cfg.safety_watch, &io) {
            (Some(sw), None) => {
                bank.enable_safety_watch(sw);
                control.safety_inhibit.store(true, Ordering::Release);
            }
            (_, Some(_)) => {
                bank.set_sto(true);
                control.safety_inhibit.store(true, Ordering::Release);
            }
            _ => {}
        }
        let axes: Vec<WinchAxis> = (0..m)
            .map(|i| {
                WinchAxis::new(
                    cfg.initial_length_m.get(i).copied().unwrap_or(5.0),
                    cfg.max_speed_m_per_s,
                    cfg.max_accel_m_per_s2,
                )
            })
            .collect();
        for (i, (w, ax)) in cfg.winches.iter().zip(&axes).enumerate() {
            let c = w.length_to_counts(ax.length_m).unwrap_or(0);
            bank.set_actual(i, c, 0, (cfg.pretension_n * 1000.0) as i32);
        }
        Self {
            buses,
            cfg,
            control,
            m,
            bank,
            io,
            axes,
            last_sync,
            cursor: 0,
            last_pass_ns: 0,
            last_stall_log_ns: 0,
        }
    }

    /// Starts the drives and the safety I/O node (boot-up) and publishes the first status.
    fn activate(&mut self) {
        self.bank.start(crs_ipc::monotonic_ns());
        if let Some((_, node, out)) = self.io.as_mut() {
            node.start(crs_ipc::monotonic_ns(), out);
        }
        self.publish(crs_ipc::monotonic_ns());
        self.last_pass_ns = crs_ipc::monotonic_ns();
    }

    /// One pass of the loop: send what is queued, handle what arrived, judge the watches,
    /// publish the status.
    fn pass(&mut self) -> Result<(), can_transport::CanError> {
        self.bank.flush(&mut self.buses)?;
        flush_io(&mut self.io, &mut self.buses)?;
        let (handled, bus_time_ns) = self.receive()?;
        let now = crs_ipc::monotonic_ns();
        // Judged at the bus time handled so far while frames are still queued (the backlog
        // cap was hit), else now.
        let judge_at = if handled >= MAX_BACKLOG {
            bus_time_ns
        } else {
            now
        };
        self.log_stall(now, handled);
        self.judge(judge_at);
        self.publish(now);
        Ok(())
    }

    /// Handles the frames that arrived, up to `MAX_BACKLOG`. Returns how many events were
    /// handled and the arrival time of the last frame.
    ///
    /// The emulated drives are hardware with their own CPUs: they see each frame when it
    /// arrives on the bus, not when this process (on a non-real-time host, or in the TCG
    /// guest) gets round to reading it. So every frame is handled at its ARRIVAL time — the
    /// kernel's receive stamp where the transport has one (SocketCAN) — and the watches are
    /// judged at the bus time processed so far. Judging at the read time faulted a starved
    /// emulator on its own backlog: the first frame read after a 700 ms stall checked the
    /// safety watch (DriveBank::handle_frame does, per frame) against the last pair handled
    /// before the stall, while the pairs that arrived meanwhile were still queued (the guest
    /// safety-hil flakes of forged_stopping and forged_rpdo_other_enabling_controlword,
    /// "safety heartbeat invalid or missing: Timeout").
    fn receive(&mut self) -> Result<(usize, u64), can_transport::CanError> {
        let mut rx =
            can_transport::recv_any(&mut self.buses, Duration::from_millis(2), &mut self.cursor)?;
        let rt_minus_mono = realtime_minus_monotonic_ns();
        let mut handled = 0;
        let mut bus_time_ns = 0;
        while let Some((iface, ev)) = rx {
            if let RxEvent::Frame(frame) = ev {
                let at = arrival_ns(&frame, rt_minus_mono);
                bus_time_ns = at;
                if let Some((io_iface, node, out)) = self.io.as_mut()
                    && *io_iface == iface
                {
                    node.handle_frame(&frame.frame, at, out);
                    self.bank.set_sto(!node.sto_released());
                }
                if self.bank.handle_frame(iface, &frame.frame, at) {
                    self.on_sync(iface, at)?;
                }
            }
            handled += 1;
            rx = next_event(&mut self.buses, handled, &mut self.cursor)?;
        }
        Ok((handled, bus_time_ns))
    }

    /// A SYNC on `iface` at `at`: the winches of that interface move for the interval since
    /// the last one, report their position, velocity and force, and the answer goes out now,
    /// not after the backlog.
    fn on_sync(&mut self, iface: usize, at: u64) -> Result<(), can_transport::CanError> {
        let cfg = self.cfg;
        let bank = &mut self.bank;
        let dt = sync_interval_s(&mut self.last_sync[iface], at, cfg.sync_period_s);
        for (i, (w, ax)) in cfg.winches.iter().zip(self.axes.iter_mut()).enumerate() {
            if bank.interface_of(i) != Some(iface) {
                continue;
            }
            match bank.demand(i) {
                MotionDemand::Follow { target_counts } => {
                    ax.step(Some(w.counts_to_length(target_counts)), dt)
                }
                MotionDemand::QuickStop => ax.step(None, dt),
                MotionDemand::Hold => ax.hold(),
            }
            let pos = w
                .length_to_counts(ax.length_m)
                .unwrap_or(if ax.length_m < 0.0 { 0 } else { i32::MAX });
            let force = cfg.pretension_n + cfg.damping_n_per_m_per_s * ax.velocity_m_per_s;
            bank.set_actual(
                i,
                pos,
                w.m_per_s_to_counts_per_s(ax.velocity_m_per_s),
                self.control.reported_force_mn(i, (force * 1000.0) as i32),
            );
        }
        bank.transmit_pdos_on(iface);
        bank.flush(&mut self.buses)?;
        if iface == 0 {
            self.control.syncs.fetch_add(1, Ordering::AcqRel);
        }
        Ok(())
    }

    /// A test double on a non-real-time host: say when this loop itself was not scheduled for
    /// a while (at most once a second), so a watch trip shows whose stall it was.
    fn log_stall(&mut self, now: u64, handled: usize) {
        let gap = now.saturating_sub(self.last_pass_ns);
        if gap > 50_000_000 && now.saturating_sub(self.last_stall_log_ns) > 1_000_000_000 {
            self.last_stall_log_ns = now;
            tracing::warn!(
                gap_ms = gap as f64 * 1e-6,
                frames_handled = handled,
                "emulator loop stalled (frames were handled with their receive time)"
            );
        }
        self.last_pass_ns = now;
    }

    /// The test's heartbeat mutes, the safety I/O node's inputs and watch, and the drives'
    /// heartbeats and safety watch, judged at `judge_at`; trips are counted in the control.
    fn judge(&mut self, judge_at: u64) {
        let control = self.control;
        let bank = &mut self.bank;
        let mute = control.heartbeat_mute_mask.load(Ordering::Acquire);
        for i in 0..self.m {
            if let Some(s) = bank.slave_mut(i) {
                s.set_heartbeat_muted(mute & (1 << i) != 0);
            }
        }
        if let Some((_, node, out)) = self.io.as_mut() {
            let inputs = control.io_inputs.load(Ordering::Acquire);
            node.set_inputs(inputs & 1 == 0, inputs & 2 != 0);
            node.poll(judge_at, out);
            let released = node.sto_released();
            bank.set_sto(!released);
            control.sto_released.store(released, Ordering::Release);
            control.safety_inhibit.store(!released, Ordering::Release);
            if let Some((reason, at_ns)) = node.watch_mut().take_trip() {
                tracing::error!(
                    ?reason,
                    at_ns,
                    "safety I/O node: heartbeat invalid or missing, STO"
                );
                control.safety_trips.fetch_add(1, Ordering::AcqRel);
                control.safety_tripped_ns.store(at_ns, Ordering::Release);
            }
        }
        bank.poll(judge_at);
        if let Some((reason, at_ns)) = bank.take_safety_trip() {
            tracing::error!(
                ?reason,
                at_ns,
                "safety heartbeat invalid or missing: drives quick-stop"
            );
            control.safety_trips.fetch_add(1, Ordering::AcqRel);
            control.safety_tripped_ns.store(at_ns, Ordering::Release);
        }
        if bank.has_safety_watch() {
            control
                .safety_inhibit
                .store(!bank.safety_permits(), Ordering::Release);
        }
    }

    /// Publishes the drives' status to the test (seqlock).
    fn publish(&self, now: u64) {
        let control = self.control;
        // Seqlock writer: odd while publishing; the fence orders the odd count before the
        // stores below, the Release of the even count the stores before it.
        control.publish_seq.fetch_add(1, Ordering::Relaxed);
        std::sync::atomic::fence(Ordering::Release);
        for (i, ax) in self.axes.iter().enumerate() {
            let d = match self.bank.demand(i) {
                MotionDemand::Follow { .. } => DEMAND_FOLLOW,
                MotionDemand::QuickStop => DEMAND_QUICK_STOP,
                MotionDemand::Hold => DEMAND_HOLD,
            };
            if control.demand[i].swap(d, Ordering::AcqRel) == DEMAND_FOLLOW && d != DEMAND_FOLLOW {
                control.left_follow_ns[i].store(now, Ordering::Release);
            }
            control.length_bits[i].store(ax.length_m.to_bits(), Ordering::Release);
            control.velocity_bits[i].store(ax.velocity_m_per_s.to_bits(), Ordering::Release);
            if let Some(s) = self.bank.slave(i) {
                control.statusword[i].store(s.statusword(), Ordering::Release);
                control.nmt[i].store(u16::from(s.nmt_state().code()), Ordering::Release);
            }
        }
        control.publish_seq.fetch_add(1, Ordering::Release);
    }
}

/// Sends the safety I/O node's frames on its interface.
fn flush_io<B: CanBus>(
    io: &mut Option<(usize, SafetyIoNode, FrameBuf)>,
    buses: &mut [B],
) -> Result<(), can_transport::CanError> {
    if let Some((iface, _, out)) = io.as_mut() {
        if let Some(bus) = buses.get_mut(*iface) {
            for f in out.as_slice() {
                match bus.send(f) {
                    Ok(()) | Err(can_transport::CanError::TxFull { .. }) => {}
                    Err(e) => return Err(e),
                }
            }
        }
        out.clear();
    }
    Ok(())
}

/// The next queued event of any bus, unless the backlog cap is reached.
fn next_event<B: CanBus>(
    buses: &mut [B],
    handled: usize,
    cursor: &mut usize,
) -> Result<Option<(usize, RxEvent)>, can_transport::CanError> {
    if handled >= MAX_BACKLOG {
        return Ok(None);
    }
    can_transport::recv_any(buses, Duration::ZERO, cursor)
}

/// Frames handled at most before the watches are judged (a flooded bus cannot stall us).
const MAX_BACKLOG: usize = 512;

/// The time since the previous SYNC of an interface (at `at_ns`), s: the real interval, within
/// [0.25, 4] nominal periods (the first SYNC, or one after a pause, counts as nominal).
fn sync_interval_s(last: &mut Option<u64>, at_ns: u64, nominal_s: f64) -> f64 {
    let dt = match last.replace(at_ns) {
        Some(prev) if at_ns > prev => (at_ns - prev) as f64 * 1e-9,
        _ => nominal_s,
    };
    if dt > 4.0 * nominal_s {
        nominal_s
    } else {
        dt.max(0.25 * nominal_s)
    }
}

/// CLOCK_REALTIME − CLOCK_MONOTONIC now, ns: converts the kernel's receive stamps (realtime)
/// to the monotonic clock every watch runs on.
fn realtime_minus_monotonic_ns() -> i128 {
    let rt = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128);
    rt - i128::from(crs_ipc::monotonic_ns())
}

/// When a frame arrived on the bus (CLOCK_MONOTONIC ns): the kernel's receive stamp where the
/// transport gives one, never later than user space's receipt; else that receipt.
fn arrival_ns(frame: &can_transport::RxFrame, rt_minus_mono: i128) -> u64 {
    match frame.kernel_rx_realtime_ns {
        Some(k) => {
            let mono = i128::from(k) - rt_minus_mono;
            u64::try_from(mono.clamp(0, i128::from(frame.rx_monotonic_ns)))
                .unwrap_or(frame.rx_monotonic_ns)
        }
        None => frame.rx_monotonic_ns,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::{CanFrame, RxFrame};

    fn rx(read_ns: u64, kernel_rt: Option<u64>) -> RxFrame {
        RxFrame {
            frame: CanFrame::new(0x80, &[]).unwrap(),
            rx_monotonic_ns: read_ns,
            kernel_rx_realtime_ns: kernel_rt,
            own: false,
        }
    }

    /// A frame that waited 700 ms in the socket while the emulator was not scheduled is handled
    /// at its kernel arrival time, converted to the monotonic clock; never later than its
    /// receipt; the receipt where the transport has no kernel stamp.
    #[test]
    fn a_queued_frame_is_handled_at_its_arrival_time() {
        let offset: i128 = 1_700_000_000_000_000_000; // realtime − monotonic
        let read = 10_000_000_000u64;
        let arrived = read - 700_000_000;
        let kernel = (i128::from(arrived) + offset) as u64;
        assert_eq!(arrival_ns(&rx(read, Some(kernel)), offset), arrived);
        // A realtime clock step cannot put the arrival after the receipt.
        assert_eq!(
            arrival_ns(&rx(read, Some(kernel)), offset - 1_000_000_000),
            read
        );
        assert_eq!(arrival_ns(&rx(read, None), offset), read);
        let now_offset = realtime_minus_monotonic_ns();
        assert!(now_offset > 0, "{now_offset}");
    }
}
