//! Jerk-limited trajectories with ruckig, planned OFF the hard loop.
//!
//! The ruckig crate's `update()`/`at_time()` allocate on every call (and its waypoint mode calls
//! a cloud API, which this project never uses), so a planner thread computes each segment with
//! `Ruckig::calculate` (offline mode, one target at a time, no intermediate waypoints), samples
//! it at the loop period into preallocated chunks and hands them to the loop through a bounded
//! lock-free queue. The loop only pops chunks, reads samples and returns the emptied chunks on a
//! second queue: no allocation, no deallocation, no lock on the loop side.

use super::cycle::Reference;
use cdpr_model::pose::Pose;
use crossbeam::queue::ArrayQueue;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Samples per chunk (64 ms at 1 kHz).
pub const CHUNK_LEN: usize = 64;
/// Chunks in flight (≈ 1 s of look-ahead at 1 kHz).
pub const CHUNKS: usize = 16;

/// A block of consecutive 1-period samples.
pub struct Chunk {
    pub samples: [Reference; CHUNK_LEN],
    pub len: usize,
}

/// Per-axis ruckig limits in pose coordinates. The loop checks the norms of table 5.1; the
/// planner uses per-axis limits of (norm limit)/√3 so that the planned motion always passes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannerLimits {
    pub linear_velocity: f64,
    pub angular_velocity: f64,
    pub linear_acceleration: f64,
    pub angular_acceleration: f64,
    pub linear_jerk: f64,
    pub angular_jerk: f64,
}

/// A target pose and the earliest time (s from start) the platform may arrive there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waypoint {
    pub pose: Pose,
    pub not_before_s: f64,
}

/// A waypoint file that cannot be used; every variant names the file and, where there is one,
/// the line.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WaypointError {
    #[error("{file}: cannot read: {reason}")]
    Read { file: String, reason: String },
    #[error("{file}:{line}: expected header `{}`", HEADER.join(","))]
    Header { file: String, line: usize },
    #[error("{file}:{line}: expected 7 columns, found {found}")]
    Columns {
        file: String,
        line: usize,
        found: usize,
    },
    #[error("{file}:{line}: column `{column}`: `{value}` is not a finite number")]
    NotANumber {
        file: String,
        line: usize,
        column: &'static str,
        value: String,
    },
    #[error("{file}:{line}: column `t_s`: times must not decrease")]
    Decreasing { file: String, line: usize },
    #[error("{file}:{line}: end of file without a waypoint row")]
    Empty { file: String, line: usize },
}

const HEADER: [&str; 7] = [
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "phi_x_deg",
    "phi_y_deg",
    "phi_z_deg",
];

/// Reads a waypoint CSV: header `t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg`, one waypoint
/// per row, `#` comment lines allowed. Errors name the line.
pub fn read_waypoints(path: &Path) -> Result<Vec<Waypoint>, WaypointError> {
    let text = std::fs::read_to_string(path).map_err(|e| WaypointError::Read {
        file: path.display().to_string(),
        reason: e.to_string(),
    })?;
    parse_waypoints(&text, &path.display().to_string())
}

pub fn parse_waypoints(text: &str, file: &str) -> Result<Vec<Waypoint>, WaypointError> {
    parse_ride(text, file).map(|r| r.waypoints)
}

/// A ride: the waypoints of a waypoint CSV with the file name and each waypoint's line, so
/// that a refusal of the ride can name where in the file the operator has to look.
#[derive(Clone, Debug, PartialEq)]
pub struct RideFile {
    pub file: String,
    pub waypoints: Vec<Waypoint>,
    /// 1-based line of each waypoint (same length as `waypoints`).
    pub lines: Vec<usize>,
}

impl RideFile {
    /// The line of waypoint `index` (0-based); the last line for an index past the end.
    pub fn line(&self, index: usize) -> usize {
        self.lines
            .get(index)
            .or(self.lines.last())
            .copied()
            .unwrap_or(1)
    }
}

/// Reads a waypoint CSV as a [`RideFile`] (errors as [`read_waypoints`]).
pub fn read_ride(path: &Path) -> Result<RideFile, WaypointError> {
    let text = std::fs::read_to_string(path).map_err(|e| WaypointError::Read {
        file: path.display().to_string(),
        reason: e.to_string(),
    })?;
    parse_ride(&text, &path.display().to_string())
}

