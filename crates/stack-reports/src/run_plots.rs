//! The report of every `crs sim` run: `<out>/index.html` — the summary as named fields with
//! units, the events in words — and its plots: `<out>/pose.svg` (tracked vs reference pose over
//! time), `<out>/tracking.svg` (the tracking error in mm and °, and the winches' lengths against
//! the commanded ones), `<out>/path.svg` (the ride's path, top and side view), `<out>/forces.svg`
//! (cable forces with f_min / f_max), `<out>/loop.svg` (histogram of the loop's setpoint period
//! and motion-core's lateness quantiles), `<out>/events.svg` (the events on the time axis).
//! Every plot's legend sits in a strip above its plot areas, never on the data.
//!
//! [`RunRecord`] is fed from the launcher's follow loop (a few lines in the `crs` binary's `sim_cmd.rs`); it keeps
//! the streams decimated to [`KEEP_EVERY`] (100 Hz of a 1 kHz stream) so a long run stays small.
//! Routine events (motion-core's plan announcement and the monitor's epoch announcement, each
//! about once a second) are kept only when they change something.

use cdpr_model::Pose;
use crs_console::status::{
    bus_state_name, describe_event, monitor_state_name, motion_state_name, process_name,
};
use crs_ipc::{
    EventKind, JointSetpoint, LoopStatsSample, MAX_CABLES, PLAN_OPEN_END, PlantTruth, ProcessId,
    StateEvent,
};
use crs_plot::{Chart, Figure, HLine, Label, Line, Markers, Panel, Rect, Rgb, VLine};
use sim_runs::sim_run::Summary;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};

/// Keep every n-th sample of the 1 kHz streams.
pub const KEEP_EVERY: u64 = 10;
/// Setpoint-period histogram: bin width and range (µs).
const BIN_US: f64 = 20.0;
const HIST_MAX_US: f64 = 3000.0;
/// Setpoints kept to pair each plant state with the newest reference published before it.
const RECENT_SETPOINTS: usize = 256;

/// One event of the run, in words.
#[derive(Clone, Debug)]
pub struct RunEvent {
    /// Seconds on the report's time axis.
    pub t_s: f64,
    pub source: String,
    pub what: String,
    /// An e-stop or a fault (drawn red).
    pub alarm: bool,
}

/// The tracking error at one kept plant state, against the newest setpoint before it.
#[derive(Clone, Debug)]
struct TrackingSample {
    t_s: f64,
    /// Plant minus reference, x, y, z (mm).
    position_mm: [f64; 3],
    /// |plant − reference| (mm).
    position_norm_mm: f64,
    /// Rotation error angle (°, eq. 3.3's ε_φ).
    rotation_deg: f64,
    /// Winch length minus commanded length per cable (mm).
    length_mm: Vec<f64>,
}

/// What a run's plots are made of.
#[derive(Default)]
pub struct RunRecord {
    t0_ns: Option<u64>,
    f_min: f64,
    f_max: f64,
    n_sp: u64,
    n_truth: u64,
    /// (t s, pose) of the reference (setpoints).
    reference: Vec<(f64, [f64; 6])>,
    /// (t s, pose, forces) of the plant.
    actual: Vec<(f64, [f64; 6], Vec<f64>)>,
    /// (timestamp ns, pose, commanded lengths) of the newest setpoints.
    recent_sp: VecDeque<(u64, [f64; 6], [f64; MAX_CABLES], usize)>,
    tracking: Vec<TrackingSample>,
    last_sp_ns: Option<u64>,
    /// Setpoint periods in bins of BIN_US; the last bin holds everything above HIST_MAX_US.
    period_hist: Vec<u64>,
    period_max_us: f64,
    /// (t s, lateness p50, p99, max µs) from motion-core's loop statistics.
    lateness: Vec<(f64, f64, f64, f64)>,
    events: Vec<RunEvent>,
    /// The last state each process announced (index: its process id): repeats are not events.
    last_state: [Option<u32>; 8],
    /// The last plan end motion-core announced.
    plan_end: Option<u64>,
}

impl RunRecord {
    pub fn new(f_min: f64, f_max: f64) -> Self {
        Self {
            f_min,
            f_max,
            period_hist: vec![0; (HIST_MAX_US / BIN_US) as usize + 1],
            ..Self::default()
        }
    }

    fn t(&mut self, ns: u64) -> f64 {
        let t0 = *self.t0_ns.get_or_insert(ns);
        (ns as f64 - t0 as f64) * 1e-9
    }

    pub fn setpoint(&mut self, sp: &JointSetpoint) {
        if let Some(prev) = self.last_sp_ns {
            let us = sp.timestamp_ns.saturating_sub(prev) as f64 * 1e-3;
            let k = ((us / BIN_US) as usize).min(self.period_hist.len() - 1);
            self.period_hist[k] += 1;
            self.period_max_us = self.period_max_us.max(us);
        }
        self.last_sp_ns = Some(sp.timestamp_ns);
        if self.n_sp.is_multiple_of(KEEP_EVERY) {
            let t = self.t(sp.timestamp_ns);
            self.reference.push((t, sp.pose));
        }
        self.n_sp += 1;
        if self.recent_sp.len() == RECENT_SETPOINTS {
            self.recent_sp.pop_front();
        }
        let m = (sp.cable_count as usize).min(MAX_CABLES);
        self.recent_sp
            .push_back((sp.timestamp_ns, sp.pose, sp.cable_length_m, m));
    }

