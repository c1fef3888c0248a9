//! The icosahedron cabin's space frame (eq. 5.2–5.7) under the closed-form cable forces
//! (eq. 3.41) of a pose, or the worst case over the operating region, with extra joint loads
//! (fig. 5.10b: 10 kN per joint), against the rods' 151 kN rating.

use crate::{AnalysisError, fmt_pose, pose_json};
use cdpr_analysis::truss::{self, ROD_RATING_N, Truss, TrussSolution};
use cdpr_model::config::Platform;
use cdpr_model::{Data, Pose, kinematics, statics};
use nalgebra::Vector3;
use serde_json::json;
use std::fmt;

/// What to load the frame with.
#[derive(Clone, Copy, Debug)]
pub struct TrussRequest {
    /// The pose to evaluate; ignored with `worst_case`.
    pub pose: Pose,
    /// Evaluate a grid over the operating region (5 positions per axis × 7 orientations: level
    /// and each axis at its limits) and report the worst member.
    pub worst_case: bool,
    /// Extra downward load at every joint, N.
    pub joint_load_n: f64,
    /// Axial stiffness EA of a rod, N.
    pub rod_ea_n: f64,
}

/// One pose's solution with its most loaded rod (index, force N).
pub struct Evaluated {
    pub pose: Pose,
    pub sol: TrussSolution,
    pub worst: (usize, f64),
}

/// The truss check of a pose, or of the worst pose of the grid.
pub struct TrussReport {
    pub platform: String,
    pub request: TrussRequest,
    pub truss: Truss,
    /// The joint each cable is attached to.
    pub cable_node: Vec<usize>,
    pub evaluated: Evaluated,
    pub poses: usize,
    pub failed: usize,
}

