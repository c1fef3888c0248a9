//! The plant behind the drives: the CAN face of the simulated plant (binary `sim-plant`).
//!
//! [`PlantBus`] answers as the m CiA 402 winch drives of `config/drives.toml` (the drive side
//! is drive-io's [`DriveBank`]) and puts the elastostatic [`Plant`] behind them:
//!
//! * every drive owns a winch ([`CspWinch`]) that follows the stream of CSP target positions
//!   like a CSP drive (velocity feed-forward from consecutive targets, dead-beat per SYNC
//!   period) within the winch limits (cable speed ≤ `bus.max_cable_speed_m_per_s`,
//!   acceleration ≤ the platform's table 5.1 limit), decelerates on quick stop and is held by
//!   its brake otherwise (not Operation Enabled, fault; NMT stopped as 0x6007 says: drive-io
//!   configures 2, disable voltage);
//! * with `[safety_heartbeat]` in the drives config the drives validate the safety monitor's
//!   heartbeat (drive-io's safety watch) and quick-stop without it;
//! * the platform settles in the equilibrium of the [`Plant`] for the lengths the winches hold
//!   (solved only when they changed by more than [`BusOptions::resolve_epsilon_m`]);
//! * the TPDOs report the axis position (encoder counts, drive-io's scaling), its speed and the
//!   force-sensor reading of the plant ([`Plant::measure`]); [`PlantBus::truth`] and
//!   [`PlantBus::tracker`] are the iceoryx2 payloads (true state / tracker reading).
//!
//! ## Set-up and the offset convention (eq. 3.14, 6.24)
//!
//! At construction the plant is set up like the real robot (sec. 6.1): the platform is held at
//! the control platform's home pose x_ini and the initial tension f_ini is set
//! ([`Plant::setup_tension`], eq. 3.19), which gives the commands q̂_ini = φ̂_el(x_ini, f_0)
//! that hold it. The drives' encoder zero is then chosen (homing) so that they READ the
//! controller's full command at the home pose, q_home: by default ([`BusOptions::home_lengths_m`]
//! = `None`) the control model's kinematic lengths φ(x_ini) — standard (or pulley, if the
//! control platform has pulleys) inverse kinematics, the command of a controller without a
//! surrogate; a controller with a surrogate commands q_θ(x_ini) = φ(x_ini) + φ_sg(x_ini)
//! (eq. 5.26) there, and the commissioning passes that as `home_lengths_m` (binary:
//! `--home-lengths-m`; `crs sim` computes it from the daemon TOML). Per cable:
//!
//! ```text
//! q_off,i   = q̂_ini,i − q_home,i              (eq. 3.14 / 6.24, m; q_home = φ(x_ini) by default)
//! q_plant,i = q_drive,i + q_off,i             (what the Plant is commanded with)
//! q_drive,i = counts_to_length(position actual) (what drive-io reports and motion-core commands)
//! ```
//!
//! So motion-core's command at the home pose holds exactly the set-up tension, drive-io's
//! first targets (= the drives' actual positions) are q_home, and a command q_θ(x) elsewhere
//! is q_θ(x) + q_off on the plant, as in the spec's experiments. Without this convention the
//! first setpoint would differ from the drives' positions by the cable stretch (≈ 20 mm at
//! 5 kN, k_F = 2000 kN, q ≈ 8 m) or by the surrogate offset at home, far above drive-io's
//! per-cycle step limit.
//!
//! Nothing here panics on bus input: targets outside `[0, max_cable_length_m]` are clamped
//! (the drive's software position limits), a plant without equilibrium is reported
//! (`converged = 0`, [`PlantBus::last_error`]) while the last equilibrium is kept.

use crate::config::PlantConfig;
use crate::plant::{Equilibrium, Plant, PlantError, TensionSetup};
use can_transport::{CanBus, CanError, CanFrame};
use cdpr_model::config::Platform;
use cdpr_model::{Data, Pose, kinematics};
use cia402_drive::bank_set::DriveBanks;
use cia402_drive::safety_io::SafetyIoNode;
use cia402_drive::slave::MotionDemand;
use crs_ipc::{CONTRACT_VERSION, MAX_CABLES, PlantTruth, TrackerPose};
use drive_bus::canopen::Ds402State;
use drive_bus::canopen::FrameBuf;
use drives_config::{DrivesConfig, WinchConfig};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Names of the configuration files, for error messages (`file: key: reason`).
#[derive(Clone, Debug)]
pub struct ConfigFiles {
    pub plant: String,
    pub control: String,
    pub drives: String,
}

impl Default for ConfigFiles {
    fn default() -> Self {
        Self {
            plant: "plant TOML".into(),
            control: "control platform TOML".into(),
            drives: "drives TOML".into(),
        }
    }
}

