//! Motion cueing as the stack's motion source (`crs sim --source cueing --vehicle FILE.csv`):
//! the [`motion_cueing`] washout runs at 1 kHz on its own thread of the launcher — off
//! motion-core's hard loop, in another process — and publishes on motion-core's cueing input
//! (`crs/v1/cueing_pose`, motion-core started with `--input cueing`) the target that makes
//! motion-core's velocity/acceleration-limited tracker move along the cueing pose
//! ([`motion_cueing::washout::tracker_target`]); the loop's checks (region, limits, dynamic
//! wrench feasibility) and the safety monitor take it like any reference. The cabin moves from
//! home to the washout's neutral pose, drives, settles and moves back; then the source falls
//! silent and motion-core exits after `--hold-s`.
//!
//! The launcher keeps motion-core's setpoints (pose and pose rates, per sequence number); after
//! the run the rider's specific force and angular velocity are computed from that reference
//! and compared with the vehicle's through the vestibular models
//! ([`motion_cueing::perception`]): the summary's `cueing` block, `cueing-perception.svg` and
//! `cueing-motion.svg` next to it.

use cdpr_model::Pose;
use cdpr_model::config::Platform;
use crs_ipc::{CueingPose, IpcNode, JointSetpoint};
use motion_core::daemon::lifecycle::Configured;
use motion_cueing::cabin::felt;
use motion_cueing::perception::{PerceptionReport, analyse};
use motion_cueing::settings::{Feasibility, SettingsError};
use motion_cueing::source::{CueingSource, Phase};
use motion_cueing::vehicle::VehicleError;
use motion_cueing::{CueingSettings, TrackerLimits, VehicleTrack, Washout};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What `crs sim --source cueing` runs.
#[derive(Clone, Debug, PartialEq)]
pub struct CueingSpec {
    /// The cueing TOML (scaling, washout, tilt, workspace, perception).
    pub settings: PathBuf,
    /// The vehicle CSV ([`motion_cueing::vehicle`]).
    pub vehicle: PathBuf,
}

