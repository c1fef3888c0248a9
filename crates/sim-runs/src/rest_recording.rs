//! Rest points of a run on the simulated stack (`crs sim --record`): the measured samples of a
//! calibration campaign (spec ch. 6.1: W_S = {x_M, q_θ, f_M}) taken from the live topics.
//!
//! A rest point is a stretch in which motion-core's reference (pose and commanded lengths) stays
//! constant for at least the settle time. Its sample is the LAST tracker pose and the last
//! force-sensor readings stamped inside the window [start + settle, last setpoint of that
//! reference] — the platform has settled and the reference has not moved yet. Readings arrive on
//! other topics than the setpoints (and may be drained later), so a finished window waits until
//! both the tracker and the force stream have passed its end before it is sampled; nothing
//! depends on sleeps. Timestamps are CLOCK_MONOTONIC ns of the publishers (one host).

use cdpr_model::Pose;
use std::collections::VecDeque;

/// Why a recording could not be set up or converted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RecordingError {
    #[error("--settle-s must be finite and > 0, got {0}")]
    SettleTime(f64),
    #[error("rest point {index}: {lengths} lengths / {forces} forces for {cables} cables")]
    ShortSample {
        index: usize,
        lengths: usize,
        forces: usize,
        cables: usize,
    },
}

/// Readings kept per stream (≈ 4 s at 1 kHz: far more than the few ms a window waits).
const RING: usize = 4096;

/// One rest point.
#[derive(Clone, Debug, PartialEq)]
pub struct RestSample {
    /// Reference pose x_ref (m, rad).
    pub reference: [f64; 6],
    /// Commanded lengths q_θ motion-core sent (what the drives hold), m.
    pub q_cmd: Vec<f64>,
    /// Tracker (measured) pose, m, rad.
    pub measured_pose: [f64; 6],
    /// Force-sensor readings, N.
    pub measured_forces: Vec<f64>,
    /// Ground truth of the plant at the same time, when it was followed.
    pub true_pose: Option<[f64; 6]>,
    /// Reference constant from `since_ns` to `until_ns` (setpoint stamps).
    pub since_ns: u64,
    pub until_ns: u64,
    /// Stamp of the tracker reading used.
    pub reading_ns: u64,
}

/// A constant-reference stretch long enough to be a rest point but without readings in its
/// window (tracker invalid, force feedback missing).
#[derive(Clone, Debug, PartialEq)]
pub struct Skipped {
    pub reference: [f64; 6],
    pub reason: String,
}

#[derive(Clone, Debug)]
struct Held {
    pose: [f64; 6],
    q: Vec<f64>,
    since_ns: u64,
    last_ns: u64,
}

struct Ring<T> {
    buf: VecDeque<(u64, T)>,
}

impl<T> Ring<T> {
    fn new() -> Self {
        Self {
            buf: VecDeque::with_capacity(RING),
        }
    }
    fn push(&mut self, ts: u64, v: T) {
        if self.buf.len() == RING {
            self.buf.pop_front();
        }
        self.buf.push_back((ts, v));
    }
    fn newest_ns(&self) -> Option<u64> {
        self.buf.iter().map(|(t, _)| *t).max()
    }
    /// The newest reading stamped in [lo, hi].
    fn latest_in(&self, lo: u64, hi: u64) -> Option<&(u64, T)> {
        self.buf
            .iter()
            .filter(|(t, _)| *t >= lo && *t <= hi)
            .max_by_key(|(t, _)| *t)
    }
}

impl Ring<Vec<f64>> {
    /// The element-wise mean of the readings stamped in [lo, hi] (stamped with the newest),
    /// over the readings as long as the first one.
    fn mean_in(&self, lo: u64, hi: u64) -> Option<(u64, Vec<f64>)> {
        let mut inside = self.buf.iter().filter(|(t, _)| *t >= lo && *t <= hi);
        let (t0, first) = inside.next()?;
        let (mut newest, mut sum, mut n) = (*t0, first.clone(), 1.0);
        for (t, v) in inside.filter(|(_, v)| v.len() == first.len()) {
            newest = newest.max(*t);
            sum.iter_mut().zip(v).for_each(|(s, x)| *s += x);
            n += 1.0;
        }
        sum.iter_mut().for_each(|s| *s /= n);
        Some((newest, sum))
    }
}

/// Detects rest points and samples them (module docs).
pub struct RestRecorder {
    settle_ns: u64,
    /// Two references are the same when every pose coordinate and length differs by less.
    tolerance: f64,
    held: Option<Held>,
    pending: VecDeque<Held>,
    tracker: Ring<[f64; 6]>,
    forces: Ring<Vec<f64>>,
    truth: Ring<[f64; 6]>,
    /// Sample the mean of the force readings in the settled window, not the last one.
    mean_forces: bool,
    pub samples: Vec<RestSample>,
    pub skipped: Vec<Skipped>,
}