/// Why the plant cannot be put on the bus. Every variant names the file(s) and key(s).
#[derive(Debug, thiserror::Error)]
pub enum BusPlantError {
    /// A drive's or force sensor's EDS (drives.toml `bus.eds`, `winch[i].eds`,
    /// `force_sensor[j].eds`) cannot be read.
    #[error("{drives}: {source}")]
    Eds {
        drives: String,
        #[source]
        source: drive_bus::eds::EdsError,
    },
    #[error(
        "{plant}: the plant has {plant_m} cables but {drives}: `winch` has {drives_m} [[winch]] \
         entries (cable i is the i-th [[winch]])"
    )]
    CableCount {
        plant: String,
        plant_m: usize,
        drives: String,
        drives_m: usize,
    },
    #[error(
        "{control}: the control platform has {control_m} cables but the plant ({plant}) has {plant_m}"
    )]
    ControlCableCount {
        control: String,
        control_m: usize,
        plant: String,
        plant_m: usize,
    },
    #[error(
        "{drives}: `winch[{index}].drum_diameter_m` = {drives_m} m differs from {control}: \
         `winch.drum_diameter_m` = {control_m} m (the drives' length <-> counts scaling must be \
         the platform's drum)"
    )]
    DrumDiameter {
        drives: String,
        index: usize,
        drives_m: f64,
        control: String,
        control_m: f64,
    },
    #[error("option `{name}`: {reason}")]
    Option { name: &'static str, reason: String },
    #[error("{plant}: the plant cannot be built: {source}")]
    Plant {
        plant: String,
        #[source]
        source: PlantError,
    },
    #[error("{control}: `home`: the control model cannot compute the home pose: {detail}")]
    ControlHome { control: String, detail: String },
    #[error(
        "setting the initial tension at the home pose of {control} on the plant {plant} failed: {source}"
    )]
    Setup {
        control: String,
        plant: String,
        #[source]
        source: PlantError,
    },
    #[error(
        "{drives}: `winch[{index}].max_cable_length_m` = {max} m: cable {cable} at the home pose \
         reads {length:.4} m (the home lengths q_home), outside [0, max_cable_length_m]"
    )]
    HomeOutOfRange {
        drives: String,
        index: usize,
        cable: usize,
        length: f64,
        max: f64,
    },
}

/// Parameters of the plant on the bus (SI).
#[derive(Clone, Debug)]
pub struct BusOptions {
    /// Physics step per SYNC, s: a CSP drive interpolates to the target latched at a SYNC over
    /// one SYNC period (the drives config's `bus.sync_period_us`).
    pub sync_period_s: f64,
    /// Largest cable speed a winch reaches, m/s.
    pub max_cable_speed_m_per_s: f64,
    /// Largest cable acceleration (also the quick-stop deceleration), m/s².
    pub max_cable_accel_m_per_s2: f64,
    /// The equilibrium is solved again only when a held length moved by more than this since
    /// the last solve, m (one equilibrium costs up to ~80 µs with every effect on).
    pub resolve_epsilon_m: f64,
    /// Initial cable forces at the home pose, N. `None`: the control platform's `home.f_ini_n`,
    /// or, if it has none, (f_min + f_max)/2 for every cable, which the projection of eq. 3.19
    /// turns into the closed-form force distribution of eq. 3.41 at the home pose.
    pub f_ini_n: Option<Vec<f64>>,
    /// Lengths the drives read at the home pose after homing, m, one per cable (module docs).
    /// `None`: φ(x_ini) of the control model (a controller without surrogate); with a surrogate
    /// the controller's full command q_θ(x_ini) = φ(x_ini) + φ_sg(x_ini) (eq. 5.26).
    pub home_lengths_m: Option<Vec<f64>>,
    /// Heartbeat producer time before the master writes 0x1017, ms.
    pub default_heartbeat_ms: u16,
    /// A drive whose measured cable force falls below this (a slack cable) raises a drive fault
    /// (EMCY [`EMCY_CABLE_SLACK`], CiA 402 Fault) as a real winch's slack-rope detection does, N.
    pub slack_fault_n: f64,
    /// A drive whose measured cable force exceeds this (the winch's rating; the control
    /// platform's `f_abs_max_n`) raises a drive fault (EMCY [`EMCY_CABLE_OVERLOAD`]), N.
    pub overload_fault_n: f64,
    pub files: ConfigFiles,
}

/// EMCY error code of a drive that detected a slack cable (manufacturer-specific range).
pub const EMCY_CABLE_SLACK: u16 = 0xFF10;
/// EMCY error code of a drive whose cable force exceeded its rating.
pub const EMCY_CABLE_OVERLOAD: u16 = 0xFF11;

impl BusOptions {
    /// Defaults from the drives config (SYNC period, cable speed limit, heartbeat) and the
    /// control platform (acceleration limit, table 5.1).
    pub fn new(drives: &DrivesConfig, control: &Platform) -> Self {
        Self {
            sync_period_s: f64::from(drives.bus.sync_period_us) * 1e-6,
            max_cable_speed_m_per_s: drives.bus.max_cable_speed_m_per_s,
            max_cable_accel_m_per_s2: control.limits.linear_acceleration_max,
            resolve_epsilon_m: 1e-7,
            f_ini_n: None,
            home_lengths_m: None,
            default_heartbeat_ms: drives.bus.heartbeat_producer_ms,
            slack_fault_n: 50.0,
            overload_fault_n: control.f_abs_max,
            files: ConfigFiles::default(),
        }
    }

    fn validate(&self) -> Result<(), BusPlantError> {
        let pos = |name, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(BusPlantError::Option {
                    name,
                    reason: format!("must be finite and > 0, got {v}"),
                })
            }
        };
        pos("sync_period_s", self.sync_period_s)?;
        pos("max_cable_speed_m_per_s", self.max_cable_speed_m_per_s)?;
        pos("max_cable_accel_m_per_s2", self.max_cable_accel_m_per_s2)?;
        pos("overload_fault_n", self.overload_fault_n)?;
        if !(self.slack_fault_n.is_finite() && self.slack_fault_n < self.overload_fault_n) {
            return Err(BusPlantError::Option {
                name: "slack_fault_n",
                reason: format!(
                    "must be finite and below overload_fault_n ({} N), got {}",
                    self.overload_fault_n, self.slack_fault_n
                ),
            });
        }
        if !(self.resolve_epsilon_m.is_finite() && self.resolve_epsilon_m >= 0.0) {
            return Err(BusPlantError::Option {
                name: "resolve_epsilon_m",
                reason: format!("must be finite and >= 0, got {}", self.resolve_epsilon_m),
            });
        }
        Ok(())
    }
}

