//! Force distribution at a pose (closed form eq. 3.41 and the exact test of eq. 3.29),
//! internal/external split and section wrenches (eq. 5.11); stiffness at the reference forces
//! (eq. 2.67–2.78). As reports.

use crate::{AnalysisError, fmt_pose, pose_json};
use cdpr_model::config::Platform;
use cdpr_model::elastostatics::{self, Stiffness};
use cdpr_model::feasibility::{self, ExactFeasibility};
use cdpr_model::statics::{self, ForceDistribution};
use cdpr_model::{Data, Pose, kinematics};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};
use serde_json::json;
use std::fmt;

/// The closed-form forces of a pose next to the exact test.
pub struct ForcesReport {
    pub platform: String,
    pub pose: Pose,
    pub f_min: f64,
    pub f_max: f64,
    /// Closed-form forces (eq. 3.41) and their external / internal parts, N.
    pub forces: Vec<f64>,
    pub external: Vec<f64>,
    pub internal: Vec<f64>,
    pub closed_form: ForceDistribution,
    pub exact: ExactFeasibility,
    pub structure_matrix: DMatrix<f64>,
    pub w_e: Vector6<f64>,
    /// Wrench of each cable section (name, [f; τ]).
    pub sections: Vec<(String, Vector6<f64>)>,
}

/// The force distribution of `pf` at `pose`.
pub fn forces(pf: &Platform, pose: &Pose) -> Result<ForcesReport, AnalysisError> {
    let model = &pf.model;
    let p = model.params();
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, pose)?;
    let m = model.m();
    let mut f = vec![0.0; m];
    let fd = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let (mut fe, mut fi) = (vec![0.0; m], vec![0.0; m]);
    statics::split_internal_external(&data, &p.w_e, &f, &mut fe, &mut fi)?;
    // The exact test of eq. (3.29): is there any distribution within the limits?
    let at = statics::structure_matrix(&data);
    let exact = feasibility::exact(
        &at,
        &DVector::from_column_slice(p.w_e.as_slice()),
        p.f_min,
        p.f_max,
    )?;
    let sections = pf
        .sections
        .iter()
        .map(|s| {
            (
                s.name.clone(),
                statics::section_wrench(&data, &f, &s.cables),
            )
        })
        .collect();
    Ok(ForcesReport {
        platform: pf.name.clone(),
        pose: *pose,
        f_min: p.f_min,
        f_max: p.f_max,
        forces: f,
        external: fe,
        internal: fi,
        closed_form: fd,
        exact,
        structure_matrix: at,
        w_e: p.w_e,
        sections,
    })
}

impl ForcesReport {
    pub fn json(&self) -> serde_json::Value {
        let secs: serde_json::Map<_, _> = self
            .sections
            .iter()
            .map(|(n, w)| (n.clone(), json!(w.as_slice())))
            .collect();
        let at = &self.structure_matrix;
        json!({
            "platform": self.platform, "pose": pose_json(&self.pose),
            "forces_n": self.forces, "external_n": self.external, "internal_n": self.internal,
            "f_min_n": self.f_min, "f_max_n": self.f_max,
            "feasible": self.closed_form.feasible, "margin_n": self.closed_form.margin,
            "exact": {
                "feasible": self.exact.feasible, "margin_n": self.exact.margin,
                "forces_n": self.exact.forces.as_slice(),
            },
            "structure_matrix": (0..at.nrows())
                .map(|r| at.row(r).iter().copied().collect::<Vec<_>>())
                .collect::<Vec<_>>(),
            "w_e": self.w_e.as_slice(),
            "section_wrenches": secs,
        })
    }
}

fn verdict(feasible: bool) -> &'static str {
    if feasible { "FEASIBLE" } else { "NOT FEASIBLE" }
}

