//! The daemon's lifecycle, after ros2_control's managed nodes: **configure** (planner limits,
//! surrogate installation, plan verification — everything that can refuse, done before anything
//! moves), **activate** (start the planner, build the [`HardLoop`]), **run** ([`run_timed`]) and
//! **deactivate** ([`HardLoop::deactivate`]). Every binary that runs or imitates the loop — the
//! `motion-core` daemon, `crs sim` (homing command, plan timing), `crs calibrate loop` (campaign
//! verification), the `loop-jitter` bench — goes through [`configure`], so the three used to
//! compute these steps each in their own copy can no longer drift apart.
//!
//! [`run_timed`]: super::run_timed

use super::HardLoop;
use super::config::{DaemonConfig, TrajectorySettings};
use super::cycle::{Cycle, OffsetModel, Reference, Rejection, SurrogateRejected};
use super::trajectory::{self, PlannerLimits, PlanningFailed, Waypoint};
use cdpr_model::Pose;
use cdpr_model::config::{MotionLimits, Platform, Region};
use cdpr_model::dynamics::{ScaleError, feasible_acceleration_scale};
use nalgebra::Vector3;

use crs_ipc::JointSetpoint;
use std::path::PathBuf;

/// Why [`configure`] refused to configure the daemon.
#[derive(Debug, thiserror::Error)]
pub enum ConfigureError {
    #[error("refusing surrogate {}: {source}", path.display())]
    SurrogateFile {
        path: PathBuf,
        #[source]
        source: surrogate::FileError,
    },
    #[error("refusing surrogate {}: {source}", path.display())]
    SurrogateRejected {
        path: PathBuf,
        #[source]
        source: SurrogateRejected,
    },
    #[error(
        "the platform's operating region is not wrench feasible with the dynamic wrench (eq. 5.13-5.16) at [{:.3}, {:.3}, {:.3}] m, [{:.1}, {:.1}, {:.1}]°: {source}",
        pose.r.x, pose.r.y, pose.r.z,
        pose.phi.x.to_degrees(), pose.phi.y.to_degrees(), pose.phi.z.to_degrees()
    )]
    DynamicallyInfeasible {
        pose: Pose,
        #[source]
        source: ScaleError,
    },
}

/// Poses the dynamic acceleration limits are computed on: `n` positions per axis of the
/// region's box (n ≥ 2, corners included) × rotations {min, 0, max} per axis (0 only where the
/// range contains it).
pub fn region_grid(region: &Region, n: usize) -> Vec<Pose> {
    let n = n.max(2);
    let lin = |lo: f64, hi: f64| (0..n).map(move |k| lo + (hi - lo) * k as f64 / (n - 1) as f64);
    let rot = |k: usize| {
        let (lo, hi) = (region.rotation_min[k], region.rotation_max[k]);
        let mut v = vec![lo, hi];
        if lo < 0.0 && hi > 0.0 {
            v.push(0.0);
        }
        v
    };
    let (pmin, pmax) = (region.position.min, region.position.max);
    let mut out = Vec::new();
    for x in lin(pmin.x, pmax.x) {
        for y in lin(pmin.y, pmax.y) {
            for z in lin(pmin.z, pmax.z) {
                for a in rot(0) {
                    for b in rot(1) {
                        for c in rot(2) {
                            out.push(Pose::new(Vector3::new(x, y, z), Vector3::new(a, b, c)));
                        }
                    }
                }
            }
        }
    }
    out
}

/// Positions per axis of [`region_grid`] for the dynamic acceleration limits.
pub const DYNAMIC_GRID_POINTS: usize = 3;

/// Poses of the region grid whose static margin is below this share of the force range
/// (f_max − f_min)/2 do not bound the planner's accelerations (see
/// `cdpr_model::dynamics::feasible_acceleration_scale`).
pub const DYNAMIC_STATIC_MARGIN_SHARE: f64 = 0.25;

fn dynamic_static_margin_n(platform: &Platform) -> f64 {
    let p = platform.model.params();
    DYNAMIC_STATIC_MARGIN_SHARE * 0.5 * (p.f_max - p.f_min)
}

/// Share of the feasible acceleration scale the planner uses: the bound is exact at the grid
/// poses, not between them.
pub const DYNAMIC_SCALE_MARGIN: f64 = 0.8;