/// The plant, the drives config and the control platform describe the same robot: cable
/// counts and the drum (the scaling drive-io and this plant both use).
fn check_same_robot(
    drives: &DrivesConfig,
    control: &Platform,
    m: usize,
    files: &ConfigFiles,
) -> Result<(), BusPlantError> {
    if drives.winches.len() != m {
        return Err(BusPlantError::CableCount {
            plant: files.plant.clone(),
            plant_m: m,
            drives: files.drives.clone(),
            drives_m: drives.winches.len(),
        });
    }
    if control.model.m() != m {
        return Err(BusPlantError::ControlCableCount {
            control: files.control.clone(),
            control_m: control.model.m(),
            plant: files.plant.clone(),
            plant_m: m,
        });
    }
    // The drives config's scaling is the one both drive-io and this plant use; a platform
    // whose drum differs would mean the configuration describes two different robots.
    let drum = control.winch.drum_diameter;
    if let Some((index, w)) = drives
        .winches
        .iter()
        .enumerate()
        .find(|(_, w)| (w.drum_diameter_m - drum).abs() > 1e-9 * drum.abs().max(1.0))
    {
        return Err(BusPlantError::DrumDiameter {
            drives: files.drives.clone(),
            index,
            drives_m: w.drum_diameter_m,
            control: files.control.clone(),
            control_m: drum,
        });
    }
    Ok(())
}

/// The set-up tension: the option, else the platform's f_ini, else mid-range.
fn initial_tension(
    opts: &BusOptions,
    control: &Platform,
    m: usize,
) -> Result<Vec<f64>, BusPlantError> {
    let f_ini = match &opts.f_ini_n {
        Some(f) => f.clone(),
        None => control.f_ini.clone().unwrap_or_else(|| {
            let p = control.model.params();
            vec![0.5 * (p.f_min + p.f_max); m]
        }),
    };
    if f_ini.len() != m || f_ini.iter().any(|f| !(f.is_finite() && *f > 0.0)) {
        return Err(BusPlantError::Option {
            name: "f_ini_n",
            reason: format!("need {m} finite forces > 0, got {f_ini:?}"),
        });
    }
    Ok(f_ini)
}

/// The encoders' home lengths: the option, else the control model's φ(x_home).
fn home_lengths(opts: &BusOptions, phi_home: &[f64], m: usize) -> Result<Vec<f64>, BusPlantError> {
    match &opts.home_lengths_m {
        None => Ok(phi_home.to_vec()),
        Some(q) => {
            if q.len() != m || q.iter().any(|l| !l.is_finite()) {
                return Err(BusPlantError::Option {
                    name: "home_lengths_m",
                    reason: format!("need {m} finite lengths (m), got {q:?}"),
                });
            }
            Ok(q.clone())
        }
    }
}

/// The safety I/O node of the layout: its interface, the node, its frames.
type SafetyIo = (usize, SafetyIoNode, FrameBuf);

/// The drive banks, one per CAN interface, and the safety I/O node when the layout has one.
fn drive_banks(
    drives: &DrivesConfig,
    opts: &BusOptions,
    files: &ConfigFiles,
) -> Result<(DriveBanks, Option<SafetyIo>), BusPlantError> {
    // The winches implement the object dictionary of their EDS (drives.toml `winch[i].eds`
    // or `bus.eds`, else the simulated winch's config/eds/crs-winch.eds), one bank of drives
    // per CAN interface; the pulleys' load cells of the `[[force_sensor]]` table report the
    // measured forces too.
    let mut bank =
        DriveBanks::from_config(drives, opts.default_heartbeat_ms).map_err(|source| {
            BusPlantError::Eds {
                drives: files.drives.clone(),
                source,
            }
        })?;
    // With a safety I/O node the drives are real CiA 402 drives: they ignore the monitor's
    // frames and the node removes their torque through STO; without one the simulated
    // drives validate the monitor's heartbeat themselves (their own watch).
    let safety_io = match (
        &drives.safety_io,
        drives.safety_heartbeat,
        drives.safety_io_interface(),
    ) {
        (Some(io), Some(watch), Some(iface)) => {
            bank.set_sto(true);
            Some((iface, SafetyIoNode::new(io, watch), FrameBuf::default()))
        }
        _ => None,
    };
    if let (Some(sw), None) = (drives.safety_heartbeat, &safety_io) {
        // The simulated drives validate the safety monitor's heartbeat (drives.toml
        // `[safety_heartbeat]` without `[safety_io]`): without it they quick-stop and the
        // brakes hold.
        bank.enable_safety_watch(sw);
    }
    Ok((bank, safety_io))
}

/// What one plant cycle did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CycleReport {
    /// The equilibrium was solved this cycle (the held lengths moved by more than ε).
    pub solved: bool,
    /// The last solve found an equilibrium.
    pub converged: bool,
    /// At least one winch is held by its brake.
    pub braked: bool,
}

/// Counters of the plant on the bus.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Winch steps ([`PlantBus::advance`]).
    pub cycles: u64,
    /// Equilibrium solves (held lengths moved by more than ε).
    pub solves: u64,
    /// Solves without equilibrium.
    pub failed_solves: u64,
    /// Drive faults raised for a slack cable / an overloaded cable.
    pub slack_faults: u64,
    pub overload_faults: u64,
}

