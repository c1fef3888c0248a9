//! The classical washout (Reid & Nahon 1985; Conrad & Schmidt 1970) with tilt coordination
//! (Nesti et al. 2012; spec sec. 5.6 and introduction), scaled and limited for the CRS cabin.
//!
//! Per sample (all filters discretised exactly for a held input, [`crate::lti`]):
//!
//! 1. **Scaling and limiting**: the vehicle's specific force deviation from rest, f − [0, 0, g],
//!    and its angular velocity ω are scaled per axis and limited smoothly,
//!    x ↦ L tanh(K x / L) (gain K near zero, never beyond L).
//! 2. **Tilt coordination** (the sustained part, through gravity): the scaled f_x, f_y pass a
//!    second-order low-pass ω_t²/(s² + 2ζ_t ω_t s + ω_t²); the tilt that makes gravity supply
//!    them (R = R_x R_y: f_x = −g sin φ_y cos φ_x, f_y = g sin φ_x) is
//!    φ_y = −asin(f_x/g), φ_x = asin(f_y/g), clamped to the tilt range and followed with
//!    |φ̇| ≤ the rotation perception threshold (≈ 3°/s) and a bounded angular acceleration, so
//!    the rider does not feel the cabin tilt, only the force.
//! 3. **Translational channel** (the onsets): the cabin acceleration that would reproduce the
//!    scaled specific force at the cabin's current attitude, a = R(β) f_s + g (Reid & Nahon's
//!    L_IS), through a third-order high-pass
//!    s³ / ((s² + 2ζ ω_n s + ω_n²)(s + ω_b)) per world axis; its double integral
//!    s / ((s² + 2ζ ω_n s + ω_n²)(s + ω_b)) is the position, which returns to neutral after any
//!    sustained input (final value 0). As the tilt builds up, R(β) f_s + g loses its horizontal
//!    part and the translation washes out.
//! 4. **Rotational channel**: the scaled ω through a third-order high-pass per axis, integrated
//!    once: angle s² / den(s), also back to neutral after a sustained rate (a turning train's
//!    yaw rate). Pose-coordinate rates are taken equal to the body rates (small angles: the
//!    cabin's ±5° make J_P ≈ E to 0.4 %).
//! 5. **Workspace limiter** (per pose coordinate): follows the desired pose (feed-forward
//!    acceleration plus a critically damped return) with |v| ≤ v_max, |a| ≤ a_max and a
//!    braking-distance bound that can always stop inside the cueing box at a_max, so every
//!    pose stays inside the box — which lies inside the platform's operating region and is
//!    checked wrench feasible for these accelerations ([`crate::settings`]).
//!
//! Model/Data split: [`Washout`] is immutable, [`WashoutState`] the state; [`step`] allocates
//! nothing.

use crate::lti::{Lti, LtiError};
use crate::vehicle::VehicleSample;
use cdpr_model::Pose;
use nalgebra::{SVector, Vector3};

/// A third-order high-pass s³ / ((s² + 2ζ ω_n s + ω_n²)(s + ω_b)) (rad/s, –, rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HighPass {
    pub omega_n: f64,
    pub zeta: f64,
    pub omega_b: f64,
}

impl HighPass {
    /// The denominator (s² + 2ζ ω_n s + ω_n²)(s + ω_b), descending powers.
    pub fn denominator(&self) -> [f64; 4] {
        let (w, z, b) = (self.omega_n, self.zeta, self.omega_b);
        [1.0, 2.0 * z * w + b, w * w + 2.0 * z * w * b, w * w * b]
    }
}

/// Tilt coordination: low-pass, tilt range and the tilt's rate and acceleration bounds (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TiltParams {
    pub omega_n: f64,
    pub zeta: f64,
    /// Largest tilt about x (roll, φ_x) and y (pitch, φ_y), rad.
    pub max_rad: [f64; 2],
    /// |φ̇| bound of the tilt, rad/s: the rotation perception threshold.
    pub rate_max: f64,
    /// |φ̈| bound of the tilt, rad/s².
    pub acceleration_max: f64,
}