/// Why [`Configured::verify_plan`] refused a plan.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanRefused {
    #[error("waypoint {}: {outside}", index + 1)]
    WaypointOutside {
        index: usize,
        outside: OutsideRegion,
    },
    #[error(
        "plan refused: segment to waypoint {} at t = {t_s:.3} s, pose [{:.3}, {:.3}, {:.3}] m: {rejection}",
        segment + 1,
        position[0],
        position[1],
        position[2]
    )]
    Rejected {
        /// 0-based index of the waypoint the refused segment leads to.
        segment: usize,
        t_s: f64,
        position: [f64; 3],
        rejection: Rejection,
    },
    #[error(transparent)]
    Planning(#[from] PlanningFailed),
}

/// Where a pose leaves the platform's operating region: the first axis out of its bounds, in
/// the units of the waypoint file (m, degrees).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("{axis} = {value:.3} {unit} lies outside the region's [{min:.3}, {max:.3}] {unit}")]
pub struct OutsideRegion {
    /// The waypoint file's column (`x_m` … `phi_z_deg`).
    pub axis: &'static str,
    pub value: f64,
    pub min: f64,
    pub max: f64,
    pub unit: &'static str,
}

/// The first axis of `pose` outside `region`, `None` when the region contains the pose.
pub fn outside_region(region: &Region, pose: &Pose) -> Option<OutsideRegion> {
    const POS: [&str; 3] = ["x_m", "y_m", "z_m"];
    const ROT: [&str; 3] = ["phi_x_deg", "phi_y_deg", "phi_z_deg"];
    let out = |v: f64, lo: f64, hi: f64| !(lo..=hi).contains(&v);
    for k in 0..3 {
        let (v, lo, hi) = (pose.r[k], region.position.min[k], region.position.max[k]);
        if out(v, lo, hi) {
            return Some(OutsideRegion {
                axis: POS[k],
                value: v,
                min: lo,
                max: hi,
                unit: "m",
            });
        }
    }
    for k in 0..3 {
        let (v, lo, hi) = (pose.phi[k], region.rotation_min[k], region.rotation_max[k]);
        if out(v, lo, hi) {
            return Some(OutsideRegion {
                axis: ROT[k],
                value: v.to_degrees(),
                min: lo.to_degrees(),
                max: hi.to_degrees(),
                unit: "°",
            });
        }
    }
    None
}

/// Why a ride (a waypoint file) was refused before anything moved: the file and the line of
/// the waypoint concerned, and what is wrong there.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RideRefused {
    #[error(transparent)]
    File(#[from] trajectory::WaypointError),
    #[error("{file}: no waypoint rows: a ride needs at least one")]
    NoWaypoints { file: String },
    #[error("{file}:{line}: {refused}")]
    Plan {
        file: String,
        line: usize,
        refused: PlanRefused,
    },
}

/// A plan that passed the loop's own checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifiedPlan {
    /// Loop periods the plan lasts.
    pub samples: usize,
    pub duration_s: f64,
}

/// The installed surrogate, for logs.
#[derive(Clone, Debug, PartialEq)]
pub struct SurrogateInfo {
    pub path: PathBuf,
    pub certified_bound_mm: f64,
}

/// Planner limits of table 5.1 scaled by the daemon's `[trajectory]` fractions, plus its jerks.
pub fn planner_limits(limits: &MotionLimits, t: &TrajectorySettings) -> PlannerLimits {
    PlannerLimits {
        linear_velocity: limits.linear_velocity_max * t.velocity_scale,
        angular_velocity: limits.angular_velocity_max * t.velocity_scale,
        linear_acceleration: limits.linear_acceleration_max * t.acceleration_scale,
        angular_acceleration: limits.angular_acceleration_max * t.acceleration_scale,
        linear_jerk: t.linear_jerk_max,
        angular_jerk: t.angular_jerk_max,
    }
}

/// The configured daemon: the cycle computation with its surrogate installed and the limits it
/// plans with. Nothing runs yet.
pub struct Configured {
    platform: Platform,
    cycle: Cycle,
    limits: PlannerLimits,
    period_ns: u64,
    check_wrench_feasibility: bool,
    surrogate: Option<SurrogateInfo>,
    /// The acceleration scale the dynamic wrench allowed (1 = table 5.1 × the daemon's
    /// scales unchanged; `None`: static check).
    dynamic_scale: Option<DynamicLimits>,
}

