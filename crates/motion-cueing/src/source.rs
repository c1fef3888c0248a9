//! A drive as a stream of cabin motion, in three phases:
//!
//! 1. [`Phase::ToNeutral`]: from the platform's home pose to the washout's neutral pose along a
//!    quintic (zero velocity and acceleration at both ends) slow enough for half the limiter's
//!    velocity and acceleration;
//! 2. [`Phase::Drive`]: the vehicle track, faded in from rest (and out at its end) over
//!    `fade_s`, one [`washout::step`] per sample period; after the track the washout runs on
//!    until the cabin rests at the neutral pose (or `settle_max_s` passed);
//! 3. [`Phase::ToHome`]: a quintic back to home from wherever the drive left the cabin.
//!
//! What `crs sim --source cueing` runs at 1 kHz and what the tests and the tuning comparison
//! run offline.

use crate::settings::CueingSettings;
use crate::vehicle::{VehicleSample, VehicleTrack};
use crate::washout::{self, CueOutput, TrackerLimits, Washout, WashoutState};
use cdpr_model::Pose;

/// The cabin counts as at rest at the neutral pose below these (m or rad, m/s or rad/s).
pub const SETTLED_POSITION: f64 = 1e-4;
pub const SETTLED_VELOCITY: f64 = 1e-4;
/// Share of the limiter's velocity and acceleration a transition uses.
pub const TRANSITION_SHARE: f64 = 0.5;

/// Which part of a run a sample belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Phase {
    ToNeutral,
    Drive,
    ToHome,
}

/// One sample: the phase, time since the run's start and since the drive's start (s), the
/// vehicle's motion (as recorded, no fade; at rest outside the drive) and the cueing's output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveSample {
    pub phase: Phase,
    pub t_s: f64,
    pub drive_t_s: f64,
    pub vehicle: VehicleSample,
    pub cue: CueOutput,
}

/// A quintic per coordinate from (p0, v0, a0) to (p1, 0, 0) over `duration`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Quintic {
    c: [[f64; 6]; 6],
    duration: f64,
}

impl Quintic {
    fn new(p0: [f64; 6], v0: [f64; 6], a0: [f64; 6], p1: [f64; 6], duration: f64) -> Self {
        let t = duration;
        let mut c = [[0.0; 6]; 6];
        for k in 0..6 {
            let (d, v, a) = (p1[k] - p0[k], v0[k], a0[k]);
            // p(τ) = p0 + v τ + a/2 τ² + c3 τ³ + c4 τ⁴ + c5 τ⁵ with p, ṗ, p̈ at T = (p1, 0, 0).
            let c3 = (20.0 * d - (12.0 * v + 3.0 * a * t) * t) / (2.0 * t.powi(3));
            let c4 = (-30.0 * d + (16.0 * v + 3.0 * a * t) * t) / (2.0 * t.powi(4));
            let c5 = (12.0 * d - (6.0 * v + a * t) * t) / (2.0 * t.powi(5));
            c[k] = [p0[k], v, 0.5 * a, c3, c4, c5];
        }
        Self { c, duration }
    }

    /// Shortest duration (≥ 1 s) whose peak speed 1.875 d/T and acceleration 5.774 d/T² of a
    /// rest-to-rest quintic stay within `v`, `a` per coordinate (linear, angular).
    fn duration_for(p0: &[f64; 6], p1: &[f64; 6], v: [f64; 2], a: [f64; 2]) -> f64 {
        let mut t: f64 = 1.0;
        for k in 0..6 {
            let d = (p1[k] - p0[k]).abs();
            let i = usize::from(k >= 3);
            t = t.max(1.875 * d / v[i]).max((5.774 * d / a[i]).sqrt());
        }
        t
    }

    fn at(&self, tau: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
        let t = tau.clamp(0.0, self.duration);
        let (mut p, mut v, mut a) = ([0.0; 6], [0.0; 6], [0.0; 6]);
        for k in 0..6 {
            let c = &self.c[k];
            p[k] = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
            v[k] = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])));
            a[k] = 2.0 * c[2] + t * (6.0 * c[3] + t * (12.0 * c[4] + t * 20.0 * c[5]));
        }
        (p, v, a)
    }
}