    pub fn truth(&mut self, p: &PlantTruth) {
        if self.n_truth.is_multiple_of(KEEP_EVERY) {
            let t = self.t(p.timestamp_ns);
            let m = (p.cable_count as usize).min(MAX_CABLES);
            self.actual.push((t, p.pose, p.force_n[..m].to_vec()));
            // The tracking error against the newest reference published before this state
            // (the summary's tracking figures pair them the same way).
            if let Some((_, r, q, n)) = self
                .recent_sp
                .iter()
                .rev()
                .find(|(ts, ..)| *ts <= p.timestamp_ns)
            {
                let (dp, dr) = Pose::from_array(p.pose).error_to(&Pose::from_array(*r));
                let n = (*n).min(m);
                self.tracking.push(TrackingSample {
                    t_s: t,
                    position_mm: [0, 1, 2].map(|k| (p.pose[k] - r[k]) * 1e3),
                    position_norm_mm: dp * 1e3,
                    rotation_deg: dr.to_degrees(),
                    length_mm: (0..n).map(|i| (p.cable_length_m[i] - q[i]) * 1e3).collect(),
                });
            }
        }
        self.n_truth += 1;
    }

    pub fn loop_stats(&mut self, s: &LoopStatsSample) {
        let t = self.t(s.timestamp_ns);
        self.lateness.push((
            t,
            s.lateness_p50_ns as f64 * 1e-3,
            s.lateness_p99_ns as f64 * 1e-3,
            s.lateness_max_ns as f64 * 1e-3,
        ));
    }

    /// Keeps the event in words; routine re-announcements that change nothing are dropped.
    pub fn event(&mut self, e: &StateEvent) {
        let Some((what, alarm)) = self.event_words(e) else {
            return;
        };
        let t = self.t(e.timestamp_ns);
        self.events.push(RunEvent {
            t_s: t,
            source: process_name(e.source).to_string(),
            what,
            alarm,
        });
    }

    fn event_words(&mut self, e: &StateEvent) -> Option<(String, bool)> {
        if let Some((kind, cause)) = describe_event(e) {
            let alarm = kind == "E-STOP" || kind == "fault";
            return Some((format!("{kind}: {cause}"), alarm));
        }
        if e.kind != EventKind::StateChanged as u32 {
            return Some((format!("event kind {}, state {}", e.kind, e.state), false));
        }
        if let Some(end) = e.plan_end() {
            if self.plan_end == Some(end) {
                return None;
            }
            self.plan_end = Some(end);
            return Some((
                if end == PLAN_OPEN_END {
                    "plan announced: open end (cueing input)".to_string()
                } else {
                    format!("plan announced: ends with setpoint #{end}")
                },
                false,
            ));
        }
        let slot = self.last_state.get_mut(e.source as usize)?;
        if *slot == Some(e.state) {
            return None;
        }
        *slot = Some(e.state);
        let words = match e.source() {
            ProcessId::MotionCore if e.is_stream_end() => {
                "end of the setpoint stream (planned)".to_string()
            }
            ProcessId::MotionCore => motion_state_name(e.state),
            ProcessId::SafetyMonitor => monitor_state_name(e.state),
            ProcessId::DriveIo => format!("bus {}", bus_state_name(e.state)),
            _ => format!("state {}", e.state),
        };
        Some((words, false))
    }

    /// The run's events in words, in the order received.
    pub fn events(&self) -> &[RunEvent] {
        &self.events
    }

    fn t_end(&self) -> f64 {
        let a = self.reference.last().map_or(0.0, |r| r.0);
        let b = self.actual.last().map_or(0.0, |r| r.0);
        a.max(b).max(1e-3)
    }
}

