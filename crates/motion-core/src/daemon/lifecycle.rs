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
use cdpr_model::config::{MotionLimits, Platform};

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
}

/// Why [`Configured::verify_plan`] refused a plan.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanRefused {
    #[error("waypoint {} lies outside the platform's workspace region", index + 1)]
    WaypointOutside { index: usize },
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
}

/// Configures the daemon for `platform`: the cycle computation (workspace, limits, eq. 3.29
/// when enabled), the surrogate of the daemon TOML loaded, identity-checked against the
/// platform and bound-checked (eq. 5.27), and the planner limits.
pub fn configure(cfg: &DaemonConfig, platform: &Platform) -> Result<Configured, ConfigureError> {
    let mut c = configure_checks(cfg, platform);
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
/// against a calibrated model whose identity the TOML's surrogate does not carry). Cannot fail.
pub fn configure_checks(cfg: &DaemonConfig, platform: &Platform) -> Configured {
    Configured {
        platform: platform.clone(),
        cycle: new_cycle(platform, cfg.check_wrench_feasibility),
        limits: planner_limits(&platform.limits, &cfg.trajectory),
        period_ns: cfg.realtime.period_ns,
        check_wrench_feasibility: cfg.check_wrench_feasibility,
        surrogate: None,
    }
}

fn new_cycle(platform: &Platform, check_wrench_feasibility: bool) -> Cycle {
    Cycle::new(
        platform.model.clone(),
        platform.limits,
        platform.region,
        check_wrench_feasibility,
    )
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
        for (index, w) in waypoints.iter().enumerate() {
            if !self.platform.region.contains(&w.pose) {
                return Err(PlanRefused::WaypointOutside { index });
            }
        }
        let mut check = new_cycle(&self.platform, self.check_wrench_feasibility);
        let period_s = self.period_s();
        let mut sp = JointSetpoint::default();
        let mut n = 0usize;
        trajectory::plan_samples(
            self.platform.home,
            waypoints,
            self.limits,
            period_s,
            |segment, r| {
                n += 1;
                check
                    .compute(&r, &mut sp)
                    .map_err(|rejection| PlanRefused::Rejected {
                        segment,
                        t_s: n as f64 * period_s,
                        position: [r.pose.r.x, r.pose.r.y, r.pose.r.z],
                        rejection,
                    })
            },
        )?;
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
        on_error: impl Fn(String) + Send + 'static,
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
