//! `crs model ik` and `crs model fk`: inverse kinematics (eq. 2.3–2.8, 2.16–2.29) and forward
//! kinematics, least squares (eq. 2.11) or elastostatic (eq. 2.42).

use super::{Common, PoseArgs, Res, fmt_pose, load, pose_json};
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, kinematics};
use serde_json::json;

pub(super) fn ik(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let pose = pa.pose(&pf)?;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
    if c.json {
        let cables: Vec<_> = (0..model.m())
            .map(|i| {
                json!({
                    "cable": i + 1,
                    "length_m": data.q[i],
                    "free_length_m": data.q_free[i],
                    "wrap_angle_deg": data.beta[i].to_degrees(),
                    "unit_vector": [data.u[i].x, data.u[i].y, data.u[i].z],
                    "exit_point_m": [data.p_exit[i].x, data.p_exit[i].y, data.p_exit[i].z],
                })
            })
            .collect();
        println!(
            "{}",
            json!({"platform": pf.name, "pose": pose_json(&pose), "cables": cables})
        );
        return Ok(());
    }
    println!("{} at {}", pf.name, fmt_pose(&pose));
    println!(
        "{:>5} {:>10} {:>10} {:>8} {:>26}",
        "cable", "q [m]", "q_f [m]", "β [°]", "u"
    );
    for i in 0..model.m() {
        let u = data.u[i];
        println!(
            "{:>5} {:>10.5} {:>10.5} {:>8.2}   [{:+.4}, {:+.4}, {:+.4}]",
            i + 1,
            data.q[i],
            data.q_free[i],
            data.beta[i].to_degrees(),
            u.x,
            u.y,
            u.z
        );
    }
    Ok(())
}

pub(super) fn fk(c: &Common, q: &[f64], elastic: bool, guess: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    if q.len() != model.m() {
        return Err(format!(
            "--lengths-m has {} values but {} has {} cables",
            q.len(),
            pf.name,
            model.m()
        )
        .into());
    }
    let g = guess.pose(&pf)?;
    let mut data = Data::new(model);
    let opts = FkOptions::default();
    let sol = if elastic {
        forward::elastostatic(model, &mut data, q, &g, &opts)?
    } else {
        forward::least_squares(model, &mut data, q, &g, &opts)?
    };
    if c.json {
        let mut v = json!({
            "platform": pf.name,
            "method": if elastic { "elastostatic" } else { "least_squares" },
            "pose": pose_json(&sol.pose),
            "iterations": sol.iterations,
            "residual": sol.residual_norm,
        });
        if elastic {
            v["forces_n"] = json!(data.f);
        }
        println!("{v}");
        return Ok(());
    }
    println!(
        "{} forward kinematics ({}): {}",
        pf.name,
        if elastic {
            "elastostatic ν_el, eq. 2.42"
        } else {
            "least squares ν, eq. 2.11"
        },
        fmt_pose(&sol.pose)
    );
    println!(
        "iterations {}, residual {:.3e} {}",
        sol.iterations,
        sol.residual_norm,
        if elastic { "N" } else { "m" }
    );
    if elastic {
        for (i, f) in data.f.iter().enumerate() {
            println!("  f_{} = {:>9.1} N", i + 1, f);
        }
    }
    Ok(())
}