/// Why the run's plots could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RunPlotError {
    /// Drawing or writing one of the SVGs (the error names the file).
    #[error(transparent)]
    Draw(#[from] crs_plot::PlotError),
    /// Writing `index.html` (`file`).
    #[error("{source}")]
    Write {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

const REFERENCE: Rgb = Rgb(239, 143, 0);
const PLANT: Rgb = Rgb(25, 90, 210);
const EVENT_GREY: Rgb = Rgb(150, 150, 150);
const ALARM: Rgb = Rgb(200, 30, 30);
/// plotters' pure primaries, the loop plot's colours.
const PURE_RED: Rgb = Rgb(255, 0, 0);
const PURE_GREEN: Rgb = Rgb(0, 255, 0);
const PURE_BLUE: Rgb = Rgb(0, 0, 255);

/// A line without a legend entry of its own (the figure's strip names it).
fn line(color: Rgb, width: u32, points: Vec<(f64, f64)>) -> Line {
    Line {
        label: None,
        color,
        width,
        dashed: false,
        opacity: 1.0,
        points,
    }
}

/// The run's events as vertical marks: grey, red for e-stops and faults.
fn event_marks(events: &[RunEvent]) -> Vec<VLine> {
    events
        .iter()
        .map(|e| VLine {
            x: e.t_s,
            color: if e.alarm { ALARM } else { EVENT_GREY },
            dashed: false,
        })
        .collect()
}

/// A chart with the given axis ranges.
fn chart(title: &str, x_label: &str, y_label: &str, x: (f64, f64), y: (f64, f64)) -> Chart {
    let mut c = Chart::new(title, x_label, y_label);
    c.x_range = Some(x);
    c.y_range = Some(y);
    c
}

/// A figure without title whose legend is the strip above its panels.
fn figure(
    size: (u32, u32),
    columns: usize,
    legend: Vec<(String, Rgb)>,
    panels: Vec<Chart>,
) -> Figure {
    Figure {
        title: String::new(),
        size,
        columns,
        panels: panels.into_iter().map(Panel::Chart).collect(),
        notes: Vec::new(),
        legend,
    }
}

/// (lo, hi) of `vals` padded by 8 % and at least `min_pad`; (0, 1) without values.
fn range(vals: impl Iterator<Item = f64>, min_pad: f64) -> (f64, f64) {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let pad = ((hi - lo) * 0.08).max(min_pad);
    (lo - pad, hi + pad)
}

fn pose_plot(r: &RunRecord) -> Figure {
    let names = ["x (m)", "y (m)", "z (m)", "φx (°)", "φy (°)", "φz (°)"];
    let t_end = r.t_end();
    let panels = (0..6)
        .map(|k| {
            let scale = if k < 3 {
                1.0
            } else {
                180.0 / std::f64::consts::PI
            };
            let y = range(
                r.reference
                    .iter()
                    .map(|(_, p)| p[k] * scale)
                    .chain(r.actual.iter().map(|(_, p, _)| p[k] * scale)),
                if k < 3 { 0.01 } else { 0.1 },
            );
            let mut c = chart(names[k], "t (s)", "", (0.0, t_end), y);
            c.vlines = event_marks(&r.events);
            c.lines = vec![
                line(
                    REFERENCE,
                    2,
                    r.reference
                        .iter()
                        .map(|(t, p)| (*t, p[k] * scale))
                        .collect(),
                ),
                line(
                    PLANT,
                    1,
                    r.actual
                        .iter()
                        .map(|(t, p, _)| (*t, p[k] * scale))
                        .collect(),
                ),
            ];
            c
        })
        .collect();
    figure(
        (1100, 670),
        3,
        vec![
            ("reference (setpoints)".into(), REFERENCE),
            ("plant (true pose)".into(), PLANT),
            ("event (grey) / e-stop, fault (red)".into(), EVENT_GREY),
        ],
        panels,
    )
}

/// The tracking error where it is visible: mm and degrees, not the metre axes of the pose plot.
fn tracking_plot(r: &RunRecord) -> Figure {
    let axes = [
        ("x", Rgb(200, 30, 30)),
        ("y", Rgb(30, 150, 30)),
        ("z", Rgb(25, 90, 210)),
    ];
    let mut legend: Vec<(String, Rgb)> = axes
        .iter()
        .map(|(a, c)| (format!("{a}: plant − reference"), *c))
        .collect();
    legend.push(("|plant − reference|".into(), Rgb::BLACK));
    let t_end = r.t_end();
    // Position error: components and norm (mm).
    let y = range(
        r.tracking.iter().flat_map(|s| {
            s.position_mm
                .into_iter()
                .chain(std::iter::once(s.position_norm_mm))
        }),
        0.05,
    );
    let mut position = chart(
        "position tracking error (plant vs the newest setpoint before it)",
        "t (s)",
        "mm",
        (0.0, t_end),
        y,
    );
    position.vlines = event_marks(&r.events);
    for (k, (_, c)) in axes.iter().enumerate() {
        position.lines.push(line(
            *c,
            1,
            r.tracking
                .iter()
                .map(|s| (s.t_s, s.position_mm[k]))
                .collect(),
        ));
    }
    position.lines.push(line(
        Rgb::BLACK,
        2,
        r.tracking
            .iter()
            .map(|s| (s.t_s, s.position_norm_mm))
            .collect(),
    ));
    // Rotation error (°).
    let (lo, hi) = range(r.tracking.iter().map(|s| s.rotation_deg), 0.005);
    let mut rotation = chart(
        "rotation tracking error (angle, eq. 3.3)",
        "t (s)",
        "°",
        (0.0, t_end),
        (lo.min(0.0), hi),
    );
    rotation.vlines = event_marks(&r.events);
    rotation.lines.push(line(
        Rgb::BLACK,
        2,
        r.tracking.iter().map(|s| (s.t_s, s.rotation_deg)).collect(),
    ));
    // Winch length against the commanded cable length, per cable (mm).
    let y = range(
        r.tracking.iter().flat_map(|s| s.length_mm.iter().copied()),
        0.05,
    );
    let mut length = chart(
        "cable length: winch − commanded, per cable (colours: cable 1 … m, as in forces.svg)",
        "t (s)",
        "mm",
        (0.0, t_end),
        y,
    );
    length.vlines = event_marks(&r.events);
    let m = r
        .tracking
        .iter()
        .map(|s| s.length_mm.len())
        .max()
        .unwrap_or(0);
    for i in 0..m {
        length.lines.push(line(
            Rgb::palette(i),
            1,
            r.tracking
                .iter()
                .filter_map(|s| s.length_mm.get(i).map(|v| (s.t_s, *v)))
                .collect(),
        ));
    }
    figure((1100, 720), 1, legend, vec![position, rotation, length])
}

/// The ride's path: top view (x–y) and side view (x–z), reference and plant.
fn path_plot(r: &RunRecord) -> Figure {
    let panels = [(1usize, "top view: y (m)"), (2, "side view: z (m)")]
        .into_iter()
        .map(|(j, name)| {
            let x = range(
                r.reference
                    .iter()
                    .map(|(_, p)| p[0])
                    .chain(r.actual.iter().map(|(_, p, _)| p[0])),
                0.05,
            );
            let y = range(
                r.reference
                    .iter()
                    .map(|(_, p)| p[j])
                    .chain(r.actual.iter().map(|(_, p, _)| p[j])),
                0.05,
            );
            let title = if j == 1 {
                "top view (x–y)"
            } else {
                "side view (x–z)"
            };
            let mut c = chart(title, "x (m)", name, x, y);
            c.lines = vec![
                line(
                    REFERENCE,
                    2,
                    r.reference.iter().map(|(_, p)| (p[0], p[j])).collect(),
                ),
                line(
                    PLANT,
                    1,
                    r.actual.iter().map(|(_, p, _)| (p[0], p[j])).collect(),
                ),
            ];
            c
        })
        .collect();
    figure(
        (1100, 520),
        2,
        vec![
            ("reference (setpoints)".into(), REFERENCE),
            ("plant (true pose)".into(), PLANT),
        ],
        panels,
    )
}

fn force_plot(r: &RunRecord) -> Figure {
    let m = r.actual.first().map_or(0, |a| a.2.len());
    let mut legend: Vec<(String, Rgb)> = (0..m)
        .map(|i| (format!("cable {}", i + 1), Rgb::palette(i)))
        .collect();
    legend.push(("f_min, f_max".into(), ALARM));
    let t_end = r.t_end();
    let f_top = r
        .actual
        .iter()
        .flat_map(|(_, _, f)| f.iter().copied())
        .fold(r.f_max, f64::max)
        * 1.05;
    let mut c = chart(
        "cable forces (plant truth) and the limits f_min, f_max",
        "t (s)",
        "N",
        (0.0, t_end),
        (0.0, f_top),
    );
    c.vlines = event_marks(&r.events);
    c.hlines = [r.f_min, r.f_max]
        .map(|y| HLine {
            y,
            color: ALARM,
            dashed: true,
        })
        .to_vec();
    for i in 0..m {
        c.lines.push(line(
            Rgb::palette(i),
            1,
            r.actual.iter().map(|(t, _, f)| (*t, f[i])).collect(),
        ));
    }
    figure((1100, 500), 1, legend, vec![c])
}

fn loop_plot(r: &RunRecord) -> Figure {
    let total: u64 = r.period_hist.iter().sum::<u64>().max(1);
    // Log-scaled counts: the tail bins (a few stalls) must stay visible next to the 1 ms peak.
    let y_top = (r.period_hist.iter().copied().max().unwrap_or(1).max(1) as f64 * 2.0).log10();
    let mut hist = chart(
        &format!(
            "setpoint period histogram ({total} periods, max {:.0} µs)",
            r.period_max_us
        ),
        "time between consecutive setpoints (µs; last bin: ≥ 3 ms)",
        "log10(count + 1)",
        (0.0, HIST_MAX_US + BIN_US),
        (0.0, y_top.max(1.0)),
    );
    hist.rects = r
        .period_hist
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let x0 = k as f64 * BIN_US;
            let colour = if k + 1 == r.period_hist.len() {
                PURE_RED
            } else {
                PURE_BLUE
            };
            Rect::filled(
                (x0, 0.0),
                (x0 + BIN_US, ((*n + 1) as f64).log10()),
                colour,
                1.0,
            )
        })
        .collect();
    let t_end = r.t_end();
    let y_max = r
        .lateness
        .iter()
        .map(|l| l.3)
        .fold(1.0f64, f64::max)
        .max(1.0);
    let mut lateness = chart(
        "motion-core lateness (cumulative quantiles)",
        "t (s)",
        "µs",
        (0.0, t_end),
        (1.0, y_max * 2.0),
    );
    lateness.y_log = true;
    for (k, colour) in [PURE_GREEN, PURE_BLUE, PURE_RED].into_iter().enumerate() {
        lateness.lines.push(line(
            colour,
            2,
            r.lateness
                .iter()
                .map(|l| (l.0, [l.1, l.2, l.3][k].max(1.0)))
                .collect(),
        ));
    }
    figure(
        (1100, 450),
        2,
        vec![
            ("periods (count)".into(), PURE_BLUE),
            ("periods ≥ 3 ms".into(), PURE_RED),
            ("lateness p50".into(), PURE_GREEN),
            ("p99".into(), PURE_BLUE),
            ("max".into(), PURE_RED),
        ],
        vec![hist, lateness],
    )
}