/// The simulated plant answering as the drives (see the module docs).
pub struct PlantBus {
    plant: Plant,
    winches: Vec<WinchConfig>,
    bank: DriveBanks,
    /// CLOCK_MONOTONIC time of the last SYNC on each interface (its drives interpolate over
    /// the time that really passed since).
    last_sync_ns: Vec<Option<u64>>,
    /// The safety I/O node (drives.toml `[safety_io]`): its interface, the node, its frames.
    safety_io: Option<SafetyIo>,
    /// The operator's devices on the node, set from outside ([`PlantBus::io_inputs`]): bit 0
    /// e-stop button pressed (circuit open), bit 1 reset key turned.
    io_inputs: std::sync::Arc<std::sync::atomic::AtomicU8>,
    /// Winch axes in drive coordinates (what the encoders read, m).
    axes: Vec<CspWinch>,
    q_off: Vec<f64>,
    home_drive: Vec<f64>,
    home: Pose,
    setup: TensionSetup,
    /// Plant commands q_plant = q_drive + q_off of this cycle, m.
    q_cmd: Vec<f64>,
    /// Commands of the last solve attempt (successful or not), m.
    q_solved: Vec<f64>,
    /// Last equilibrium found.
    eq: Equilibrium,
    converged: bool,
    last_error: Option<PlantError>,
    braked: Vec<bool>,
    measured_forces: Vec<f64>,
    prev_pose: Pose,
    truth: PlantTruth,
    tracker: TrackerPose,
    stats: BusStats,
    opts: BusOptions,
}

impl PlantBus {
    /// Builds the plant, sets the initial tension at the control platform's home pose, homes
    /// the encoders (module docs) and settles the plant there. `control` is the model the
    /// controller commands with (usually the plant's nominal platform, `plant.platform`).
    pub fn new(
        plant_cfg: PlantConfig,
        control: &Platform,
        drives: &DrivesConfig,
        opts: BusOptions,
    ) -> Result<Self, BusPlantError> {
        opts.validate()?;
        let files = opts.files.clone();
        let mut plant = Plant::new(plant_cfg).map_err(|source| BusPlantError::Plant {
            plant: files.plant.clone(),
            source,
        })?;
        let m = plant.m();
        check_same_robot(drives, control, m, &files)?;
        let f_ini = initial_tension(&opts, control, m)?;
        let home = control.home;
        // eq. (3.14) / (6.24): q_off = φ̂_el(x_ini, f_ini) − φ(x_ini).
        let setup = plant
            .setup_tension(&home, &f_ini)
            .map_err(|source| BusPlantError::Setup {
                control: files.control.clone(),
                plant: files.plant.clone(),
                source,
            })?;
        let mut data = Data::new(&control.model);
        kinematics::inverse(&control.model, &mut data, &home).map_err(|e| {
            BusPlantError::ControlHome {
                control: files.control.clone(),
                detail: e.to_string(),
            }
        })?;
        let home_drive = home_lengths(&opts, &data.q, m)?;
        let q_off: Vec<f64> = setup
            .q_cmd
            .iter()
            .zip(&home_drive)
            .map(|(qc, phi)| qc - phi)
            .collect();
        for (i, (w, l)) in drives.winches.iter().zip(&home_drive).enumerate() {
            if w.length_to_counts(*l).is_none() {
                return Err(BusPlantError::HomeOutOfRange {
                    drives: files.drives,
                    index: i,
                    cable: i + 1,
                    length: *l,
                    max: w.max_cable_length_m,
                });
            }
        }
        // Settle at home with the set-up command, so the run starts from the set-up state.
        let eq = plant
            .step(&setup.q_cmd)
            .map_err(|source| BusPlantError::Setup {
                control: files.control.clone(),
                plant: files.plant.clone(),
                source,
            })?;
        let (bank, safety_io) = drive_banks(drives, &opts, &files)?;
        let interfaces = bank.interfaces();
        let axes = home_drive
            .iter()
            .map(|l| {
                CspWinch::new(
                    *l,
                    opts.max_cable_speed_m_per_s,
                    opts.max_cable_accel_m_per_s2,
                )
            })
            .collect();
        let truth = PlantTruth {
            version: CONTRACT_VERSION,
            cable_count: m as u32,
            ..PlantTruth::default()
        };
        let mut s = Self {
            plant,
            winches: drives.winches.clone(),
            bank,
            last_sync_ns: vec![None; interfaces],
            safety_io,
            io_inputs: Default::default(),
            axes,
            q_off,
            home_drive,
            home,
            q_cmd: setup.q_cmd.clone(),
            q_solved: setup.q_cmd.clone(),
            setup,
            prev_pose: eq.pose,
            eq,
            converged: true,
            last_error: None,
            braked: vec![true; m],
            measured_forces: vec![0.0; m],
            truth,
            tracker: TrackerPose::default(),
            stats: BusStats::default(),
            opts,
        };
        s.measure_and_report(crs_ipc::monotonic_ns(), 0.0);
        Ok(s)
    }

    pub fn m(&self) -> usize {
        self.axes.len()
    }

    /// Power-on of all drives (boot-up messages queued; send with [`PlantBus::flush`]).
    pub fn start(&mut self, now_ns: u64) {
        self.bank.start(now_ns);
        if let Some((_, node, out)) = self.safety_io.as_mut() {
            node.start(now_ns, out);
        }
        self.apply_sto();
    }

    /// The drives' STO inputs follow the safety I/O node's outputs (hard-wired).
    fn apply_sto(&mut self) {
        if let Some((_, node, _)) = &self.safety_io {
            self.bank.set_sto(!node.sto_released());
        }
    }

    /// The safety I/O node, if the drives config has one (its inputs: e-stop, reset key).
    pub fn safety_io(&self) -> Option<&SafetyIoNode> {
        self.safety_io.as_ref().map(|(_, n, _)| n)
    }
    pub fn safety_io_mut(&mut self) -> Option<&mut SafetyIoNode> {
        self.safety_io.as_mut().map(|(_, n, _)| n)
    }