impl RestRecorder {
    /// `settle_s`: how long the reference must have been constant before readings count.
    pub fn new(settle_s: f64) -> Result<Self, RecordingError> {
        if !(settle_s.is_finite() && settle_s > 0.0) {
            return Err(RecordingError::SettleTime(settle_s));
        }
        Ok(Self {
            settle_ns: (settle_s * 1e9) as u64,
            tolerance: 1e-9,
            held: None,
            pending: VecDeque::new(),
            tracker: Ring::new(),
            forces: Ring::new(),
            truth: Ring::new(),
            mean_forces: false,
            samples: Vec::new(),
            skipped: Vec::new(),
        })
    }

    /// With `mean`, a rest point's forces are the mean of every force reading in its settled
    /// window (σ/√n for n readings of independent sensor noise) instead of the last reading.
    pub fn averaging_forces(mut self, mean: bool) -> Self {
        self.mean_forces = mean;
        self
    }

    fn same(&self, h: &Held, pose: &[f64; 6], q: &[f64]) -> bool {
        h.q.len() == q.len()
            && h.pose
                .iter()
                .zip(pose)
                .chain(h.q.iter().zip(q))
                .all(|(a, b)| (a - b).abs() <= self.tolerance)
    }

    /// A setpoint of motion-core: reference pose and commanded lengths at `ts`.
    pub fn setpoint(&mut self, ts: u64, pose: [f64; 6], q: &[f64]) {
        let same = self
            .held
            .as_ref()
            .is_some_and(|h| ts >= h.last_ns && self.same(h, &pose, q));
        if same {
            if let Some(h) = self.held.as_mut() {
                h.last_ns = ts;
            }
        } else {
            self.close_held();
            self.held = Some(Held {
                pose,
                q: q.to_vec(),
                since_ns: ts,
                last_ns: ts,
            });
        }
        self.flush(false);
    }

    /// A tracker reading (`valid` = the tracker sees the platform).
    pub fn tracker(&mut self, ts: u64, pose: [f64; 6], valid: bool) {
        if valid {
            self.tracker.push(ts, pose);
        }
        self.flush(false);
    }

    /// Force-sensor readings (drive-io's feedback), N.
    pub fn forces(&mut self, ts: u64, f: &[f64]) {
        self.forces.push(ts, f.to_vec());
        self.flush(false);
    }

    /// The plant's true pose (for the ground-truth error next to the measured one).
    pub fn truth(&mut self, ts: u64, pose: [f64; 6]) {
        self.truth.push(ts, pose);
    }

    /// End of the run: the last stretch counts if it lasted long enough; every waiting window
    /// is sampled with what arrived.
    pub fn finish(&mut self) {
        self.close_held();
        self.flush(true);
    }

    fn close_held(&mut self) {
        if let Some(h) = self.held.take()
            && h.last_ns.saturating_sub(h.since_ns) >= self.settle_ns
        {
            self.pending.push_back(h);
        }
    }

    fn flush(&mut self, all: bool) {
        while let Some(h) = self.pending.front() {
            let passed = |n: Option<u64>| n.is_some_and(|t| t >= h.last_ns);
            let ready = passed(self.tracker.newest_ns()) && passed(self.forces.newest_ns());
            if !(all || ready) {
                break;
            }
            let h = self.pending.pop_front().expect("front exists");
            self.sample(h);
        }
    }

    fn sample(&mut self, h: Held) {
        let lo = h.since_ns + self.settle_ns;
        let tr = self.tracker.latest_in(lo, h.last_ns).cloned();
        let fr = if self.mean_forces {
            self.forces.mean_in(lo, h.last_ns)
        } else {
            self.forces.latest_in(lo, h.last_ns).cloned()
        };
        match (tr, fr) {
            (Some((t_ts, pose)), Some((_, f))) => {
                let true_pose = self.truth.latest_in(lo, h.last_ns).map(|(_, p)| *p);
                self.samples.push(RestSample {
                    reference: h.pose,
                    q_cmd: h.q,
                    measured_pose: pose,
                    measured_forces: f,
                    true_pose,
                    since_ns: h.since_ns,
                    until_ns: h.last_ns,
                    reading_ns: t_ts,
                });
            }
            (t, f) => self.skipped.push(Skipped {
                reference: h.pose,
                reason: format!(
                    "no {} reading in the settled window",
                    match (t.is_none(), f.is_none()) {
                        (true, true) => "tracker or force",
                        (true, false) => "valid tracker",
                        _ => "force",
                    }
                ),
            }),
        }
    }
}

