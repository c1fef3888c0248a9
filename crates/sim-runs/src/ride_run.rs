//! The helicopter hover physics as the stack's motion source (`crs sim --source helicopter`):
//! the [`ride_physics`] model (eq. 5.21–5.22) runs at 1 kHz on its own
//! thread of the launcher — off motion-core's hard loop, in another process — and publishes
//! its pose on motion-core's cueing input (`crs/v1/cueing_pose`, motion-core started with
//! `--input cueing`), where the loop's velocity/acceleration-limited tracker and its checks
//! take it like any reference. The pilot is a recorded CSV ([`ride_physics::pilot`]), a
//! scripted manoeuvre (`script:walls`, `script:corners`) or a game controller (`gamepad`).
//! When the pilot's input ends the source falls silent; motion-core holds and exits after
//! `--hold-s`. The flown path is plotted against the walls (SVG next to the summary).

pub use crate::pilot::{LivePilot, Pilot};
use cdpr_model::config::Platform;
use crs_ipc::{CueingPose, IpcNode};
use ride_physics::plot::{PathPoint, path_svg};
use ride_physics::settings::HoverSettings;
use ride_physics::{HoverModel, HoverState, PilotTrack};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Where the pilot's input comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum PilotSpec {
    /// A recorded pilot CSV (columns in [`ride_physics::pilot`]).
    Csv(PathBuf),
    /// A built-in manoeuvre ([`PilotTrack::script`]).
    Script {
        name: String,
        push_s: f64,
        release_s: f64,
    },
    /// A game controller (evdev) for this long, s.
    Gamepad { duration_s: f64 },
}

impl PilotSpec {
    /// `FILE.csv`, `script:NAME` or `gamepad` (flight of `gamepad_s` seconds).
    pub fn parse(text: &str, gamepad_s: f64) -> PilotSpec {
        if let Some(name) = text.strip_prefix("script:") {
            PilotSpec::Script {
                name: name.to_string(),
                push_s: 5.0,
                release_s: 2.0,
            }
        } else if text == "gamepad" {
            PilotSpec::Gamepad {
                duration_s: gamepad_s,
            }
        } else {
            PilotSpec::Csv(PathBuf::from(text))
        }
    }

    pub fn describe(&self) -> String {
        match self {
            PilotSpec::Csv(p) => p.display().to_string(),
            PilotSpec::Script { name, .. } => format!("script:{name}"),
            PilotSpec::Gamepad { duration_s } => format!("gamepad ({duration_s} s)"),
        }
    }
}

/// What `crs sim --source helicopter` runs.
#[derive(Clone, Debug, PartialEq)]
pub struct RideSpec {
    /// The ride TOML (damping, controls, walls).
    pub settings: PathBuf,
    pub pilot: PilotSpec,
}

/// The validated ride: model and pilot, checked before anything starts.
pub struct PreparedRide {
    pub model: HoverModel,
    pub pilot: Pilot,
    /// How long the flight lasts, s.
    pub duration_s: f64,
    pub describe: String,
}

