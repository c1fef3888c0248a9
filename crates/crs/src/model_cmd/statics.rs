//! `crs model forces` and `crs model stiffness`: force distribution (closed form eq. 3.41 and the
//! exact test of eq. 3.29), internal/external split, section wrenches; stiffness (eq. 2.67–2.78).

use super::{Common, PoseArgs, Res, fmt_pose, load, pose_json};
use cdpr_model::elastostatics::{self, Stiffness};
use cdpr_model::{Data, feasibility, kinematics, statics};
use nalgebra::{DVector, Matrix6};
use serde_json::json;

pub(super) fn forces(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let p = model.params();
    let pose = pa.pose(&pf)?;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
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
    let sections: Vec<_> = pf
        .sections
        .iter()
        .map(|s| {
            (
                s.name.clone(),
                statics::section_wrench(&data, &f, &s.cables),
            )
        })
        .collect();
    if c.json {
        let secs: serde_json::Map<_, _> = sections
            .iter()
            .map(|(n, w)| (n.clone(), json!(w.as_slice())))
            .collect();
        println!(
            "{}",
            json!({
                "platform": pf.name, "pose": pose_json(&pose),
                "forces_n": f, "external_n": fe, "internal_n": fi,
                "f_min_n": p.f_min, "f_max_n": p.f_max, "feasible": fd.feasible, "margin_n": fd.margin,
                "exact": {
                    "feasible": exact.feasible, "margin_n": exact.margin,
                    "forces_n": exact.forces.as_slice(),
                },
                "structure_matrix": (0..at.nrows())
                    .map(|r| at.row(r).iter().copied().collect::<Vec<_>>())
                    .collect::<Vec<_>>(),
                "w_e": p.w_e.as_slice(),
                "section_wrenches": secs,
            })
        );
        return Ok(());
    }
    println!("{} at {}", pf.name, fmt_pose(&pose));
    println!(
        "closed-form force distribution (eq. 3.41), limits [{:.0}, {:.0}] N",
        p.f_min, p.f_max
    );
    println!(
        "{:>5} {:>10} {:>10} {:>10}",
        "cable", "f [N]", "f_ext [N]", "f_int [N]"
    );
    for i in 0..m {
        println!(
            "{:>5} {:>10.1} {:>10.1} {:>10.1}",
            i + 1,
            f[i],
            fe[i],
            fi[i]
        );
    }
    println!(
        "verdict: {} (min {:.1} N on cable {}, max {:.1} N on cable {}, margin {:.1} N)",
        if fd.feasible {
            "FEASIBLE"
        } else {
            "NOT FEASIBLE"
        },
        fd.f_lo,
        fd.cable_lo + 1,
        fd.f_hi,
        fd.cable_hi + 1,
        fd.margin
    );
    println!(
        "exact test (eq. 3.29, max-margin LP): {}, margin {:.1} N{}",
        if exact.feasible {
            "FEASIBLE"
        } else {
            "NOT FEASIBLE"
        },
        exact.margin,
        if exact.feasible && !fd.feasible {
            " (another distribution fits where eq. 3.41 does not)"
        } else {
            ""
        }
    );
    for (name, w) in &sections {
        println!(
            "section wrench {name} (eq. 5.11): f = [{:.0}, {:.0}, {:.0}] N, τ = [{:.0}, {:.0}, {:.0}] N·m",
            w[0], w[1], w[2], w[3], w[4], w[5]
        );
    }
    Ok(())
}

pub(super) fn stiffness(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let p = model.params();
    let pose = pa.pose(&pf)?;
    let m = model.m();
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
    let mut f = vec![0.0; m];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let mut qt = vec![0.0; m];
    elastostatics::inverse(model, &mut data, &pose, &f, &mut qt)?;
    elastostatics::cable_forces(&mut data, &model.linear_law(), &qt);
    let s = Stiffness::at(model, &data);
    let k_sys = -s.k_wx; // positive-definite stiffness, δw = −K_wx δx (eq. 2.76)
    let eig = k_sys.symmetric_eigen().eigenvalues;
    let translational = [k_sys[(0, 0)], k_sys[(1, 1)], k_sys[(2, 2)]];
    if c.json {
        let mat = |m: &Matrix6<f64>| {
            (0..6)
                .map(|r| (0..6).map(|k| m[(r, k)]).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        };
        println!(
            "{}",
            json!({
                "platform": pf.name, "pose": pose_json(&pose), "forces_n": f,
                "k_c": mat(&s.k_c), "k_g": mat(&s.k_g), "k_wx": mat(&s.k_wx),
                "stiffness_eigenvalues": eig.as_slice(),
                "translational_stiffness_n_per_m": translational,
            })
        );
        return Ok(());
    }
    println!(
        "{} at {} with the reference forces of eq. 3.41",
        pf.name,
        fmt_pose(&pose)
    );
    for (name, mat) in [
        ("K_C = A^T K A (eq. 2.75)", s.k_c),
        ("K_G (eq. 2.67)", s.k_g),
        ("K_wx = K_G − K_C (eq. 2.76)", s.k_wx),
    ] {
        println!("{name}  [N/m | N | N·m/rad]");
        for r in 0..6 {
            println!(
                "  {}",
                (0..6)
                    .map(|k| format!("{:>12.4e}", mat[(r, k)]))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
    }
    println!(
        "translational stiffness diag(−K_wx): x {:.3e}, y {:.3e}, z {:.3e} N/m; eigenvalues of −K_wx: {}",
        translational[0],
        translational[1],
        translational[2],
        eig.iter()
            .map(|e| format!("{e:.3e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