/// Parses a waypoint CSV's text as a [`RideFile`] named `file`.
pub fn parse_ride(text: &str, file_name: &str) -> Result<RideFile, WaypointError> {
    use crs_dataset::table::{TableError, read_table};
    let file = || file_name.to_string();
    let table = read_table(text, &HEADER).map_err(|e| match e {
        TableError::NoHeader { lines } => WaypointError::Empty {
            file: file(),
            line: lines.max(1),
        },
        TableError::Header { line, .. } | TableError::Csv { line, .. } => {
            WaypointError::Header { file: file(), line }
        }
        TableError::Columns { line, found, .. } => WaypointError::Columns {
            file: file(),
            line,
            found,
        },
    })?;
    let mut out = Vec::new();
    let mut lines = Vec::new();
    for row in &table.rows {
        let ln = row.line;
        let mut v = [0.0; 7];
        for (k, c) in row.fields.iter().enumerate() {
            v[k] = c
                .text
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| WaypointError::NotANumber {
                    file: file(),
                    line: ln,
                    column: HEADER[k],
                    value: c.text.clone(),
                })?;
        }
        if let Some(prev) = out.last().map(|w: &Waypoint| w.not_before_s)
            && v[0] < prev
        {
            return Err(WaypointError::Decreasing {
                file: file(),
                line: ln,
            });
        }
        lines.push(ln);
        out.push(Waypoint {
            not_before_s: v[0],
            pose: Pose::from_array([
                v[1],
                v[2],
                v[3],
                v[4].to_radians(),
                v[5].to_radians(),
                v[6].to_radians(),
            ]),
        });
    }
    Ok(RideFile {
        file: file(),
        waypoints: out,
        lines,
    })
}

/// Loop side: pops chunks and yields one reference per cycle.
pub struct Sampler {
    full: Arc<ArrayQueue<Box<Chunk>>>,
    empty: Arc<ArrayQueue<Box<Chunk>>>,
    current: Option<Box<Chunk>>,
    index: usize,
    last: Reference,
    done: Arc<AtomicBool>,
    /// Tells the planner thread to stop (an aborted or replaced plan).
    cancel: Arc<AtomicBool>,
}

impl Sampler {
    /// Next reference; when the planner has nothing queued the last sample is held (zero
    /// velocity and acceleration) and `starved` is reported. Allocation- and lock-free.
    #[inline]
    pub fn next_reference(&mut self) -> (Reference, bool) {
        loop {
            if let Some(c) = &self.current {
                if self.index < c.len {
                    self.last = c.samples[self.index];
                    self.index += 1;
                    return (self.last, false);
                }
                if let Some(c) = self.current.take() {
                    // The planner allocated CHUNKS chunks and waits for this one: never full.
                    let _ = self.empty.push(c);
                }
            }
            match self.full.pop() {
                Some(c) => {
                    self.current = Some(c);
                    self.index = 0;
                }
                None => {
                    let hold = Reference {
                        pose: self.last.pose,
                        ..Reference::default()
                    };
                    return (hold, !self.done.load(Ordering::Acquire));
                }
            }
        }
    }

    /// True when the planner has queued its whole look-ahead ([`CHUNKS`] chunks not yet taken
    /// by the loop) or delivered the whole plan: the loop cannot starve before it has consumed
    /// that much. Lets a caller wait on the condition instead of a guessed time.
    pub fn look_ahead_full(&self) -> bool {
        self.done.load(Ordering::Acquire) || self.full.is_full()
    }

    /// Stops the planner thread of this plan (it ends at its next sample); the loop's hand-back
    /// of a plan it no longer follows. Lock-free.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Release);
    }

    /// True when the planner has delivered everything and the queue is drained.
    pub fn finished(&self) -> bool {
        self.done.load(Ordering::Acquire)
            && self.full.is_empty()
            && self.current.as_ref().is_none_or(|c| self.index >= c.len)
    }
}

/// Starts the planner thread for a list of waypoints from `start` and returns the loop-side
/// sampler. Planning errors end the plan early and are reported through `on_error`.
pub fn spawn_planner(
    start: Pose,
    waypoints: Vec<Waypoint>,
    limits: PlannerLimits,
    period_s: f64,
    on_error: impl Fn(PlanningFailed) + Send + 'static,
) -> Sampler {
    let full = Arc::new(ArrayQueue::new(CHUNKS));
    let empty = Arc::new(ArrayQueue::new(CHUNKS));
    for _ in 0..CHUNKS {
        let _ = empty.push(Box::new(Chunk {
            samples: [Reference::default(); CHUNK_LEN],
            len: 0,
        }));
    }
    // No waypoints, no samples: the plan is delivered from the first cycle on (an idle loop
    // is idle from its first heartbeat, not once the planner thread got scheduled).
    let done = Arc::new(AtomicBool::new(waypoints.is_empty()));
    let cancel = Arc::new(AtomicBool::new(false));
    let (f2, e2, d2, c2) = (full.clone(), empty.clone(), done.clone(), cancel.clone());
    std::thread::Builder::new()
        .name("crs-planner".into())
        .spawn(move || {
            if let Err(PlanStop::Failed(e)) =
                plan(start, &waypoints, limits, period_s, &f2, &e2, &c2)
            {
                on_error(e);
            }
            d2.store(true, Ordering::Release);
        })
        .expect("spawning the planner thread");
    Sampler {
        full,
        empty,
        current: None,
        index: 0,
        last: Reference {
            pose: start,
            ..Reference::default()
        },
        done,
        cancel,
    }
}

