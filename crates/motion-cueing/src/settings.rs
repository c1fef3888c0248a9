//! The cueing TOML (`config/cueing.toml`): scaling and limiting, the washout filters, tilt
//! coordination, the cueing workspace and its limits, the rider's head and the vestibular
//! models — every key with its unit in the name and its bounds checked here; unknown keys are
//! rejected; errors name the file, the key and, for syntax errors, the line.
//!
//! [`CueingSettings::washout`] turns it into a [`Washout`] for one platform and refuses a
//! tuning the platform cannot fly: the cueing box must lie inside the operating region, the
//! limits inside table 5.1, and every pose of the box (a grid of 5 positions per axis ×
//! {−, 0, +} rotations per axis) must be wrench feasible at rest and stay so for every
//! acceleration and angular velocity the limiter allows (eq. 3.29 with the closed form
//! eq. 3.41 and the dynamic wrench of eq. 5.13–5.16, `cdpr_model::dynamics`), with
//! [`FEASIBILITY_MARGIN`].

use crate::vestibular::VestibularParams;
use crate::washout::{HighPass, TiltParams, Washout, WashoutParams, WorkspaceParams};
use cdpr_model::Pose;
use cdpr_model::config::Platform;
use cdpr_model::dynamics::GRAVITY_M_PER_S2;
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::Path;

/// The dynamic feasibility check of the cueing box asks for this factor over the limiter's
/// accelerations (the grid samples the box; between its points the forces differ a little).
pub const FEASIBILITY_MARGIN: f64 = 1.2;

/// Grid points per position axis of the feasibility check.
pub const BOX_GRID_POINTS: usize = 5;

/// Poses checked on the straight way from home to the neutral pose.
pub const TRANSITION_SAMPLES: usize = 20;

