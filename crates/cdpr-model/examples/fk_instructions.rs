//! A fixed number of forward-kinematics solves (ν or ν_el, 1 cm / 1° off the pose) for an
//! instruction count under callgrind, which, unlike wall time, does not depend on the host's
//! load (this VM exposes no hardware counters to `perf`). The per-solve count is the difference
//! of two runs, which cancels the set-up:
//!
//! ```text
//! cargo build --profile bench -p cdpr-model --example fk_instructions
//! valgrind --tool=callgrind --callgrind-out-file=/dev/null \
//!     target/release/examples/fk_instructions ls icosahedron.toml 200     # and 2200
//! ```
//!
//! Arguments: `ls` (ν) or `el` (ν_el), a platform file of config/, the number of solves.

use cdpr_model::config::load_platform;
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Pose, elastostatics, kinematics, statics};
use nalgebra::Vector3;
use std::hint::black_box;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, solver, file, count] = args.as_slice() else {
        return Err("usage: fk_instructions ls|el PLATFORM.toml COUNT".into());
    };
    let count: usize = count.parse()?;
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config");
    let model = load_platform(format!("{dir}/{file}"))?.model;
    let p = model.params().clone();
    let mut data = Data::new(&model);
    let pose = Pose::new(
        Vector3::new(0.4, -0.3, 1.8),
        Vector3::new(0.05, -0.04, 0.08),
    );
    let guess = Pose::new(
        pose.r + Vector3::new(0.01, -0.01, 0.01),
        pose.phi + Vector3::repeat(1f64.to_radians()),
    );
    kinematics::inverse(&model, &mut data, &pose)?;
    let q = data.q.clone();
    let mut f = vec![0.0; model.m()];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let mut q_theta = vec![0.0; model.m()];
    elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta)?;
    let opts = FkOptions::default();
    for _ in 0..count {
        let sol = match solver.as_str() {
            "ls" => forward::least_squares(&model, &mut data, black_box(&q), &guess, &opts)?,
            "el" => forward::elastostatic(&model, &mut data, black_box(&q_theta), &guess, &opts)?,
            other => return Err(format!("unknown solver `{other}` (ls or el)").into()),
        };
        black_box(sol);
    }
    Ok(())
}