/// Why the cueing could not be prepared, run or reported.
#[derive(Debug, thiserror::Error)]
pub enum CueingError {
    /// The cueing TOML, or a tuning the platform cannot fly (names the file and key).
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The vehicle CSV (names the file, line and column).
    #[error(transparent)]
    Vehicle(#[from] VehicleError),
    /// A limit of the cueing above what motion-core's tracker follows.
    #[error(
        "{file}: `{key}` = {value:.4} (SI) exceeds motion-core's cueing tracker limit {tracker:.4} (its [trajectory] scales of table 5.1, with the dynamic wrench): the tracker would not follow the cueing"
    )]
    AboveTracker {
        file: String,
        key: &'static str,
        value: f64,
        tracker: f64,
    },
    #[error(
        "--source cueing drives the vehicle profile: --waypoints, --dwell-s, --record and --pilot belong to other sources"
    )]
    WithOtherSource,
    /// The source thread's iceoryx2 node or publisher.
    #[error(transparent)]
    Ipc(#[from] crs_ipc::IpcError),
    #[error("cannot start the cueing thread: {0}")]
    Spawn(#[source] std::io::Error),
    #[error("the cueing thread panicked")]
    Panicked,
    /// The vestibular models could not be built (bad time constants).
    #[error("perception models: {0}")]
    Perception(#[from] motion_cueing::lti::LtiError),
    /// Writing a figure.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The validated cueing, checked before anything starts.
pub struct PreparedCueing {
    pub settings: CueingSettings,
    /// The washout for motion-core's tracker (its box shrunk for the tracker lead) and as
    /// configured (the box the workspace use is measured against).
    pub washout: Washout,
    pub configured_washout: Washout,
    pub track: VehicleTrack,
    pub tracker: TrackerLimits,
    pub feasibility: Feasibility,
    pub home: Pose,
    pub describe: String,
    pub settings_file: PathBuf,
}

/// The source's sample period, s (the washout is discretised for it).
pub const DT_S: f64 = 1e-3;

/// Loads the cueing TOML for `platform` (refused when the platform cannot fly it), the
/// vehicle CSV, and checks the cueing's limits against motion-core's tracker (`configured`).
pub fn prepare(
    spec: &CueingSpec,
    platform: &Platform,
    configured: &Configured,
) -> Result<PreparedCueing, CueingError> {
    let file = spec.settings.display().to_string();
    let settings = CueingSettings::load(&spec.settings)?;
    let (washout, feasibility) = settings.washout(platform, DT_S, &file)?;
    let pl = configured.planner_limits();
    let ws = &settings.washout.workspace;
    for (key, value, tracker) in [
        (
            "workspace.linear_velocity_max_m_per_s",
            ws.linear_velocity_max,
            pl.linear_velocity,
        ),
        (
            "workspace.linear_acceleration_max_m_per_s2",
            ws.linear_acceleration_max,
            pl.linear_acceleration,
        ),
        (
            "workspace.angular_velocity_max_deg_per_s",
            ws.angular_velocity_max,
            pl.angular_velocity,
        ),
        (
            "workspace.angular_acceleration_max_deg_per_s2",
            ws.angular_acceleration_max,
            pl.angular_acceleration,
        ),
    ] {
        if value > tracker {
            return Err(CueingError::AboveTracker {
                file: file.clone(),
                key,
                value,
                tracker,
            });
        }
    }
    let track = VehicleTrack::read_csv(&spec.vehicle)?;
    let tracker = TrackerLimits {
        linear_acceleration: pl.linear_acceleration,
        angular_acceleration: pl.angular_acceleration,
        period_s: configured.period_s(),
        lead_s: settings.tracker_lead_s,
    };
    let configured_washout = washout.clone();
    let washout = washout.for_tracker(&tracker);
    Ok(PreparedCueing {
        configured_washout,
        describe: format!(
            "{} ({:.1} s) with {}",
            spec.vehicle.display(),
            track.duration_s(),
            spec.settings.display()
        ),
        tracker,
        settings,
        washout,
        track,
        feasibility,
        home: platform.home,
        settings_file: spec.settings.clone(),
    })
}

/// What the cueing did (the summary's `cueing` block).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CueingSummary {
    pub source: String,
    /// The vehicle track's length and the whole run's (to neutral, drive, settle, home), s.
    pub drive_s: f64,
    pub run_s: f64,
    /// Largest tilt-coordination rate, °/s, and its threshold.
    pub max_tilt_rate_deg_per_s: f64,
    pub tilt_rate_threshold_deg_per_s: f64,
    /// Steps in which the workspace limiter departed from the washout's demand.
    pub limited_steps: u64,
    /// Largest excursion of motion-core's reference from the neutral pose per coordinate
    /// while driving, as a share of the cueing box's half-width on that side (1 = its edge).
    pub workspace_use: [f64; 6],
    /// The platform check of the cueing box (grid poses, static margin, acceleration scale).
    pub feasibility: Option<Feasibility>,
    /// Source steps later than 1 ms after their deadline (the thread's own timing).
    pub late_steps: u64,
    /// Setpoints missing from the launcher's record of the drive (sequence gaps; held over).
    pub missing_setpoints: u64,
    /// Vehicle vs cabin (motion-core's reference) vs perceived, per axis; None when the run
    /// recorded no setpoint of the drive.
    pub perception: Option<PerceptionReport>,
    pub perception_svg: Option<PathBuf>,
    pub motion_svg: Option<PathBuf>,
}

/// What the source thread hands back.
struct ThreadResult {
    t0_ns: u64,
    /// Run time (s since t0) at which the drive phase started and ended.
    drive_start_s: f64,
    drive_end_s: f64,
    run_s: f64,
    late_steps: u64,
    max_tilt_rate: f64,
    limited_steps: u64,
    /// Every 10th drive sample.
    plot: Vec<PlotPoint>,
}

/// One drive sample for the motion figure: run time, washout demand, cueing pose, tilt.
struct PlotPoint {
    t_s: f64,
    desired: [f64; 6],
    pose: [f64; 6],
    tilt: [f64; 2],
}

/// The source thread: its stop flag and handle.
type SourceThread = (
    Arc<AtomicBool>,
    std::thread::JoinHandle<Result<ThreadResult, CueingError>>,
);

/// The cueing of one run: prepared, then running on its thread, then reported.
pub struct CueingRun {
    prepared: Option<PreparedCueing>,
    thread: Option<SourceThread>,
    /// motion-core's setpoints: (sequence, timestamp, pose, pose rates).
    setpoints: Vec<(u64, u64, [f64; 6], [f64; 6])>,
    washout: Washout,
    settings: CueingSettings,
    track: VehicleTrack,
    feasibility: Feasibility,
    describe: String,
}

impl CueingRun {
    pub fn new(p: PreparedCueing) -> Self {
        Self {
            washout: p.configured_washout.clone(),
            settings: p.settings.clone(),
            track: p.track.clone(),
            feasibility: p.feasibility,
            describe: p.describe.clone(),
            prepared: Some(p),
            thread: None,
            setpoints: Vec::new(),
        }
    }

    /// Records one of motion-core's setpoints.
    pub fn setpoint(&mut self, sp: &JointSetpoint) {
        if self.thread.is_some() {
            self.setpoints
                .push((sp.sequence, sp.timestamp_ns, sp.pose, sp.pose_velocity));
        }
    }

    /// Starts the source on the run's iceoryx2 prefix (once, when motion-core's first setpoint
    /// showed its cueing subscriber is up).
    pub fn start(&mut self, prefix: &str) -> Result<(), CueingError> {
        let Some(p) = self.prepared.take() else {
            return Ok(());
        };
        println!(
            "  motion cueing (classical washout, tilt coordination) driving {} on motion-core's cueing input",
            p.describe
        );
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let prefix = prefix.to_string();
        let handle = std::thread::Builder::new()
            .name("crs-cueing".into())
            .spawn(move || drive(p, &prefix, &s))
            .map_err(CueingError::Spawn)?;
        self.thread = Some((stop, handle));
        Ok(())
    }

    pub fn started(&self) -> bool {
        self.thread.is_some()
    }

    /// Stops the source (if still running), analyses the drive against motion-core's
    /// reference and writes the figures into `out`.
    pub fn finish(
        mut self,
        out: &Path,
        loop_period_s: f64,
    ) -> Result<Option<CueingSummary>, CueingError> {
        let Some((stop, handle)) = self.thread.take() else {
            return Ok(None);
        };
        stop.store(true, Ordering::Relaxed);
        let r = handle.join().map_err(|_| CueingError::Panicked)??;
        let mut sum = CueingSummary {
            source: self.describe.clone(),
            drive_s: self.track.duration_s(),
            run_s: r.run_s,
            max_tilt_rate_deg_per_s: r.max_tilt_rate.to_degrees(),
            tilt_rate_threshold_deg_per_s: self.settings.washout.tilt.rate_max.to_degrees(),
            limited_steps: r.limited_steps,
            feasibility: Some(self.feasibility),
            late_steps: r.late_steps,
            ..CueingSummary::default()
        };
        // The drive's setpoints on a uniform grid of sequence numbers (a sequence gap repeats
        // the sample after it; the acceleration across it is the mean).
        let in_drive = |ts: u64| {
            let t = ts.saturating_sub(r.t0_ns) as f64 * 1e-9;
            t >= r.drive_start_s && t <= r.drive_end_s
        };
        let sps: Vec<_> = self
            .setpoints
            .iter()
            .filter(|s| in_drive(s.1))
            .copied()
            .collect();
        let head = self.settings.washout.head_m;
        let mut samples = Vec::new();
        let mut refs = Vec::new();
        let mut prev: Option<(u64, [f64; 6])> = None;
        for (seq, ts, pose, vel) in &sps {
            let acc: [f64; 6] = match prev {
                Some((ps, pv)) if *seq > ps => {
                    sum.missing_setpoints += seq - ps - 1;
                    let dt = (seq - ps) as f64 * loop_period_s;
                    std::array::from_fn(|k| (vel[k] - pv[k]) / dt)
                }
                _ => [0.0; 6],
            };
            let held = prev.map_or(1, |(ps, _)| seq.saturating_sub(ps).max(1));
            prev = Some((*seq, *vel));
            let t_drive = ts.saturating_sub(r.t0_ns) as f64 * 1e-9 - r.drive_start_s;
            let veh = self.track.at(self.track.start_s() + t_drive).unwrap_or(
                motion_cueing::VehicleSample::at_rest(self.settings.washout.gravity),
            );
            let f = felt(&Pose::from_array(*pose), vel, &acc, &head);
            for _ in 0..held {
                samples.push((t_drive, veh, f));
            }
            refs.push(*pose);
        }
        sum.workspace_use = motion_cueing::washout::workspace_use(&self.washout, &refs);
        if !samples.is_empty() {
            let (rep, series) = analyse(&self.settings.perception, loop_period_s, samples)?;
            let svg = motion_cueing::plot::perception_svg(
                &format!(
                    "{}: vehicle vs cabin (motion-core's reference) vs perceived",
                    self.describe
                ),
                &series,
                &rep,
            );
            let p = out.join("cueing-perception.svg");
            std::fs::write(&p, svg).map_err(|source| CueingError::Write {
                path: p.clone(),
                source,
            })?;
            sum.perception_svg = Some(p);
            sum.perception = Some(rep);
        }
        // The reference against the washout's demand and the box.
        let t: Vec<f64> = r.plot.iter().map(|p| p.t_s - r.drive_start_s).collect();
        let desired: Vec<[f64; 6]> = r.plot.iter().map(|p| p.desired).collect();
        let reference: Vec<[f64; 6]> = r
            .plot
            .iter()
            .map(|p| {
                // The setpoint closest in time to the plot sample (motion-core's reference).
                let ts = r.t0_ns + (p.t_s * 1e9) as u64;
                let k = sps.partition_point(|s| s.1 < ts);
                sps.get(k).or(sps.last()).map_or(p.pose, |s| s.2)
            })
            .collect();
        let tilt: Vec<[f64; 2]> = r.plot.iter().map(|p| p.tilt).collect();
        let svg = motion_cueing::plot::motion_svg(
            &format!(
                "{}: motion-core's reference (blue) in the cueing box (red)",
                self.describe
            ),
            &t,
            &desired,
            &reference,
            &tilt,
            &self.washout.box_min,
            &self.washout.box_max,
        );
        let p = out.join("cueing-motion.svg");
        std::fs::write(&p, svg).map_err(|source| CueingError::Write {
            path: p.clone(),
            source,
        })?;
        sum.motion_svg = Some(p);
        Ok(Some(sum))
    }
}

/// The source thread: the 1 kHz loop with absolute deadlines publishing the tracker target.
fn drive(p: PreparedCueing, prefix: &str, stop: &AtomicBool) -> Result<ThreadResult, CueingError> {
    let node = IpcNode::with_prefix("crs-cueing", prefix)?;
    let publisher = node.publisher::<CueingPose>()?;
    let tracker = p.tracker;
    let mut src = CueingSource::new(p.washout, &p.settings, p.track, p.home);
    let mut r = ThreadResult {
        t0_ns: crs_ipc::monotonic_ns(),
        drive_start_s: f64::NAN,
        drive_end_s: f64::NAN,
        run_s: 0.0,
        late_steps: 0,
        max_tilt_rate: 0.0,
        limited_steps: 0,
        plot: Vec::new(),
    };
    let t0 = Instant::now();
    let mut k: u64 = 0;
    while !stop.load(Ordering::Relaxed) {
        let Some(s) = src.next_sample() else { break };
        let target = src.tracker_target(&s, &tracker);
        let _ = publisher.publish(&CueingPose::new(target, k + 1));
        if s.phase == Phase::Drive {
            if r.drive_start_s.is_nan() {
                r.drive_start_s = s.t_s;
            }
            r.drive_end_s = s.t_s;
            r.max_tilt_rate = r
                .max_tilt_rate
                .max(s.cue.tilt_rate[0].abs())
                .max(s.cue.tilt_rate[1].abs());
            if k.is_multiple_of(10) {
                r.plot.push(PlotPoint {
                    t_s: s.t_s,
                    desired: s.cue.desired,
                    pose: s.cue.pose,
                    tilt: s.cue.tilt,
                });
            }
        }
        r.run_s = s.t_s;
        k += 1;
        let deadline = t0 + Duration::from_secs_f64(k as f64 * DT_S);
        let now = Instant::now();
        if now < deadline {
            std::thread::sleep(deadline - now);
        } else if now - deadline > Duration::from_secs_f64(DT_S) {
            r.late_steps += 1;
        }
    }
    r.limited_steps = src.state().limited_steps;
    Ok(r)
}

/// The summary line of `crs sim`.
pub fn print_summary(c: &CueingSummary) {
    println!(
        "  motion cueing ({}): {:.1} s driven ({:.1} s with the moves to and from neutral), tilt rate ≤ {:.2}°/s (threshold {:.1}°/s), limiter active {} steps, workspace use x {:.0} % y {:.0} % z {:.0} % roll {:.0} % pitch {:.0} % yaw {:.0} %, {} late source steps, {} setpoints missing",
        c.source,
        c.drive_s,
        c.run_s,
        c.max_tilt_rate_deg_per_s,
        c.tilt_rate_threshold_deg_per_s,
        c.limited_steps,
        c.workspace_use[0] * 100.0,
        c.workspace_use[1] * 100.0,
        c.workspace_use[2] * 100.0,
        c.workspace_use[3] * 100.0,
        c.workspace_use[4] * 100.0,
        c.workspace_use[5] * 100.0,
        c.late_steps,
        c.missing_setpoints
    );
    match &c.perception {
        Some(p) => {
            let corr = |x: Option<f64>| x.map_or("–".to_string(), |x| format!("{x:.2}"));
            let f = &p.specific_force;
            let w = &p.angular_velocity;
            println!(
                "  perceived (vehicle vs cabin): f_x RMS error {:.3} m/s² corr. {}, f_y {:.3} corr. {}, ω_x {:.2}°/s corr. {}, ω_y {:.2}°/s corr. {}, ω_z {:.2}°/s corr. {}{}",
                f[0].perceived.rms_error,
                corr(f[0].perceived.correlation),
                f[1].perceived.rms_error,
                corr(f[1].perceived.correlation),
                w[0].perceived.rms_error.to_degrees(),
                corr(w[0].perceived.correlation),
                w[1].perceived.rms_error.to_degrees(),
                corr(w[1].perceived.correlation),
                w[2].perceived.rms_error.to_degrees(),
                corr(w[2].perceived.correlation),
                c.perception_svg
                    .as_ref()
                    .map_or(String::new(), |p| format!("; {}", p.display()))
            );
        }
        None => println!("  perception: not computed (no setpoint of the drive recorded)"),
    }
}