fn events_plot(r: &RunRecord) -> Figure {
    let sources = [
        "motion-core",
        "drive-io",
        "safety-monitor",
        "operator",
        "other",
    ];
    let t_end = r.t_end();
    let mut c = chart(
        &format!(
            "events on the process bus ({}; state changes only)",
            r.events.len()
        ),
        "t (s)",
        "",
        (0.0, t_end),
        (-0.5, sources.len() as f64 - 0.5),
    );
    c.y_categories = sources.iter().map(|s| s.to_string()).collect();
    let dot = |color| Markers {
        label: None,
        color,
        radius: 5,
        filled: true,
        points: Vec::new(),
        texts: Vec::new(),
    };
    let (mut plain, mut alarm) = (dot(PLANT), dot(ALARM));
    // Labels of events close in time on one row alternate above and below the marker.
    let mut last: [(f64, usize); 5] = [(f64::NEG_INFINITY, 0); 5];
    for e in &r.events {
        let k = sources.iter().position(|s| *s == e.source).unwrap_or(4);
        let row = k as f64;
        let near = e.t_s - last[k].0 < 0.12 * t_end;
        let level = if near { (last[k].1 + 1) % 2 } else { 0 };
        last[k] = (e.t_s, level);
        if e.alarm { &mut alarm } else { &mut plain }
            .points
            .push((e.t_s, row));
        c.labels.push(Label {
            at: (e.t_s, row + if level == 0 { 0.3 } else { -0.12 }),
            text: e.what.clone(),
            color: Rgb::BLACK,
        });
    }
    c.markers = vec![plain, alarm];
    figure((1100, 300), 1, Vec::new(), vec![c])
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A number with `digits` decimals; NaN / ±∞ as `none` (what a figure not measured means).
fn num(x: f64, digits: usize, none: &str) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        none.to_string()
    }
}

/// The summary table: sections of named fields, each with its value and unit; `data-field`
/// names the summary.json key.
struct Table(String);

impl Table {
    fn section(&mut self, title: &str) {
        self.0.push_str(&format!(
            "<tr class=\"section\"><th colspan=\"3\">{}</th></tr>\n",
            html_escape(title)
        ));
    }
    fn row(&mut self, field: &str, name: &str, value: String, unit: &str) {
        self.0.push_str(&format!(
            "<tr data-field=\"{}\"><th>{}</th><td class=\"value\">{}</td><td class=\"unit\">{}</td></tr>\n",
            html_escape(field),
            html_escape(name),
            html_escape(&value),
            html_escape(unit)
        ));
    }
}