    /// Handles one frame received on interface `iface` (at `now_ns`, its arrival); true if it
    /// was a SYNC the drives of that interface act on: then move them with
    /// [`PlantBus::advance_interface`] and, once every interface has had its SYNC of the
    /// instant, settle and [`PlantBus::transmit_pdos`].
    pub fn handle_frame(&mut self, iface: usize, frame: &CanFrame, now_ns: u64) -> bool {
        if let Some((io_iface, node, out)) = self.safety_io.as_mut()
            && *io_iface == iface
        {
            node.handle_frame(frame, now_ns, out);
            self.apply_sto();
        }
        self.bank.handle_frame(iface, frame, now_ns)
    }

    /// Number of CAN interfaces the drives are on.
    pub fn interfaces(&self) -> usize {
        self.bank.interfaces()
    }

    /// Moves the winches of interface `iface` for its SYNC received at `sync_ns`: each CSP
    /// drive latched its new target at the SYNC and interpolates towards it over the nominal
    /// period (0x60C2) for the time that REALLY passed since the previous SYNC of the
    /// interface — a late SYNC leaves the winch at its target for the rest of the interval,
    /// an early one cuts the interpolation short, so SYNC jitter shows as motion (velocity
    /// ripple, tracking error) as it does on real drives. Returns that interval, s.
    pub fn advance_interface(&mut self, iface: usize, sync_ns: u64) -> f64 {
        let nominal = self.opts.sync_period_s;
        let dt = match self
            .last_sync_ns
            .get_mut(iface)
            .and_then(|l| l.replace(sync_ns))
        {
            // A first SYNC, or one after a pause (drive-io restarted): one nominal period.
            Some(prev) if sync_ns > prev && ((sync_ns - prev) as f64) * 1e-9 <= 4.0 * nominal => {
                (sync_ns - prev) as f64 * 1e-9
            }
            _ => nominal,
        };
        for i in 0..self.axes.len() {
            if self.bank.interface_of(i) == Some(iface) {
                self.step_winch(i, dt, nominal);
            }
        }
        dt
    }

    /// One plant cycle of `dt_s` seconds at `now_ns` (CLOCK_MONOTONIC, for the payload stamps):
    /// [`PlantBus::advance`] then [`PlantBus::settle`].
    pub fn cycle(&mut self, now_ns: u64, dt_s: f64) -> CycleReport {
        self.advance(dt_s);
        self.settle(now_ns, dt_s)
    }