/// The running drive (Data around the immutable [`Washout`]).
pub struct CueingSource {
    washout: Washout,
    state: WashoutState,
    track: VehicleTrack,
    home: Pose,
    fade_s: f64,
    settle_max_s: f64,
    phase: Phase,
    transition: Quintic,
    /// Samples since the run's start and since the current phase's start.
    k: u64,
    k_phase: u64,
    /// Time the cabin has been at rest after the drive, s.
    settled_s: f64,
    last: Option<CueOutput>,
}

impl CueingSource {
    /// A run from the platform's `home` through `track` and back.
    pub fn new(
        washout: Washout,
        settings: &CueingSettings,
        track: VehicleTrack,
        home: Pose,
    ) -> Self {
        let state = washout.at_rest();
        let transition = Self::transition(
            &washout,
            home.to_array(),
            [0.0; 6],
            [0.0; 6],
            washout.neutral.to_array(),
        );
        Self {
            washout,
            state,
            track,
            home,
            fade_s: settings.fade_s,
            settle_max_s: settings.settle_max_s,
            phase: Phase::ToNeutral,
            transition,
            k: 0,
            k_phase: 0,
            settled_s: 0.0,
            last: None,
        }
    }

    fn transition(w: &Washout, p0: [f64; 6], v0: [f64; 6], a0: [f64; 6], p1: [f64; 6]) -> Quintic {
        let ws = &w.params.workspace;
        let t = Quintic::duration_for(
            &p0,
            &p1,
            [ws.linear_velocity_max, ws.angular_velocity_max].map(|v| v * TRANSITION_SHARE),
            [ws.linear_acceleration_max, ws.angular_acceleration_max].map(|a| a * TRANSITION_SHARE),
        );
        Quintic::new(p0, v0, a0, p1, t)
    }

    pub fn washout(&self) -> &Washout {
        &self.washout
    }

    /// The target for motion-core's cueing tracker for `sample` ([`washout::tracker_target`]):
    /// clamped to the cueing box while driving, and to the ends of the move while moving to or
    /// from the neutral pose.
    pub fn tracker_target(&self, sample: &DriveSample, lim: &TrackerLimits) -> [f64; 6] {
        match sample.phase {
            Phase::Drive => washout::tracker_target(
                &sample.cue,
                lim,
                &self.washout.box_min,
                &self.washout.box_max,
            ),
            Phase::ToNeutral | Phase::ToHome => {
                let (a, b) = (
                    self.transition.c.map(|c| c[0]),
                    self.transition.at(self.transition.duration).0,
                );
                let lo = std::array::from_fn(|k| a[k].min(b[k]));
                let hi = std::array::from_fn(|k| a[k].max(b[k]));
                washout::tracker_target(&sample.cue, lim, &lo, &hi)
            }
        }
    }

    pub fn state(&self) -> &WashoutState {
        &self.state
    }

    /// Length of the vehicle track, s.
    pub fn drive_s(&self) -> f64 {
        self.track.duration_s()
    }

    fn transition_sample(&self, t: f64, tau: f64, drive_t: f64) -> DriveSample {
        let (pose, velocity, acceleration) = self.transition.at(tau);
        let rest = VehicleSample::at_rest(self.washout.params.gravity);
        DriveSample {
            phase: self.phase,
            t_s: t,
            drive_t_s: drive_t,
            vehicle: rest,
            cue: CueOutput {
                pose,
                velocity,
                acceleration,
                desired: pose,
                scaled: rest,
                tilt: [0.0; 2],
                tilt_rate: [0.0; 2],
                limited: false,
            },
        }
    }

