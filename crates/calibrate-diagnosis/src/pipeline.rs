//! The spec's calibration steps end to end (ch. 6.1–6.5) plus the model extension:
//! nominal kinematic → optimal kinematic (eq. 4.8, sec. 6.2) → nominal elastostatic (offsets
//! from the measured tension, eq. 3.14 / 6.24, sec. 6.4) → optimal elastostatic (eq. 4.38,
//! sec. 6.5) → + the effects the residuals support ([`crate::effects`]). Every figure is
//! computed on held-out samples through the forward kinematics ([`calibrate::validate`]).

use crate::effects::{self, Effect, SelectConfig, Selection};
use calibrate::identify::{self, Fit, FitError, FitSpec};
use calibrate::observation::Observation;
use calibrate::params::{CalModel, Group, ParamId, group};
use calibrate::residual::{Kind, Weights};
use calibrate::validate::{self, Errors};
use cdpr_model::Model;
use serde::Serialize;

/// Pipeline settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PipelineConfig {
    pub weights: Weights,
    /// Ridge λ on the platform anchors b in the elastostatic fit (sec. 6.5), 0 = off.
    pub ridge_b: f64,
    /// Lasso λ on the platform anchors b, 0 = off (eq. 4.32).
    pub lasso_b: f64,
    /// Ridge λ on the cable stiffnesses k_F (towards the nominal, in units of 1e6 N) in the
    /// elastostatic fit, 0 = off: k_F is the weakest-determined group on short campaigns.
    pub ridge_kf: f64,
    /// Choose the k_F ridge from [`RIDGE_KF_GRID`] by the held-out errors (needs a held-out
    /// set; `ridge_kf` is then ignored).
    pub ridge_kf_auto: bool,
    /// Identify b in the kinematic step too (the spec's sec. 6.2 identifies a only).
    pub kinematic_b: bool,
    pub select: SelectConfig,
    /// After the diagnosis, also fit the flexible per-cable length correction
    /// ([`calibrate::params::ParamId::Flex`]) as its own, clearly labelled stage.
    pub flexible: bool,
    /// Skip the diagnosis/extension loop.
    pub no_extension: bool,
    /// Also fit the kinematic parameters on the Cartesian residual through the forward
    /// kinematics (eq. 4.3–4.4), from the optimal joint-space model; reported as its own stage.
    pub cartesian: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            weights: Weights::default(),
            ridge_b: 0.0,
            lasso_b: 0.0,
            ridge_kf: 0.0,
            ridge_kf_auto: false,
            kinematic_b: false,
            select: SelectConfig::default(),
            no_extension: false,
            flexible: false,
            cartesian: false,
        }
    }
}

/// One step of the table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Stage {
    pub name: String,
    pub kind: Kind,
    pub model: CalModel,
    pub fit: Option<Fit>,
    pub holdout: Errors,
}

impl Stage {
    /// The step's forward kinematics failed on some held-out sample: it is not validated.
    pub fn failed(&self) -> bool {
        self.holdout.failed()
    }
}

/// Everything the report shows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PipelineReport {
    pub n_train: usize,
    pub n_holdout: usize,
    pub config: PipelineConfig,
    pub stages: Vec<Stage>,
    pub selection: Option<Selection>,
    /// Multi-start, second run and bootstrap ([`crate::repeatability`]), when asked for.
    pub repeatability: Option<crate::repeatability_figures::Repeatability>,
    /// The k_F ridge the elastostatic steps used, and the sweep that chose it (empty when it
    /// was configured).
    pub ridge_kf: f64,
    pub ridge_kf_sweep: Vec<RidgePoint>,
    /// Structure left in the final model's held-out length residuals ([`crate::structure`]);
    /// `None` when there was no separate held-out set.
    pub structure: Option<crate::structure::StructureReport>,
    /// Why the optional flexible correction could not be fitted (`None`: fitted or not asked).
    pub flexible_failure: Option<String>,
    /// The chosen model's parameters estimated on every sample (training + held-out) once the
    /// held-out set has chosen it; `None` without effects or without a held-out set.
    pub all_samples: Option<AllSamplesEstimate>,
    /// Why that estimate could not be made (the training-only fit then stands alone).
    pub all_samples_failure: Option<String>,
}