/// The cueing workspace and the limiter's bounds (SI). The washout moves the cabin about a
/// neutral pose (the home pose offset by `neutral_offset`, `neutral_rotation`: the icosahedron's
/// closed-form wrench-feasible set is small and lopsided around home), inside a box relative
/// to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkspaceParams {
    pub neutral_offset: Vector3<f64>,
    /// Rotation coordinates of the neutral pose relative to home, rad.
    pub neutral_rotation: Vector3<f64>,
    /// The cueing box relative to the neutral pose.
    pub position_min: Vector3<f64>,
    pub position_max: Vector3<f64>,
    /// Symmetric rotation range about the neutral orientation, rad.
    pub rotation_max: Vector3<f64>,
    pub linear_velocity_max: f64,
    pub linear_acceleration_max: f64,
    pub angular_velocity_max: f64,
    pub angular_acceleration_max: f64,
    /// Natural frequency of the limiter's critically damped return to the desired pose, rad/s.
    pub return_omega: f64,
}

/// Every parameter of the cueing, validated by [`crate::settings`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WashoutParams {
    /// Gain K and limit L of the specific force's deviation from rest (per cabin axis, m/s²).
    pub specific_force_gain: Vector3<f64>,
    pub specific_force_limit: Vector3<f64>,
    /// Gain and limit of the angular velocity (rad/s).
    pub angular_velocity_gain: Vector3<f64>,
    pub angular_velocity_limit: Vector3<f64>,
    pub translation: [HighPass; 3],
    pub rotation: [HighPass; 3],
    pub tilt: TiltParams,
    pub workspace: WorkspaceParams,
    /// The rider's head in cabin coordinates, m (where the specific force is felt).
    pub head_m: Vector3<f64>,
    /// Gravity, m/s².
    pub gravity: f64,
}

/// The washout for one platform and sample period (Model).
#[derive(Clone, Debug, PartialEq)]
pub struct Washout {
    pub params: WashoutParams,
    /// The neutral pose the washout returns to (home + the neutral offsets).
    pub neutral: Pose,
    pub dt: f64,
    /// The cueing box in pose coordinates (absolute), per coordinate.
    pub box_min: [f64; 6],
    pub box_max: [f64; 6],
    v_max: [f64; 6],
    a_max: [f64; 6],
    translation: [Lti<3>; 3],
    rotation: [Lti<3>; 3],
    tilt_low_pass: Lti<2>,
}

/// The washout's state (Data).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WashoutState {
    translation: [SVector<f64, 3>; 3],
    rotation: [SVector<f64, 3>; 3],
    tilt_low_pass: [SVector<f64, 2>; 2],
    /// Tilt (φ_x, φ_y) and its rate, rad and rad/s.
    pub tilt: [f64; 2],
    pub tilt_rate: [f64; 2],
    /// The limited cabin pose coordinates and their rates.
    pub pos: [f64; 6],
    pub vel: [f64; 6],
    prev_desired_vel: [f64; 6],
    /// Steps in which the limiter departed from the desired pose.
    pub limited_steps: u64,
}

/// One sample of the cueing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CueOutput {
    /// Cabin pose coordinates [x, y, z, φx, φy, φz] (m, rad), rates and accelerations.
    pub pose: [f64; 6],
    pub velocity: [f64; 6],
    pub acceleration: [f64; 6],
    /// What the washout asked for before the limiter.
    pub desired: [f64; 6],
    /// The vehicle motion after scaling and limiting.
    pub scaled: VehicleSample,
    /// The tilt coordination's part of the rotation (φ_x, φ_y) and its rate.
    pub tilt: [f64; 2],
    pub tilt_rate: [f64; 2],
    /// The limiter departed from the desired pose in this step.
    pub limited: bool,
}

/// Limits of motion-core's cueing tracker (its per-coordinate accelerations and loop period),
/// for the target that makes the tracker land on the cueing pose ([`Washout::tracker_target`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerLimits {
    pub linear_acceleration: f64,
    pub angular_acceleration: f64,
    pub period_s: f64,
    /// Send the tracker this far ahead, s (see [`tracker_target`]).
    pub lead_s: f64,
}

/// How far inside the configured cueing box the limiter keeps the pose (m or rad): more than
/// the discrete braking's round-off (≈ 1e-8), far below anything physical.
pub const BOX_ROUND_OFF: f64 = 1e-6;

/// Largest speed from which a double integrator braking at `a` (discrete, step `dt`, position
/// updated with the new velocity) still stops within `dist`: a·dt·n with
/// a·dt²·n(n+1)/2 = dist (the law of motion-core's cueing tracker).
#[inline]
pub fn braking_reach(dist: f64, a: f64, dt: f64) -> f64 {
    if dist <= 0.0 {
        return 0.0;
    }
    let adt2 = a * dt * dt;
    let n = 0.5 * ((1.0 + 8.0 * dist / adt2).sqrt() - 1.0);
    a * dt * n
}