/// Pose errors at the rest points: measured (tracker vs reference) and true (plant vs reference).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RestErrors {
    pub rest_points: usize,
    pub position_mean_mm: f64,
    pub position_max_mm: f64,
    pub rotation_mean_deg: f64,
    pub rotation_max_deg: f64,
    pub true_position_mean_mm: f64,
    pub true_position_max_mm: f64,
    pub true_rotation_mean_deg: f64,
    pub true_rotation_max_deg: f64,
}

pub fn rest_errors(samples: &[RestSample]) -> RestErrors {
    let mut e = RestErrors {
        rest_points: samples.len(),
        ..RestErrors::default()
    };
    if samples.is_empty() {
        return e;
    }
    let n = samples.len() as f64;
    let (mut nt, mut sp, mut sr, mut tp, mut tr) = (0usize, 0.0, 0.0, 0.0, 0.0);
    for s in samples {
        let r = Pose::from_array(s.reference);
        let (dp, dr) = Pose::from_array(s.measured_pose).error_to(&r);
        sp += dp;
        sr += dr;
        e.position_max_mm = e.position_max_mm.max(dp * 1e3);
        e.rotation_max_deg = e.rotation_max_deg.max(dr.to_degrees());
        if let Some(t) = s.true_pose {
            let (dp, dr) = Pose::from_array(t).error_to(&r);
            nt += 1;
            tp += dp;
            tr += dr;
            e.true_position_max_mm = e.true_position_max_mm.max(dp * 1e3);
            e.true_rotation_max_deg = e.true_rotation_max_deg.max(dr.to_degrees());
        }
    }
    e.position_mean_mm = sp / n * 1e3;
    e.rotation_mean_deg = (sr / n).to_degrees();
    if nt > 0 {
        e.true_position_mean_mm = tp / nt as f64 * 1e3;
        e.true_rotation_mean_deg = (tr / nt as f64).to_degrees();
    }
    e
}

