//! Timing of the 62-parameter elastostatic identification p = (a, b, k_F, w_e) (eq. 6.14) on
//! the 91 pose samples of the CRS-like campaign (config/plant/campaign-91.toml), for the
//! comparison with scipy.optimize.least_squares in benches/calibrate_vs_scipy.py.
//!
//! Usage: cargo run --release -p calibrate --example calibrate_bench -- [--export FILE.json] [--repeat N]
//! Writes the data, start point, scales, weights and the Rust optimum/timing to FILE.json.

use calibrate::identify::estimate_offsets;
use calibrate::params::{Group, group};
use calibrate::{CalModel, FitSpec, Kind, ParamId, fit, from_dataset};
use crs_dataset::Phase;
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let mut export: Option<PathBuf> = None;
    let mut repeat = 20usize;
    let mut k = 1;
    while k < args.len() {
        match args[k].as_str() {
            "--export" => {
                export = Some(args.get(k + 1).ok_or("--export needs a file")?.into());
                k += 2;
            }
            "--repeat" => {
                repeat = args.get(k + 1).ok_or("--repeat needs a number")?.parse()?;
                k += 2;
            }
            a => return Err(format!("unknown argument `{a}`").into()),
        }
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/plant");
    let pcfg = sim_plant::load_plant(root.join("crs-like.toml"))?;
    let mut camp = sim_plant::load_campaign(root.join("campaign-91.toml"))?;
    camp.tension_test = None;
    // The spec's first data set has n_s = 91 samples (sec. 6.1): draw random poses until 91
    // are reachable under nominal kinematic control (the others violate the force limits).
    if let sim_plant::PoseSet::Random { count, .. } = &mut camp.poses {
        *count = 200;
    }
    let base = pcfg.platform.clone();
    let mut plant = sim_plant::Plant::new(pcfg)?;
    let ds = sim_plant::run_campaign(&mut plant, &base, &camp, "nominal")?.dataset;
    let obs: Vec<_> = from_dataset(&ds, base.model.m())?
        .into_iter()
        .filter(|o| o.phase == Phase::Pose)
        .take(91)
        .collect();
    let m = base.model.m();
    let mut start = CalModel::from_model(&base.model);
    let mut spec = FitSpec::new(Kind::Elastostatic, Vec::new());
    // Offsets from the measured tension with the nominal model (eq. 6.24), then fixed.
    estimate_offsets(Kind::Elastostatic, &mut start, &obs, spec.weights)?;
    spec.free = [Group::A, Group::B, Group::KF, Group::We]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect::<Vec<ParamId>>();
    spec.min_relative_singular_value = 0.0;
    let mut times = Vec::new();
    let mut result = None;
    for _ in 0..repeat {
        let t = Instant::now();
        let f = fit(&start, &obs, &spec, &mut |_, _| {})?;
        times.push(t.elapsed().as_secs_f64());
        result = Some(f);
    }
    let f = result.ok_or("--repeat must be >= 1")?;
    times.sort_by(|a, b| a.total_cmp(b));
    // The median by the stack's one quantile definition (nearest rank).
    let median = crs_limits::quantile::quantile_sorted(&times, 0.5).ok_or("no runs")?;
    println!(
        "rust: {} samples, {} parameters, {} residuals, {} iterations, cost {:.9e}, median {:.3} ms over {} runs",
        obs.len(),
        f.free.len(),
        f.n_residuals,
        f.iterations,
        f.cost,
        median * 1e3,
        repeat
    );
    if let Some(path) = export {
        let samples: Vec<serde_json::Value> = obs
            .iter()
            .map(|o| {
                serde_json::json!({
                    "q_cmd": o.q_cmd, "pose": o.pose.to_array(), "forces": o.forces,
                })
            })
            .collect();
        let p0: Vec<f64> = spec.free.iter().map(|p| start.get(*p)).collect();
        let popt: Vec<f64> = spec.free.iter().map(|p| f.model.get(*p)).collect();
        let scales: Vec<f64> = spec.free.iter().map(|p| p.scale()).collect();
        let names: Vec<String> = spec.free.iter().map(|p| p.name()).collect();
        let j = serde_json::json!({
            "m": m,
            "samples": samples,
            "offsets": start.offset,
            "names": names,
            "p0": p0,
            "scales": scales,
            "weights": {"wrench": spec.weights.wrench, "length": spec.weights.length},
            "rust": {"p_opt": popt, "cost": f.cost, "iterations": f.iterations,
                     "evaluations": f.evaluations, "median_s": median, "runs": repeat},
        });
        std::fs::write(&path, serde_json::to_string(&j)?)?;
        println!("exported {}", path.display());
    }
    Ok(())
}