    /// The next sample, None once the cabin is back home.
    pub fn next_sample(&mut self) -> Option<DriveSample> {
        let dt = self.washout.dt;
        let t = self.k as f64 * dt;
        let tau = self.k_phase as f64 * dt;
        let sample = match self.phase {
            Phase::ToNeutral => {
                if tau > self.transition.duration {
                    self.phase = Phase::Drive;
                    self.k_phase = 0;
                    return self.next_sample();
                }
                self.transition_sample(t, tau, 0.0)
            }
            Phase::Drive => match self.drive_step(tau) {
                Some(s) => s,
                None => {
                    let last = self
                        .last
                        .map_or(self.washout.neutral.to_array(), |c| c.pose);
                    let (v0, a0) = self
                        .last
                        .map_or(([0.0; 6], [0.0; 6]), |c| (c.velocity, c.acceleration));
                    self.transition =
                        Self::transition(&self.washout, last, v0, a0, self.home.to_array());
                    self.phase = Phase::ToHome;
                    self.k_phase = 0;
                    return self.next_sample();
                }
            },
            Phase::ToHome => {
                if tau > self.transition.duration {
                    return None;
                }
                let drive_t = self.track.duration_s() + tau;
                self.transition_sample(t, tau, drive_t)
            }
        };
        self.k += 1;
        self.k_phase += 1;
        self.last = Some(sample.cue);
        Some(sample)
    }

    /// One washout step of the drive at drive time `t` (None once it is over).
    fn drive_step(&mut self, t: f64) -> Option<DriveSample> {
        let dt = self.washout.dt;
        let g = self.washout.params.gravity;
        let rest = VehicleSample::at_rest(g);
        let drive = self.track.duration_s();
        let vehicle = self.track.at(self.track.start_s() + t);
        if vehicle.is_none() {
            let n = self.washout.neutral.to_array();
            let still = (0..6).all(|k| {
                (self.state.pos[k] - n[k]).abs() < SETTLED_POSITION
                    && self.state.vel[k].abs() < SETTLED_VELOCITY
            });
            self.settled_s = if still { self.settled_s + dt } else { 0.0 };
            if self.settled_s >= 0.2 || t - drive > self.settle_max_s {
                return None;
            }
        }
        let v = vehicle.unwrap_or(rest);
        // Fade weight: smoothstep in over the first fade_s and out over the last.
        let w = if self.fade_s > 0.0 {
            let s = (t / self.fade_s)
                .min((drive - t) / self.fade_s)
                .clamp(0.0, 1.0);
            s * s * (3.0 - 2.0 * s)
        } else if vehicle.is_some() {
            1.0
        } else {
            0.0
        };
        let input = rest.lerp(&v, w);
        let cue = washout::step(&self.washout, &mut self.state, &input);
        Some(DriveSample {
            phase: Phase::Drive,
            t_s: self.k as f64 * dt,
            drive_t_s: t,
            vehicle: v,
            cue,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quintic_meets_its_boundary_conditions() {
        let q = Quintic::new([0.0; 6], [0.1; 6], [0.2; 6], [1.0; 6], 3.0);
        let (p, v, a) = q.at(0.0);
        assert!((p[0]).abs() < 1e-12 && (v[0] - 0.1).abs() < 1e-12 && (a[0] - 0.2).abs() < 1e-12);
        let (p, v, a) = q.at(3.0);
        assert!(
            (p[2] - 1.0).abs() < 1e-12 && v[2].abs() < 1e-12 && a[2].abs() < 1e-12,
            "{p:?} {v:?} {a:?}"
        );
        // Rest to rest: peak speed and acceleration as the duration rule assumes.
        let q = Quintic::new([0.0; 6], [0.0; 6], [0.0; 6], [1.0; 6], 2.0);
        let (mut vmax, mut amax) = (0.0f64, 0.0f64);
        for i in 0..=2000 {
            let (_, v, a) = q.at(i as f64 * 1e-3);
            vmax = vmax.max(v[0].abs());
            amax = amax.max(a[0].abs());
        }
        assert!(
            (vmax - 1.875 / 2.0).abs() < 1e-3 && amax <= 5.774 / 4.0 + 1e-3,
            "{vmax} {amax}"
        );
    }
}