    /// Moves the winch axes by `dt_s` seconds according to the drives' demand (cheap; call it
    /// at every SYNC, as the drives latch a new target at every SYNC). A non-finite or
    /// negative `dt_s` is treated as 0 (no motion).
    pub fn advance(&mut self, dt_s: f64) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            0.0
        };
        for i in 0..self.axes.len() {
            self.step_winch(i, dt, dt);
        }
        self.stats.cycles += 1;
    }

    /// One winch for `dt` seconds; a following drive interpolates its target over `interp`.
    fn step_winch(&mut self, i: usize, dt: f64, interp: f64) {
        let w = &self.winches[i];
        let ax = &mut self.axes[i];
        match self.bank.demand(i) {
            MotionDemand::Follow { target_counts } => {
                if dt > 0.0 {
                    // Software position limits of the drive: never beyond the drum range.
                    let t = w
                        .counts_to_length(target_counts)
                        .clamp(0.0, w.max_cable_length_m);
                    ax.follow_interpolated(t, interp, dt);
                }
                self.braked[i] = false;
            }
            MotionDemand::QuickStop => {
                if dt > 0.0 {
                    ax.quick_stop(dt);
                }
                // Decelerated to rest: the brake holds (quick stop option code 6).
                self.braked[i] = ax.velocity_m_per_s == 0.0;
            }
            MotionDemand::Hold => {
                ax.hold();
                self.braked[i] = true;
            }
        }
        self.q_cmd[i] = ax.length_m + self.q_off[i];
    }

    /// Settles the platform for the lengths the winches hold now (the equilibrium is solved
    /// only if they moved by more than ε since the last solve), reads the sensors and updates
    /// the drives' actual values and the payloads. `dt_s` = time since the last settle (for
    /// the tracker's pose velocity).
    pub fn settle(&mut self, now_ns: u64, dt_s: f64) -> CycleReport {
        let moved = self
            .q_cmd
            .iter()
            .zip(&self.q_solved)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let solved = moved > self.opts.resolve_epsilon_m;
        if solved {
            self.q_solved.copy_from_slice(&self.q_cmd);
            self.stats.solves += 1;
            match self.plant.step(&self.q_cmd) {
                Ok(eq) => {
                    if !self.converged {
                        tracing::info!("plant equilibrium found again");
                    }
                    self.eq = eq;
                    self.converged = true;
                    self.last_error = None;
                }
                Err(e) => {
                    self.stats.failed_solves += 1;
                    if self.converged {
                        tracing::error!(
                            error = %e,
                            lengths_m = ?self.q_cmd,
                            "plant has no equilibrium for the held cable lengths; reporting the \
                             last equilibrium with converged = 0"
                        );
                    }
                    self.converged = false;
                    self.last_error = Some(e);
                }
            }
        }
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            0.0
        };
        self.measure_and_report(now_ns, dt);
        CycleReport {
            solved,
            converged: self.converged,
            braked: self.truth.braked != 0,
        }
    }

    /// Sensor readings of the current equilibrium into the drives' actual values and payloads.
    fn measure_and_report(&mut self, now_ns: u64, dt: f64) {
        let reading = self.plant.measure(&self.eq);
        let braked = self.braked.iter().any(|b| *b);
        for i in 0..self.axes.len() {
            let w = &self.winches[i];
            let ax = &self.axes[i];
            let counts = counts_saturating(w, ax.length_m);
            self.measured_forces[i] = reading.forces[i];
            // The drive supervises its own force sensor while it holds the cable under
            // control: slack or beyond the rating => drive fault, visible on the bus as EMCY
            // and the statusword's fault bit (drive-io stops all drives on either).
            let enabled = self
                .bank
                .slave(i)
                .is_some_and(|s| s.ds402_state() == Ds402State::OperationEnabled);
            if enabled {
                let f = reading.forces[i];
                // (a NaN reading counts as slack: the drive cannot vouch for the cable)
                if f.is_nan() || f < self.opts.slack_fault_n {
                    tracing::error!(
                        cable = i + 1,
                        force_n = f,
                        "plant: slack cable, drive fault"
                    );
                    self.stats.slack_faults += 1;
                    self.bank.raise_fault(i, EMCY_CABLE_SLACK);
                } else if f > self.opts.overload_fault_n {
                    tracing::error!(
                        cable = i + 1,
                        force_n = f,
                        "plant: cable overload, drive fault"
                    );
                    self.stats.overload_faults += 1;
                    self.bank.raise_fault(i, EMCY_CABLE_OVERLOAD);
                }
            }
            let force_mn = (reading.forces[i] * 1000.0)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
            self.bank.set_actual(
                i,
                counts,
                w.m_per_s_to_counts_per_s(ax.velocity_m_per_s),
                force_mn,
            );
        }
        let t = &mut self.truth;
        t.sequence += 1;
        t.timestamp_ns = now_ns;
        t.pose = self.eq.pose.to_array();
        let m = self.axes.len().min(MAX_CABLES);
        t.force_n[..m].copy_from_slice(&self.eq.forces[..m]);
        t.cable_length_m[..m].copy_from_slice(&self.q_cmd[..m]);
        t.converged = u32::from(self.converged);
        t.braked = u32::from(braked);
        let tr = &mut self.tracker;
        tr.sequence += 1;
        tr.timestamp_ns = now_ns;
        tr.valid = u32::from(self.converged);
        tr.pose = reading.pose.to_array();
        let (p, q) = (self.eq.pose.to_array(), self.prev_pose.to_array());
        for k in 0..6 {
            tr.pose_velocity[k] = if dt > 0.0 { (p[k] - q[k]) / dt } else { 0.0 };
        }
        self.prev_pose = self.eq.pose;
    }

    /// TPDO1 + TPDO2 of every operational drive (after the cycle of a SYNC).
    pub fn transmit_pdos(&mut self) {
        self.bank.transmit_pdos();
    }

    /// TPDOs of the drives on interface `iface`.
    pub fn transmit_pdos_on(&mut self, iface: usize) {
        self.bank.transmit_pdos_on(iface);
    }

    /// The safety I/O node's inputs as the operator sets them (bit 0 e-stop pressed, bit 1
    /// reset key turned; 0 = at rest): another thread writes them (sim-plant's `--io-control`),
    /// [`PlantBus::poll`] applies them.
    pub fn io_inputs(&self) -> std::sync::Arc<std::sync::atomic::AtomicU8> {
        self.io_inputs.clone()
    }

    /// Heartbeats when due; the safety I/O node's inputs, validation time and TPDO.
    pub fn poll(&mut self, now_ns: u64) {
        if let Some((_, node, out)) = self.safety_io.as_mut() {
            let i = self.io_inputs.load(std::sync::atomic::Ordering::Acquire);
            node.set_inputs(i & 1 == 0, i & 2 != 0);
            node.poll(now_ns, out);
        }
        self.apply_sto();
        self.bank.poll(now_ns);
    }

    /// Earliest heartbeat due time of all drives (CLOCK_MONOTONIC ns), if any drive produces one.
    pub fn next_heartbeat_ns(&self) -> Option<u64> {
        let io = self.safety_io.as_ref().map(|(_, n, _)| n.next_due_ns());
        match (self.bank.next_heartbeat_ns(), io) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Sends the queued frames of every interface on its bus (`buses[k]` = interface k; a full
    /// TX queue drops frames, as a CAN controller would).
    pub fn flush<B: CanBus>(&mut self, buses: &mut [B]) -> Result<(), CanError> {
        self.bank.flush(buses)?;
        if let Some((iface, _, out)) = self.safety_io.as_mut() {
            let r = match buses.get_mut(*iface) {
                Some(bus) => out.as_slice().iter().try_for_each(|f| match bus.send(f) {
                    Ok(()) | Err(CanError::TxFull { .. }) => Ok(()),
                    Err(e) => Err(e),
                }),
                None => Ok(()),
            };
            out.clear();
            r?;
        }
        Ok(())
    }

    /// The drives (for fault injection and state inspection).
    pub fn drives(&self) -> &DriveBanks {
        &self.bank
    }
    pub fn drives_mut(&mut self) -> &mut DriveBanks {
        &mut self.bank
    }

    /// Ground truth of the last cycle (iceoryx2 `crs/v1/plant_truth`). `cable_length_m` holds
    /// the PLANT commands q_plant = q_drive + q_off; `force_n` the true forces.
    pub fn truth(&self) -> &PlantTruth {
        &self.truth
    }
    /// Tracker reading of the last cycle (iceoryx2 `crs/v1/tracker_pose`): the true pose with
    /// the plant's tracker noise; `pose_velocity` is the finite difference of the true pose
    /// coordinates over the cycle; `valid` = converged.
    pub fn tracker(&self) -> &TrackerPose {
        &self.tracker
    }
    /// Force-sensor readings reported in the last TPDOs, N.
    pub fn measured_forces(&self) -> &[f64] {
        &self.measured_forces
    }
    /// The last equilibrium found.
    pub fn equilibrium(&self) -> &Equilibrium {
        &self.eq
    }
    pub fn converged(&self) -> bool {
        self.converged
    }
    /// Why the last solve failed (None while it converges).
    pub fn last_error(&self) -> Option<&PlantError> {
        self.last_error.as_ref()
    }
    /// Cable offsets q_off = q̂_ini − q_home, m (module docs).
    pub fn q_off(&self) -> &[f64] {
        &self.q_off
    }
    /// The set-up of the initial tension (plant commands and forces at the home pose).
    pub fn setup(&self) -> &TensionSetup {
        &self.setup
    }
    /// q_home: the drive lengths at start (φ(x_ini) of the control model unless
    /// [`BusOptions::home_lengths_m`] says otherwise), m.
    pub fn home_drive_lengths(&self) -> &[f64] {
        &self.home_drive
    }
    pub fn home(&self) -> &Pose {
        &self.home
    }
    /// Cable length winch `i` holds in drive coordinates (encoder reading), m.
    pub fn drive_length_m(&self, i: usize) -> Option<f64> {
        self.axes.get(i).map(|a| a.length_m)
    }
    /// Plant commands of the last cycle, m.
    pub fn plant_lengths(&self) -> &[f64] {
        &self.q_cmd
    }
    pub fn plant(&self) -> &Plant {
        &self.plant
    }
    pub fn stats(&self) -> BusStats {
        self.stats
    }
    pub fn options(&self) -> &BusOptions {
        &self.opts
    }
}

/// A winch in cyclic synchronous position mode (SI, drive coordinates).
///
/// A CSP drive receives a new target every SYNC period and moves so that it is there at the
/// end of the period; the speed it needs follows from consecutive targets (velocity
/// feed-forward), so a smooth target stream is followed without lag. A position error left
/// over (start of following, a jump of the target, the limits) is removed with the largest
/// speed from which the winch can still stop at the target (≈ √(2 a |e|)), so a far target
/// is approached without overshoot. Speed and acceleration are limited throughout.
/// (drive-io's `WinchAxis` test double treats every target as a stop point, which lags a
/// moving target by v²/2a: 80 mm at 1.5 m/s.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CspWinch {
    pub length_m: f64,
    pub velocity_m_per_s: f64,
    pub max_speed_m_per_s: f64,
    pub max_accel_m_per_s2: f64,
    /// Target of the previous SYNC period while following (None after a hold or quick stop).
    prev_target_m: Option<f64>,
}