/// The final estimate of the chosen model: the held-out set chose the effects and validated the
/// training-only fit; the same parameters (free, fixed, penalties, start at the training
/// optimum) are then estimated on the training and held-out samples together, as a
/// calibration engineer estimates a chosen model on all the data. Its sizes have ≈ √(n_train /
/// n_all) of the training fit's 1σ. Its held-out errors would be in-sample, so the report's
/// held-out figures stay those of the training-only fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AllSamplesEstimate {
    pub samples: usize,
    pub fit: Fit,
    /// Sizes of the chosen effects in this fit, ±1σ (same order as the selection's).
    pub sizes: Vec<effects::EffectSize>,
}

/// The chosen model of `sel` estimated on `train` and `holdout` together (see
/// [`AllSamplesEstimate`]).
pub fn estimate_on_all_samples(
    sel: &Selection,
    spec: &FitSpec,
    train: &[Observation],
    holdout: &[Observation],
    progress: &mut dyn FnMut(&str, usize, f64),
) -> Result<AllSamplesEstimate, FitError> {
    let all: Vec<Observation> = train.iter().chain(holdout).cloned().collect();
    let mut spec = spec.clone();
    spec.free = sel.fit.free.clone();
    let fit = identify::fit(&sel.fit.model, &all, &spec, &mut |it, c| {
        progress("final estimate on all samples", it, c)
    })?;
    let chosen: Vec<(Effect, effects::Form)> = sel
        .chosen
        .iter()
        .copied()
        .zip(sel.forms.iter().copied())
        .collect();
    let sizes = effects::effect_sizes(&fit, &chosen, &all);
    Ok(AllSamplesEstimate {
        samples: all.len(),
        fit,
        sizes,
    })
}

impl PipelineReport {
    pub fn stage(&self, name: &str) -> Option<&Stage> {
        self.stages.iter().find(|s| s.name == name)
    }
    /// The final (best) model.
    pub fn final_stage(&self) -> &Stage {
        self.stages.last().expect("pipeline produces stages")
    }
    /// The last step whose forward kinematics converged on every held-out sample.
    pub fn last_validated_stage(&self) -> Option<&Stage> {
        self.stages.iter().rev().find(|s| !s.failed())
    }
    /// Steps that failed validation, with their failure text.
    pub fn failed_stages(&self) -> Vec<(String, String)> {
        self.stages
            .iter()
            .filter_map(|s| s.holdout.failure_text().map(|t| (s.name.clone(), t)))
            .collect()
    }
}

/// The optimal elastostatic step's fit (eq. 4.38): p = (a, b, k_F, w_e) + offsets with the
/// configured ridge/lasso penalties.
pub fn elastostatic_spec(cfg: &PipelineConfig, m: usize) -> FitSpec {
    let free: Vec<ParamId> = [Group::A, Group::B, Group::KF, Group::We, Group::Offset]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect();
    let mut spec_e = FitSpec::new(Kind::Elastostatic, free);
    spec_e.weights = cfg.weights;
    if cfg.ridge_b > 0.0 {
        spec_e.ridge = group(Group::B, m)
            .into_iter()
            .map(|p| (p, cfg.ridge_b))
            .collect();
    }
    if cfg.ridge_kf > 0.0 {
        spec_e
            .ridge
            .extend(group(Group::KF, m).into_iter().map(|p| (p, cfg.ridge_kf)));
    }
    if cfg.lasso_b > 0.0 {
        spec_e.lasso = group(Group::B, m)
            .into_iter()
            .map(|p| (p, cfg.lasso_b))
            .collect();
    }
    spec_e
}

/// Ridge λ on k_F (units of 1e6 N, eq. 4.32) tried by `ridge_kf_auto`, ascending.
pub const RIDGE_KF_GRID: &[f64] = &[0.0, 10.0, 100.0, 1000.0, 10000.0];