fn evaluate(
    pf: &Platform,
    t: &Truss,
    cable_node: &[usize],
    data: &mut Data,
    pose: &Pose,
    joint_load: &Vector3<f64>,
) -> Result<Evaluated, AnalysisError> {
    let model = &pf.model;
    let p = model.params();
    kinematics::inverse(model, data, pose)?;
    let mut f = vec![0.0; model.m()];
    statics::force_distribution(data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let w_force = Vector3::new(p.w_e[0], p.w_e[1], p.w_e[2]);
    let w = truss::cabin_loads(
        t,
        cable_node,
        &pose.rotation(),
        &data.u,
        &f,
        &w_force,
        joint_load,
    );
    let sol = truss::solve(t, &w)?;
    let worst = sol
        .member_forces
        .iter()
        .enumerate()
        .fold((0, 0.0f64), |acc, (j, v)| {
            if v.abs() > acc.1.abs() { (j, *v) } else { acc }
        });
    Ok(Evaluated {
        pose: *pose,
        sol,
        worst,
    })
}

/// The truss check of `pf`'s cabin for `r`.
pub fn truss(pf: &Platform, r: &TrussRequest) -> Result<TrussReport, AnalysisError> {
    let (t, cable_node) = truss::icosahedron_cabin(&pf.model.params().b, r.rod_ea_n)?;
    let joint_load = Vector3::new(0.0, 0.0, -r.joint_load_n);
    let mut data = Data::new(&pf.model);
    let (ev, poses, failed) = if r.worst_case {
        let reg = &pf.region;
        let lin = |lo: f64, hi: f64, k: usize| lo + (hi - lo) * k as f64 / 4.0;
        let mut orient = vec![Vector3::zeros()];
        for k in 0..3 {
            for lim in [reg.rotation_min[k], reg.rotation_max[k]] {
                let mut v = Vector3::zeros();
                v[k] = lim;
                orient.push(v);
            }
        }
        let (mut best, mut n, mut failed): (Option<Evaluated>, usize, usize) = (None, 0, 0);
        for i in 0..5 {
            for j in 0..5 {
                for k in 0..5 {
                    let pos = Vector3::new(
                        lin(reg.position.min.x, reg.position.max.x, i),
                        lin(reg.position.min.y, reg.position.max.y, j),
                        lin(reg.position.min.z, reg.position.max.z, k),
                    );
                    for phi in &orient {
                        n += 1;
                        let pose = Pose::new(pos, *phi);
                        match evaluate(pf, &t, &cable_node, &mut data, &pose, &joint_load) {
                            Ok(e) => {
                                if best
                                    .as_ref()
                                    .is_none_or(|b| e.worst.1.abs() > b.worst.1.abs())
                                {
                                    best = Some(e);
                                }
                            }
                            Err(_) => failed += 1,
                        }
                    }
                }
            }
        }
        (best.ok_or(AnalysisError::NoPoseEvaluated)?, n, failed)
    } else {
        let ev = evaluate(pf, &t, &cable_node, &mut data, &r.pose, &joint_load)?;
        (ev, 1, 0)
    };
    Ok(TrussReport {
        platform: pf.name.clone(),
        request: *r,
        truss: t,
        cable_node,
        evaluated: ev,
        poses,
        failed,
    })
}

impl TrussReport {
    /// The worst rod's utilisation of the rating.
    pub fn utilisation(&self) -> f64 {
        self.evaluated.worst.1.abs() / ROD_RATING_N
    }

    fn max_displacement(&self) -> f64 {
        self.evaluated
            .sol
            .displacements
            .iter()
            .map(|d| d.norm())
            .fold(0.0, f64::max)
    }

    fn reaction(&self) -> Vector3<f64> {
        self.evaluated.sol.reactions.iter().sum()
    }

    pub fn json(&self) -> serde_json::Value {
        let (ev, r) = (&self.evaluated, &self.request);
        let (j, fw) = ev.worst;
        json!({
            "platform": self.platform, "pose": pose_json(&ev.pose),
            "worst_case": r.worst_case, "poses_evaluated": self.poses - self.failed, "poses_failed": self.failed,
            "joint_load_n": r.joint_load_n, "rod_ea_n": r.rod_ea_n,
            "member_forces_n": ev.sol.member_forces,
            "members": self.truss.members.iter().map(|(p, q)| [p + 1, q + 1]).collect::<Vec<_>>(),
            "cable_joints": self.cable_node.iter().map(|k| k + 1).collect::<Vec<_>>(),
            "worst_member": j + 1, "worst_force_n": fw, "rating_n": ROD_RATING_N,
            "utilisation": self.utilisation(), "max_displacement_m": self.max_displacement(),
            "reaction_sum_n": self.reaction().as_slice(),
        })
    }
}

impl fmt::Display for TrussReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (ev, r, t) = (&self.evaluated, &self.request, &self.truss);
        let (j, fw) = ev.worst;
        let (p, q) = t.members[j];
        let utilisation = self.utilisation();
        let reaction = self.reaction();
        writeln!(
            f,
            "{}: icosahedron space frame (12 joints, 30 rods, EA {:.3e} N), joint load {:.0} N down, cable forces by eq. 3.41",
            self.platform, r.rod_ea_n, r.joint_load_n
        )?;
        if r.worst_case {
            writeln!(
                f,
                "worst case over {} poses of the operating region{}: {}",
                self.poses - self.failed,
                if self.failed > 0 {
                    format!(" ({} poses could not be evaluated)", self.failed)
                } else {
                    String::new()
                },
                fmt_pose(&ev.pose)
            )?;
        } else {
            writeln!(f, "pose {}", fmt_pose(&ev.pose))?;
            writeln!(f, "{:>6} {:>9} {:>12}", "rod", "joints", "f_sf [N]")?;
            for (k, force) in ev.sol.member_forces.iter().enumerate() {
                let (p, q) = t.members[k];
                writeln!(f, "{:>6} {:>4}-{:<4} {:>12.1}", k + 1, p + 1, q + 1, force)?;
            }
        }
        writeln!(
            f,
            "worst rod {} (joints {}-{}): {:.1} kN {} — {:.1} % of the {:.0} kN rating{}",
            j + 1,
            p + 1,
            q + 1,
            fw / 1e3,
            if fw < 0.0 { "compression" } else { "tension" },
            100.0 * utilisation,
            ROD_RATING_N / 1e3,
            if utilisation > 1.0 {
                "  ** OVER RATING **"
            } else {
                ""
            }
        )?;
        writeln!(
            f,
            "largest joint displacement {:.3} mm; support reactions sum [{:.1}, {:.1}, {:.1}] N (non-zero = loads the cables do not balance)",
            self.max_displacement() * 1e3,
            reaction.x,
            reaction.y,
            reaction.z
        )
    }
}
