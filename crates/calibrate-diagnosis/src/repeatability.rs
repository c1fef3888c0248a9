//! How far to trust one calibration run: does the optimiser land on the same
//! optimum from other starts, does a second data set give the same geometry, and do the chosen
//! effects and key parameters survive resampling of the training poses?
//!
//! 1. **Multi-start** (eq. 6.8): the optimal elastostatic fit again from frame anchors
//!    a_ini = a_N + U(−0.5, 0.5) m per coordinate; the optimum is "the same" when its cost is
//!    within 1e-6 (relative) of the pipeline's and no frame anchor moved by more than 1 mm. A
//!    lower cost found from another start is a better local optimum the pipeline missed.
//! 2. **Second run** (eq. 6.10): the same fit on the held-out set; Δa₂ = a_opt₂ − a_opt against
//!    the pipeline's 1σ (the spec found |Δa₂| up to 87 mm at an unchanged accuracy level: the
//!    geometry of a CDPR is weakly determined by its cable lengths, Fig. 6.11–6.12).
//! 3. **Bootstrap**: the whole pipeline (fit, diagnosis, extension) on B resamples of the
//!    training *poses* with replacement (the rows of a pose's tension test stay together),
//!    validated on the same held-out set: how often each effect is chosen, whether the chosen
//!    set is the pipeline's, and the spread of k_F and of every extension parameter.
//!
//! Off by default (it costs B pipeline runs); `crs calibrate run --multi-start K --bootstrap B`.

use crate::effects::Effect;
use crate::pipeline::{self, PipelineConfig, PipelineReport};
use calibrate::identify::{self, FitSpec};
use calibrate::observation::Observation;
use calibrate::params::{CalModel, ParamId};
use cdpr_model::Model;
use nalgebra::Vector3;

pub use crate::repeatability_figures::{
    Bootstrap, MultiStart, ParamSpread, Repeatability, RepeatabilityConfig, SecondRun,
};

/// splitmix64 → uniform [0, 1): reproducible without a dependency.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Distance of each frame anchor of `a` from the same anchor of `b`, mm.
fn anchor_distances_mm(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| (x - y).norm() * 1e3).collect()
}

/// Runs the configured tests for a pipeline report `rep` made from `train` / `holdout`.
pub fn assess(
    nominal: &Model,
    train: &[Observation],
    holdout: &[Observation],
    cfg: &PipelineConfig,
    rep: &PipelineReport,
    rc: &RepeatabilityConfig,
    progress: &mut dyn FnMut(&str, usize),
) -> Repeatability {
    let mut rng = Rng(rc.seed);
    let base = rep
        .stage("optimal elastostatic")
        .and_then(|s| s.fit.as_ref());
    let start = rep.stage("nominal elastostatic").map(|s| &s.model);
    // The same fit as the pipeline's step, with the k_F ridge it used (configured or chosen).
    let mut fixed = cfg.clone();
    fixed.ridge_kf = rep.ridge_kf;
    fixed.ridge_kf_auto = false;
    let spec = pipeline::elastostatic_spec(&fixed, nominal.m());
    let multi_start = match (base, start) {
        (Some(base), Some(start)) if rc.multi_starts > 0 => {
            let mut ms = MultiStart {
                starts: rc.multi_starts,
                failed: 0,
                same_optimum: 0,
                lower_cost: 0,
                max_anchor_distance_mm: None,
                best_cost_ratio: None,
            };
            for k in 0..rc.multi_starts {
                progress("multi-start", k);
                let mut s: CalModel = start.clone();
                for a in s.a.iter_mut() {
                    for c in 0..3 {
                        a[c] += rng.next() - 0.5; // eq. 6.8: U(−0.5, 0.5) m
                    }
                }
                match identify::fit(&s, train, &spec, &mut |_, _| {}) {
                    Ok(f) => {
                        let d = anchor_distances_mm(&f.model.a, &base.model.a)
                            .into_iter()
                            .fold(0.0, f64::max);
                        let ratio = f.cost / base.cost;
                        ms.max_anchor_distance_mm =
                            Some(ms.max_anchor_distance_mm.map_or(d, |m| m.max(d)));
                        ms.best_cost_ratio =
                            Some(ms.best_cost_ratio.map_or(ratio, |m| m.min(ratio)));
                        if (ratio - 1.0).abs() <= 1e-6 && d <= 1.0 {
                            ms.same_optimum += 1;
                        } else if ratio < 1.0 - 1e-6 {
                            ms.lower_cost += 1;
                        }
                    }
                    Err(_) => ms.failed += 1,
                }
            }
            Some(ms)
        }
        _ => None,
    };
    let second_run = match (base, start) {
        (Some(base), Some(start)) if !holdout.is_empty() && rc.multi_starts > 0 => {
            progress("second run", 0);
            Some(second_run(base, start, holdout, &spec))
        }
        _ => None,
    };
    let run = Run {
        nominal,
        train,
        holdout,
        cfg,
        rep,
    };
    let bootstrap = (rc.bootstrap > 0).then(|| bootstrap(&run, rc.bootstrap, &mut rng, progress));
    Repeatability {
        config: *rc,
        multi_start,
        second_run,
        bootstrap,
    }
}