/// The distance a discrete double integrator braking at `a` covers from speed `v` ≥ 0:
/// a·dt²·n(n+1)/2 with n = v/(a dt), the inverse of [`braking_reach`].
#[inline]
pub fn braking_distance(v: f64, a: f64, dt: f64) -> f64 {
    let n = v / (a * dt);
    0.5 * a * dt * dt * n * (n + 1.0)
}

/// Smooth limit L tanh(K x / L) (0 when L = 0).
#[inline]
fn soft_limit(x: f64, gain: f64, limit: f64) -> f64 {
    if limit <= 0.0 {
        0.0
    } else {
        limit * (gain * x / limit).tanh()
    }
}

impl Washout {
    /// The neutral pose of `params` for the platform's `home`.
    pub fn neutral_of(params: &WashoutParams, home: &Pose) -> Pose {
        Pose::new(
            home.r + params.workspace.neutral_offset,
            home.phi + params.workspace.neutral_rotation,
        )
    }

    /// The discretised washout about the neutral pose for the platform's `home`, sample period
    /// `dt`.
    pub fn new(params: WashoutParams, home: Pose, dt: f64) -> Result<Self, LtiError> {
        let neutral = Self::neutral_of(&params, &home);
        let tp = |hp: &HighPass| Lti::<3>::from_tf(&[1.0, 0.0], &hp.denominator(), dt);
        let rp = |hp: &HighPass| Lti::<3>::from_tf(&[1.0, 0.0, 0.0], &hp.denominator(), dt);
        let translation = [
            tp(&params.translation[0])?,
            tp(&params.translation[1])?,
            tp(&params.translation[2])?,
        ];
        let rotation = [
            rp(&params.rotation[0])?,
            rp(&params.rotation[1])?,
            rp(&params.rotation[2])?,
        ];
        let t = &params.tilt;
        let tilt_low_pass = Lti::<2>::from_tf(
            &[t.omega_n * t.omega_n],
            &[1.0, 2.0 * t.zeta * t.omega_n, t.omega_n * t.omega_n],
            dt,
        )?;
        let w = &params.workspace;
        let h = neutral.to_array();
        let mut box_min = [0.0; 6];
        let mut box_max = [0.0; 6];
        // The box the limiter keeps is the configured one shrunk by BOX_ROUND_OFF: a configured
        // edge may coincide with the operating region's, which motion-core checks exactly.
        for k in 0..3 {
            box_min[k] = h[k] + w.position_min[k] + BOX_ROUND_OFF;
            box_max[k] = h[k] + w.position_max[k] - BOX_ROUND_OFF;
            box_min[k + 3] = h[k + 3] - w.rotation_max[k] + BOX_ROUND_OFF;
            box_max[k + 3] = h[k + 3] + w.rotation_max[k] - BOX_ROUND_OFF;
        }
        let (lv, la, av, aa) = (
            w.linear_velocity_max,
            w.linear_acceleration_max,
            w.angular_velocity_max,
            w.angular_acceleration_max,
        );
        Ok(Self {
            params,
            neutral,
            dt,
            box_min,
            box_max,
            v_max: [lv, lv, lv, av, av, av],
            a_max: [la, la, la, aa, aa, aa],
            translation,
            rotation,
            tilt_low_pass,
        })
    }

    /// The washout for motion-core's tracker `lim`: the limiter's box shrunk by the most the
    /// tracker, running `lim.lead_s` ahead ([`tracker_target`]), can pass a target the limiter
    /// brakes to at its edge. Braking at a_b below the tracker's a_tr leaves
    /// d_b(v) − d_tr(v) = v²(1/a_b − 1/a_tr)/2 of room, so the lead's v τ overshoots by at most
    /// max_v (v τ − v²(1/a_b − 1/a_tr)/2) = τ²/(2 (1/a_b − 1/a_tr)) (at most v_max τ), plus one
    /// tracker step a_tr dt² of discrete slack.
    pub fn for_tracker(mut self, lim: &TrackerLimits) -> Self {
        let tau = lim.lead_s;
        for k in 0..6 {
            let a_tr = if k < 3 {
                lim.linear_acceleration
            } else {
                lim.angular_acceleration
            };
            let a_b = self.a_max[k];
            let room = 1.0 / a_b - 1.0 / a_tr;
            let mut m = self.v_max[k] * tau;
            if room > 0.0 {
                m = m.min(tau * tau / (2.0 * room));
            }
            m += a_tr * lim.period_s * lim.period_s;
            let mid = 0.5 * (self.box_min[k] + self.box_max[k]);
            self.box_min[k] = (self.box_min[k] + m).min(mid);
            self.box_max[k] = (self.box_max[k] - m).max(mid);
        }
        self
    }