/// The file name of `p` when it lies in `out` (a link relative to index.html), else its path.
fn link_target(out: &Path, p: &Path) -> String {
    match p.strip_prefix(out) {
        Ok(rel) => rel.display().to_string(),
        Err(_) => p.display().to_string(),
    }
}

/// The outcome: completed, who stopped it, what ran.
fn outcome_rows(t: &mut Table, s: &Summary) {
    t.section("Outcome");
    t.row(
        "completed",
        "completed",
        if s.completed {
            "yes: the ride ran to its end and the platform held".into()
        } else {
            "NO: the run was stopped before the ride ended".into()
        },
        "",
    );
    t.row(
        "stopped_by",
        "stopped by",
        s.stopped_by.clone().unwrap_or_else(|| {
            if s.completed {
                "nobody (planned end)".into()
            } else {
                "the run ended early (see the events)".into()
            }
        }),
        "",
    );
    t.row("duration_s", "run duration", num(s.duration_s, 1, "–"), "s");
    t.row("platform", "platform", s.platform.clone(), "");
    t.row("transport", "buses", s.transport.clone(), "");
    t.row(
        "monitor",
        "safety monitor",
        if s.monitor { "on" } else { "off" }.into(),
        "",
    );
}

/// Tracking during the run, at rest after it and at the recorded rest points.
fn tracking_rows(t: &mut Table, s: &Summary) {
    t.section("Tracking (plant pose vs the setpoints)");
    t.row(
        "tracking_position_mean_mm",
        "position error, mean",
        num(s.tracking_position_mean_mm, 2, "–"),
        "mm",
    );
    t.row(
        "tracking_position_max_mm",
        "position error, max",
        num(s.tracking_position_max_mm, 2, "–"),
        "mm",
    );
    t.row(
        "tracking_rotation_mean_deg",
        "rotation error, mean",
        num(s.tracking_rotation_mean_deg, 3, "–"),
        "°",
    );
    t.row(
        "tracking_rotation_max_deg",
        "rotation error, max",
        num(s.tracking_rotation_max_deg, 3, "–"),
        "°",
    );
    let not_reached = if s.completed {
        "not measured"
    } else {
        "not reached (the run was stopped)"
    };
    t.row(
        "static_position_mm",
        "at rest after the ride: position error",
        num(s.static_position_mm, 2, not_reached),
        "mm",
    );
    t.row(
        "static_rotation_deg",
        "at rest after the ride: rotation error",
        num(s.static_rotation_deg, 3, not_reached),
        "°",
    );
    if s.rest.rest_points > 0 || s.rest_points_skipped > 0 {
        let r = &s.rest;
        t.row(
            "rest.rest_points",
            "rest points recorded",
            r.rest_points.to_string(),
            "",
        );
        t.row(
            "rest_points_skipped",
            "rest points skipped (no readings)",
            s.rest_points_skipped.to_string(),
            "",
        );
        t.row(
            "rest.position_mean_mm",
            "rest points, measured position error mean / max",
            format!(
                "{} / {}",
                num(r.position_mean_mm, 2, "–"),
                num(r.position_max_mm, 2, "–")
            ),
            "mm",
        );
        t.row(
            "rest.true_position_mean_mm",
            "rest points, true position error mean / max",
            format!(
                "{} / {}",
                num(r.true_position_mean_mm, 2, "–"),
                num(r.true_position_max_mm, 2, "–")
            ),
            "mm",
        );
    }
}

/// The cable forces seen against the limits.
fn forces_rows(t: &mut Table, s: &Summary) {
    t.section("Cable forces");
    let seen = s.force_min_n <= s.force_max_n;
    t.row(
        "force_min_n",
        "force, lowest seen",
        num(s.force_min_n, 0, "none seen"),
        "N",
    );
    t.row(
        "force_max_n",
        "force, highest seen",
        num(s.force_max_n, 0, "none seen"),
        "N",
    );
    t.row(
        "f_min_n",
        "force limits, lowest … highest allowed",
        format!("{} … {}", num(s.f_min_n, 0, "–"), num(s.f_max_n, 0, "–")),
        "N",
    );
    t.row(
        "forces_within",
        "forces within the limits",
        if !seen {
            "no force seen".into()
        } else if s.force_min_n >= s.f_min_n && s.force_max_n <= s.f_max_n {
            "yes".into()
        } else {
            "NO: outside the limits".into()
        },
        "",
    );
}

/// motion-core's loop statistics and the samples received.
fn hard_loop_rows(t: &mut Table, s: &Summary) {
    t.section("Loop (motion-core)");
    t.row("loop_cycles", "cycles", s.loop_cycles.to_string(), "");
    t.row("loop_overruns", "overruns", s.loop_overruns.to_string(), "");
    t.row(
        "loop_rejected",
        "references rejected",
        s.loop_rejected.to_string(),
        "",
    );
    t.row(
        "loop_dropped",
        "setpoints not handed to the publish stage",
        s.loop_dropped.to_string(),
        "",
    );
    t.row(
        "loop_lateness_p99_us",
        "lateness p99 / max",
        format!(
            "{} / {}",
            num(s.loop_lateness_p99_us, 1, "–"),
            num(s.loop_lateness_max_us, 1, "–")
        ),
        "µs",
    );
    t.row(
        "loop_compute_p99_us",
        "compute p99",
        num(s.loop_compute_p99_us, 1, "–"),
        "µs",
    );
    t.row(
        "setpoints",
        "setpoints received",
        s.setpoints.to_string(),
        "",
    );
    t.row(
        "plant_samples",
        "plant states received",
        s.plant_samples.to_string(),
        "",
    );
    t.row(
        "non_converged_plant_steps",
        "plant steps without equilibrium",
        s.non_converged_plant_steps.to_string(),
        "",
    );
}