fn second_run(
    base: &identify::Fit,
    start: &CalModel,
    holdout: &[Observation],
    spec: &FitSpec,
) -> SecondRun {
    match identify::fit(start, holdout, spec, &mut |_, _| {}) {
        Ok(f2) => {
            let d = anchor_distances_mm(&f2.model.a, &base.model.a);
            let mut ratio: Option<f64> = None;
            for (c, p) in base.free.iter().enumerate() {
                if let ParamId::A(i, k) = p {
                    let sd = base.std[c];
                    if sd.is_finite() && sd > 0.0 {
                        let r = (f2.model.a[*i][*k] - base.model.a[*i][*k]).abs()
                            / (std::f64::consts::SQRT_2 * sd);
                        ratio = Some(ratio.map_or(r, |m| m.max(r)));
                    }
                }
            }
            SecondRun {
                max_anchor_change_mm: d.iter().copied().reduce(f64::max),
                mean_anchor_change_mm: (!d.is_empty())
                    .then(|| d.iter().sum::<f64>() / d.len() as f64),
                max_change_over_sigma: ratio,
                failure: None,
            }
        }
        Err(e) => SecondRun {
            max_anchor_change_mm: None,
            mean_anchor_change_mm: None,
            max_change_over_sigma: None,
            failure: Some(e.to_string()),
        },
    }
}

/// The pipeline run under test: its inputs and its report.
struct Run<'a> {
    nominal: &'a Model,
    train: &'a [Observation],
    holdout: &'a [Observation],
    cfg: &'a PipelineConfig,
    rep: &'a PipelineReport,
}

fn bootstrap(
    run: &Run,
    resamples: usize,
    rng: &mut Rng,
    progress: &mut dyn FnMut(&str, usize),
) -> Bootstrap {
    let Run {
        nominal,
        train,
        holdout,
        cfg,
        rep,
    } = *run;
    let mut poses: Vec<u64> = train.iter().map(|o| o.pose_index).collect();
    poses.sort_unstable();
    poses.dedup();
    let main_effects: Vec<Effect> = rep
        .selection
        .as_ref()
        .map(|s| s.chosen.clone())
        .unwrap_or_default();
    let same_set =
        |c: &[Effect]| c.len() == main_effects.len() && c.iter().all(|e| main_effects.contains(e));
    let main_fit = rep.final_stage().fit.as_ref();
    let mut out = Bootstrap {
        runs: resamples,
        failed: 0,
        same_effects: 0,
        effect_counts: Effect::ALL.iter().map(|e| (*e, 0)).collect(),
        params: Vec::new(),
        max_anchor_sd_mm: None,
    };
    // Values per parameter name over the runs, and the anchors of every run.
    let mut values: Vec<(ParamId, Vec<f64>)> = Vec::new();
    let mut anchors: Vec<Vec<Vector3<f64>>> = Vec::new();
    let mut quiet = cfg.clone();
    quiet.cartesian = false;
    for b in 0..resamples {
        progress("bootstrap", b);
        let mut sample = Vec::with_capacity(train.len());
        for _ in 0..poses.len() {
            let p = poses[((rng.next() * poses.len() as f64) as usize).min(poses.len() - 1)];
            sample.extend(train.iter().filter(|o| o.pose_index == p).cloned());
        }
        let r = match pipeline::run(nominal, &sample, holdout, &quiet, &mut |_, _, _| {}) {
            Ok(r) if !r.final_stage().failed() => r,
            _ => {
                out.failed += 1;
                continue;
            }
        };
        let chosen: Vec<Effect> = r
            .selection
            .as_ref()
            .map(|s| s.chosen.clone())
            .unwrap_or_default();
        if same_set(&chosen) {
            out.same_effects += 1;
        }
        for (e, n) in out.effect_counts.iter_mut() {
            if chosen.contains(e) {
                *n += 1;
            }
        }
        if let Some(f) = r.final_stage().fit.as_ref() {
            for p in &f.free {
                if matches!(p, ParamId::KF(_)) || !p.is_base() {
                    let v = f.model.get(*p);
                    match values.iter_mut().find(|(q, _)| q == p) {
                        Some((_, vs)) => vs.push(v),
                        None => values.push((*p, vec![v])),
                    }
                }
            }
            anchors.push(f.model.a.clone());
        }
    }
    for (p, vs) in values {
        let n = vs.len();
        let mean = vs.iter().sum::<f64>() / n as f64;
        let sd = if n > 1 {
            (vs.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            f64::NAN
        };
        let (value, sigma) = main_fit
            .and_then(|f| {
                f.free
                    .iter()
                    .position(|q| *q == p)
                    .map(|c| (f.model.get(p), f.std[c]))
            })
            .unwrap_or((f64::NAN, f64::NAN));
        out.params.push(ParamSpread {
            name: p.name(),
            value,
            sigma,
            runs: n,
            mean,
            sd,
        });
    }
    if anchors.len() > 1 {
        let n = anchors.len() as f64;
        let m = anchors[0].len();
        let mut worst = 0.0f64;
        for i in 0..m {
            for k in 0..3 {
                let mean = anchors.iter().map(|a| a[i][k]).sum::<f64>() / n;
                let var = anchors
                    .iter()
                    .map(|a| (a[i][k] - mean).powi(2))
                    .sum::<f64>()
                    / (n - 1.0);
                worst = worst.max(var.sqrt() * 1e3);
            }
        }
        out.max_anchor_sd_mm = Some(worst);
    }
    out
}
