//! Inverse kinematics (eq. 2.3–2.8, 2.16–2.29) and forward kinematics, least squares (eq. 2.11)
//! or elastostatic (eq. 2.42), of a platform at a pose, as reports.

use crate::{AnalysisError, fmt_pose, pose_json};
use cdpr_model::config::Platform;
use cdpr_model::forward::{self, FkOptions, FkSolution};
use cdpr_model::{Data, Pose, kinematics};
use serde_json::json;
use std::fmt;

/// Cable lengths, free lengths, wrap angles, directions and exit points at a pose.
pub struct IkReport {
    pub platform: String,
    pub pose: Pose,
    pub data: Data,
}

/// The inverse kinematics of `pf` at `pose`.
pub fn ik(pf: &Platform, pose: &Pose) -> Result<IkReport, AnalysisError> {
    let mut data = Data::new(&pf.model);
    kinematics::inverse(&pf.model, &mut data, pose)?;
    Ok(IkReport {
        platform: pf.name.clone(),
        pose: *pose,
        data,
    })
}

impl IkReport {
    pub fn json(&self) -> serde_json::Value {
        let d = &self.data;
        let cables: Vec<_> = (0..d.q.len())
            .map(|i| {
                json!({
                    "cable": i + 1,
                    "length_m": d.q[i],
                    "free_length_m": d.q_free[i],
                    "wrap_angle_deg": d.beta[i].to_degrees(),
                    "unit_vector": [d.u[i].x, d.u[i].y, d.u[i].z],
                    "exit_point_m": [d.p_exit[i].x, d.p_exit[i].y, d.p_exit[i].z],
                })
            })
            .collect();
        json!({"platform": self.platform, "pose": pose_json(&self.pose), "cables": cables})
    }
}

impl fmt::Display for IkReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = &self.data;
        writeln!(f, "{} at {}", self.platform, fmt_pose(&self.pose))?;
        writeln!(
            f,
            "{:>5} {:>10} {:>10} {:>8} {:>26}",
            "cable", "q [m]", "q_f [m]", "β [°]", "u"
        )?;
        for i in 0..d.q.len() {
            let u = d.u[i];
            writeln!(
                f,
                "{:>5} {:>10.5} {:>10.5} {:>8.2}   [{:+.4}, {:+.4}, {:+.4}]",
                i + 1,
                d.q[i],
                d.q_free[i],
                d.beta[i].to_degrees(),
                u.x,
                u.y,
                u.z
            )?;
        }
        Ok(())
    }
}

/// The pose from controlled cable lengths, and with `elastic` the cable forces there.
pub struct FkReport {
    pub platform: String,
    pub elastic: bool,
    pub solution: FkSolution,
    /// Cable forces at the solution (elastostatic only), N.
    pub forces_n: Option<Vec<f64>>,
}

/// The forward kinematics of `pf` from lengths `q` (one per cable, m) starting at `guess`:
/// least squares ν (eq. 2.11), or with `elastic` the elastostatic ν_el (eq. 2.42).
pub fn fk(
    pf: &Platform,
    q: &[f64],
    elastic: bool,
    guess: &Pose,
) -> Result<FkReport, AnalysisError> {
    let model = &pf.model;
    let mut data = Data::new(model);
    let opts = FkOptions::default();
    let solution = if elastic {
        forward::elastostatic(model, &mut data, q, guess, &opts)?
    } else {
        forward::least_squares(model, &mut data, q, guess, &opts)?
    };
    Ok(FkReport {
        platform: pf.name.clone(),
        elastic,
        solution,
        forces_n: elastic.then(|| data.f.clone()),
    })
}

impl FkReport {
    pub fn json(&self) -> serde_json::Value {
        let sol = &self.solution;
        let mut v = json!({
            "platform": self.platform,
            "method": if self.elastic { "elastostatic" } else { "least_squares" },
            "pose": pose_json(&sol.pose),
            "iterations": sol.iterations,
            "residual": sol.residual_norm,
        });
        if let Some(f) = &self.forces_n {
            v["forces_n"] = json!(f);
        }
        v
    }
}

impl fmt::Display for FkReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sol = &self.solution;
        writeln!(
            f,
            "{} forward kinematics ({}): {}",
            self.platform,
            if self.elastic {
                "elastostatic ν_el, eq. 2.42"
            } else {
                "least squares ν, eq. 2.11"
            },
            fmt_pose(&sol.pose)
        )?;
        writeln!(
            f,
            "iterations {}, residual {:.3e} {}",
            sol.iterations,
            sol.residual_norm,
            if self.elastic { "N" } else { "m" }
        )?;
        for (i, force) in self.forces_n.iter().flatten().enumerate() {
            writeln!(f, "  f_{} = {:>9.1} N", i + 1, force)?;
        }
        Ok(())
    }
}