/// The cueing TOML, validated, SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct CueingSettings {
    pub washout: WashoutParams,
    pub perception: VestibularParams,
    /// Fade the vehicle's motion in from rest (and out at the end), s.
    pub fade_s: f64,
    /// After the drive, run on until the cabin rests at the neutral pose, at most this long, s.
    pub settle_max_s: f64,
    /// How far ahead of the cueing pose motion-core's tracker is sent, s
    /// ([`crate::washout::tracker_target`]): a source thread late by less than this does not
    /// make the tracker brake.
    pub tracker_lead_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    scaling: RawScaling,
    translation: RawHighPass,
    rotation: RawHighPass,
    tilt: RawTilt,
    workspace: RawWorkspace,
    rider: RawRider,
    run: RawRun,
    perception: RawPerception,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScaling {
    specific_force_gain: [f64; 3],
    specific_force_limit_m_per_s2: [f64; 3],
    angular_velocity_gain: [f64; 3],
    angular_velocity_limit_deg_per_s: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHighPass {
    omega_n_rad_per_s: [f64; 3],
    zeta: [f64; 3],
    omega_b_rad_per_s: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTilt {
    omega_n_rad_per_s: f64,
    zeta: f64,
    max_deg: [f64; 2],
    rate_max_deg_per_s: f64,
    acceleration_max_deg_per_s2: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorkspace {
    neutral_offset_m: [f64; 3],
    neutral_rotation_deg: [f64; 3],
    position_min_m: [f64; 3],
    position_max_m: [f64; 3],
    rotation_max_deg: [f64; 3],
    linear_velocity_max_m_per_s: f64,
    linear_acceleration_max_m_per_s2: f64,
    angular_velocity_max_deg_per_s: f64,
    angular_acceleration_max_deg_per_s2: f64,
    return_omega_rad_per_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRider {
    head_position_m: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRun {
    fade_s: f64,
    settle_max_s: f64,
    tracker_lead_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPerception {
    otolith_tau_a_s: f64,
    otolith_tau_l_s: f64,
    otolith_tau_s_s: f64,
    canal_tau_a_s: f64,
    canal_tau_l_s: f64,
    canal_tau_s_s: f64,
    canal_tau_lead_s: f64,
    threshold_specific_force_m_per_s2: f64,
    threshold_angular_velocity_deg_per_s: f64,
}

/// Why the cueing TOML cannot be used (for this platform).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{file}{}: {}{message}", line.map_or(String::new(), |l| format!(":{l}")), if key.is_empty() { String::new() } else { format!("`{key}`: ") })]
pub struct SettingsError {
    pub file: String,
    pub line: Option<usize>,
    pub key: String,
    pub message: String,
}

/// A bounds check on one key.
struct Check<'a> {
    file: &'a str,
}

impl Check<'_> {
    fn err(&self, key: &str, message: String) -> SettingsError {
        SettingsError {
            file: self.file.into(),
            line: None,
            key: key.into(),
            message,
        }
    }
    /// `lo < x ≤ hi` (`open_lo`) or `lo ≤ x ≤ hi`.
    fn range(
        &self,
        x: f64,
        key: &str,
        lo: f64,
        hi: f64,
        open_lo: bool,
    ) -> Result<f64, SettingsError> {
        let ok = x.is_finite() && x <= hi && if open_lo { x > lo } else { x >= lo };
        if ok {
            Ok(x)
        } else {
            let l = if open_lo { "(" } else { "[" };
            Err(self.err(key, format!("must lie in {l}{lo}, {hi}], got {x}")))
        }
    }
    fn range3(
        &self,
        v: [f64; 3],
        key: &str,
        lo: f64,
        hi: f64,
        open_lo: bool,
    ) -> Result<Vector3<f64>, SettingsError> {
        for (k, x) in v.iter().enumerate() {
            self.range(*x, &format!("{key}[{k}]"), lo, hi, open_lo)?;
        }
        Ok(Vector3::from(v))
    }
}

/// `[scaling]`: gains and limits of the specific force and angular velocity (SI inside).
struct Scaling {
    specific_force_gain: Vector3<f64>,
    specific_force_limit: Vector3<f64>,
    angular_velocity_gain: Vector3<f64>,
    angular_velocity_limit: Vector3<f64>,
}

impl RawScaling {
    fn validate(&self, c: &Check) -> Result<Scaling, SettingsError> {
        Ok(Scaling {
            specific_force_gain: c.range3(
                self.specific_force_gain,
                "scaling.specific_force_gain",
                0.0,
                1.0,
                false,
            )?,
            specific_force_limit: c.range3(
                self.specific_force_limit_m_per_s2,
                "scaling.specific_force_limit_m_per_s2",
                0.0,
                5.0,
                false,
            )?,
            angular_velocity_gain: c.range3(
                self.angular_velocity_gain,
                "scaling.angular_velocity_gain",
                0.0,
                1.0,
                false,
            )?,
            angular_velocity_limit: c
                .range3(
                    self.angular_velocity_limit_deg_per_s,
                    "scaling.angular_velocity_limit_deg_per_s",
                    0.0,
                    30.0,
                    false,
                )?
                .map(f64::to_radians),
        })
    }
}

impl RawHighPass {
    /// `[translation]` or `[rotation]` (`section`): one high-pass filter per axis.
    fn validate(&self, c: &Check, section: &str) -> Result<[HighPass; 3], SettingsError> {
        let w = c.range3(
            self.omega_n_rad_per_s,
            &format!("{section}.omega_n_rad_per_s"),
            0.0,
            20.0,
            true,
        )?;
        let z = c.range3(self.zeta, &format!("{section}.zeta"), 0.0, 3.0, true)?;
        let b = c.range3(
            self.omega_b_rad_per_s,
            &format!("{section}.omega_b_rad_per_s"),
            0.0,
            10.0,
            true,
        )?;
        Ok([0, 1, 2].map(|k| HighPass {
            omega_n: w[k],
            zeta: z[k],
            omega_b: b[k],
        }))
    }
}

impl RawWorkspace {
    fn validate(&self, c: &Check) -> Result<WorkspaceParams, SettingsError> {
        let position_min = c.range3(
            self.position_min_m,
            "workspace.position_min_m",
            -5.0,
            0.0,
            false,
        )?;
        let position_max = c.range3(
            self.position_max_m,
            "workspace.position_max_m",
            0.0,
            5.0,
            false,
        )?;
        let rotation_max = c
            .range3(
                self.rotation_max_deg,
                "workspace.rotation_max_deg",
                0.0,
                30.0,
                false,
            )?
            .map(f64::to_radians);
        Ok(WorkspaceParams {
            neutral_offset: c.range3(
                self.neutral_offset_m,
                "workspace.neutral_offset_m",
                -5.0,
                5.0,
                false,
            )?,
            neutral_rotation: c
                .range3(
                    self.neutral_rotation_deg,
                    "workspace.neutral_rotation_deg",
                    -30.0,
                    30.0,
                    false,
                )?
                .map(f64::to_radians),
            position_min,
            position_max,
            rotation_max,
            linear_velocity_max: c.range(
                self.linear_velocity_max_m_per_s,
                "workspace.linear_velocity_max_m_per_s",
                0.0,
                10.0,
                true,
            )?,
            linear_acceleration_max: c.range(
                self.linear_acceleration_max_m_per_s2,
                "workspace.linear_acceleration_max_m_per_s2",
                0.0,
                20.0,
                true,
            )?,
            angular_velocity_max: c
                .range(
                    self.angular_velocity_max_deg_per_s,
                    "workspace.angular_velocity_max_deg_per_s",
                    0.0,
                    180.0,
                    true,
                )?
                .to_radians(),
            angular_acceleration_max: c
                .range(
                    self.angular_acceleration_max_deg_per_s2,
                    "workspace.angular_acceleration_max_deg_per_s2",
                    0.0,
                    360.0,
                    true,
                )?
                .to_radians(),
            return_omega: c.range(
                self.return_omega_rad_per_s,
                "workspace.return_omega_rad_per_s",
                0.0,
                50.0,
                true,
            )?,
        })
    }
}

impl RawTilt {
    /// `[tilt]`, inside the workspace's rotation, rate and acceleration limits (`raw_ws` for
    /// the file's own numbers in the messages).
    fn validate(
        &self,
        c: &Check,
        raw_ws: &RawWorkspace,
        workspace: &WorkspaceParams,
    ) -> Result<TiltParams, SettingsError> {
        let max_deg = [
            c.range(self.max_deg[0], "tilt.max_deg[0]", 0.0, 30.0, false)?,
            c.range(self.max_deg[1], "tilt.max_deg[1]", 0.0, 30.0, false)?,
        ];
        let tilt = TiltParams {
            omega_n: c.range(
                self.omega_n_rad_per_s,
                "tilt.omega_n_rad_per_s",
                0.0,
                20.0,
                true,
            )?,
            zeta: c.range(self.zeta, "tilt.zeta", 0.0, 3.0, true)?,
            max_rad: max_deg.map(f64::to_radians),
            rate_max: c
                .range(
                    self.rate_max_deg_per_s,
                    "tilt.rate_max_deg_per_s",
                    0.0,
                    10.0,
                    true,
                )?
                .to_radians(),
            acceleration_max: c
                .range(
                    self.acceleration_max_deg_per_s2,
                    "tilt.acceleration_max_deg_per_s2",
                    0.0,
                    100.0,
                    true,
                )?
                .to_radians(),
        };
        // The tilt lives inside the cueing rotation range. (A sustained specific force beyond
        // g sin(tilt.max_deg) is held at that: with specific_force_limit at most that, every
        // sustained part the scaling lets through is reproduced.)
        for (k, deg) in max_deg.iter().enumerate() {
            if tilt.max_rad[k] > workspace.rotation_max[k] {
                return Err(c.err(
                    &format!("tilt.max_deg[{k}]"),
                    format!(
                        "{deg} exceeds workspace.rotation_max_deg[{k}] = {}",
                        raw_ws.rotation_max_deg[k]
                    ),
                ));
            }
        }
        if tilt.acceleration_max > workspace.angular_acceleration_max {
            return Err(c.err(
                "tilt.acceleration_max_deg_per_s2",
                "exceeds workspace.angular_acceleration_max_deg_per_s2".into(),
            ));
        }
        if tilt.rate_max > workspace.angular_velocity_max {
            return Err(c.err(
                "tilt.rate_max_deg_per_s",
                "exceeds workspace.angular_velocity_max_deg_per_s".into(),
            ));
        }
        Ok(tilt)
    }
}

impl RawPerception {
    fn validate(&self, c: &Check) -> Result<VestibularParams, SettingsError> {
        let tau = |x: f64, key: &str| c.range(x, &format!("perception.{key}"), 0.0, 1000.0, true);
        Ok(VestibularParams {
            otolith_tau_a_s: tau(self.otolith_tau_a_s, "otolith_tau_a_s")?,
            otolith_tau_l_s: tau(self.otolith_tau_l_s, "otolith_tau_l_s")?,
            otolith_tau_s_s: tau(self.otolith_tau_s_s, "otolith_tau_s_s")?,
            canal_tau_a_s: tau(self.canal_tau_a_s, "canal_tau_a_s")?,
            canal_tau_l_s: tau(self.canal_tau_l_s, "canal_tau_l_s")?,
            canal_tau_s_s: tau(self.canal_tau_s_s, "canal_tau_s_s")?,
            canal_tau_lead_s: tau(self.canal_tau_lead_s, "canal_tau_lead_s")?,
            threshold_specific_force: c.range(
                self.threshold_specific_force_m_per_s2,
                "perception.threshold_specific_force_m_per_s2",
                0.0,
                10.0,
                true,
            )?,
            threshold_angular_velocity: c
                .range(
                    self.threshold_angular_velocity_deg_per_s,
                    "perception.threshold_angular_velocity_deg_per_s",
                    0.0,
                    30.0,
                    true,
                )?
                .to_radians(),
        })
    }
}

impl RawRun {
    fn validate(&self, c: &Check) -> Result<RawRun, SettingsError> {
        Ok(RawRun {
            fade_s: c.range(self.fade_s, "run.fade_s", 0.0, 10.0, false)?,
            settle_max_s: c.range(self.settle_max_s, "run.settle_max_s", 0.0, 120.0, true)?,
            tracker_lead_s: c.range(self.tracker_lead_s, "run.tracker_lead_s", 0.0, 0.1, false)?,
        })
    }
}

impl CueingSettings {
    pub fn load(path: &Path) -> Result<Self, SettingsError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SettingsError {
            file: file.clone(),
            line: None,
            key: String::new(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, &file)
    }

    pub fn parse(text: &str, file: &str) -> Result<Self, SettingsError> {
        let raw: Raw = toml::from_str(text).map_err(|e| SettingsError {
            file: file.into(),
            line: e
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1),
            key: String::new(),
            message: e.message().trim().to_string(),
        })?;
        let c = Check { file };
        // Section by section, in the file's order of dependence: the tilt is checked against
        // the workspace it lives in.
        let scaling = raw.scaling.validate(&c)?;
        let translation = raw.translation.validate(&c, "translation")?;
        let rotation = raw.rotation.validate(&c, "rotation")?;
        let workspace = raw.workspace.validate(&c)?;
        let tilt = raw.tilt.validate(&c, &raw.workspace, &workspace)?;
        let head_m = c.range3(
            raw.rider.head_position_m,
            "rider.head_position_m",
            -3.0,
            3.0,
            false,
        )?;
        let perception = raw.perception.validate(&c)?;
        let run = raw.run.validate(&c)?;
        Ok(Self {
            washout: WashoutParams {
                specific_force_gain: scaling.specific_force_gain,
                specific_force_limit: scaling.specific_force_limit,
                angular_velocity_gain: scaling.angular_velocity_gain,
                angular_velocity_limit: scaling.angular_velocity_limit,
                translation,
                rotation,
                tilt,
                workspace,
                head_m,
                gravity: GRAVITY_M_PER_S2,
            },
            perception,
            fade_s: run.fade_s,
            settle_max_s: run.settle_max_s,
            tracker_lead_s: run.tracker_lead_s,
        })
    }

    /// The washout for `platform` with sample period `dt` (module docs: refused when the
    /// platform cannot fly it; `file` names the TOML in errors).
    pub fn washout(
        &self,
        platform: &Platform,
        dt: f64,
        file: &str,
    ) -> Result<(Washout, Feasibility), SettingsError> {
        let c = Check { file };
        let feas = check_platform(&self.washout, platform, &c)?;
        let w =
            Washout::new(self.washout, platform.home, dt).map_err(|e| c.err("", e.to_string()))?;
        Ok((w, feas))
    }
}

/// What the platform check found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Feasibility {
    /// Grid poses of the cueing box checked.
    pub poses: usize,
    /// Smallest static margin (eq. 3.41) over them, N.
    pub min_static_margin_n: f64,
    /// The largest factor on the limiter's accelerations (and angular velocity) that keeps
    /// them all feasible with the dynamic wrench; `None` when the platform has no `[dynamics]`
    /// (static check only, as motion-core checks such a platform).
    pub acceleration_scale: Option<f64>,
}

/// The cueing box's grid around `neutral`: `BOX_GRID_POINTS` positions per axis × {min, 0,
/// max} rotations.
pub fn box_grid(neutral: &Pose, w: &WorkspaceParams) -> Vec<Pose> {
    let n = BOX_GRID_POINTS;
    let lin = |lo: f64, hi: f64, i: usize| lo + (hi - lo) * i as f64 / (n - 1) as f64;
    let mut out = Vec::with_capacity(n * n * n * 27);
    for ix in 0..n {
        for iy in 0..n {
            for iz in 0..n {
                let r = neutral.r
                    + Vector3::new(
                        lin(w.position_min.x, w.position_max.x, ix),
                        lin(w.position_min.y, w.position_max.y, iy),
                        lin(w.position_min.z, w.position_max.z, iz),
                    );
                for a in [-1.0, 0.0, 1.0] {
                    for b in [-1.0, 0.0, 1.0] {
                        for cc in [-1.0, 0.0, 1.0] {
                            let phi =
                                neutral.phi + Vector3::new(a, b, cc).component_mul(&w.rotation_max);
                            out.push(Pose::new(r, phi));
                        }
                    }
                }
            }
        }
    }
    out
}

fn check_platform(
    p: &WashoutParams,
    platform: &Platform,
    c: &Check,
) -> Result<Feasibility, SettingsError> {
    let w = &p.workspace;
    let neutral = Washout::neutral_of(p, &platform.home);
    box_inside_region(w, &neutral, platform, c)?;
    limiter_within_platform_limits(w, platform, c)?;
    let poses = checked_poses(&neutral, w, &platform.home);
    let min_margin = static_margin(&poses, platform, c)?;
    let acceleration_scale = match &platform.dynamics {
        None => None,
        Some(body) => Some(dynamic_scale(w, body, &poses, platform, c)?),
    };
    Ok(Feasibility {
        poses: poses.len(),
        min_static_margin_n: min_margin,
        acceleration_scale,
    })
}

/// The cueing box around `neutral` inside the platform's operating region and rotation range.
fn box_inside_region(
    w: &WorkspaceParams,
    neutral: &Pose,
    platform: &Platform,
    c: &Check,
) -> Result<(), SettingsError> {
    let reg = &platform.region;
    for k in 0..3 {
        if neutral.r[k] + w.position_min[k] < reg.position.min[k] - 1e-12 {
            return Err(c.err(
                &format!("workspace.position_min_m[{k}]"),
                format!(
                    "neutral {:.3} m {:+.3} m leaves the operating region of `{}` (min {:.3} m)",
                    neutral.r[k], w.position_min[k], platform.name, reg.position.min[k]
                ),
            ));
        }
        if neutral.r[k] + w.position_max[k] > reg.position.max[k] + 1e-12 {
            return Err(c.err(
                &format!("workspace.position_max_m[{k}]"),
                format!(
                    "neutral {:.3} m {:+.3} m leaves the operating region of `{}` (max {:.3} m)",
                    neutral.r[k], w.position_max[k], platform.name, reg.position.max[k]
                ),
            ));
        }
        if neutral.phi[k] - w.rotation_max[k] < reg.rotation_min[k] - 1e-12
            || neutral.phi[k] + w.rotation_max[k] > reg.rotation_max[k] + 1e-12
        {
            return Err(c.err(
                &format!("workspace.rotation_max_deg[{k}]"),
                format!(
                    "neutral {:.2}° ± {:.2}° leaves the rotation range of `{}` ([{:.2}, {:.2}]°)",
                    neutral.phi[k].to_degrees(),
                    w.rotation_max[k].to_degrees(),
                    platform.name,
                    reg.rotation_min[k].to_degrees(),
                    reg.rotation_max[k].to_degrees()
                ),
            ));
        }
    }
    Ok(())
}

/// The limiter's per-coordinate limits within the platform's (table 5.1).
fn limiter_within_platform_limits(
    w: &WorkspaceParams,
    platform: &Platform,
    c: &Check,
) -> Result<(), SettingsError> {
    let lim = &platform.limits;
    for (x, max, key) in [
        (
            w.linear_velocity_max,
            lim.linear_velocity_max,
            "workspace.linear_velocity_max_m_per_s",
        ),
        (
            w.linear_acceleration_max,
            lim.linear_acceleration_max,
            "workspace.linear_acceleration_max_m_per_s2",
        ),
        (
            w.angular_velocity_max,
            lim.angular_velocity_max,
            "workspace.angular_velocity_max_deg_per_s",
        ),
        (
            w.angular_acceleration_max,
            lim.angular_acceleration_max,
            "workspace.angular_acceleration_max_deg_per_s2",
        ),
    ] {
        // The limiter bounds each coordinate; the platform's limits (table 5.1) bound the norm.
        if x * 3f64.sqrt() > max {
            return Err(c.err(
                key,
                format!("√3 × {x:.4} (all three axes at once) exceeds the platform's limit {max:.4} (table 5.1, SI)"),
            ));
        }
    }
    Ok(())
}

/// The box's grid, and the straight way from home to the neutral pose (the cabin moves
/// there before the drive and back after it, at most at the limiter's accelerations).
fn checked_poses(neutral: &Pose, w: &WorkspaceParams, home: &Pose) -> Vec<Pose> {
    let mut poses = box_grid(neutral, w);
    let way = TRANSITION_SAMPLES;
    for i in 0..=way {
        let s = i as f64 / way as f64;
        poses.push(Pose::new(
            home.r + (neutral.r - home.r) * s,
            home.phi + (neutral.phi - home.phi) * s,
        ));
    }
    poses
}

/// The smallest static margin (eq. 3.41) over `poses`; an error at the first pose that is not
/// wrench feasible at rest.
fn static_margin(poses: &[Pose], platform: &Platform, c: &Check) -> Result<f64, SettingsError> {
    let model = &platform.model;
    let pp = model.params();
    let mut data = cdpr_model::Data::new(model);
    let mut forces = vec![0.0; model.m()];
    let mut min_margin = f64::INFINITY;
    for pose in poses {
        let infeasible = |why: String| {
            c.err(
                "workspace",
                format!(
                    "the cueing box (or the way from home to it) is not wrench feasible at rest on `{}` at [{:.3}, {:.3}, {:.3}] m, [{:.2}, {:.2}, {:.2}]°: {why}",
                    platform.name,
                    pose.r.x,
                    pose.r.y,
                    pose.r.z,
                    pose.phi.x.to_degrees(),
                    pose.phi.y.to_degrees(),
                    pose.phi.z.to_degrees()
                ),
            )
        };
        cdpr_model::kinematics::inverse(model, &mut data, pose)
            .map_err(|e| infeasible(e.to_string()))?;
        let fd = cdpr_model::statics::force_distribution(
            &data,
            &pp.w_e,
            pp.f_min,
            pp.f_max,
            &mut forces,
        )
        .map_err(|e| infeasible(e.to_string()))?;
        if !fd.feasible {
            return Err(infeasible(format!(
                "forces {:.0} … {:.0} N outside [{:.0}, {:.0}] N",
                fd.f_lo, fd.f_hi, pp.f_min, pp.f_max
            )));
        }
        min_margin = min_margin.min(fd.margin);
    }
    Ok(min_margin)
}

/// The largest factor on the limiter's accelerations that keeps every pose feasible with the
/// dynamic wrench of `body`; an error below `FEASIBILITY_MARGIN`.
fn dynamic_scale(
    w: &WorkspaceParams,
    body: &cdpr_model::dynamics::RigidBody,
    poses: &[Pose],
    platform: &Platform,
    c: &Check,
) -> Result<f64, SettingsError> {
    let model = &platform.model;
    // Per-coordinate limits: the norm of (a_x, a_y, a_z) reaches √3 a_max.
    let r3 = 3f64.sqrt();
    let s = cdpr_model::dynamics::feasible_acceleration_scale(
        model,
        body,
        poses,
        f64::NEG_INFINITY,
        r3 * w.linear_acceleration_max,
        r3 * w.angular_acceleration_max,
        r3 * w.angular_velocity_max,
    )
    .map_err(|e| {
        c.err(
            "workspace",
            format!("dynamic wrench on `{}`: {e}", platform.name),
        )
    })?;
    if s.scale < FEASIBILITY_MARGIN {
        let at = poses[s.pose_index];
        return Err(c.err(
            "workspace",
            format!(
                "the limiter's accelerations are not wrench feasible with margin on `{}`: \
                 scale {:.2} < {FEASIBILITY_MARGIN} at [{:.3}, {:.3}, {:.3}] m, [{:.2}, {:.2}, {:.2}]°, cable {} \
                 (lower workspace.linear_acceleration_max_m_per_s2 / angular limits or shrink the box)",
                platform.name,
                s.scale,
                at.r.x,
                at.r.y,
                at.r.z,
                at.phi.x.to_degrees(),
                at.phi.y.to_degrees(),
                at.phi.z.to_degrees(),
                s.cable + 1
            ),
        ));
    }
    Ok(s.scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config")
            .join(name)
    }

    fn text() -> String {
        std::fs::read_to_string(config("cueing.toml")).unwrap()
    }

    #[test]
    fn bad_keys_and_values_are_named() {
        let e = CueingSettings::parse(&text().replace("[tilt]", "[tilt]\nspeed = 1"), "c.toml")
            .unwrap_err();
        assert!(e.line.is_some() && e.message.contains("speed"), "{e}");
        let e = CueingSettings::parse(
            &text().replace("max_deg = [2.8, 2.8]", "max_deg = [2.8, 3.5]"),
            "c.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("c.toml: `tilt.max_deg[1]`: 3.5 exceeds workspace.rotation_max_deg[1]"),
            "{e}"
        );
        let e = CueingSettings::parse(
            &text().replace("zeta = [1.0, 1.0, 1.0]", "zeta = [1.0, -1.0, 1.0]"),
            "c.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`translation.zeta[1]`: must lie in (0, 3]"),
            "{e}"
        );
    }

    #[test]
    fn a_box_about_home_is_refused_as_not_wrench_feasible() {
        // The icosahedron's feasible set is lopsided around home: the same box there fails
        // (the reason the shipped tuning cues about a neutral pose).
        let pf = cdpr_model::config::load_platform(config("icosahedron.toml")).unwrap();
        let s = CueingSettings::parse(
            &text()
                .replace(
                    "neutral_offset_m = [-0.1, 1.0, -0.55]",
                    "neutral_offset_m = [0.0, 0.0, 0.0]",
                )
                .replace(
                    "neutral_rotation_deg = [0.0, 0.0, 3.0]",
                    "neutral_rotation_deg = [0.0, 0.0, 0.0]",
                ),
            "c.toml",
        )
        .unwrap();
        let e = s.washout(&pf, 1e-3, "c.toml").unwrap_err().to_string();
        assert!(
            e.contains("`workspace`: the cueing box") && e.contains("not wrench feasible"),
            "{e}"
        );
        let (_, f) = CueingSettings::parse(&text(), "c.toml")
            .unwrap()
            .washout(&pf, 1e-3, "c.toml")
            .unwrap();
        assert!(f.min_static_margin_n > 0.0 && f.acceleration_scale.unwrap() >= FEASIBILITY_MARGIN);
    }

    #[test]
    fn braking_distance_inverts_braking_reach() {
        for v in [0.001, 0.05, 0.4, 1.3] {
            let d = crate::washout::braking_distance(v, 2.0, 1e-3);
            let r = crate::washout::braking_reach(d, 2.0, 1e-3);
            assert!((r - v).abs() < 1e-9, "{v} -> {d} -> {r}");
        }
        assert_eq!(crate::washout::braking_reach(-0.1, 2.0, 1e-3), 0.0);
    }
}
