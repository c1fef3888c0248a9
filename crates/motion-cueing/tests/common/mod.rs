#![allow(dead_code)]
//! A drive through motion-core's own cueing tracker and per-cycle checks, as the daemon runs
//! it: the cueing source at 1 kHz publishes its tracker target; every loop period (1 ms, or
//! 4 ms as the relaxed timing of the stack tests) motion-core takes the newest target into its
//! velocity/acceleration-limited tracker (limits of `lifecycle::configure`, with the dynamic
//! wrench) and `Cycle::compute` checks the reference: region, velocity/acceleration limits,
//! eq. 3.29 with w = w_e + w_in in closed form (eq. 3.41). What the rider feels is computed
//! from the tracker's reference (the pose the stack commands).
use cdpr_model::config::{Platform, load_platform};
use motion_core::daemon::config;
use motion_core::daemon::cueing::{CueingFilter, CueingLimits};
use motion_core::daemon::cycle::{Cycle, Rejection};
use motion_core::daemon::lifecycle;
use motion_cueing::cabin::{Felt, felt};
use motion_cueing::perception::{PerceptionReport, PerceptionSeries, analyse};
use motion_cueing::source::CueingSource;
use motion_cueing::{CueingSettings, TrackerLimits, VehicleSample, VehicleTrack};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

pub fn cfg(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

/// The platform and motion-core's cueing-tracker limits for a daemon TOML (configure once per
/// daemon: it evaluates the region grid).
pub fn platform_and_limits(daemon_toml: &str) -> (Platform, CueingLimits) {
    let daemon = config::load(&cfg(daemon_toml)).unwrap();
    let pf = load_platform(&daemon.platform).unwrap();
    let configured = lifecycle::configure_checks(&daemon, &pf).unwrap();
    let lim = configured.planner_limits();
    (
        pf,
        CueingLimits {
            linear_velocity: lim.linear_velocity,
            linear_acceleration: lim.linear_acceleration,
            angular_velocity: lim.angular_velocity,
            angular_acceleration: lim.angular_acceleration,
        },
    )
}

/// The nominal icosahedron's mass properties (`[dynamics]` of config/icosahedron.toml).
pub fn nominal_body() -> Option<&'static cdpr_model::dynamics::RigidBody> {
    static BODY: std::sync::OnceLock<Option<cdpr_model::dynamics::RigidBody>> =
        std::sync::OnceLock::new();
    BODY.get_or_init(|| load_platform(cfg("icosahedron.toml")).unwrap().dynamics)
        .as_ref()
}

/// Everything a flight measured.
pub struct Flight {
    pub refused: Option<(usize, Rejection)>,
    pub steps: usize,
    pub f_lo: f64,
    pub f_hi: f64,
    /// Largest |tracker reference − cueing pose| per coordinate.
    pub max_tracking: [f64; 6],
    /// Largest |tilt rate| of the tilt channel and largest |φ̇x|, |φ̇y| of the reference, rad/s.
    pub max_tilt_rate: f64,
    pub max_ref_roll_pitch_rate: f64,
    /// The reference left the cueing box while driving / the region (counted per cycle).
    pub outside_box: usize,
    pub outside_region: usize,
    /// Per loop period: time, vehicle (as recorded), what the cabin's rider felt, the cueing's
    /// scaled input, the reference pose, the washout demand and the tilt.
    pub t: Vec<f64>,
    pub vehicle: Vec<VehicleSample>,
    pub felt: Vec<Felt>,
    pub scaled: Vec<VehicleSample>,
    pub reference: Vec<[f64; 6]>,
    pub desired: Vec<[f64; 6]>,
    pub tilt: Vec<[f64; 2]>,
    pub limited_steps: u64,
    pub box_min: [f64; 6],
    pub box_max: [f64; 6],
}

impl Flight {
    pub fn perception(
        &self,
        settings: &CueingSettings,
        dt: f64,
    ) -> (PerceptionReport, PerceptionSeries) {
        analyse(
            &settings.perception,
            dt,
            self.t
                .iter()
                .zip(&self.vehicle)
                .zip(&self.felt)
                .map(|((t, v), f)| (*t, *v, *f)),
        )
        .unwrap()
    }
}