/// How the dynamic wrench limited the planner (for logs and `crs sim`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicLimits {
    /// Factor applied to the configured planner accelerations (≤ 1).
    pub acceleration_factor: f64,
    /// The pose of the region grid and the cable that bound it.
    pub bound_at: Pose,
    pub cable: usize,
}

/// Configures the daemon for `platform`: the cycle computation (workspace, limits, eq. 3.29
/// when enabled), the surrogate of the daemon TOML loaded, identity-checked against the
/// platform and bound-checked (eq. 5.27), and the planner limits.
pub fn configure(cfg: &DaemonConfig, platform: &Platform) -> Result<Configured, ConfigureError> {
    let mut c = configure_checks(cfg, platform)?;
    if let Some(path) = &cfg.surrogate {
        let s = surrogate::Surrogate::load(path, &platform.model.identity_hex()).map_err(|e| {
            ConfigureError::SurrogateFile {
                path: path.clone(),
                source: e,
            }
        })?;
        let bound = s.report().certified_bound_mm;
        let n = s.n_cables();
        c.install_surrogate(Box::new(s), n)
            .map_err(|e| ConfigureError::SurrogateRejected {
                path: path.clone(),
                source: e,
            })?;
        c.surrogate = Some(SurrogateInfo {
            path: path.clone(),
            certified_bound_mm: bound,
        });
    }
    Ok(c)
}

/// The checks and planner limits of [`configure`] without the surrogate of the daemon TOML,
/// for offline plan verification and timing against another platform file (a campaign checked
/// against a calibrated model whose identity the TOML's surrogate does not carry).
///
/// With the dynamic wrench (`dynamic_wrench` and the platform's `[dynamics]`, eq. 5.13–5.16)
/// the planner's accelerations come from what stays feasible: the largest scale of the
/// configured accelerations for which every pose of the region grid stays wrench feasible at
/// any acceleration within them (and the planner's angular velocity), times
/// [`DYNAMIC_SCALE_MARGIN`]; refused when the region is not feasible even at rest.
pub fn configure_checks(
    cfg: &DaemonConfig,
    platform: &Platform,
) -> Result<Configured, ConfigureError> {
    let dynamics = platform
        .dynamics
        .filter(|_| cfg.dynamic_wrench && cfg.check_wrench_feasibility);
    let mut limits = planner_limits(&platform.limits, &cfg.trajectory);
    let mut dynamic_scale = None;
    if let Some(body) = &dynamics {
        let poses = region_grid(&platform.region, DYNAMIC_GRID_POINTS);
        let s = feasible_acceleration_scale(
            &platform.model,
            body,
            &poses,
            dynamic_static_margin_n(platform),
            limits.linear_acceleration,
            limits.angular_acceleration,
            limits.angular_velocity,
        )
        .map_err(|source| {
            let k = match source {
                ScaleError::Singular { pose_index }
                | ScaleError::NotFeasibleAtRest { pose_index, .. } => pose_index,
            };
            ConfigureError::DynamicallyInfeasible {
                pose: poses[k],
                source,
            }
        })?;
        let factor = (s.scale * DYNAMIC_SCALE_MARGIN).min(1.0);
        limits.linear_acceleration *= factor;
        limits.angular_acceleration *= factor;
        dynamic_scale = Some(DynamicLimits {
            acceleration_factor: factor,
            bound_at: poses[s.pose_index],
            cable: s.cable,
        });
    }
    Ok(Configured {
        platform: platform.clone(),
        cycle: new_cycle(platform, cfg.check_wrench_feasibility, dynamics),
        limits,
        period_ns: cfg.realtime.period_ns,
        check_wrench_feasibility: cfg.check_wrench_feasibility,
        surrogate: None,
        dynamic_scale,
    })
}

fn new_cycle(
    platform: &Platform,
    check_wrench_feasibility: bool,
    dynamics: Option<cdpr_model::dynamics::RigidBody>,
) -> Cycle {
    let mut c = Cycle::new(
        platform.model.clone(),
        platform.limits,
        platform.region,
        check_wrench_feasibility,
    );
    c.set_dynamics(dynamics);
    c
}

impl Configured {
    /// Installs (or replaces) the surrogate offset model, with the same checks as [`configure`]
    /// (for benches that fit one at start-up).
    pub fn install_surrogate(
        &mut self,
        s: Box<dyn OffsetModel>,
        n_cables: usize,
    ) -> Result<(), SurrogateRejected> {
        self.cycle.set_surrogate(s, n_cables)
    }