    /// At rest at the neutral pose, the filters settled on a vehicle at rest.
    pub fn at_rest(&self) -> WashoutState {
        WashoutState {
            translation: [SVector::zeros(); 3],
            rotation: [SVector::zeros(); 3],
            tilt_low_pass: [SVector::zeros(); 2],
            tilt: [0.0; 2],
            tilt_rate: [0.0; 2],
            pos: self.neutral.to_array(),
            vel: [0.0; 6],
            prev_desired_vel: [0.0; 6],
            limited_steps: 0,
        }
    }
}

/// The target to publish on motion-core's cueing input so that its tracker (which brakes
/// towards each target at its acceleration limit a, period dt: `motion_core::daemon::cueing`)
/// moves along `out`'s pose: per coordinate the pose predicted `lead_s` ahead
/// (p + v τ + a τ²/2, v + a τ) one tracker period back plus the tracker's braking distance at
/// that rate (its speed command then equals the cueing's rate). Without the lead (τ = 0) the
/// tracker lands exactly on the cueing pose, but a source late by one period already makes it
/// brake (the target is a stop point); with it the tracker runs τ ahead of the cueing pose and
/// coasts through a late source of up to τ. Each coordinate is clamped to [lo, hi] (and never
/// beyond the predicted pose itself).
pub fn tracker_target(
    out: &CueOutput,
    lim: &TrackerLimits,
    lo: &[f64; 6],
    hi: &[f64; 6],
) -> [f64; 6] {
    let mut t = [0.0; 6];
    let tau = lim.lead_s;
    for k in 0..6 {
        let a_tr = if k < 3 {
            lim.linear_acceleration
        } else {
            lim.angular_acceleration
        };
        let acc = out.acceleration[k];
        let (lo_k, hi_k) = (lo[k].min(out.pose[k]), hi[k].max(out.pose[k]));
        let p = (out.pose[k] + out.velocity[k] * tau + 0.5 * acc * tau * tau).clamp(lo_k, hi_k);
        let v = out.velocity[k] + acc * tau;
        let lead = braking_distance(v.abs(), a_tr, lim.period_s) - v.abs() * lim.period_s;
        t[k] = (p + v.signum() * lead).clamp(lo_k, hi_k);
    }
    t
}

/// Workspace use of `poses`: per coordinate the largest excursion from the neutral pose as a
/// share of the cueing box's half-width on that side (1 = the box's edge). `w` is the washout
/// as configured (before [`Washout::for_tracker`] shrinks its box).
pub fn workspace_use<'a>(w: &Washout, poses: impl IntoIterator<Item = &'a [f64; 6]>) -> [f64; 6] {
    let n = w.neutral.to_array();
    let mut u = [0.0f64; 6];
    for p in poses {
        for (k, uk) in u.iter_mut().enumerate() {
            let d = p[k] - n[k];
            let half = if d >= 0.0 {
                w.box_max[k] - n[k]
            } else {
                n[k] - w.box_min[k]
            };
            if half > 0.0 {
                *uk = uk.max(d.abs() / half);
            }
        }
    }
    u
}

/// The time-optimal follower of the tilt (stop-at-target law with |φ̇| ≤ r, |φ̈| ≤ α).
#[inline]
fn follow(pos: &mut f64, vel: &mut f64, target: f64, r: f64, alpha: f64, dt: f64) {
    let e = target - *pos;
    let v_des = e.signum() * r.min(braking_reach(e.abs(), alpha, dt)).min(e.abs() / dt);
    *vel += (v_des - *vel).clamp(-alpha * dt, alpha * dt);
    *pos += *vel * dt;
}