/// Flies `track` with `settings` on `pf`, motion-core's loop every `loop_period_s` (a
/// multiple of the cueing's 1 ms).
pub fn fly(
    pf: &Platform,
    limits: CueingLimits,
    settings: &CueingSettings,
    track: VehicleTrack,
    loop_period_s: f64,
) -> Flight {
    let dt = 1e-3;
    let (washout, _feas) = settings.washout(pf, dt, "cueing.toml").unwrap();
    let tl = TrackerLimits {
        linear_acceleration: limits.linear_acceleration,
        angular_acceleration: limits.angular_acceleration,
        period_s: loop_period_s,
        lead_s: settings.tracker_lead_s,
    };
    // The configured box (what must hold), then the limiter's, shrunk for the tracker's lead.
    let (box_min, box_max) = (washout.box_min, washout.box_max);
    let washout = washout.for_tracker(&tl);
    let mut src = CueingSource::new(washout, settings, track, pf.home);
    let mut filter = CueingFilter::new(&pf.home, limits, loop_period_s);
    let mut cycle = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    cycle.set_dynamics(pf.dynamics);
    let mut sp = crs_ipc::JointSetpoint::default();
    let mut data = cdpr_model::Data::new(&pf.model);
    let mut forces = vec![0.0; pf.model.m()];
    let every = (loop_period_s / dt).round() as usize;
    let mut f = Flight {
        refused: None,
        steps: 0,
        f_lo: f64::INFINITY,
        f_hi: f64::NEG_INFINITY,
        max_tracking: [0.0; 6],
        max_tilt_rate: 0.0,
        max_ref_roll_pitch_rate: 0.0,
        outside_box: 0,
        outside_region: 0,
        t: vec![],
        vehicle: vec![],
        felt: vec![],
        scaled: vec![],
        reference: vec![],
        desired: vec![],
        tilt: vec![],
        limited_steps: 0,
        box_min,
        box_max,
    };
    let head = settings.washout.head_m;
    let mut prev_vel: Option<[f64; 6]> = None;
    let mut k = 0usize;
    while let Some(s) = src.next_sample() {
        k += 1;
        f.max_tilt_rate = f
            .max_tilt_rate
            .max(s.cue.tilt_rate[0].abs())
            .max(s.cue.tilt_rate[1].abs());
        if !k.is_multiple_of(every) {
            continue;
        }
        let target = src.tracker_target(&s, &tl);
        filter.set_target(&target);
        let r = filter.step();
        f.steps += 1;
        if let Err(e) = cycle.compute(&r, &mut sp) {
            if f.refused.is_none() && std::env::var("CUEING_DEBUG").is_ok() {
                eprintln!(
                    "refused {e} at {:?} phase {:?}: ref {:?} cue {:?} target {:?} box {:?} {:?}",
                    f.steps,
                    s.phase,
                    r.pose.to_array(),
                    s.cue.pose,
                    target,
                    box_min,
                    box_max
                );
            }
            f.refused.get_or_insert((f.steps, e));
        }
        let p = r.pose.to_array();
        // Against the cueing pose predicted by the tracker lead τ (what the target aims at).
        let tau = settings.tracker_lead_s;
        for (c, m) in f.max_tracking.iter_mut().enumerate() {
            let aim =
                s.cue.pose[c] + s.cue.velocity[c] * tau + 0.5 * s.cue.acceleration[c] * tau * tau;
            *m = m.max((p[c] - aim).abs());
        }
        if s.phase == motion_cueing::source::Phase::Drive
            && (0..6).any(|c| p[c] < box_min[c] - 1e-9 || p[c] > box_max[c] + 1e-9)
        {
            f.outside_box += 1;
        }
        if !pf.region.contains(&r.pose) {
            f.outside_region += 1;
        }
        f.max_ref_roll_pitch_rate = f
            .max_ref_roll_pitch_rate
            .max(r.velocity[3].abs())
            .max(r.velocity[4].abs());
        // Closed-form forces of the dynamic wrench (what the check judged), every 10th cycle.
        if f.steps.is_multiple_of(10) {
            record_forces(pf, &r, &mut data, &mut forces, &mut f);
        }
        // The rider feels the reference: its acceleration is the tracker's (piecewise
        // constant per period, as the stack's setpoints give it by differencing).
        let acc = match prev_vel {
            Some(pv) => std::array::from_fn(|c| (r.velocity[c] - pv[c]) / loop_period_s),
            None => [0.0; 6],
        };
        prev_vel = Some(r.velocity);
        if s.phase != motion_cueing::source::Phase::Drive {
            continue;
        }
        f.t.push(s.drive_t_s);
        f.vehicle.push(s.vehicle);
        f.felt.push(felt(&r.pose, &r.velocity, &acc, &head));
        f.scaled.push(s.cue.scaled);
        f.reference.push(p);
        f.desired.push(s.cue.desired);
        f.tilt.push(s.cue.tilt);
    }
    f.limited_steps = src.state().limited_steps;
    f
}