    pub fn platform(&self) -> &Platform {
        &self.platform
    }

    pub fn planner_limits(&self) -> PlannerLimits {
        self.limits
    }

    /// How the dynamic wrench limited the planner's accelerations (`None`: static check).
    pub fn dynamic_limits(&self) -> Option<DynamicLimits> {
        self.dynamic_scale
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    pub fn period_s(&self) -> f64 {
        self.period_ns as f64 * 1e-9
    }

    /// The surrogate loaded from the daemon TOML, if any.
    pub fn surrogate(&self) -> Option<&SurrogateInfo> {
        self.surrogate.as_ref()
    }

    pub fn has_surrogate(&self) -> bool {
        self.cycle.has_surrogate()
    }

    /// The controller's full command at the home pose, q_θ(home) = φ(home) + φ_sg(home)
    /// (eq. 5.26): the lengths the drives are homed to.
    pub fn home_command(&mut self) -> Result<Vec<f64>, Rejection> {
        let mut sp = JointSetpoint::default();
        self.cycle.compute(
            &Reference {
                pose: self.platform.home,
                ..Reference::default()
            },
            &mut sp,
        )?;
        Ok(sp.cable_length_m[..self.platform.model.m()].to_vec())
    }

    /// Verifies a whole plan from the home pose with the loop's own per-cycle checks
    /// (waypoints inside the region, then every sample: workspace, limits, eq. 3.29) before
    /// anything moves; the error names the waypoint, time and pose. The surrogate offset is not
    /// part of the check (a fresh cycle without it, as the daemon has always verified).
    pub fn verify_plan(&self, waypoints: &[Waypoint]) -> Result<VerifiedPlan, PlanRefused> {
        self.verify_plan_from(self.platform.home, waypoints)
    }

    /// [`Self::verify_plan`] of a ride file: the refusal names the file and the line of the
    /// waypoint concerned (the waypoint outside the region, or the one the refused segment
    /// leads to). A file without waypoints is refused too.
    pub fn verify_ride(&self, ride: &trajectory::RideFile) -> Result<VerifiedPlan, RideRefused> {
        if ride.waypoints.is_empty() {
            return Err(RideRefused::NoWaypoints {
                file: ride.file.clone(),
            });
        }
        self.verify_plan(&ride.waypoints).map_err(|refused| {
            let index = match &refused {
                PlanRefused::WaypointOutside { index, .. } => *index,
                PlanRefused::Rejected { segment, .. } => *segment,
                PlanRefused::Planning(p) => p.waypoint,
            };
            RideRefused::Plan {
                file: ride.file.clone(),
                line: ride.line(index),
                refused,
            }
        })
    }

    /// [`Self::verify_plan`] from another start pose than home (the return home from where
    /// the platform holds).
    pub fn verify_plan_from(
        &self,
        start: Pose,
        waypoints: &[Waypoint],
    ) -> Result<VerifiedPlan, PlanRefused> {
        for (index, w) in waypoints.iter().enumerate() {
            if let Some(outside) = outside_region(&self.platform.region, &w.pose) {
                return Err(PlanRefused::WaypointOutside { index, outside });
            }
        }
        let mut check = new_cycle(
            &self.platform,
            self.check_wrench_feasibility,
            self.cycle.dynamics().copied(),
        );
        let period_s = self.period_s();
        let mut sp = JointSetpoint::default();
        let mut n = 0usize;
        trajectory::plan_samples(start, waypoints, self.limits, period_s, |segment, r| {
            n += 1;
            check
                .compute(&r, &mut sp)
                .map_err(|rejection| PlanRefused::Rejected {
                    segment,
                    t_s: n as f64 * period_s,
                    position: [r.pose.r.x, r.pose.r.y, r.pose.r.z],
                    rejection,
                })
        })?;
        Ok(VerifiedPlan {
            samples: n,
            duration_s: n as f64 * period_s,
        })
    }

    /// Activates: starts the planner thread for `waypoints` from the home pose (errors end the
    /// plan early and go to `on_error`) and returns the loop, running.
    pub fn activate(
        self,
        waypoints: Vec<Waypoint>,
        on_error: impl Fn(PlanningFailed) + Send + 'static,
    ) -> HardLoop {
        let sampler = trajectory::spawn_planner(
            self.platform.home,
            waypoints,
            self.limits,
            self.period_s(),
            on_error,
        );
        HardLoop::new(self.cycle, sampler)
    }
}