impl CspWinch {
    pub fn new(length_m: f64, max_speed_m_per_s: f64, max_accel_m_per_s2: f64) -> Self {
        Self {
            length_m,
            velocity_m_per_s: 0.0,
            max_speed_m_per_s,
            max_accel_m_per_s2,
            prev_target_m: None,
        }
    }

    /// One period `dt` (> 0) towards `target_m`, the target latched at this SYNC.
    pub fn follow(&mut self, target_m: f64, dt: f64) {
        let prev = self.prev_target_m.unwrap_or(target_m);
        self.follow_from(prev, target_m, dt);
    }

    /// Moves over `dt` from the reference `prev` towards `target_m` (velocity feed-forward
    /// plus the bounded correction of the error left at `prev`).
    fn follow_from(&mut self, prev: f64, target_m: f64, dt: f64) {
        self.prev_target_m = Some(target_m);
        let a = self.max_accel_m_per_s2;
        let v_ff = (target_m - prev) / dt;
        // Error to the previous target (what is left over from the last periods).
        let e = prev - self.length_m;
        // Largest speed from which the discrete braking (−a·dt per period) still stops at the
        // target: (v/(a dt))·(v/(a dt) + 1)/2 · a dt² ≤ |e|, i.e. the continuous √(2 a |e|)
        // less half a period's speed change; and never more than the rest in one period.
        let h = 0.5 * a * dt;
        let v_stop = (h * h + 2.0 * a * e.abs()).sqrt() - h;
        let v_corr = (e.abs() / dt).min(v_stop).copysign(e);
        let v_des = (v_ff + v_corr).clamp(-self.max_speed_m_per_s, self.max_speed_m_per_s);
        self.velocity_m_per_s += (v_des - self.velocity_m_per_s).clamp(-a * dt, a * dt);
        self.length_m += self.velocity_m_per_s * dt;
    }

    /// The SYNC latched `target_m`; the drive interpolates from its previous target to it over
    /// `interp` (its interpolation period, 0x60C2) and the motor follows that reference for
    /// `dt` (the time until the next SYNC really came): with `dt` = `interp` this is
    /// [`CspWinch::follow`]; over a longer interval the winch arrives at the target only at its
    /// end (slower on average), a shorter one stops part-way (the next interpolation starts
    /// from there).
    pub fn follow_interpolated(&mut self, target_m: f64, interp: f64, dt: f64) {
        let prev = self.prev_target_m.unwrap_or(target_m);
        let reached = if interp > 0.0 {
            (dt / interp).min(1.0)
        } else {
            1.0
        };
        self.follow_from(prev, prev + (target_m - prev) * reached, dt);
    }

    /// Quick stop: decelerate at the maximum deceleration to rest.
    pub fn quick_stop(&mut self, dt: f64) {
        self.prev_target_m = None;
        let a = self.max_accel_m_per_s2 * dt;
        self.velocity_m_per_s -= self.velocity_m_per_s.clamp(-a, a);
        self.length_m += self.velocity_m_per_s * dt;
    }

    /// Brake: the drum stops at once.
    pub fn hold(&mut self) {
        self.prev_target_m = None;
        self.velocity_m_per_s = 0.0;
    }
}