/// Why a ride could not be prepared, flown or plotted.
#[derive(Debug, thiserror::Error)]
pub enum RideError {
    /// The ride TOML (names its file and key).
    #[error(transparent)]
    Settings(#[from] ride_physics::settings::SettingsError),
    /// The pilot CSV or script (names its file/line or the script).
    #[error(transparent)]
    Pilot(#[from] ride_physics::pilot::PilotError),
    /// No game controller to fly.
    #[error(transparent)]
    Gamepad(#[from] crate::gamepad::GamepadError),
    /// The model thread's iceoryx2 node or publisher.
    #[error(transparent)]
    Ipc(#[from] crs_ipc::IpcError),
    #[error("cannot start the ride thread: {0}")]
    Spawn(#[source] std::io::Error),
    #[error("the ride thread panicked")]
    Panicked,
    /// Writing the path plot `path`.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Loads the ride TOML for `platform` and the pilot's input; every error names its file.
pub fn prepare(spec: &RideSpec, platform: &Platform) -> Result<PreparedRide, RideError> {
    let file = spec.settings.display().to_string();
    let model = HoverSettings::load(&spec.settings).and_then(|s| s.model(platform, &file))?;
    let (pilot, duration_s) = match &spec.pilot {
        PilotSpec::Csv(p) => {
            let t = PilotTrack::read_csv(p)?;
            let d = t.duration_s();
            (Pilot::Track(t), d)
        }
        PilotSpec::Script {
            name,
            push_s,
            release_s,
        } => {
            let t = PilotTrack::script(name, *push_s, *release_s)?;
            let d = t.duration_s();
            (Pilot::Track(t), d)
        }
        PilotSpec::Gamepad { duration_s } => (Pilot::Live(crate::gamepad::open()?), *duration_s),
    };
    Ok(PreparedRide {
        model,
        pilot,
        duration_s,
        describe: spec.pilot.describe(),
    })
}

/// What the flight did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RideSummary {
    pub pilot: String,
    pub flown_s: f64,
    /// Largest distance the cabin went beyond each wall axis (x, y, z), mm, and the margin
    /// between the walls and the operating region, mm.
    pub max_wall_penetration_mm: [f64; 3],
    pub wall_margin_mm: [f64; 3],
    /// Time a wall pushed, s.
    pub wall_contact_s: f64,
    /// Model steps that came later than 1 ms after their deadline (the source's own timing).
    pub late_steps: u64,
    pub path_svg: Option<PathBuf>,
}

/// The running source.
pub struct RideThread {
    stop: Arc<AtomicBool>,
    handle: std::thread::JoinHandle<Result<(RideSummary, Vec<PathPoint>), RideError>>,
}

/// Starts the 1 kHz model thread publishing on the run's iceoryx2 prefix, from `home`.
pub fn start(
    ride: PreparedRide,
    prefix: &str,
    home: cdpr_model::Pose,
) -> Result<RideThread, RideError> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let prefix = prefix.to_string();
    let handle = std::thread::Builder::new()
        .name("crs-ride".into())
        .spawn(move || fly(ride, &prefix, home, &s))
        .map_err(RideError::Spawn)?;
    Ok(RideThread { stop, handle })
}

impl RideThread {
    /// True once the flight ended.
    pub fn finished(&self) -> bool {
        self.handle.is_finished()
    }

    /// Stops (if still flying) and returns the flight.
    pub fn join(self) -> Result<(RideSummary, Vec<PathPoint>), RideError> {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.join().map_err(|_| RideError::Panicked)?
    }
}

const DT_S: f64 = 1e-3;

fn fly(
    mut ride: PreparedRide,
    prefix: &str,
    home: cdpr_model::Pose,
    stop: &AtomicBool,
) -> Result<(RideSummary, Vec<PathPoint>), RideError> {
    let node = IpcNode::with_prefix("crs-ride", prefix)?;
    let publisher = node.publisher::<CueingPose>()?;
    let model = ride.model;
    let mut state = HoverState::at_rest(&home);
    let mut sum = RideSummary {
        pilot: ride.describe.clone(),
        ..RideSummary::default()
    };
    let mut path = Vec::new();
    let mut pen = nalgebra::Vector3::<f64>::zeros();
    let t0 = Instant::now();
    let mut k: u64 = 0;
    while !stop.load(Ordering::Relaxed) {
        let t = k as f64 * DT_S;
        let input = match &mut ride.pilot {
            Pilot::Track(track) => match track.at(t) {
                Some(u) => u,
                None => break,
            },
            Pilot::Live(p) => {
                if t > ride.duration_s {
                    break;
                }
                p.poll()
            }
        };
        ride_physics::step(&model, &mut state, &input, DT_S);
        pen = pen.sup(&model.walls.penetration(&state.r));
        if state.in_contact() {
            sum.wall_contact_s += DT_S;
        }
        let _ = publisher.publish(&CueingPose::new(state.pose_array(), k + 1));
        if k.is_multiple_of(10) {
            path.push(PathPoint {
                t_s: state.t,
                pose: state.pose_array(),
                contact: state.in_contact(),
            });
        }
        k += 1;
        // Absolute deadlines on the monotonic clock: a late step is counted, not caught up
        // in a burst beyond one period.
        let deadline = t0 + Duration::from_secs_f64(k as f64 * DT_S);
        let now = Instant::now();
        if now < deadline {
            std::thread::sleep(deadline - now);
        } else if now - deadline > Duration::from_secs_f64(DT_S) {
            sum.late_steps += 1;
        }
    }
    sum.flown_s = state.t;
    sum.max_wall_penetration_mm = [pen.x * 1e3, pen.y * 1e3, pen.z * 1e3];
    Ok((sum, path))
}

/// Writes the flown path (`hover`) and motion-core's reference (`reference`, positions) into
/// `<out>/ride-path.svg`.
pub fn write_svg(
    out: &Path,
    platform: &Platform,
    model: &HoverModel,
    summary: &mut RideSummary,
    hover: &[PathPoint],
    reference: &[[f64; 3]],
) -> Result<(), RideError> {
    let reg = &platform.region;
    summary.wall_margin_mm = [0, 1, 2].map(|k| (model.walls.min[k] - reg.position.min[k]) * 1e3);
    let svg = path_svg(
        &format!(
            "{}: hover flight ({}), {:.1} s, walls pushed {:.1} s, max beyond the walls {:.0}/{:.0}/{:.0} mm (x/y/z)",
            platform.name,
            summary.pilot,
            summary.flown_s,
            summary.wall_contact_s,
            summary.max_wall_penetration_mm[0],
            summary.max_wall_penetration_mm[1],
            summary.max_wall_penetration_mm[2]
        ),
        reg,
        &model.walls,
        hover,
        reference,
    );
    let p = out.join("ride-path.svg");
    if let Err(source) = std::fs::write(&p, svg) {
        return Err(RideError::Write { path: p, source });
    }
    summary.path_svg = Some(p);
    Ok(())
}