/// One sample: the vehicle's motion `vehicle` in, the cabin's motion out. Allocation-free.
pub fn step(w: &Washout, s: &mut WashoutState, vehicle: &VehicleSample) -> CueOutput {
    let p = &w.params;
    let g = p.gravity;
    let dt = w.dt;
    // 1. Scaling and limiting.
    let rest = Vector3::new(0.0, 0.0, g);
    let dev = vehicle.specific_force - rest;
    let f_s = rest
        + Vector3::from_fn(|k, _| {
            soft_limit(dev[k], p.specific_force_gain[k], p.specific_force_limit[k])
        });
    let w_s = Vector3::from_fn(|k, _| {
        soft_limit(
            vehicle.angular_velocity[k],
            p.angular_velocity_gain[k],
            p.angular_velocity_limit[k],
        )
    });
    // 2. Tilt coordination.
    let f_lp = [
        w.tilt_low_pass.step(&mut s.tilt_low_pass[0], f_s.x),
        w.tilt_low_pass.step(&mut s.tilt_low_pass[1], f_s.y),
    ];
    let t = &p.tilt;
    let sin_pitch = t.max_rad[1].sin();
    let sin_roll = t.max_rad[0].sin();
    let targets = [
        (f_lp[1] / g).clamp(-sin_roll, sin_roll).asin(),
        -(f_lp[0] / g).clamp(-sin_pitch, sin_pitch).asin(),
    ];
    for ((pos, vel), target) in s.tilt.iter_mut().zip(&mut s.tilt_rate).zip(targets) {
        follow(pos, vel, target, t.rate_max, t.acceleration_max, dt);
    }
    // 3. Translational channel: the acceleration that reproduces f_s at the cabin's attitude.
    let attitude = Pose::new(Vector3::zeros(), Vector3::new(s.pos[3], s.pos[4], s.pos[5]));
    let a_in = attitude.rotation() * f_s - rest;
    let mut desired = [0.0; 6];
    let mut desired_vel = [0.0; 6];
    let h = w.neutral.to_array();
    for k in 0..3 {
        let f = &w.translation[k];
        let z = &mut s.translation[k];
        f.step(z, a_in[k]);
        // Canonical states of s/den: position z₂, velocity z₃ (module docs of `lti`).
        desired[k] = h[k] + z[1];
        desired_vel[k] = z[2];
    }
    // 4. Rotational channel: angle s²/den (state z₃), its rate ż₃.
    for k in 0..3 {
        let f = &w.rotation[k];
        let z = &mut s.rotation[k];
        f.step(z, w_s[k]);
        let rate = f.derivative(z, w_s[k])[2];
        let tilt = if k < 2 { s.tilt[k] } else { 0.0 };
        let tilt_rate = if k < 2 { s.tilt_rate[k] } else { 0.0 };
        desired[k + 3] = h[k + 3] + z[2] + tilt;
        desired_vel[k + 3] = rate + tilt_rate;
    }
    // 5. Workspace limiter.
    let wo = p.workspace.return_omega;
    let mut acc = [0.0; 6];
    let mut limited = false;
    for k in 0..6 {
        let (x, v) = (s.pos[k], s.vel[k]);
        let a_ff = (desired_vel[k] - s.prev_desired_vel[k]) / dt;
        let a_free = a_ff + wo * wo * (desired[k] - x) + 2.0 * wo * (desired_vel[k] - v);
        let a_max = w.a_max[k];
        let a_cmd = a_free.clamp(-a_max, a_max);
        let v_hi = w.v_max[k].min(braking_reach(w.box_max[k] - x, a_max, dt));
        let v_lo = -w.v_max[k].min(braking_reach(x - w.box_min[k], a_max, dt));
        let v_new = (v + a_cmd * dt)
            .clamp(v_lo, v_hi)
            .clamp(v - a_max * dt, v + a_max * dt);
        if (v_new - (v + a_free * dt)).abs() > 1e-12 {
            limited = true;
        }
        acc[k] = (v_new - v) / dt;
        s.vel[k] = v_new;
        // The braking bound lands on the edge up to round-off; never past it.
        s.pos[k] = (x + v_new * dt).clamp(w.box_min[k].min(x), w.box_max[k].max(x));
    }
    s.prev_desired_vel = desired_vel;
    if limited {
        s.limited_steps += 1;
    }
    CueOutput {
        pose: s.pos,
        velocity: s.vel,
        acceleration: acc,
        desired,
        scaled: VehicleSample {
            specific_force: f_s,
            angular_velocity: w_s,
        },
        tilt: s.tilt,
        tilt_rate: s.tilt_rate,
        limited,
    }
}
