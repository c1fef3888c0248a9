//! Motion-cueing input: a stream of reference poses (e.g. a simulator's washout filter output on
//! the `crs/v1/cueing_pose` topic) that the loop follows online.
//!
//! The stream is not trusted to be smooth: each cycle the newest target passes through a
//! per-coordinate velocity- and acceleration-limited tracker (a discrete time-optimal
//! double-integrator law: command the largest speed from which the remaining distance can still
//! be braked at a_max, v_des = sign(e)·min(v_max, √(2 a_max |e|)), and move the velocity towards
//! it by at most a_max·dt; the braking distance is taken in discrete time, so it lands without
//! overshoot). The result goes through the loop's normal checks like every other
//! reference (finite, workspace box, wrench feasibility, limits), so a target outside the region
//! latches a refusal instead of being followed. ruckig's online `update()` allocates on every call
//! (measured), hence this allocation-free law on the loop thread.

use super::cycle::Reference;
use cdpr_model::Pose;

/// Where the newest cueing target comes from (iceoryx2 subscriber in the daemon). Must not
/// block or allocate: called once per cycle on the loop thread.
pub trait CueingSource {
    /// The newest target pose [x, y, z, φx, φy, φz] (m, rad) received since the last call,
    /// or `None` if nothing new arrived.
    fn latest(&mut self) -> Option<[f64; 6]>;
}

/// Per-coordinate limits of the tracker (m/s, m/s², rad/s, rad/s²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CueingLimits {
    pub linear_velocity: f64,
    pub linear_acceleration: f64,
    pub angular_velocity: f64,
    pub angular_acceleration: f64,
}

/// The velocity/acceleration-limited tracker state.
#[derive(Clone, Debug)]
pub struct CueingFilter {
    limits: CueingLimits,
    dt: f64,
    target: [f64; 6],
    pos: [f64; 6],
    vel: [f64; 6],
    /// Targets received that were not finite (ignored, counted).
    pub rejected_targets: u64,
}

impl CueingFilter {
    /// Starts at rest at `start` with the loop period `dt` (s).
    pub fn new(start: &Pose, limits: CueingLimits, dt: f64) -> Self {
        let p = start.to_array();
        Self {
            limits,
            dt,
            target: p,
            pos: p,
            vel: [0.0; 6],
            rejected_targets: 0,
        }
    }

    /// Sets a new target; a non-finite target is ignored (and counted), the old one kept.
    #[inline]
    pub fn set_target(&mut self, t: &[f64; 6]) {
        if t.iter().all(|v| v.is_finite()) {
            self.target = *t;
        } else {
            self.rejected_targets += 1;
        }
    }

    /// Advances one period and returns the reference.
    #[inline]
    pub fn step(&mut self) -> Reference {
        let mut acc = [0.0; 6];
        for k in 0..6 {
            let (v_max, a_max) = if k < 3 {
                (self.limits.linear_velocity, self.limits.linear_acceleration)
            } else {
                (
                    self.limits.angular_velocity,
                    self.limits.angular_acceleration,
                )
            };
            let e = self.target[k] - self.pos[k];
            // Braking bound in discrete time: decelerating from v = n·a·dt by a·dt per step
            // (position updated with the new velocity) covers a·dt²·n(n+1)/2, so the largest
            // speed that still stops within |e| is a·dt·n with n solving that for |e|.
            let adt2 = a_max * self.dt * self.dt;
            let n = 0.5 * ((1.0 + 8.0 * e.abs() / adt2).sqrt() - 1.0);
            let reach = a_max * self.dt * n;
            let v_des = e.signum() * v_max.min(reach).min(e.abs() / self.dt);
            let dv = (v_des - self.vel[k]).clamp(-a_max * self.dt, a_max * self.dt);
            self.vel[k] += dv;
            self.pos[k] += self.vel[k] * self.dt;
            acc[k] = dv / self.dt;
        }
        Reference {
            pose: Pose::from_array(self.pos),
            velocity: self.vel,
            acceleration: acc,
        }
    }

    pub fn position(&self) -> [f64; 6] {
        self.pos
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn limits() -> CueingLimits {
        CueingLimits {
            linear_velocity: 1.0,
            linear_acceleration: 2.0,
            angular_velocity: 0.5,
            angular_acceleration: 1.0,
        }
    }

    #[test]
    fn reaches_a_step_target_within_limits_without_overshoot() {
        let start = Pose::new(Vector3::new(0.0, 0.0, 2.0), Vector3::zeros());
        let mut f = CueingFilter::new(&start, limits(), 1e-3);
        f.set_target(&[0.5, -0.2, 2.1, 0.05, 0.0, -0.03]);
        let mut prev = [0.0; 6];
        let mut max_overshoot: f64 = 0.0;
        for _ in 0..5000 {
            let r = f.step();
            for k in 0..6 {
                let (v, a) = if k < 3 { (1.0, 2.0) } else { (0.5, 1.0) };
                assert!(r.velocity[k].abs() <= v + 1e-9);
                assert!(r.acceleration[k].abs() <= a + 1e-9);
                let t: f64 = [0.5, -0.2, 2.1, 0.05, 0.0, -0.03][k];
                let s: f64 = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0][k];
                if (t - s).abs() > 0.0 {
                    let over = (r.pose.to_array()[k] - s) / (t - s) - 1.0;
                    max_overshoot = max_overshoot.max(over);
                }
            }
            prev = r.pose.to_array();
        }
        let t = [0.5, -0.2, 2.1, 0.05, 0.0, -0.03];
        for k in 0..6 {
            assert!((prev[k] - t[k]).abs() < 1e-9, "coord {k}: {}", prev[k]);
        }
        assert!(max_overshoot < 1e-3, "overshoot {max_overshoot}");
    }

    #[test]
    fn non_finite_targets_are_ignored_and_counted() {
        let start = Pose::new(Vector3::new(0.0, 0.0, 2.0), Vector3::zeros());
        let mut f = CueingFilter::new(&start, limits(), 1e-3);
        f.set_target(&[f64::NAN, 0.0, 2.0, 0.0, 0.0, 0.0]);
        f.set_target(&[0.0, f64::INFINITY, 2.0, 0.0, 0.0, 0.0]);
        assert_eq!(f.rejected_targets, 2);
        for _ in 0..100 {
            let r = f.step();
            assert_eq!(r.pose.to_array(), start.to_array());
        }
    }
}
