//! `crs model truss`: the icosahedron cabin's space frame (eq. 5.2–5.7) under the closed-form
//! cable forces (eq. 3.41) of a pose, or the worst case over the operating region, with extra
//! joint loads (fig. 5.10b: 10 kN per joint), against the rods' 151 kN rating.

use super::{Common, PoseArgs, Res, fmt_pose, load, pose_json};
use cdpr_model::truss::{self, ROD_EA_DEFAULT_N, ROD_RATING_N, Truss, TrussSolution};
use cdpr_model::{Data, Pose, kinematics, statics};
use nalgebra::Vector3;
use serde_json::json;

#[derive(clap::Args, Debug, Clone)]
pub struct TrussArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    pose: PoseArgs,
    /// Evaluate a grid over the operating region (5 positions per axis × 7 orientations: level
    /// and each axis at its limits) and report the worst member.
    #[arg(long)]
    worst_case: bool,
    /// Extra downward load at every joint (equipment), N; fig. 5.10b uses 10000.
    #[arg(long, default_value_t = 0.0)]
    joint_load_n: f64,
    /// Axial stiffness EA of a rod, N (the spec gives none; forces of the determinate
    /// icosahedron do not depend on it, displacements do).
    #[arg(long, default_value_t = ROD_EA_DEFAULT_N)]
    rod_ea_n: f64,
}

struct Evaluated {
    pose: Pose,
    sol: TrussSolution,
    worst: (usize, f64),
}

fn evaluate(
    pf: &cdpr_model::config::Platform,
    t: &Truss,
    cable_node: &[usize],
    data: &mut Data,
    pose: &Pose,
    joint_load: &Vector3<f64>,
) -> Result<Evaluated, Box<dyn std::error::Error>> {
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

pub(super) fn truss_cmd(a: &TrussArgs) -> Res {
    if !(a.joint_load_n.is_finite() && a.joint_load_n >= 0.0) {
        return Err("--joint-load-n must be a finite force >= 0 N".into());
    }
    let pf = load(&a.common)?;
    let (t, cable_node) = truss::icosahedron_cabin(&pf.model.params().b, a.rod_ea_n)?;
    let joint_load = Vector3::new(0.0, 0.0, -a.joint_load_n);
    let mut data = Data::new(&pf.model);
    let (ev, n_poses, n_failed) = if a.worst_case {
        let r = &pf.region;
        let lin = |lo: f64, hi: f64, k: usize| lo + (hi - lo) * k as f64 / 4.0;
        let mut orient = vec![Vector3::zeros()];
        for k in 0..3 {
            for lim in [r.rotation_min[k], r.rotation_max[k]] {
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
                        lin(r.position.min.x, r.position.max.x, i),
                        lin(r.position.min.y, r.position.max.y, j),
                        lin(r.position.min.z, r.position.max.z, k),
                    );
                    for phi in &orient {
                        n += 1;
                        match evaluate(
                            &pf,
                            &t,
                            &cable_node,
                            &mut data,
                            &Pose::new(pos, *phi),
                            &joint_load,
                        ) {
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
        (
            best.ok_or("no pose of the grid could be evaluated")?,
            n,
            failed,
        )
    } else {
        let pose = a.pose.pose(&pf)?;
        (
            evaluate(&pf, &t, &cable_node, &mut data, &pose, &joint_load)?,
            1,
            0,
        )
    };
    let (j, fw) = ev.worst;
    let (p, q) = t.members[j];
    let utilisation = fw.abs() / ROD_RATING_N;
    let max_disp = ev
        .sol
        .displacements
        .iter()
        .map(|d| d.norm())
        .fold(0.0, f64::max);
    let reaction: Vector3<f64> = ev.sol.reactions.iter().sum();
    if a.common.json {
        println!(
            "{}",
            json!({
                "platform": pf.name, "pose": pose_json(&ev.pose),
                "worst_case": a.worst_case, "poses_evaluated": n_poses - n_failed, "poses_failed": n_failed,
                "joint_load_n": a.joint_load_n, "rod_ea_n": a.rod_ea_n,
                "member_forces_n": ev.sol.member_forces,
                "members": t.members.iter().map(|(p, q)| [p + 1, q + 1]).collect::<Vec<_>>(),
                "cable_joints": cable_node.iter().map(|k| k + 1).collect::<Vec<_>>(),
                "worst_member": j + 1, "worst_force_n": fw, "rating_n": ROD_RATING_N,
                "utilisation": utilisation, "max_displacement_m": max_disp,
                "reaction_sum_n": reaction.as_slice(),
            })
        );
        return Ok(());
    }
    println!(
        "{}: icosahedron space frame (12 joints, 30 rods, EA {:.3e} N), joint load {:.0} N down, cable forces by eq. 3.41",
        pf.name, a.rod_ea_n, a.joint_load_n
    );
    if a.worst_case {
        println!(
            "worst case over {} poses of the operating region{}: {}",
            n_poses - n_failed,
            if n_failed > 0 {
                format!(" ({n_failed} poses could not be evaluated)")
            } else {
                String::new()
            },
            fmt_pose(&ev.pose)
        );
    } else {
        println!("pose {}", fmt_pose(&ev.pose));
        println!("{:>6} {:>9} {:>12}", "rod", "joints", "f_sf [N]");
        for (k, f) in ev.sol.member_forces.iter().enumerate() {
            let (p, q) = t.members[k];
            println!("{:>6} {:>4}-{:<4} {:>12.1}", k + 1, p + 1, q + 1, f);
        }
    }
    println!(
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
    );
    println!(
        "largest joint displacement {:.3} mm; support reactions sum [{:.1}, {:.1}, {:.1}] N (non-zero = loads the cables do not balance)",
        max_disp * 1e3,
        reaction.x,
        reaction.y,
        reaction.z
    );
    Ok(())
}