fn record_forces(
    pf: &Platform,
    r: &motion_core::daemon::cycle::Reference,
    data: &mut cdpr_model::Data,
    forces: &mut [f64],
    f: &mut Flight,
) {
    if cdpr_model::kinematics::inverse(&pf.model, data, &r.pose).is_err() {
        return;
    }
    let t = cdpr_model::pose::twist_from_coordinates(&r.pose);
    let v = t * nalgebra::Vector6::from_column_slice(&r.velocity);
    let a = t * nalgebra::Vector6::from_column_slice(&r.acceleration);
    let p = pf.model.params();
    // A platform without [dynamics] (the calibrated one: its identified load is not a pure
    // weight) is checked statically by motion-core; the forces recorded here still include the
    // inertial wrench, with the nominal cabin's mass properties.
    let w = match pf.dynamics.as_ref().or(nominal_body()) {
        None => p.w_e,
        Some(body) => {
            let m = cdpr_model::dynamics::Motion {
                acceleration: a.fixed_rows::<3>(0).into_owned(),
                angular_velocity: v.fixed_rows::<3>(3).into_owned(),
                angular_acceleration: a.fixed_rows::<3>(3).into_owned(),
            };
            p.w_e + cdpr_model::dynamics::inertial_wrench(body, &r.pose, &m)
        }
    };
    if let Ok(fd) = cdpr_model::statics::force_distribution(data, &w, p.f_min, p.f_max, forces) {
        f.f_lo = f.f_lo.min(fd.f_lo);
        f.f_hi = f.f_hi.max(fd.f_hi);
    }
}

/// A sustained specific force along x (m/s²) after `onset_s` of rest, held `hold_s`, no
/// rotation: the tilt-coordination test input.
pub fn sustained_x(level: f64, onset_s: f64, hold_s: f64) -> VehicleTrack {
    let g = cdpr_model::dynamics::GRAVITY_M_PER_S2;
    let mut s = Vec::new();
    let n = ((onset_s + hold_s + 4.0) / 0.01) as usize;
    for k in 0..=n {
        let t = k as f64 * 0.01;
        let ramp = ((t - onset_s) / 0.3).clamp(0.0, 1.0);
        let end = ((t - onset_s - hold_s) / 0.3).clamp(0.0, 1.0);
        s.push((
            t,
            VehicleSample {
                specific_force: Vector3::new(level * (ramp - end), 0.0, g),
                angular_velocity: Vector3::zeros(),
            },
        ));
    }
    VehicleTrack::from_samples(s)
}

/// A hostile drive: sine waves of specific force (`f_amp`, about rest) and angular velocity
/// (`w_amp`) with `period_s`, `cycles` of them after 1 s of rest.
pub fn waves(f_amp: Vector3<f64>, w_amp: Vector3<f64>, period_s: f64, cycles: f64) -> VehicleTrack {
    let g = cdpr_model::dynamics::GRAVITY_M_PER_S2;
    let dur = 1.0 + period_s * cycles;
    let n = ((dur + 2.0) / 0.01) as usize;
    let s = (0..=n)
        .map(|k| {
            let t = k as f64 * 0.01;
            let x = if t > 1.0 && t < dur {
                (2.0 * std::f64::consts::PI * (t - 1.0) / period_s).sin()
            } else {
                0.0
            };
            (
                t,
                VehicleSample {
                    specific_force: Vector3::new(0.0, 0.0, g) + f_amp * x,
                    angular_velocity: w_amp * x,
                },
            )
        })
        .collect();
    VehicleTrack::from_samples(s)
}