/// E-stops, monitor trips and heartbeats, drive faults and bus stops.
fn safety_rows(t: &mut Table, s: &Summary) {
    t.section("Safety");
    t.row("estops", "e-stops", s.estops.to_string(), "");
    for (k, trip) in s.monitor_trips.iter().enumerate() {
        t.row(
            "monitor_trips",
            &format!("monitor trip {}", k + 1),
            trip.clone(),
            "",
        );
    }
    t.row(
        "monitor_heartbeats",
        "monitor heartbeats",
        if s.monitor {
            s.monitor_heartbeats.to_string()
        } else {
            "monitor not running".into()
        },
        "",
    );
    t.row(
        "drive_faults",
        "drive fault reports",
        s.drive_faults.to_string(),
        "",
    );
    t.row(
        "bus_stopped_during_run",
        "drive bus stopped during the ride",
        s.bus_stopped_during_run
            .clone()
            .unwrap_or_else(|| "no".into()),
        "",
    );
    for reason in &s.bus_stop_reasons {
        t.row("bus_stop_reasons", "drive-io said", reason.clone(), "");
    }
}

/// The wire model's buses (wire modes only).
fn buses_rows(t: &mut Table, s: &Summary) {
    if !s.wire.is_empty() {
        t.section("Buses (wire model)");
        for w in &s.wire {
            t.row(
                "wire",
                &format!("bus {}: frames / dropped at a full queue", w.bus),
                format!("{} / {}", w.frames, w.dropped),
                "",
            );
            t.row(
                "wire",
                &format!("bus {}: load mean / busiest second", w.bus),
                format!(
                    "{} / {}",
                    num(w.load_mean_percent, 1, "–"),
                    w.load_max_percent
                        .map_or("not measured".into(), |x| num(x, 1, "–"))
                ),
                "%",
            );
            t.row(
                "wire",
                &format!("bus {}: worst frame latency", w.bus),
                num(w.latency_max_us, 0, "–"),
                "µs",
            );
        }
    }
}

/// The hover flight of a helicopter ride.
fn hover_flight_rows(t: &mut Table, s: &Summary) {
    if let Some(r) = &s.ride {
        t.section("Hover flight");
        t.row("ride.pilot", "pilot", r.pilot.clone(), "");
        t.row("ride.flown_s", "flown", num(r.flown_s, 1, "–"), "s");
        t.row(
            "ride.wall_contact_s",
            "walls pushed",
            num(r.wall_contact_s, 1, "–"),
            "s",
        );
        t.row(
            "ride.max_wall_penetration_mm",
            "max beyond the walls x / y / z",
            r.max_wall_penetration_mm
                .map(|v| num(v, 1, "–"))
                .join(" / "),
            "mm",
        );
        t.row(
            "ride.late_steps",
            "late model steps",
            r.late_steps.to_string(),
            "",
        );
    }
}

/// The motion cueing of a vehicle track.
fn cueing_rows(t: &mut Table, s: &Summary) {
    if let Some(c) = &s.cueing {
        t.section("Motion cueing");
        t.row("cueing.source", "vehicle", c.source.clone(), "");
        t.row("cueing.drive_s", "drive", num(c.drive_s, 1, "–"), "s");
        t.row(
            "cueing.max_tilt_rate_deg_per_s",
            "max tilt rate (threshold)",
            format!(
                "{} ({})",
                num(c.max_tilt_rate_deg_per_s, 2, "–"),
                num(c.tilt_rate_threshold_deg_per_s, 2, "–")
            ),
            "°/s",
        );
        t.row(
            "cueing.limited_steps",
            "limited steps",
            c.limited_steps.to_string(),
            "",
        );
    }
}

/// The recorded data set.
fn recording_rows(t: &mut Table, s: &Summary) {
    if let Some(p) = &s.record {
        t.section("Recording");
        t.row("record", "data set", p.display().to_string(), "");
    }
}

/// The summary as the index's table, section by section: every row names its summary.json
/// field and unit.
fn summary_table(s: &Summary) -> String {
    let mut t = Table(String::new());
    outcome_rows(&mut t, s);
    tracking_rows(&mut t, s);
    forces_rows(&mut t, s);
    hard_loop_rows(&mut t, s);
    safety_rows(&mut t, s);
    buses_rows(&mut t, s);
    hover_flight_rows(&mut t, s);
    cueing_rows(&mut t, s);
    recording_rows(&mut t, s);
    t.0
}

/// The events table's rows, in time order.
fn events_rows(r: &RunRecord) -> String {
    // In time order (the topics of several processes arrive interleaved).
    let mut events = r.events.clone();
    events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let mut ev = String::new();
    for e in &events {
        ev.push_str(&format!(
            "<tr{}><td>{:.3}</td><td>{}</td><td>{}</td></tr>\n",
            if e.alarm { " class=\"alarm\"" } else { "" },
            e.t_s,
            html_escape(&e.source),
            html_escape(&e.what)
        ));
    }
    if events.is_empty() {
        ev.push_str("<tr><td colspan=\"3\">no events</td></tr>\n");
    }
    ev
}

