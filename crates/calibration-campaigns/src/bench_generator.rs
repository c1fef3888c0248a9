//! The independent benchmark plant (crates/bench-plant) as data sets: the nominal platform
//! handed to its controller, its recordings written in the crs-dataset format
//! (docs/data-format.md) so `crs calibrate run` reads them like a real plant's, and the truth
//! beside them (`crs calibrate generate`).

use bench_plant::{Generated, Kind, Nominal, Phase, Recording};
use cdpr_model::Pose;
use cdpr_model::config::{Platform, load_platform};
use crs_dataset::{Dataset, Sample};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Why a scenario could not be generated or written.
#[derive(Debug, thiserror::Error)]
pub enum GeneratorError {
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    #[error(
        "{0}: the independent plant's controller drives straight cables; a platform with pulleys is not supported"
    )]
    Pulleys(String),
    #[error("{0}: no initial tension (home.f_ini_n) to set the plant up with")]
    NoInitialTension(String),
    #[error("unknown scenario kind `{0}` (one of: {1})")]
    UnknownKind(String, String),
    #[error("{kinds} kinds but {magnitudes} magnitudes")]
    MagnitudeCount { kinds: usize, magnitudes: usize },
    #[error("magnitude {0} is not a fraction in [0, 1]")]
    Magnitude(f64),
    #[error("the independent plant: {0}")]
    Plant(#[from] bench_plant::PlantError),
    #[error("{path}: {err}")]
    Write { path: PathBuf, err: std::io::Error },
}

/// The nominal robot as bench-plant's controller knows it.
pub fn nominal(platform: &Platform, file: &str) -> Result<Nominal, GeneratorError> {
    let p = platform.model.params();
    if p.pulleys.is_some() {
        return Err(GeneratorError::Pulleys(file.into()));
    }
    let v = |x: &nalgebra::Vector3<f64>| DVec3::new(x.x, x.y, x.z);
    Ok(Nominal {
        exits: p.a.iter().map(v).collect(),
        anchors: p.b.iter().map(v).collect(),
        k_f: p.k_f.clone(),
        wrench: [p.w_e[0], p.w_e[1], p.w_e[2], p.w_e[3], p.w_e[4], p.w_e[5]],
        home: platform.home.to_array(),
        f_ini: platform
            .f_ini
            .clone()
            .ok_or_else(|| GeneratorError::NoInitialTension(file.into()))?,
        f_min: p.f_min,
        f_max: p.f_max,
        f_abs_max: platform.f_abs_max,
    })
}

/// Scenario kinds from their names (`baseline`, `drum-setup`, …).
pub fn kinds(names: &[String]) -> Result<Vec<Kind>, GeneratorError> {
    names
        .iter()
        .map(|n| {
            Kind::from_name(n.trim()).ok_or_else(|| {
                GeneratorError::UnknownKind(
                    n.clone(),
                    Kind::ALL
                        .iter()
                        .map(|k| k.name())
                        .collect::<Vec<_>>()
                        .join(", "),
                )
            })
        })
        .collect()
}

/// A recording as a data set. The metadata says what recorded it, never the truth.
pub fn dataset(rec: &Recording, m: usize, campaign: &str, seed: u64) -> Dataset {
    let mut ds = Dataset::new(m, true, true);
    ds.metadata.push((
        "platform".into(),
        "independent benchmark plant (bench-plant)".into(),
    ));
    ds.metadata
        .push(("control_model".into(), "kinematic".into()));
    ds.metadata.push(("campaign".into(), campaign.into()));
    ds.metadata.push(("seed".into(), seed.to_string()));
    ds.metadata.push((
        "tension_test_shortening_m".into(),
        bench_plant::TENSION_TEST_M.to_string(),
    ));
    for s in &rec.skipped {
        ds.metadata.push((
            "unreachable".into(),
            format!(
                "pose_index {} phase {}: {}",
                s.pose_index, s.phase as u8, s.reason
            ),
        ));
    }
    ds.samples = rec
        .rows
        .iter()
        .map(|r| Sample {
            sample: r.sample,
            pose_index: r.pose_index,
            phase: match r.phase {
                Phase::Pose => crs_dataset::Phase::Pose,
                Phase::Tensioned => crs_dataset::Phase::Tensioned,
                Phase::Returned => crs_dataset::Phase::Returned,
            },
            q_cmd: r.q_cmd.clone(),
            pose: Pose::from_array(r.pose),
            forces: Some(r.forces.clone()),
            pose_ref: Some(Pose::from_array(r.pose_ref)),
        })
        .collect();
    ds
}

/// The truth of a generated scenario as JSON (kinds, drawn magnitudes, true values).
pub fn truth_json(g: &Generated, u: &[f64], seed: u64) -> serde_json::Value {
    serde_json::json!({
        "generator": "bench-plant (independent of calibrate and sim-plant)",
        "seed": seed,
        "effects": g.truth.kinds.iter().zip(&g.truth.magnitudes).zip(u).map(|((k, a), u)| {
            let (lo, hi, unit, what) = k.range();
            serde_json::json!({
                "kind": k.name(),
                "effect": k.effect(),
                "magnitude": a,
                "magnitude_fraction": u,
                "range": [lo, hi],
                "unit": unit,
                "what": what,
            })
        }).collect::<Vec<_>>(),
        "values": g.truth.values.iter().map(|v| serde_json::json!({
            "kind": v.kind.name(),
            "name": v.name,
            "values": v.values,
        })).collect::<Vec<_>>(),
        "rows": { "identification": g.train.rows.len(), "validation": g.holdout.rows.len() },
    })
}

/// Generates one scenario on the platform file `platform` and writes `identification.csv`,
/// `validation.csv` and `truth.json` into `out`.
pub fn write_scenario(
    platform: &Path,
    kinds: &[Kind],
    u: &[f64],
    seed: u64,
    poses: usize,
    out: &Path,
) -> Result<Generated, GeneratorError> {
    if kinds.len() != u.len() {
        return Err(GeneratorError::MagnitudeCount {
            kinds: kinds.len(),
            magnitudes: u.len(),
        });
    }
    if let Some(bad) = u.iter().find(|v| !(0.0..=1.0).contains(*v)) {
        return Err(GeneratorError::Magnitude(*bad));
    }
    let file = platform.display().to_string();
    let pf = load_platform(platform)?;
    let nominal = nominal(&pf, &file)?;
    let g = bench_plant::generate(&nominal, kinds, u, seed, poses)?;
    let write = |name: &str, bytes: Vec<u8>| {
        let path = out.join(name);
        std::fs::create_dir_all(out)
            .and_then(|_| std::fs::write(&path, bytes))
            .map_err(|err| GeneratorError::Write { path, err })
    };
    let m = nominal.m();
    for (name, rec, campaign) in [
        ("identification.csv", &g.train, "identification"),
        ("validation.csv", &g.holdout, "validation"),
    ] {
        let mut buf = Vec::new();
        crs_dataset::write_dataset(&mut buf, &dataset(rec, m, campaign, seed)).map_err(|err| {
            GeneratorError::Write {
                path: out.join(name),
                err,
            }
        })?;
        write(name, buf)?;
    }
    let truth = serde_json::to_vec_pretty(&truth_json(&g, u, seed)).unwrap_or_default();
    write("truth.json", truth)?;
    Ok(g)
}