/// Why the planner thread ended early.
enum PlanStop {
    Failed(PlanningFailed),
    /// The loop no longer follows this plan.
    Cancelled,
}

impl From<PlanningFailed> for PlanStop {
    fn from(e: PlanningFailed) -> Self {
        Self::Failed(e)
    }
}

/// ruckig found no trajectory for a segment.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("waypoint {}: ruckig could not plan the segment ({result})", waypoint + 1)]
pub struct PlanningFailed {
    /// 0-based waypoint index (the segment ending there).
    pub waypoint: usize,
    /// ruckig's result code.
    pub result: String,
}

/// For the command-line glue whose errors are messages.
impl From<PlanningFailed> for String {
    fn from(e: PlanningFailed) -> Self {
        e.to_string()
    }
}

/// Samples the whole plan at the loop period, calling `emit(segment, reference)` for each
/// sample (segment = 0-based waypoint index). Used both to verify a plan before it runs and to
/// stream it to the loop.
pub fn plan_samples<E: From<PlanningFailed>>(
    start: Pose,
    waypoints: &[Waypoint],
    lim: PlannerLimits,
    period_s: f64,
    mut emit: impl FnMut(usize, Reference) -> Result<(), E>,
) -> Result<(), E> {
    let s3 = 3f64.sqrt();
    let mut ruckig = ruckig::Ruckig::new_direct_and_offline(6);
    let mut t_global = 0.0;
    let mut current = start.to_array();
    let lin_ang = |l: f64, a: f64| [l, l, l, a, a, a].map(|v| v / s3).to_vec();
    for (k, wp) in waypoints.iter().enumerate() {
        let mut input = ruckig::InputParameter::new(6);
        input.current_position = current.to_vec();
        input.target_position = wp.pose.to_array().to_vec();
        input.max_velocity = lin_ang(lim.linear_velocity, lim.angular_velocity);
        input.max_acceleration = lin_ang(lim.linear_acceleration, lim.angular_acceleration);
        input.max_jerk = lin_ang(lim.linear_jerk, lim.angular_jerk);
        let mut traj = ruckig::Trajectory::new_direct(6);
        let res = ruckig.calculate(&mut input, &mut traj);
        if !matches!(res, ruckig::Result::Working | ruckig::Result::Finished) {
            return Err(PlanningFailed {
                waypoint: k,
                result: format!("{res:?}"),
            }
            .into());
        }
        // Dwell until the waypoint's earliest arrival time allows the segment to end there.
        let duration = traj.get_duration();
        while t_global + duration < wp.not_before_s {
            emit(
                k,
                Reference {
                    pose: Pose::from_array(current),
                    ..Reference::default()
                },
            )?;
            t_global += period_s;
        }
        let steps = (duration / period_s).ceil() as usize;
        for s in 1..=steps {
            let t = (s as f64 * period_s).min(duration);
            let (p, v, a) = traj.at_time(t);
            let r = Reference {
                pose: Pose::from_array([p[0], p[1], p[2], p[3], p[4], p[5]]),
                velocity: [v[0], v[1], v[2], v[3], v[4], v[5]],
                acceleration: [a[0], a[1], a[2], a[3], a[4], a[5]],
            };
            emit(k, r)?;
            t_global += period_s;
        }
        current = wp.pose.to_array();
    }
    Ok(())
}

fn plan(
    start: Pose,
    waypoints: &[Waypoint],
    lim: PlannerLimits,
    period_s: f64,
    full: &ArrayQueue<Box<Chunk>>,
    empty: &ArrayQueue<Box<Chunk>>,
    cancel: &AtomicBool,
) -> Result<(), PlanStop> {
    let mut chunk: Option<Box<Chunk>> = None;
    let wait = || {
        std::thread::sleep(std::time::Duration::from_micros(500));
        if cancel.load(Ordering::Acquire) {
            Err(PlanStop::Cancelled)
        } else {
            Ok(())
        }
    };
    plan_samples::<PlanStop>(start, waypoints, lim, period_s, |_, r| {
        if cancel.load(Ordering::Acquire) {
            return Err(PlanStop::Cancelled);
        }
        let c = loop {
            if let Some(c) = chunk.as_mut() {
                break c;
            }
            match empty.pop() {
                Some(mut c) => {
                    c.len = 0;
                    chunk = Some(c);
                }
                None => wait()?,
            }
        };
        c.samples[c.len] = r;
        c.len += 1;
        if c.len == CHUNK_LEN {
            let mut full_chunk = chunk.take().expect("set above");
            while let Err(back) = full.push(full_chunk) {
                full_chunk = back;
                wait()?;
            }
        }
        Ok(())
    })?;
    if let Some(mut c) = chunk.take().filter(|c| c.len > 0) {
        while let Err(back) = full.push(c) {
            c = back;
            wait()?;
        }
    }
    Ok(())
}