/// The figures the run's motion source made (the hover flight's path, the cueing's
/// perception and motion), each under its title.
fn source_figures(out: &Path, summary: &Summary) -> String {
    let mut extra = String::new();
    let mut figure = |title: &str, p: &Path, alt: &str| {
        let href = html_escape(&link_target(out, p));
        extra.push_str(&format!(
            "<h2>{title}</h2><p><a href=\"{href}\">{href}</a></p><img src=\"{href}\" alt=\"{alt}\">\n"
        ));
    };
    if let Some(p) = summary.ride.as_ref().and_then(|r| r.path_svg.as_ref()) {
        figure("Hover flight: the ride's path", p, "hover flight path");
    }
    if let Some(c) = &summary.cueing {
        if let Some(p) = &c.perception_svg {
            figure("Motion cueing: perception", p, "cueing perception");
        }
        if let Some(p) = &c.motion_svg {
            figure("Motion cueing: motion", p, "cueing motion");
        }
    }
    extra
}

/// The path section's links: path.svg and, for a ride, the hover flight's own plot.
fn ride_path_links(out: &Path, summary: &Summary) -> String {
    match summary.ride.as_ref().and_then(|r| r.path_svg.as_ref()) {
        Some(p) => {
            let href = html_escape(&link_target(out, p));
            format!(
                "<a href=\"path.svg\">path.svg</a> (reference and plant) and the hover flight's <a href=\"{href}\">{href}</a>"
            )
        }
        None => "<a href=\"path.svg\">path.svg</a>".into(),
    }
}

/// Links to the logs and files this run wrote (only those that exist).
fn file_links(out: &Path) -> String {
    let mut files: Vec<String> = [
        "sim-plant.log",
        "safety-monitor.log",
        "drive-io.log",
        "motion-core.log",
        "can-wire.log",
        "summary.json",
        "waypoints-timed.csv",
    ]
    .iter()
    .filter(|f| out.join(f).is_file())
    .map(|f| format!("<a href=\"{f}\">{f}</a>"))
    .collect();
    if files.is_empty() {
        files.push("none written".into());
    }
    files.join(", ")
}

/// The verdict line at the top of the index.
fn verdict(summary: &Summary) -> String {
    if summary.completed {
        "<p class=\"verdict ok\">Completed: the ride ran to its end and the platform held.</p>"
            .to_string()
    } else {
        format!(
            "<p class=\"verdict stopped\">STOPPED before the ride ended: {}</p>",
            html_escape(
                summary
                    .stopped_by
                    .as_deref()
                    .unwrap_or("the run ended early (see the events)")
            )
        )
    }
}