/// One λ of the k_F ridge sweep: held-out mean position / force error through the FK, or why
/// it is not a number.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RidgePoint {
    pub lambda: f64,
    pub pos_mm: Option<f64>,
    pub force_n: Option<f64>,
    pub failure: Option<String>,
}

/// Family-wise level of the unexplained-structure test (Bonferroni over the cables).
pub const STRUCTURE_ALPHA: f64 = 0.001;

fn structure_of(
    last: Option<&Stage>,
    holdout: &[Observation],
) -> Option<crate::structure::StructureReport> {
    let st = last?;
    (!holdout.is_empty() && !st.failed())
        .then(|| crate::structure::test(st.kind, &st.model, holdout, &st.name, STRUCTURE_ALPHA))
}

/// Runs the steps on `train`, reporting on `holdout` (the training set if empty).
pub fn run(
    nominal: &Model,
    train: &[Observation],
    holdout: &[Observation],
    cfg: &PipelineConfig,
    progress: &mut dyn FnMut(&str, usize, f64),
) -> Result<PipelineReport, FitError> {
    let m = nominal.m();
    let eval = if holdout.is_empty() { train } else { holdout };
    let has_forces = train.iter().all(|o| o.forces.is_some());
    let mut stages = Vec::new();
    // 1. Nominal kinematic model p_N (offsets from the data).
    let mut nom_k = CalModel::from_model(nominal);
    identify::estimate_offsets(Kind::Kinematic, &mut nom_k, train, cfg.weights)?;
    stages.push(Stage {
        name: "nominal kinematic".into(),
        kind: Kind::Kinematic,
        holdout: validate::evaluate(Kind::Kinematic, &nom_k, eval),
        model: nom_k.clone(),
        fit: None,
    });
    // 2. Optimal kinematic model (eq. 4.8–4.10).
    let mut free: Vec<ParamId> = group(Group::A, m);
    if cfg.kinematic_b {
        free.extend(group(Group::B, m));
    }
    free.extend(group(Group::Offset, m));
    let mut spec_k = FitSpec::new(Kind::Kinematic, free);
    spec_k.weights = Weights {
        wrench: cfg.weights.wrench,
        length: 1.0,
    };
    let fit_k = identify::fit(&nom_k, train, &spec_k, &mut |it, c| {
        progress("kinematic", it, c)
    })?;
    let free_k = fit_k.free.clone();
    let start_c = fit_k.model.clone();
    stages.push(Stage {
        name: "optimal kinematic".into(),
        kind: Kind::Kinematic,
        holdout: validate::evaluate(Kind::Kinematic, &fit_k.model, eval),
        model: fit_k.model.clone(),
        fit: Some(fit_k),
    });
    // 2b. Optional: the same parameters on the Cartesian residual (eq. 4.3–4.4), which weighs
    // the errors as the pose tracker sees them rather than per cable.
    if cfg.cartesian {
        let mut spec_c = FitSpec::new(Kind::Cartesian, free_k);
        spec_c.weights = Weights {
            wrench: cfg.weights.wrench,
            length: 1.0,
        };
        let fit_c = identify::fit(&start_c, train, &spec_c, &mut |it, c| {
            progress("cartesian", it, c)
        })?;
        stages.push(Stage {
            name: "optimal kinematic (Cartesian residual)".into(),
            kind: Kind::Cartesian,
            holdout: validate::evaluate(Kind::Cartesian, &fit_c.model, eval),
            model: fit_c.model.clone(),
            fit: Some(fit_c),
        });
    }
    if !has_forces {
        return Ok(PipelineReport {
            n_train: train.len(),
            n_holdout: holdout.len(),
            config: cfg.clone(),
            structure: structure_of(stages.last(), holdout),
            flexible_failure: None,
            all_samples: None,
            all_samples_failure: None,
            stages,
            selection: None,
            repeatability: None,
            ridge_kf: cfg.ridge_kf,
            ridge_kf_sweep: Vec::new(),
        });
    }
    // 3. Nominal elastostatic model: k_F, w_e of the platform, offsets from the tension (6.24).
    let mut nom_e = CalModel::from_model(nominal);
    identify::estimate_offsets(Kind::Elastostatic, &mut nom_e, train, cfg.weights)?;
    stages.push(Stage {
        name: "nominal elastostatic".into(),
        kind: Kind::Elastostatic,
        holdout: validate::evaluate(Kind::Elastostatic, &nom_e, eval),
        model: nom_e.clone(),
        fit: None,
    });
    // 4. Optimal elastostatic model (eq. 4.38) with p = (a, b, k_F, w_e) + offsets. The ridge
    // on k_F towards the nominal (eq. 4.32) — k_F is the weakest-determined group on short
    // campaigns — is either the configured λ or, with `ridge_kf_auto` and a held-out set,
    // chosen from RIDGE_KF_GRID by the held-out position and force errors through the FK.
    let mut ridge_kf_sweep = Vec::new();
    let fit_configured = |progress: &mut dyn FnMut(&str, usize, f64)| {
        let spec = elastostatic_spec(cfg, m);
        identify::fit(&nom_e, train, &spec, &mut |it, c| {
            progress("elastostatic", it, c)
        })
        .map(|fit| (spec, fit, cfg.ridge_kf))
    };
    let (spec_e, fit_e, ridge_kf) = if cfg.ridge_kf_auto && !holdout.is_empty() {
        let mut best: Option<(f64, FitSpec, Fit, f64)> = None;
        let mut reference: Option<(f64, f64)> = None;
        // The sweep's fits after the first are screening fits on the first's free parameters
        // (its identifiability analysis holds for a ridge that only adds penalty rows); the
        // chosen λ is refitted in full (condition numbers, singular values) from its optimum.
        let mut free_sweep: Option<Vec<ParamId>> = None;
        for &lambda in RIDGE_KF_GRID {
            let mut c = cfg.clone();
            c.ridge_kf = lambda;
            let spec = elastostatic_spec(&c, m);
            let mut sweep_spec = spec.clone();
            if let Some(free) = &free_sweep {
                sweep_spec.free = free.clone();
                sweep_spec.quick = true;
            }
            let fit = match identify::fit(&nom_e, train, &sweep_spec, &mut |it, c| {
                progress("elastostatic", it, c)
            }) {
                Ok(f) => f,
                Err(e) => {
                    ridge_kf_sweep.push(RidgePoint {
                        lambda,
                        pos_mm: None,
                        force_n: None,
                        failure: Some(e.to_string()),
                    });
                    continue;
                }
            };
            free_sweep.get_or_insert_with(|| fit.free.clone());
            let h = validate::evaluate(Kind::Elastostatic, &fit.model, holdout);
            let point = RidgePoint {
                lambda,
                pos_mm: (!h.failed()).then_some(h.pos_mean_mm),
                force_n: if h.failed() { None } else { h.force_mean_n },
                failure: h.failure_text(),
            };
            ridge_kf_sweep.push(point.clone());
            let (Some(p), Some(f)) = (point.pos_mm, point.force_n) else {
                continue;
            };
            let (p0, f0) = *reference.get_or_insert((p, f));
            // Combined relative held-out error; a penalty must pay by 1 % to replace a
            // smaller one (parsimony: the grid is ascending from λ = 0).
            let score = p / p0 + f / f0;
            if best.as_ref().is_none_or(|b| score < 0.99 * b.0) {
                best = Some((score, spec, fit, lambda));
            }
        }
        match best {
            Some((_, spec, fit, lambda)) if fit.cond_end_scaled.is_nan() => {
                // A screening fit: the full analysis from its optimum (same minimum).
                match identify::fit(&fit.model, train, &spec, &mut |it, c| {
                    progress("elastostatic", it, c)
                }) {
                    Ok(full) => (spec, full, lambda),
                    Err(_) => (spec, fit, lambda),
                }
            }
            Some((_, spec, fit, lambda)) => (spec, fit, lambda),
            // No λ validated: the configured fit, whose failure the stage reports.
            None => fit_configured(progress)?,
        }
    } else {
        fit_configured(progress)?
    };
    stages.push(Stage {
        name: "optimal elastostatic".into(),
        kind: Kind::Elastostatic,
        holdout: validate::evaluate(Kind::Elastostatic, &fit_e.model, eval),
        model: fit_e.model.clone(),
        fit: Some(fit_e.clone()),
    });
    // 5. Residual diagnosis and extension.
    let selection = if cfg.no_extension {
        None
    } else {
        let mut sel = effects::select(
            fit_e,
            &spec_e,
            train,
            holdout,
            &cfg.select,
            &mut |e: Effect| progress(&format!("candidate {}", e.name()), 0, f64::NAN),
        );
        // The candidates' fits are screening fits: the extended step gets the full analysis
        // (identifiability, condition numbers, singular values) from its optimum.
        if !sel.chosen.is_empty() && sel.fit.cond_end_scaled.is_nan() {
            let mut full = spec_e.clone();
            full.free = sel.fit.free.clone();
            if let Ok(f) = identify::fit(&sel.fit.model, train, &full, &mut |it, c| {
                progress("extended model", it, c)
            }) {
                sel.fit = f;
                let chosen: Vec<(Effect, effects::Form)> = sel
                    .chosen
                    .iter()
                    .copied()
                    .zip(sel.forms.iter().copied())
                    .collect();
                sel.sizes = effects::effect_sizes(&sel.fit, &chosen, train);
            }
        }
        if !sel.chosen.is_empty() {
            let names: Vec<&str> = sel.chosen.iter().map(|e| e.name()).collect();
            stages.push(Stage {
                name: format!("optimal elastostatic + {}", names.join(" + ")),
                kind: Kind::Elastostatic,
                holdout: validate::evaluate(Kind::Elastostatic, &sel.fit.model, eval),
                model: sel.fit.model.clone(),
                fit: Some(sel.fit.clone()),
            });
        }
        Some(sel)
    };
    // 5b. The chosen model's final estimate on every sample.
    let (all_samples, all_samples_failure) = match &selection {
        Some(sel) if !sel.chosen.is_empty() && !holdout.is_empty() => {
            match estimate_on_all_samples(sel, &spec_e, train, holdout, progress) {
                Ok(est) => (Some(est), None),
                Err(e) => (None, Some(e.to_string())),
            }
        }
        _ => (None, None),
    };
    // The structure test judges the catalogue's best model, before any flexible correction.
    let structure = structure_of(stages.last(), holdout);
    // 6. Optional flexible correction: for when accuracy matters more than
    // explanation. Never a diagnosis: its stage name says so and the selection never adds it.
    let mut flexible_failure = None;
    if cfg.flexible
        && let Some(last) = stages.last().and_then(|st| st.fit.clone())
    {
        let mut spec = spec_e.clone();
        spec.free =
            last.free
                .iter()
                .copied()
                .chain((0..m).flat_map(|i| {
                    (0..calibrate::params::FLEX_TERMS).map(move |k| ParamId::Flex(i, k))
                }))
                .collect();
        match identify::fit(&last.model, train, &spec, &mut |it, c| {
            progress("flexible correction", it, c)
        }) {
            Ok(f) => stages.push(Stage {
                name: format!(
                    "{} + flexible length correction (not a physical effect)",
                    stages.last().map_or("", |st| st.name.as_str())
                ),
                kind: Kind::Elastostatic,
                holdout: validate::evaluate(Kind::Elastostatic, &f.model, eval),
                model: f.model.clone(),
                fit: Some(f),
            }),
            Err(e) => flexible_failure = Some(e.to_string()),
        }
    }
    Ok(PipelineReport {
        n_train: train.len(),
        n_holdout: holdout.len(),
        config: cfg.clone(),
        structure,
        flexible_failure,
        all_samples,
        all_samples_failure,
        stages,
        selection,
        repeatability: None,
        ridge_kf,
        ridge_kf_sweep,
    })
}