/// The rest points as a `crs-dataset 1` data set (docs/data-format.md): q_cmd = the commanded
/// lengths, x..phi_z = the tracker pose, f_i = the force sensors, x_ref.. = the reference.
pub fn to_dataset(
    samples: &[RestSample],
    m: usize,
    metadata: Vec<(String, String)>,
) -> Result<crs_dataset::Dataset, RecordingError> {
    let mut ds = crs_dataset::Dataset::new(m, true, true);
    ds.metadata = metadata;
    for (k, s) in samples.iter().enumerate() {
        if s.q_cmd.len() < m || s.measured_forces.len() < m {
            return Err(RecordingError::ShortSample {
                index: k,
                lengths: s.q_cmd.len(),
                forces: s.measured_forces.len(),
                cables: m,
            });
        }
        ds.samples.push(crs_dataset::Sample {
            sample: k as u64,
            pose_index: k as u64,
            phase: crs_dataset::Phase::Pose,
            q_cmd: s.q_cmd[..m].to_vec(),
            pose: Pose::from_array(s.measured_pose),
            forces: Some(s.measured_forces[..m].to_vec()),
            pose_ref: Some(Pose::from_array(s.reference)),
        });
    }
    Ok(ds)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn pose(x: f64) -> [f64; 6] {
        [x, 0.0, 2.0, 0.0, 0.0, 0.0]
    }

    /// A 1 kHz stream: the reference dwells at A (t 0..1 s), moves (1..1.5 s), dwells at B
    /// (1.5..2.3 s); tracker and forces follow with a 2 ms delay and carry the time in their
    /// values so the test can tell which reading was taken.
    fn feed(r: &mut RestRecorder, drain_readings_late: bool) {
        let mut late: Vec<(u64, f64)> = Vec::new();
        for k in 0..2300u64 {
            let ts = k * MS;
            let x = if k < 1000 {
                0.1
            } else if k < 1500 {
                0.1 + 0.2 * (k - 999) as f64 / 501.0
            } else {
                0.3
            };
            r.setpoint(ts, pose(x), &[x + 8.0, 9.0]);
            if k >= 2 {
                let tr = (k - 2) as f64;
                if drain_readings_late {
                    late.push(((k - 2) * MS, tr));
                } else {
                    r.tracker((k - 2) * MS, pose(tr), true);
                    r.forces((k - 2) * MS, &[tr, tr]);
                }
            }
            // Drained in bursts of 50 after the setpoints (as a 5 ms poll loop would, worse).
            if drain_readings_late && late.len() >= 50 {
                for (t, v) in late.drain(..) {
                    r.tracker(t, pose(v), true);
                    r.forces(t, &[v, v]);
                    r.truth(t, pose(v));
                }
            }
        }
        for (t, v) in late.drain(..) {
            r.tracker(t, pose(v), true);
            r.forces(t, &[v, v]);
        }
        r.finish();
    }

    #[test]
    fn takes_the_last_reading_before_the_reference_moves() {
        for late in [false, true] {
            let mut r = RestRecorder::new(0.5).unwrap();
            feed(&mut r, late);
            assert_eq!(r.samples.len(), 2, "late = {late}: {:?}", r.skipped);
            let a = &r.samples[0];
            assert_eq!(a.reference, pose(0.1));
            assert_eq!(a.q_cmd, vec![8.1, 9.0]);
            // Reference constant over setpoints 0..=999 ms: the last reading stamped ≤ 999 ms.
            assert_eq!(a.until_ns, 999 * MS);
            assert_eq!(a.measured_pose[0], 999.0, "late = {late}");
            assert_eq!(a.measured_forces, vec![999.0, 999.0]);
            let b = &r.samples[1];
            assert_eq!(b.reference, pose(0.3));
            // B lasts 1500..=2299 ms; the last reading before the run ended is stamped 2297.
            assert_eq!(b.measured_pose[0], 2297.0);
            assert_eq!(b.since_ns, 1500 * MS);
        }
    }

    #[test]
    fn averaging_takes_the_mean_of_the_settled_window_only() {
        for late in [false, true] {
            let mut r = RestRecorder::new(0.5).unwrap().averaging_forces(true);
            feed(&mut r, late);
            assert_eq!(r.samples.len(), 2);
            // A: readings stamped 500..=999 ms carry 500..=999; nothing from the motion after.
            assert_eq!(
                r.samples[0].measured_forces,
                vec![749.5, 749.5],
                "late = {late}"
            );
            // The pose stays the last tracker reading.
            assert_eq!(r.samples[0].measured_pose[0], 999.0);
            // B: 2000..=2297 ms.
            assert_eq!(r.samples[1].measured_forces, vec![2148.5, 2148.5]);
        }
    }

    #[test]
    fn short_dwells_and_missing_readings_are_not_samples() {
        // Settle 0.9 s: A (setpoints 0..=999 ms) counts, B (1500..=2299 ms) does not.
        let mut r = RestRecorder::new(0.9).unwrap();
        feed(&mut r, false);
        assert_eq!(r.samples.len(), 1);
        assert_eq!(r.samples[0].reference, pose(0.1));
        // Settle 1.0 s: neither (A spans 0.999 s); the motion in between never counts.
        let mut r = RestRecorder::new(1.0).unwrap();
        feed(&mut r, false);
        assert!(r.samples.is_empty());
        // A settled window without tracker readings is reported, not sampled.
        let mut r = RestRecorder::new(0.2).unwrap();
        for k in 0..500u64 {
            r.setpoint(k * MS, pose(0.0), &[8.0]);
            r.forces(k * MS, &[5000.0]);
            r.tracker(k * MS, pose(0.0), false);
        }
        r.finish();
        assert!(r.samples.is_empty());
        assert_eq!(r.skipped.len(), 1);
        assert!(r.skipped[0].reason.contains("tracker"), "{:?}", r.skipped);
        assert!(RestRecorder::new(0.0).is_err());
        assert!(RestRecorder::new(f64::NAN).is_err());
    }

    #[test]
    fn errors_and_dataset_of_the_samples() {
        let s = RestSample {
            reference: pose(0.1),
            q_cmd: vec![8.0, 9.0],
            measured_pose: [0.103, 0.004, 2.0, 0.0, 0.0, 0.01],
            measured_forces: vec![4000.0, 5000.0],
            true_pose: Some([0.1, 0.0, 2.0, 0.0, 0.0, 0.0]),
            since_ns: 0,
            until_ns: 1,
            reading_ns: 1,
        };
        let e = rest_errors(&[s.clone(), s.clone()]);
        assert_eq!(e.rest_points, 2);
        assert!((e.position_mean_mm - 5.0).abs() < 1e-9, "{e:?}");
        assert!((e.position_max_mm - 5.0).abs() < 1e-9);
        assert!((e.rotation_mean_deg - 0.01f64.to_degrees()).abs() < 1e-9);
        assert_eq!(e.true_position_max_mm, 0.0);
        let ds = to_dataset(
            std::slice::from_ref(&s),
            2,
            vec![("campaign".into(), "t".into())],
        )
        .unwrap();
        let mut buf = Vec::new();
        crs_dataset::write_dataset(&mut buf, &ds).unwrap();
        let back = crs_dataset::read_dataset(&buf[..], "mem").unwrap();
        assert_eq!(back.samples.len(), 1);
        assert_eq!(back.samples[0].q_cmd, vec![8.0, 9.0]);
        assert_eq!(back.samples[0].pose.to_array(), s.measured_pose);
        assert_eq!(back.samples[0].pose_ref.unwrap().to_array(), s.reference);
        assert_eq!(back.meta("campaign"), Some("t"));
        assert!(to_dataset(&[s], 3, vec![]).is_err());
    }
}