/// Writes the plots and index.html into `out`; returns the index path.
pub fn write(out: &Path, r: &RunRecord, summary: &Summary) -> Result<PathBuf, RunPlotError> {
    type Draw = fn(&RunRecord) -> Figure;
    let plots: [(&str, Draw); 6] = [
        ("pose.svg", pose_plot),
        ("tracking.svg", tracking_plot),
        ("path.svg", path_plot),
        ("forces.svg", force_plot),
        ("loop.svg", loop_plot),
        ("events.svg", events_plot),
    ];
    for (name, plot) in plots {
        plot(r).write(&out.join(name))?;
    }
    let rows = summary_table(summary);
    let ev = events_rows(r);
    let extra = source_figures(out, summary);
    let ride_path = ride_path_links(out, summary);
    let files = file_links(out);
    let verdict = verdict(summary);
    let html = format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>crs sim run: {platform}</title>
<style>body{{font-family:sans-serif;margin:16px;color:#1d232b;max-width:1150px}} table{{border-collapse:collapse}} th,td{{padding:2px 8px;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}} td.value{{font-variant-numeric:tabular-nums}} tr.section th{{background:#eef1f4;padding-top:8px}} tr.alarm td{{color:#c62828;font-weight:600}} img{{max-width:100%;border:1px solid #ddd;margin:6px 0;display:block}} .verdict{{font-size:18px;font-weight:700;padding:6px 10px;border-radius:4px}} .ok{{background:#e3f2e5;color:#1b5e20}} .stopped{{background:#fde7e7;color:#b71c1c}}</style>
</head><body>
<h1>crs sim run: {platform}</h1>
{verdict}
<p>Time axis of every plot: seconds from the first setpoint or plant state the launcher received. Grey vertical lines mark events, red ones e-stops and faults; each plot's legend is in the strip above it.</p>
<h2 id="summary">Summary</h2>
<table id="summary-table">
<tr><th>quantity</th><th>value</th><th>unit</th></tr>
{rows}</table>
<h2 id="events">Events (state changes, in time order)</h2>
<table id="events-table"><tr><th>t (s)</th><th>source</th><th>event</th></tr>
{ev}</table>
<img src="events.svg" alt="events">
<h2 id="tracking">Tracking error (mm, °)</h2><img src="tracking.svg" alt="tracking error">
<h2 id="pose">Tracked vs reference pose</h2><img src="pose.svg" alt="pose">
<h2 id="path">The ride's path</h2><p>{ride_path}</p><img src="path.svg" alt="ride path">
<h2 id="forces">Cable forces</h2><img src="forces.svg" alt="forces">
<h2 id="loop">Loop timing</h2><img src="loop.svg" alt="loop">
{extra}<p>Files of this run: {files}.</p>
</body></html>
"#,
        platform = html_escape(&summary.platform),
    );
    let index = out.join("index.html");
    if let Err(source) = std::fs::write(&index, html) {
        return Err(RunPlotError::Write {
            file: index,
            source,
        });
    }
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record() -> RunRecord {
        let mut r = RunRecord::new(1000.0, 9000.0);
        for k in 0..2000u64 {
            let mut sp = JointSetpoint {
                sequence: k + 1,
                cable_count: 8,
                timestamp_ns: 1_000_000_000 + k * 1_000_000 + if k >= 1500 { 4_000_000 } else { 0 },
                ..Default::default()
            };
            sp.pose[0] = k as f64 * 1e-4;
            sp.cable_length_m[..8].fill(5.0);
            r.setpoint(&sp);
            let mut t = PlantTruth {
                cable_count: 8,
                timestamp_ns: sp.timestamp_ns + 500_000,
                ..Default::default()
            };
            // 2 mm behind in x; the winches 0.5 mm longer than commanded.
            t.pose = sp.pose;
            t.pose[0] -= 2e-3;
            t.cable_length_m[..8].fill(5.0005);
            t.force_n[..8].fill(3000.0 + k as f64);
            r.truth(&t);
        }
        r
    }

    #[test]
    fn routine_announcements_are_events_only_when_they_change_something() {
        let mut r = record();
        // motion-core re-announces its plan about once a second, the monitor its epoch.
        for s in 0..5 {
            let mut e = StateEvent::plan(9000, s);
            e.timestamp_ns = 1_100_000_000 + s * 100_000_000;
            r.event(&e);
            let mut m = StateEvent::monitor(
                crs_ipc::MonitorState::Armed,
                crs_ipc::MonitorCode::EpochAnnounce,
                s,
            );
            m.timestamp_ns = e.timestamp_ns;
            r.event(&m);
        }
        let mut e = StateEvent::plan(9500, 9);
        e.timestamp_ns = 2_000_000_000;
        r.event(&e);
        let mut e = StateEvent::motion(crs_ipc::MotionState::Stopping, 10);
        e.timestamp_ns = 2_900_000_000;
        r.event(&e);
        let words: Vec<String> = r
            .events()
            .iter()
            .map(|e| format!("{}: {}", e.source, e.what))
            .collect();
        assert_eq!(
            words,
            [
                "motion-core: plan announced: ends with setpoint #9000",
                "safety-monitor: armed",
                "motion-core: plan announced: ends with setpoint #9500",
                "motion-core: end of the setpoint stream (planned)",
            ]
        );
        assert!(r.events().iter().all(|e| !e.alarm));
    }

    #[test]
    fn the_tracking_error_is_in_mm_against_the_newest_setpoint_before_each_state() {
        let r = record();
        assert_eq!(r.tracking.len(), 200);
        for s in &r.tracking {
            assert!((s.position_mm[0] + 2.0).abs() < 1e-6, "{:?}", s.position_mm);
            assert!((s.position_norm_mm - 2.0).abs() < 1e-6);
            assert!(s.rotation_deg.abs() < 1e-9);
            assert_eq!(s.length_mm.len(), 8);
            assert!(s.length_mm.iter().all(|l| (l - 0.5).abs() < 1e-6));
        }
    }

    #[test]
    fn writes_the_plots_and_an_index_with_named_fields_units_and_events_in_words() {
        let dir = std::env::temp_dir().join(format!("crs-sim-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = record();
        let mut e = StateEvent::new(ProcessId::Operator, EventKind::EStop, 1);
        e.timestamp_ns = 2_500_000_000;
        r.event(&e);
        // 1999 periods: 1998 of 1 ms, one of 5 ms (the stall) in the overflow bin.
        assert_eq!(r.period_hist.iter().sum::<u64>(), 1999);
        assert_eq!(*r.period_hist.last().unwrap(), 1);
        assert_eq!(r.period_hist[(1000.0 / BIN_US) as usize], 1998);
        let summary = Summary {
            platform: "icosahedron".into(),
            completed: false,
            stopped_by: Some("operator: stop requested by an operator".into()),
            setpoints: 2000,
            tracking_position_mean_mm: 1.25,
            static_position_mm: f64::NAN,
            force_min_n: 3000.0,
            force_max_n: 4999.0,
            f_min_n: 1000.0,
            f_max_n: 9000.0,
            estops: 1,
            ..Summary::default()
        };
        std::fs::write(dir.join("summary.json"), "{}").unwrap();
        let index = write(&dir, &r, &summary).unwrap();
        let html = std::fs::read_to_string(index).unwrap();
        assert!(html.contains(
            "<tr data-field=\"tracking_position_mean_mm\"><th>position error, mean</th><td class=\"value\">1.25</td><td class=\"unit\">mm</td></tr>"
        ), "{html}");
        assert!(
            html.contains("STOPPED before the ride ended: operator: stop requested by an operator")
        );
        assert!(html.contains("not reached (the run was stopped)"));
        assert!(html.contains("<td>operator</td><td>E-STOP: stop requested by an operator</td>"));
        let coded = html
            .match_indices("state ")
            .any(|(i, _)| html[i + 6..].starts_with(|c: char| c.is_ascii_digit()));
        assert!(!coded, "a state code in the report");
        // Only the files that exist are linked.
        assert!(html.contains("<a href=\"summary.json\">") && !html.contains("drive-io.log"));
        for f in [
            "pose.svg",
            "tracking.svg",
            "path.svg",
            "forces.svg",
            "loop.svg",
            "events.svg",
        ] {
            let svg = std::fs::read_to_string(dir.join(f)).unwrap();
            assert!(svg.starts_with("<svg") && svg.len() > 2000, "{f}");
            assert!(html.contains(&format!("src=\"{f}\"")), "{f} not shown");
        }
        // The force plot's legend names 8 cables and the limits, in the strip above the plot.
        let svg = std::fs::read_to_string(dir.join("forces.svg")).unwrap();
        for label in ["cable 1", "cable 8", "f_min, f_max"] {
            let at = svg.find(&format!(">\n{label}\n</text>")).expect(label);
            let tag = &svg[svg[..at].rfind("<text").unwrap()..at];
            let y: f64 = tag
                .split("y=\"")
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap()
                .parse()
                .unwrap();
            assert!(
                y < f64::from(crs_plot::LEGEND_STRIP_PX),
                "{label} at y = {y}: {tag}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