impl fmt::Display for ForcesReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (fd, exact) = (&self.closed_form, &self.exact);
        writeln!(f, "{} at {}", self.platform, fmt_pose(&self.pose))?;
        writeln!(
            f,
            "closed-form force distribution (eq. 3.41), limits [{:.0}, {:.0}] N",
            self.f_min, self.f_max
        )?;
        writeln!(
            f,
            "{:>5} {:>10} {:>10} {:>10}",
            "cable", "f [N]", "f_ext [N]", "f_int [N]"
        )?;
        for i in 0..self.forces.len() {
            writeln!(
                f,
                "{:>5} {:>10.1} {:>10.1} {:>10.1}",
                i + 1,
                self.forces[i],
                self.external[i],
                self.internal[i]
            )?;
        }
        writeln!(
            f,
            "verdict: {} (min {:.1} N on cable {}, max {:.1} N on cable {}, margin {:.1} N)",
            verdict(fd.feasible),
            fd.f_lo,
            fd.cable_lo + 1,
            fd.f_hi,
            fd.cable_hi + 1,
            fd.margin
        )?;
        writeln!(
            f,
            "exact test (eq. 3.29, max-margin LP): {}, margin {:.1} N{}",
            verdict(exact.feasible),
            exact.margin,
            if exact.feasible && !fd.feasible {
                " (another distribution fits where eq. 3.41 does not)"
            } else {
                ""
            }
        )?;
        for (name, w) in &self.sections {
            writeln!(
                f,
                "section wrench {name} (eq. 5.11): f = [{:.0}, {:.0}, {:.0}] N, τ = [{:.0}, {:.0}, {:.0}] N·m",
                w[0], w[1], w[2], w[3], w[4], w[5]
            )?;
        }
        Ok(())
    }
}

/// The stiffness matrices at the reference force distribution of a pose.
pub struct StiffnessReport {
    pub platform: String,
    pub pose: Pose,
    /// Reference forces (eq. 3.41), N.
    pub forces: Vec<f64>,
    pub stiffness: Stiffness,
    /// Eigenvalues of −K_wx.
    pub eigenvalues: Vec<f64>,
    /// diag(−K_wx) of the translations, N/m.
    pub translational: [f64; 3],
}

/// The stiffness of `pf` at `pose` with the closed-form forces of eq. 3.41.
pub fn stiffness(pf: &Platform, pose: &Pose) -> Result<StiffnessReport, AnalysisError> {
    let model = &pf.model;
    let p = model.params();
    let m = model.m();
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, pose)?;
    let mut f = vec![0.0; m];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let mut qt = vec![0.0; m];
    elastostatics::inverse(model, &mut data, pose, &f, &mut qt)?;
    elastostatics::cable_forces(&mut data, &model.linear_law(), &qt);
    let s = Stiffness::at(model, &data);
    let k_sys = -s.k_wx; // positive-definite stiffness, δw = −K_wx δx (eq. 2.76)
    let eig = k_sys.symmetric_eigen().eigenvalues;
    Ok(StiffnessReport {
        platform: pf.name.clone(),
        pose: *pose,
        forces: f,
        translational: [k_sys[(0, 0)], k_sys[(1, 1)], k_sys[(2, 2)]],
        eigenvalues: eig.iter().copied().collect(),
        stiffness: s,
    })
}

impl StiffnessReport {
    pub fn json(&self) -> serde_json::Value {
        let mat = |m: &Matrix6<f64>| {
            (0..6)
                .map(|r| (0..6).map(|k| m[(r, k)]).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        };
        let s = &self.stiffness;
        json!({
            "platform": self.platform, "pose": pose_json(&self.pose), "forces_n": self.forces,
            "k_c": mat(&s.k_c), "k_g": mat(&s.k_g), "k_wx": mat(&s.k_wx),
            "stiffness_eigenvalues": self.eigenvalues,
            "translational_stiffness_n_per_m": self.translational,
        })
    }
}

impl fmt::Display for StiffnessReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = &self.stiffness;
        writeln!(
            f,
            "{} at {} with the reference forces of eq. 3.41",
            self.platform,
            fmt_pose(&self.pose)
        )?;
        for (name, mat) in [
            ("K_C = A^T K A (eq. 2.75)", s.k_c),
            ("K_G (eq. 2.67)", s.k_g),
            ("K_wx = K_G − K_C (eq. 2.76)", s.k_wx),
        ] {
            writeln!(f, "{name}  [N/m | N | N·m/rad]")?;
            for r in 0..6 {
                writeln!(
                    f,
                    "  {}",
                    (0..6)
                        .map(|k| format!("{:>12.4e}", mat[(r, k)]))
                        .collect::<Vec<_>>()
                        .join(" ")
                )?;
            }
        }
        let t = &self.translational;
        writeln!(
            f,
            "translational stiffness diag(−K_wx): x {:.3e}, y {:.3e}, z {:.3e} N/m; eigenvalues of −K_wx: {}",
            t[0],
            t[1],
            t[2],
            self.eigenvalues
                .iter()
                .map(|e| format!("{e:.3e}"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}