/// Encoder counts of a cable length with drive-io's scaling, saturated to the i32 range of
/// 0x6064 (a quick stop near the end of the range may overshoot it).
fn counts_saturating(w: &WinchConfig, length_m: f64) -> i32 {
    (w.offset_counts as f64 + f64::from(w.sign) * length_m * w.counts_per_m())
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

// ---------------------------------------------------------------------------------------------
// Process loop

/// Frames handled at most before the plant settles (a flooded bus cannot stall the physics).
const MAX_DRAIN: usize = 1024;

/// Summary of [`run`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoopSummary {
    /// SYNCs acted on (one winch step of the SYNC period each).
    pub syncs: u64,
    /// Equilibria settled after SYNCs; fewer than `syncs` when the plant fell behind and
    /// several SYNCs were waiting (their winch steps are all made, the platform settles once).
    pub sync_settles: u64,
    /// Free-running cycles (no SYNC on the bus).
    pub free_cycles: u64,
    /// Free-running deadlines missed by more than a period (host not real time).
    pub overruns: u64,
    pub frames_received: u64,
    pub stats: BusStats,
}

/// Runs the plant on `buses` (`buses[k]` = CAN interface k of the drives config) until `stop`
/// is set.
///
/// At each SYNC the drives of its interface latch their targets and their winches move over
/// the time since that interface's previous SYNC ([`PlantBus::advance_interface`]). drive-io
/// sends the SYNC on every interface at the same instant; once each interface has had its SYNC
/// of the instant (or `SYNC_GATHER` after the first, if one is missing), the platform settles
/// once and every drive's TPDOs go out. With a solver slower than the SYNC period (e.g. an
/// unoptimised build), SYNCs that queued up are all applied to the winches and the platform
/// settles once, so the winch motion stays exact and the plant answers at a lower rate instead
/// of falling ever further behind. While no SYNC arrives for three SYNC periods (drive-io not
/// started, or stopped) the plant runs free every `period` (no TPDOs), so the ground truth
/// keeps flowing and quick stops complete. After every settle `publish` gets the truth and the
/// tracker reading. Bus errors other than a full TX queue end the loop.
pub fn run<B: CanBus>(
    buses: &mut [B],
    plant: &mut PlantBus,
    period: Duration,
    stop: &AtomicBool,
    mut publish: impl FnMut(&PlantTruth, &TrackerPose),
) -> Result<LoopSummary, CanError> {
    let period_ns = (period.as_nanos() as u64).max(1);
    let period_s = period_ns as f64 * 1e-9;
    let sync_s = plant.options().sync_period_s;
    let quiet_ns = ((3.0 * sync_s * 1e9) as u64).max(period_ns);
    // How long the SYNCs of one instant may arrive apart on the interfaces (drive-io sends them
    // back to back; a quarter period covers its sends and the wire's arbitration).
    let gather_ns = ((0.25 * sync_s * 1e9) as u64).max(1);
    let n_itf = plant.interfaces().max(1);
    let mut summary = LoopSummary::default();
    let now = crs_ipc::monotonic_ns();
    plant.start(now);
    let mut next_free = now + period_ns;
    let mut last_settle = now;
    // Interfaces whose SYNC of the current instant was handled, and when the first came.
    let mut synced = vec![false; n_itf];
    let mut first_sync_ns: Option<u64> = None;
    let mut cursor = 0usize;
    publish(plant.truth(), plant.tracker());
    while !stop.load(Ordering::Relaxed) {
        plant.flush(buses)?;
        let now = crs_ipc::monotonic_ns();
        let mut due = plant
            .next_heartbeat_ns()
            .map_or(next_free, |h| h.min(next_free));
        if let Some(t) = first_sync_ns {
            due = due.min(t + gather_ns);
        }
        let mut rx = can_transport::recv_any(
            buses,
            Duration::from_nanos(due.saturating_sub(now)),
            &mut cursor,
        )?;
        let mut syncs = 0u64;
        let mut handled = 0;
        while let Some((iface, ev)) = rx {
            handled += 1;
            if let can_transport::RxEvent::Frame(f) = ev {
                summary.frames_received += 1;
                if plant.handle_frame(iface, &f.frame, f.rx_monotonic_ns) {
                    // The drives latched new targets: move the winches over this SYNC period
                    // now, before a later RPDO in the queue replaces the pending target.
                    plant.advance_interface(iface, f.rx_monotonic_ns);
                    syncs += 1;
                    if let Some(s) = synced.get_mut(iface) {
                        *s = true;
                    }
                    first_sync_ns.get_or_insert(f.rx_monotonic_ns);
                }
            }
            if handled >= MAX_DRAIN {
                break;
            }
            rx = can_transport::recv_any(buses, Duration::ZERO, &mut cursor)?;
        }
        let now = crs_ipc::monotonic_ns();
        summary.syncs += syncs;
        let instant_complete =
            synced.iter().all(|s| *s) || first_sync_ns.is_some_and(|t| now >= t + gather_ns);
        if first_sync_ns.is_some() && instant_complete {
            plant.settle(now, (now - last_settle) as f64 * 1e-9);
            plant.transmit_pdos();
            publish(plant.truth(), plant.tracker());
            last_settle = now;
            summary.sync_settles += 1;
            next_free = now + quiet_ns;
            synced.iter_mut().for_each(|s| *s = false);
            first_sync_ns = None;
        } else if first_sync_ns.is_none() && now >= next_free {
            plant.advance(period_s);
            plant.settle(now, (now - last_settle) as f64 * 1e-9);
            publish(plant.truth(), plant.tracker());
            last_settle = now;
            summary.free_cycles += 1;
            next_free += period_ns;
            if next_free <= now {
                // Fell behind (non-real-time host): re-anchor instead of bursting cycles.
                summary.overruns += 1;
                next_free = now + period_ns;
            }
        }
        plant.poll(now);
    }
    plant.flush(buses)?;
    summary.stats = plant.stats();
    Ok(summary)
}
