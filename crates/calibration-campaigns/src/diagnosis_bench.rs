//! The residual diagnosis held to a benchmark (`crs calibrate bench-diagnosis`). Scenarios from
//! two generators, each with several seeds and a randomised magnitude, run through the pipeline
//! as `crs calibrate run` runs it; for each: what was named, whether the true effect matters
//! (the model that carries it is better on the held-out set), FK failures, non-physical
//! parameters, the held-out pose error against the true-effect model, the fitted magnitudes
//! against the truth, the time.
//!
//! * **sim-plant** (`--generator sim-plant`): one scenario per catalogue effect on the simulated
//!   plant, whose effects are written in the same parameterization as calibrate's candidates —
//!   agreement with itself. Magnitudes are the CRS-like plant's values (config/plant/crs-like.toml,
//!   each taken from the spec: r_p = 161 mm table 5.1, 12–25 m stored rope sec. 5.1, stiffness
//!   exponent and ±150 N hysteresis sized to the 600 N linear-fit error of sec. 5.1, 0.8 kg/m
//!   rope, 0.1 mm drum radius error, the cabin load of eq. 6.23, 1 % sensor gains) times a factor
//!   drawn log-uniformly from [0.25, 2]. Tracker noise (2 mm, 0.05°) and 20 N force noise and
//!   the reference geometry deviation are on in every scenario.
//! * **independent** (`--generator independent`, the acceptance): crates/bench-plant, the effects
//!   written a second time on plant-oracle's energy formulation with their own physics and
//!   parameters, in the variants real machines show, single and two at a time, plus a baseline
//!   and an effect outside the catalogue (encoder offsets after a re-homing). Magnitudes are
//!   drawn log-uniformly over each kind's range ([`bench_plant::Kind::range`]).

use bench_plant::Kind;
use calibrate::{Observation, from_dataset};
use calibrate_diagnosis::effects::{Effect, Form};
use calibrate_diagnosis::pipeline::{self, PipelineConfig, PipelineReport};
use cdpr_model::config::{Platform, load_platform};
use crs_limits::quantile::quantile_sorted;
use nalgebra::Vector3;
use sim_plant::config::{Effects, ForceSensors};
use sim_plant::{CampaignConfig, Plant, PlantConfig, PoseSet, run_campaign};
use std::path::{Path, PathBuf};

/// What one benchmark run does (`crs calibrate bench-diagnosis`'s options).
#[derive(Debug, Clone)]
pub struct BenchConfig {
    /// Nominal platform (the control model and the plant's nominal).
    pub platform: PathBuf,
    /// Plant whose effect magnitudes are the 1× reference.
    pub plant: PathBuf,
    /// Seeds per scenario.
    pub seeds: u64,
    /// Random poses of the identification campaign (each with a tension test: 2 rows per pose
    /// plus the return); the validation campaign has 3/4 of them.
    pub poses: usize,
    /// Scenarios (comma separated): baseline and catalogue effect names; default all.
    pub scenarios: Option<Vec<String>>,
    /// A scenario's effect "matters" when the true-effect model cuts the held-out mean
    /// position error of the base model by at least this fraction ...
    pub matters_pos: f64,
    /// ... or its held-out mean force error by at least this fraction. Both sit above what a
    /// catalogue candidate gains on data without any effect (≤ 1.3 % position, ≤ 12.1 % force
    /// on 20 baseline sets), so "matters" means "can be told from the noise of the fit".
    pub matters_force: f64,
    /// Seeds of the baseline scenario (no effect): the false-addition rate needs more than the
    /// effect scenarios' seeds to be a rate.
    pub baseline_seeds: u64,
    /// First seed: another value draws other magnitudes, poses and noise (the selection's
    /// thresholds were set on seeds 0–19 of the baseline, so a run from another first seed is
    /// an out-of-sample check of them).
    pub first_seed: u64,
    /// Print every candidate's evidence (round, held-out gains, verdict) of runs where the
    /// true effect matters but was not chosen, or where another effect was chosen.
    pub explain_misses: bool,
    /// Which generator's scenarios to run.
    pub generator: Generator,
    /// Scenarios of the independent generator: kind names (`drum-setup`, …) and pairs
    /// (`drum-setup+hysteresis-command`); default [`default_independent_scenarios`].
    pub kinds: Option<Vec<String>>,
    /// Seeds per two-effect scenario of the independent generator.
    pub pair_seeds: u64,
    /// Print the per-run lines on stderr.
    pub verbose: bool,
    /// Write every candidate's evidence of every round (one CSV row each) here: the data the
    /// selection thresholds are set on.
    pub candidates_csv: Option<PathBuf>,
}

/// The scenario generators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Generator {
    SimPlant,
    Independent,
    Both,
}

/// The independent generator's two-effect scenarios by default: effects a real machine shows
/// together, chosen so that each pair has a member that can hide the other (both shorten or
/// lengthen cables, both act on the forces the model predicts).
pub const DEFAULT_PAIRS: [(Kind, Kind); 6] = [
    (Kind::DrumFromSetUp, Kind::HysteresisCommand),
    (Kind::PowertrainRope, Kind::DrumFromSetUp),
    (Kind::HysteresisForce, Kind::PowertrainRope),
    (Kind::Pulleys, Kind::LoadCog),
    (Kind::DrumFromZero, Kind::ForceSensors),
    (Kind::Stiffness, Kind::HysteresisCommandDeadBand),
];

/// Every single kind (baseline included) and the default pairs, as scenario names.
pub fn default_independent_scenarios() -> Vec<String> {
    Kind::ALL
        .iter()
        .map(|k| k.name().to_string())
        .chain(
            DEFAULT_PAIRS
                .iter()
                .map(|(a, b)| format!("{}+{}", a.name(), b.name())),
        )
        .collect()
}

/// splitmix64: reproducible magnitudes without a dependency.
fn unit(seed: u64) -> f64 {
    let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// The plant effects of one scenario at magnitude factor `u` of the reference plant.
fn scenario_effects(effect: Option<Effect>, reference: &Effects, u: f64) -> Effects {
    let m = 8;
    // The reference plant's geometry deviation is in every scenario (the base model identifies
    // it); it also tensions the cables like the assembly errors of a real robot do.
    let mut fx = Effects {
        geometry: reference.geometry.clone(),
        tracker: reference.tracker,
        force_sensors: Some(ForceSensors {
            noise: reference.force_sensors.as_ref().map_or(20.0, |f| f.noise),
            offset: vec![0.0; m],
            gain: vec![1.0; m],
        }),
        ..Effects::default()
    };
    match effect {
        None => {}
        Some(Effect::Pulleys) => {
            let mut p = reference.pulleys.clone().expect("reference pulleys");
            p.radius.iter_mut().for_each(|r| *r *= u);
            fx.pulleys = Some(p);
        }
        Some(Effect::Powertrain) => {
            let mut p = reference.powertrain.clone().expect("reference powertrain");
            p.extra_length.iter_mut().for_each(|l| *l *= u);
            fx.powertrain = Some(p);
        }
        Some(Effect::Stiffness) => {
            let mut s = reference.stiffness.expect("reference stiffness");
            s.exponent = (s.exponent * u).min(0.9);
            fx.stiffness = Some(s);
        }
        Some(Effect::Hysteresis) => {
            let mut h = reference.hysteresis.expect("reference hysteresis");
            h.half_width *= u;
            fx.hysteresis = Some(h);
        }
        Some(Effect::Sag) => {
            let mut s = reference.sag.expect("reference sag");
            s.mass_per_length *= u;
            fx.sag = Some(s);
        }
        Some(Effect::Drum) => {
            let mut w = reference.winch.clone().expect("reference winch errors");
            // 0.1 mm on a 152.5 mm drum is small against 2 mm tracker noise: the range is
            // 0.25–2 × 1 mm (a wrong rope-diameter assumption), i.e. ×10 the plant's.
            w.length_scale
                .iter_mut()
                .for_each(|s| *s = 1.0 + (*s - 1.0) * 10.0 * u);
            w.encoder_offset.iter_mut().for_each(|o| *o = 0.0);
            fx.winch = Some(w);
        }
        Some(Effect::LoadCog) => {
            let mut l = reference.load.expect("reference load");
            l.center_of_gravity *= u;
            fx.load = Some(l);
        }
        Some(Effect::ForceSensors) => {
            let f = reference.force_sensors.clone().expect("reference sensors");
            fx.force_sensors = Some(ForceSensors {
                noise: f.noise,
                offset: f.offset.iter().map(|o| o * u).collect(),
                gain: f.gain.iter().map(|g| 1.0 + (g - 1.0) * u).collect(),
            });
        }
    }
    fx
}

/// Why the benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The nominal platform or the reference plant TOML (names its file and key).
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// `--scenarios` names no catalogue effect (nor `baseline`).
    #[error("--scenarios: unknown scenario `{0}`")]
    UnknownScenario(String),
    /// A scenario's plant refuses to start.
    #[error(transparent)]
    Plant(#[from] sim_plant::PlantError),
    /// A scenario's recording campaign.
    #[error(transparent)]
    Campaign(#[from] sim_plant::CampaignError),
    /// A recorded data set does not give observations.
    #[error(transparent)]
    Observations(#[from] calibrate::observation::ObservationError),
    /// The calibration pipeline.
    #[error(transparent)]
    Pipeline(#[from] calibrate::FitError),
    /// The pipeline report has no optimal elastostatic step to compare with.
    #[error("no elastostatic step")]
    NoElastostaticStep,
    /// `--kinds` names no kind of the independent generator.
    #[error("--kinds: {0}")]
    Generator(#[from] crate::bench_generator::GeneratorError),
    /// `--candidates-csv` could not be written.
    #[error("{path}: {err}")]
    Write { path: PathBuf, err: std::io::Error },
    /// The independent plant could not record a scenario.
    #[error("independent plant, scenario {scenario} seed {seed}: {err}")]
    IndependentPlant {
        scenario: String,
        seed: u64,
        err: bench_plant::PlantError,
    },
}

fn record(
    platform: &Platform,
    path: &std::path::Path,
    effects: &Effects,
    poses: usize,
    seed: u64,
) -> Result<Vec<Observation>, BenchError> {
    let mut cfg = PlantConfig::ideal(platform.clone(), path.to_path_buf());
    cfg.effects = effects.clone();
    cfg.seed = seed;
    let mut plant = Plant::new(cfg)?;
    let campaign = CampaignConfig {
        name: "bench".into(),
        poses: PoseSet::Random {
            min: Vector3::new(-1.5, -1.5, 1.25),
            max: Vector3::new(1.5, 1.5, 2.0),
            count: poses,
            rotation_max: Vector3::repeat(5f64.to_radians()),
            seed,
        },
        tension_test: Some(0.03),
        seed: Some(seed),
        ..CampaignConfig::default()
    };
    let mut ds = run_campaign(&mut plant, platform, &campaign, "bench")?.dataset;
    // A pose where the nominal controller leaves a cable slack gives a reading ≤ 0 (noise
    // around zero force): such rows carry no elastostatic information and are dropped, as an
    // engineer would drop them from a real campaign.
    let before = ds.samples.len();
    ds.samples
        .retain(|s| s.forces.as_ref().is_none_or(|f| f.iter().all(|v| *v > 0.0)));
    if ds.samples.len() < before {
        eprintln!(
            "seed {seed}: dropped {} of {before} rows with a slack cable",
            before - ds.samples.len()
        );
    }
    Ok(from_dataset(&ds, platform.model.m())?)
}

/// The plant seed and the magnitude fractions of run `seed` of an independent scenario: the
/// scenario's seed space is its name's (adding a scenario keeps the others' draws), the
/// fractions uniform in [0, 1) (log-uniform magnitudes over each kind's range). `crs calibrate
/// generate --bench-seed` writes the same data set.
pub fn independent_draw(kinds: &[Kind], seed: u64) -> (u64, Vec<f64>) {
    let label = kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+");
    let key = label.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    });
    let s = key.wrapping_add(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    // Two effects at once are drawn in the upper half of their ranges: the question is whether
    // both are named when both can be told from the noise, which a small draw of either rarely
    // is.
    let (lo, width) = if kinds.len() > 1 {
        (0.5, 0.5)
    } else {
        (0.0, 1.0)
    };
    let u = (0..kinds.len())
        .map(|k| lo + width * unit(s.wrapping_add(k as u64 * 7919)))
        .collect();
    (s, u)
}

/// A magnitude checked against the truth.
#[derive(Clone, Debug, PartialEq)]
pub struct MagnitudeCheck {
    pub effect: Effect,
    /// What is compared, e.g. "drum scale s_i".
    pub what: String,
    /// Relative error ‖fitted − true‖ / ‖true‖.
    pub relative_error: f64,
    /// The tolerance of the acceptance (drum 20 %, hysteresis 30 %), `None` when it has none.
    pub tolerance: Option<f64>,
    /// |fitted − true| within 2σ of the fit (every component).
    pub within_two_sigma: bool,
    /// The drawn magnitude of the effect (in its kind's unit, [`Kind::range`]).
    pub magnitude: f64,
    /// For a size made of one number (the drum's RMS over the cables): fitted ±1σ and truth.
    pub size: Option<calibrate_diagnosis::magnitude::SizeCheck>,
}

/// What the drum's acceptance compares: the effect's size, the RMS of the scales over the
/// cables (noise bias taken off, ±1σ through the fit's covariance) against the RMS of the true
/// scales ([`calibrate_diagnosis::magnitude`]).
pub const DRUM_SIZE: &str = "drum size (RMS of s_i over the cables)";
/// The per-cable comparison, ‖ε − s‖/‖s‖ (reported next to the size, no tolerance of its own).
pub const DRUM_PER_CABLE: &str = "drum scale s_i per cable";

/// One acceptance item: what was measured against its target.
#[derive(Clone, Debug, PartialEq)]
pub struct Acceptance {
    pub item: String,
    pub value: String,
    pub target: String,
    /// `None`: no run measured it (e.g. a benchmark of a few kinds has no pairs).
    pub met: Option<bool>,
}

/// The share of the runs naming an effect that must size it within its tolerance. The issue
/// gives the tolerances (drum 20 %, hysteresis 30 %) but no rate; this is its naming rate.
pub const MAGNITUDE_RATE: f64 = 0.9;

/// Largest drum scale from which 120 rows resolve the per-cable scales to ~20 % (their 1σ is
/// 0.3–0.9e-3 with 2 mm tracker noise): the benchmark reports the tolerance above it apart.
pub const DRUM_RESOLVED: f64 = 2.5e-3;

/// One benchmark run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunResult {
    pub generator: &'static str,
    pub scenario: String,
    pub seed: u64,
    /// The catalogue effects the plant carries (empty: baseline or an effect outside the
    /// catalogue).
    pub truth: Vec<Effect>,
    /// The plant carries an effect outside the catalogue (re-homing).
    pub out_of_catalogue: bool,
    /// Magnitude fraction of each effect in its range.
    pub u: Vec<f64>,
    pub chosen: Vec<Effect>,
    pub forms: Vec<Form>,
    pub fk_failed: bool,
    pub non_physical: Vec<String>,
    pub base_pos: f64,
    pub final_pos: f64,
    /// The true-effect model's held-out mean position error (`None`: its FK failed).
    pub true_pos: Option<f64>,
    /// Per true effect: does it matter (the model with it is better on the held-out set by
    /// the thresholds)?
    pub matters: Vec<bool>,
    pub seconds: f64,
    /// CPU time of the pipeline's thread, s: on a shared machine the wall time also counts
    /// the other processes' share of the cores.
    pub cpu_seconds: f64,
    /// The final model's held-out residuals show unexplained structure.
    pub structure: bool,
    /// The sizes of the report: the chosen model estimated on every sample (training +
    /// held-out), or on the training samples when there is no such estimate.
    pub magnitudes: Vec<MagnitudeCheck>,
    /// The same comparisons for the training-only fit (the alternative, reported next to them).
    pub training_magnitudes: Vec<MagnitudeCheck>,
    pub rows: (usize, usize),
    /// Every candidate row of every round (`--candidates-csv`).
    pub candidate_rows: Vec<CandidateRow>,
}

/// One row of `--candidates-csv`: a candidate of one selection round. The numbers are
/// formatted here (fixed decimals; an empty field where the candidate has none), the csv
/// writer does the separators and the quoting.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CandidateRow {
    pub generator: String,
    pub scenario: String,
    pub seed: u64,
    pub truth: String,
    pub round: usize,
    pub effect: String,
    pub pair: String,
    pub form: String,
    pub n_params: usize,
    pub moved: bool,
    pub fk_failed: bool,
    pub gain_pos: String,
    pub z_pos: String,
    pub gain_force: String,
    pub z_force: String,
    pub score: String,
    pub score_critical: String,
    pub bic_before: String,
    pub bic_after: String,
    pub rms_gain: String,
    pub verdict: String,
}

impl RunResult {
    fn named(&self, e: Effect) -> bool {
        self.chosen.contains(&e)
    }
}

/// What a run of the benchmark measured, per generator.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    pub runs: Vec<RunResult>,
}

fn ratio(n: usize, d: usize) -> String {
    if d == 0 {
        "–".into()
    } else {
        format!("{n}/{d} ({:.0} %)", 100.0 * n as f64 / d as f64)
    }
}

impl Summary {
    fn of<'a>(&'a self, generator: &'a str) -> impl Iterator<Item = &'a RunResult> + 'a {
        self.runs.iter().filter(move |r| r.generator == generator)
    }
    /// (named, runs) over single-effect runs where the effect matters.
    pub fn single_named(&self, generator: &str) -> (usize, usize) {
        let m: Vec<&RunResult> = self
            .of(generator)
            .filter(|r| r.truth.len() == 1 && r.matters[0])
            .collect();
        (m.iter().filter(|r| r.named(r.truth[0])).count(), m.len())
    }
    /// (both named, runs) over two-effect runs where both matter.
    pub fn pair_named(&self, generator: &str) -> (usize, usize) {
        let m: Vec<&RunResult> = self
            .of(generator)
            .filter(|r| r.truth.len() == 2 && r.matters.iter().all(|m| *m))
            .collect();
        (
            m.iter()
                .filter(|r| r.truth.iter().all(|t| r.named(*t)))
                .count(),
            m.len(),
        )
    }
    /// (nothing added, runs) over the baselines.
    pub fn baselines_clean(&self, generator: &str) -> (usize, usize) {
        let b: Vec<&RunResult> = self
            .of(generator)
            .filter(|r| r.truth.is_empty() && !r.out_of_catalogue)
            .collect();
        (b.iter().filter(|r| r.chosen.is_empty()).count(), b.len())
    }
    pub fn fk_failures(&self, generator: &str) -> (usize, usize) {
        let n = self.of(generator).count();
        (self.of(generator).filter(|r| r.fk_failed).count(), n)
    }
    pub fn non_physical(&self, generator: &str) -> (usize, usize) {
        let n = self.of(generator).count();
        (
            self.of(generator)
                .filter(|r| !r.non_physical.is_empty())
                .count(),
            n,
        )
    }
    /// (final held-out position within 10 % of the true-effect model, runs where that model
    /// validated) and the worst ratio.
    pub fn within_true_model(&self, generator: &str) -> (usize, usize, f64) {
        let ratios: Vec<f64> = self
            .of(generator)
            .filter_map(|r| r.true_pos.map(|t| r.final_pos / t))
            .collect();
        (
            ratios.iter().filter(|x| **x <= 1.10).count(),
            ratios.len(),
            ratios.iter().copied().fold(0.0, f64::max),
        )
    }
    /// (within tolerance, checked) of the magnitudes with a tolerance, for `effect`.
    pub fn magnitudes_within(&self, generator: &str, effect: Effect) -> (usize, usize) {
        let c: Vec<&MagnitudeCheck> = self
            .of(generator)
            .flat_map(|r| r.magnitudes.iter())
            .filter(|m| m.effect == effect && m.tolerance.is_some())
            .collect();
        (
            c.iter()
                .filter(|m| m.relative_error <= m.tolerance.unwrap_or(f64::INFINITY))
                .count(),
            c.len(),
        )
    }
    /// (within 20 %, within ±2σ every cable, checked) of the drum's per-cable comparisons.
    pub fn drum_per_cable(&self, generator: &str) -> (usize, usize, usize) {
        let c: Vec<&MagnitudeCheck> = self
            .of(generator)
            .flat_map(|r| r.magnitudes.iter())
            .filter(|m| m.what == DRUM_PER_CABLE)
            .collect();
        (
            c.iter().filter(|m| m.relative_error <= 0.2).count(),
            c.iter().filter(|m| m.within_two_sigma).count(),
            c.len(),
        )
    }
    /// The acceptance items, measured on `generator`'s runs.
    pub fn acceptance(&self, generator: &str) -> Vec<Acceptance> {
        let rate = |(n, d): (usize, usize), min: f64, target: &str, item: &str| Acceptance {
            item: item.into(),
            value: ratio(n, d),
            target: target.into(),
            met: (d > 0).then_some(n as f64 >= min * d as f64),
        };
        let none = |(n, d): (usize, usize), item: &str| Acceptance {
            item: item.into(),
            value: format!("{n}/{d}"),
            target: "0".into(),
            met: (d > 0).then_some(n == 0),
        };
        let (w, wd, worst) = self.within_true_model(generator);
        let (_, cpu_max) = self.seconds(generator, true);
        let n = self.of(generator).count();
        vec![
            rate(
                self.single_named(generator),
                0.9,
                "≥ 90 %",
                "single-effect runs where the effect matters: effect named",
            ),
            rate(
                self.pair_named(generator),
                0.8,
                "≥ 80 %",
                "two-effect runs where both matter: both named",
            ),
            rate(
                self.baselines_clean(generator),
                0.95,
                "≥ 95 %",
                "baselines with nothing added",
            ),
            none(
                self.fk_failures(generator),
                "runs with an FK failure in any step",
            ),
            none(
                self.non_physical(generator),
                "runs with a non-physical final parameter",
            ),
            Acceptance {
                item: "held-out position error within 10 % of the true-effect model".into(),
                value: format!("{} (worst ratio {worst:.2})", ratio(w, wd)),
                target: "all".into(),
                met: (wd > 0).then_some(w == wd),
            },
            rate(
                self.magnitudes_within(generator, Effect::Drum),
                MAGNITUDE_RATE,
                "within 20 % in ≥ 90 %",
                &format!(
                    "{DRUM_SIZE}: within 20 % of the truth's (runs naming the drum of a drum-scale scenario)"
                ),
            ),
            rate(
                self.magnitudes_within(generator, Effect::Hysteresis),
                MAGNITUDE_RATE,
                "within 30 % in ≥ 90 %",
                "hysteresis h within 30 % of the truth (runs naming hysteresis)",
            ),
            Acceptance {
                item: "pipeline CPU time per set, max".into(),
                value: format!("{cpu_max:.2} s"),
                target: "≤ 1 s".into(),
                met: (n > 0).then_some(cpu_max <= 1.0),
            },
        ]
    }
    /// Pipeline time per set (mean, max): wall clock, or the thread's CPU time.
    pub fn seconds(&self, generator: &str, cpu: bool) -> (f64, f64) {
        let t: Vec<f64> = self
            .of(generator)
            .map(|r| if cpu { r.cpu_seconds } else { r.seconds })
            .collect();
        (
            t.iter().sum::<f64>() / t.len().max(1) as f64,
            t.iter().copied().fold(0.0, f64::max),
        )
    }
}

/// The pipeline as `crs calibrate run` runs it, on one scenario's data; `truth` the catalogue
/// effects the plant carries, `fitted_truth` compares the final model's parameters with the
/// truth when the effect was named.
#[allow(clippy::too_many_arguments)]
fn evaluate(
    a: &BenchConfig,
    platform: &Platform,
    train: &[Observation],
    held: &[Observation],
    generator: &'static str,
    scenario: String,
    seed: u64,
    truth: Vec<Effect>,
    out_of_catalogue: bool,
    u: Vec<f64>,
    fitted_truth: &dyn Fn(&PipelineReport, bool) -> Vec<MagnitudeCheck>,
) -> Result<RunResult, BenchError> {
    // As `crs calibrate run` runs by default: the k_F ridge chosen on the held-out set.
    let cfg = PipelineConfig {
        ridge_kf_auto: true,
        ..PipelineConfig::default()
    };
    let t0 = std::time::Instant::now();
    let c0 = thread_cpu_seconds();
    let rep = pipeline::run(&platform.model, train, held, &cfg, &mut |_, _, _| {})?;
    let seconds = t0.elapsed().as_secs_f64();
    let cpu_seconds = thread_cpu_seconds() - c0;
    let base = rep
        .stage("optimal elastostatic")
        .ok_or(BenchError::NoElastostaticStep)?;
    let fin = rep.final_stage();
    let fk_failed = rep.stages.iter().any(|st| st.failed());
    let non_physical = non_physical_params(fin);
    let (true_pos, matters) =
        true_effect_model(a, &cfg, &rep, base, platform, train, held, &truth)?;
    let sel = rep.selection.as_ref();
    let chosen = sel.map(|s| s.chosen.clone()).unwrap_or_default();
    let forms = sel.map(|s| s.forms.clone()).unwrap_or_default();
    let magnitudes = fitted_truth(&rep, false);
    let training_magnitudes = fitted_truth(&rep, true);
    let truth_label = truth.iter().map(|e| e.name()).collect::<Vec<_>>().join("+");
    let candidate_rows = candidate_rows(sel, generator, &scenario, seed, &truth_label);
    let r = RunResult {
        candidate_rows,
        generator,
        scenario,
        seed,
        truth,
        out_of_catalogue,
        u,
        chosen,
        forms,
        fk_failed,
        non_physical,
        base_pos: base.holdout.pos_mean_mm,
        final_pos: fin.holdout.pos_mean_mm,
        true_pos,
        matters,
        seconds,
        cpu_seconds,
        structure: rep.structure.as_ref().is_some_and(|st| st.any()),
        magnitudes,
        training_magnitudes,
        rows: (train.len(), held.len()),
    };
    if a.verbose {
        print_run(&r, fin);
    }
    let missed = r
        .truth
        .iter()
        .zip(&r.matters)
        .any(|(t, m)| *m && !r.named(*t));
    let wrong = r.chosen.iter().any(|c| !r.truth.contains(c));
    if a.explain_misses
        && (missed || wrong)
        && let Some(sel) = &rep.selection
    {
        explain(sel);
    }
    Ok(r)
}

/// The final model's parameters outside their physical bounds (k_F and every bounded free
/// parameter), each as `name = value`.
fn non_physical_params(fin: &pipeline::Stage) -> Vec<String> {
    let mut non_physical = Vec::new();
    for (i, k) in fin.model.k_f.iter().enumerate() {
        if !(calibrate::params::KF_MIN_N..=calibrate::params::KF_MAX_N).contains(k) {
            non_physical.push(format!("k_F{} = {k:.3e}", i + 1));
        }
    }
    if let Some(f) = &fin.fit {
        for p in &f.free {
            if let Some((lo, hi)) = p.bounds()
                && !(lo..=hi).contains(&f.model.get(*p))
            {
                non_physical.push(format!("{} = {:.3e}", p.name(), f.model.get(*p)));
            }
        }
    }
    non_physical
}

/// How well the model that carries the plant's true effects fits the held-out data (its mean
/// position error), and whether each true effect matters: an effect matters when its model
/// gains more than the noise of the fit.
#[allow(clippy::too_many_arguments)]
fn true_effect_model(
    a: &BenchConfig,
    cfg: &PipelineConfig,
    rep: &PipelineReport,
    base: &pipeline::Stage,
    platform: &Platform,
    train: &[Observation],
    held: &[Observation],
    truth: &[Effect],
) -> Result<(Option<f64>, Vec<bool>), BenchError> {
    let round1 = rep.selection.as_ref().and_then(|s| s.rounds.first());
    let row = |e: Effect| round1.and_then(|r| r.iter().find(|c| c.effect == e && c.pair.is_none()));
    let base_force = base.holdout.force_mean_n;
    // An effect matters when its model gains more than the noise of the fit: 5 % in position
    // or 15 % in force, and for a per-cable length freedom (the drum) more in force than
    // refitting it gains on data without any effect (the selection's force gate for it).
    let gains =
        |e: Effect, pos: Option<f64>, force: Option<f64>, ref_pos: f64, ref_force: Option<f64>| {
            let mf = a.matters_force.max(cfg.select.force_gate(e));
            pos.is_some_and(|p| p <= (1.0 - a.matters_pos) * ref_pos)
                || matches!((force, ref_force), (Some(t), Some(b)) if t <= (1.0 - mf) * b)
        };
    // A candidate whose parameters did not move leaves the base model as it is.
    let single = |e: Effect| -> (Option<f64>, Option<f64>) {
        match row(e) {
            Some(c) if !c.moved => (Some(base.holdout.pos_mean_mm), base_force),
            Some(c) => (c.holdout_pos_mm_after, c.holdout_force_n_after),
            None => (None, None),
        }
    };
    Ok(match truth {
        [] => (Some(base.holdout.pos_mean_mm), vec![]),
        [e] => {
            let (p, f) = single(*e);
            (
                p,
                vec![gains(*e, p, f, base.holdout.pos_mean_mm, base_force)],
            )
        }
        parts => {
            // The model that carries both: fitted here like a diagnosis pair, each effect in the
            // form round 1 chose for it.
            let base_fit = base.fit.clone().ok_or(BenchError::NoElastostaticStep)?;
            let mut c2 = cfg.clone();
            c2.ridge_kf = rep.ridge_kf;
            let spec = pipeline::elastostatic_spec(&c2, platform.model.m());
            let forms: Vec<(Effect, Form)> = parts
                .iter()
                .map(|e| (*e, row(*e).map_or(e.forms()[0], |c| c.form)))
                .collect();
            let both = calibrate_diagnosis::effects::fit_effects(&base_fit, &spec, train, &forms)
                .ok()
                .map(|f| calibrate::validate::evaluate(f.kind, &f.model, held))
                .filter(|e| !e.failed());
            let (bp, bf) = (
                both.as_ref().map(|e| e.pos_mean_mm),
                both.and_then(|e| e.force_mean_n),
            );
            // Each matters when adding it to the model with the other one gains.
            let matters = (0..parts.len())
                .map(|k| {
                    let (op, of) = single(parts[1 - k]);
                    match op {
                        Some(op) => gains(parts[k], bp, bf, op, of),
                        None => false,
                    }
                })
                .collect();
            (bp, matters)
        }
    })
}

/// One row per candidate of every selection round (the bench's candidates file).
fn candidate_rows(
    sel: Option<&calibrate_diagnosis::effects::Selection>,
    generator: &str,
    scenario: &str,
    seed: u64,
    truth_label: &str,
) -> Vec<CandidateRow> {
    let Some(sel) = sel else {
        return Vec::new();
    };
    let o = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6}"));
    sel.rounds
        .iter()
        .enumerate()
        .flat_map(|(k, round)| {
            round.iter().map(move |c| CandidateRow {
                generator: generator.into(),
                scenario: scenario.into(),
                seed,
                truth: truth_label.into(),
                round: k + 1,
                effect: c.effect.name().into(),
                pair: c.pair.map_or("", |(e, _)| e.name()).into(),
                form: format!("{:?}", c.form),
                n_params: c.n_params,
                moved: c.moved,
                fk_failed: c.fk_failure.is_some(),
                gain_pos: o(c.gain_pos),
                z_pos: o(c.z_pos),
                gain_force: o(c.gain_force),
                z_force: o(c.z_force),
                score: format!("{:.4}", c.score),
                score_critical: format!("{:.4}", c.score_critical),
                bic_before: format!("{:.3}", c.bic_before),
                bic_after: format!("{:.3}", c.bic_after),
                rms_gain: format!("{:.6}", 1.0 - c.holdout_rms_after / c.holdout_rms_before),
                verdict: c.verdict.clone(),
            })
        })
        .collect()
}

/// Writes `--candidates-csv`: a header from [`CandidateRow`]'s fields, then every run's rows.
fn write_candidates(path: &Path, runs: &[RunResult]) -> Result<(), BenchError> {
    let io = |err: csv::Error| BenchError::Write {
        path: path.to_path_buf(),
        err: std::io::Error::other(err),
    };
    let mut w = csv::Writer::from_path(path).map_err(io)?;
    for row in runs.iter().flat_map(|r| r.candidate_rows.iter()) {
        w.serialize(row).map_err(io)?;
    }
    w.flush().map_err(|err| BenchError::Write {
        path: path.to_path_buf(),
        err,
    })
}

/// One run on stderr (`--verbose`): what was chosen, whether it matters, the errors before,
/// after and of the true-effect model, the time and the fitted sizes against the truth.
fn print_run(r: &RunResult, fin: &pipeline::Stage) {
    let (generator, seed, fk_failed, cpu_seconds) =
        (r.generator, r.seed, r.fk_failed, r.cpu_seconds);
    eprintln!(
        "{:<10} {:<44} seed {seed:<4} u {}: chosen [{}]{}{} base {:.2} mm → final {} (true-effect model {}) {:.2} s CPU{}",
        generator,
        r.scenario,
        r.u.iter()
            .map(|u| format!("{u:.2}"))
            .collect::<Vec<_>>()
            .join("/"),
        r.chosen
            .iter()
            .zip(&r.forms)
            .map(|(e, f)| if f.describe().is_empty() {
                e.name().to_string()
            } else {
                format!("{} ({})", e.name(), f.describe())
            })
            .collect::<Vec<_>>()
            .join(", "),
        if r.matters.iter().any(|m| *m) {
            format!(" (matters: {:?})", r.matters)
        } else {
            String::new()
        },
        if fk_failed { " FK FAILED" } else { "" },
        r.base_pos,
        fin.holdout
            .failure_text()
            .unwrap_or_else(|| format!("{:.2} mm", r.final_pos)),
        r.true_pos
            .map_or("FK failed".into(), |p| format!("{p:.2} mm")),
        cpu_seconds,
        r.magnitudes
            .iter()
            .map(|m| format!(
                " {}: {:.0} % off{}{}",
                m.what,
                100.0 * m.relative_error,
                m.size.map_or(String::new(), |c| format!(
                    " ({:.3} ± {:.3} ‰ vs {:.3} ‰)",
                    1e3 * c.fitted,
                    1e3 * c.sigma,
                    1e3 * c.truth
                )),
                if m.within_two_sigma {
                    " (within 2σ)"
                } else {
                    " (beyond 2σ)"
                }
            ))
            .collect::<String>()
    );
}

fn explain(sel: &calibrate_diagnosis::effects::Selection) {
    for (r, round) in sel.rounds.iter().enumerate() {
        for c in round {
            let pct = |g: Option<f64>| g.map_or("–".into(), |g| format!("{:+.1} %", 100.0 * g));
            eprintln!(
                "    round {} {:<13}{} pos {} (z {}) force {} (z {}) score {:.1}/{:.1} BIC {:.1} → {:.1}: {}",
                r + 1,
                c.effect.name(),
                c.pair
                    .map_or(String::new(), |(e, _)| format!("+{}", e.name())),
                pct(c.gain_pos),
                c.z_pos.map_or("–".into(), |z| format!("{z:.1}")),
                pct(c.gain_force),
                c.z_force.map_or("–".into(), |z| format!("{z:.1}")),
                c.score,
                c.score_critical,
                c.bic_before,
                c.bic_after,
                c.verdict
            );
            let v: Vec<String> = c
                .params
                .iter()
                .take(8)
                .map(|(n, v, _)| format!("{n}={v:.3e}"))
                .collect();
            eprintln!("        [{}] {}", c.form.describe(), v.join(" "));
        }
    }
}

fn sim_plant_runs(
    a: &BenchConfig,
    platform: &Platform,
    out: &mut Summary,
) -> Result<(), BenchError> {
    let reference = sim_plant::load_plant(&a.plant)?.effects;
    let all: Vec<Option<Effect>> = std::iter::once(None)
        .chain(Effect::ALL.iter().copied().map(Some))
        .collect();
    let scenarios: Vec<Option<Effect>> = match &a.scenarios {
        None => all,
        Some(names) => names
            .iter()
            .map(|n| match n.trim() {
                "baseline" => Ok(None),
                s => Effect::from_name(s)
                    .map(Some)
                    .ok_or_else(|| BenchError::UnknownScenario(s.to_string())),
            })
            .collect::<Result<_, _>>()?,
    };
    for (si, truth) in scenarios.iter().enumerate() {
        let seeds = if truth.is_none() {
            a.baseline_seeds
        } else {
            a.seeds
        };
        for seed in a.first_seed..a.first_seed + seeds {
            let s = 1000 * (si as u64 + 1) + seed;
            let u = 0.25 * 8f64.powf(unit(s));
            let fx = scenario_effects(*truth, &reference, u);
            let train = record(&platform.clone(), &a.platform, &fx, a.poses, s)?;
            let held = record(
                platform,
                &a.platform,
                &fx,
                (a.poses * 3).div_ceil(4),
                s + 500,
            )?;
            out.runs.push(evaluate(
                a,
                platform,
                &train,
                &held,
                "sim-plant",
                truth.map_or("baseline".into(), |e| e.name().to_string()),
                seed,
                truth.iter().copied().collect(),
                false,
                vec![u],
                &|_, _| Vec::new(),
            )?);
        }
    }
    Ok(())
}

/// The independent scenarios: kind names and pairs `a+b`.
fn parse_independent(names: &[String]) -> Result<Vec<Vec<Kind>>, BenchError> {
    names
        .iter()
        .map(|n| {
            let parts: Vec<String> = n.split('+').map(|s| s.trim().to_string()).collect();
            Ok(crate::bench_generator::kinds(&parts)?)
        })
        .collect()
}

/// ‖f − t‖ / ‖t‖.
fn relative_distance(f: &[f64], t: &[f64]) -> f64 {
    let num: f64 = f
        .iter()
        .zip(t)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let den: f64 = t.iter().map(|b| b * b).sum::<f64>().sqrt();
    num / den.max(1e-300)
}

/// The drum's per-cable scales against the truth's `truth`, and its size (the scales' rms).
fn drum_checks(
    size: &calibrate_diagnosis::effects::EffectSize,
    fitted: &[(f64, f64)],
    truth: &[f64],
    magnitude: f64,
    out: &mut Vec<MagnitudeCheck>,
) {
    // Both kinds are ε_i = s_i in the candidate's q_θ = (1 + ε_i) q_cmd + δ_i (from
    // the set-up: δ_i takes −s_i q₀,i). The layer step has no scale to compare.
    let f: Vec<f64> = fitted.iter().map(|x| x.0).collect();
    out.push(MagnitudeCheck {
        effect: Effect::Drum,
        what: DRUM_PER_CABLE.into(),
        relative_error: relative_distance(&f, truth),
        tolerance: None,
        within_two_sigma: fitted
            .iter()
            .zip(truth)
            .all(|((x, sd), b)| sd.is_finite() && (x - b).abs() <= 2.0 * sd),
        magnitude,
        size: None,
    });
    // No covariance, no size: counted as a miss (NaN is within no tolerance).
    let c = size
        .rms
        .map(|r| calibrate_diagnosis::magnitude::check_rms(&r, truth));
    out.push(MagnitudeCheck {
        effect: Effect::Drum,
        what: DRUM_SIZE.into(),
        relative_error: c.map_or(f64::NAN, |c| c.relative_error),
        tolerance: Some(0.2),
        within_two_sigma: c.is_some_and(|c| c.within_two_sigma),
        magnitude,
        size: c,
    });
}

/// Compares the final model's parameters with the independent plant's truth, for the named
/// effects that have a truth in the calibrate parameterisation: the report's final estimate
/// on every sample, or (`training_only`, and where there is no such estimate) the fit on the
/// training samples.
fn independent_magnitudes(
    truth: &bench_plant::Truth,
    rep: &PipelineReport,
    training_only: bool,
) -> Vec<MagnitudeCheck> {
    let Some(sel) = rep.selection.as_ref() else {
        return Vec::new();
    };
    let (sizes, k_f) = match (&rep.all_samples, training_only) {
        (Some(all), false) => (&all.sizes, &all.fit.model.k_f),
        _ => (&sel.sizes, &rep.final_stage().model.k_f),
    };
    let mut out = Vec::new();
    for v in &truth.values {
        let Some(size) = sizes
            .iter()
            .find(|s| Some(s.effect.name()) == v.kind.effect())
        else {
            continue;
        };
        let magnitude = truth
            .kinds
            .iter()
            .position(|k| *k == v.kind)
            .map_or(f64::NAN, |k| truth.magnitudes[k]);
        let fitted: Vec<(f64, f64)> = size.params.iter().map(|(_, x, sd)| (*x, *sd)).collect();
        match (v.kind, size.effect, size.form) {
            (Kind::DrumFromSetUp | Kind::DrumFromZero, Effect::Drum, _) => {
                drum_checks(size, &fitted, &v.values, magnitude, &mut out);
            }
            (
                Kind::HysteresisCommand
                | Kind::HysteresisCommandDeadBand
                | Kind::HysteresisForce
                | Kind::HysteresisForceDeadBand,
                Effect::Hysteresis,
                form,
            ) => {
                let h_true = v.values[0];
                // A force band ±H acts as a length offset of H (q + l)/k_F: the report's
                // length equivalent at the training samples' mean compliance.
                let (h, sd) = match (form, size.length_equivalent) {
                    (
                        Form::LengthByCommand
                        | Form::LengthByForce
                        | Form::LengthByForceBeyondNoise,
                        _,
                    ) => fitted[0],
                    (_, Some(eq)) => eq,
                    _ => continue,
                };
                out.push(MagnitudeCheck {
                    effect: Effect::Hysteresis,
                    what: "hysteresis h".into(),
                    relative_error: (h.abs() - h_true).abs() / h_true,
                    tolerance: Some(0.3),
                    within_two_sigma: sd.is_finite() && (h.abs() - h_true).abs() <= 2.0 * sd,
                    magnitude,
                    size: None,
                });
            }
            (Kind::PowertrainRope | Kind::PowertrainCompliance, Effect::Powertrain, form) => {
                // Stored rope per cable l_i = k_F,i c_s for a compliance (its 1σ likewise; the
                // k_F's own uncertainty left out).
                let l: Vec<(f64, f64)> = match form {
                    Form::SharedCompliance => k_f
                        .iter()
                        .map(|k| (k * fitted[0].0, k * fitted[0].1))
                        .collect(),
                    _ => fitted.clone(),
                };
                let lv: Vec<f64> = l.iter().map(|x| x.0).collect();
                out.push(MagnitudeCheck {
                    effect: Effect::Powertrain,
                    what: "stored rope l_i".into(),
                    relative_error: relative_distance(&lv, &v.values),
                    tolerance: None,
                    within_two_sigma: l
                        .iter()
                        .zip(&v.values)
                        .all(|((x, sd), b)| sd.is_finite() && (x - b).abs() <= 2.0 * sd),
                    magnitude,
                    size: None,
                });
            }
            _ => {}
        }
    }
    out
}

/// One run of the independent generator: scenario `kinds`, run `seed` (its plant seed and
/// magnitudes from [`independent_draw`]), through the pipeline.
pub fn independent_run(
    a: &BenchConfig,
    platform: &Platform,
    kinds: &[Kind],
    seed: u64,
) -> Result<RunResult, BenchError> {
    let file = a.platform.display().to_string();
    let nominal = crate::bench_generator::nominal(platform, &file)?;
    let label = kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+");
    let (s, u) = independent_draw(kinds, seed);
    let g = bench_plant::generate(&nominal, kinds, &u, s, a.poses).map_err(|err| {
        BenchError::IndependentPlant {
            scenario: label.clone(),
            seed,
            err,
        }
    })?;
    let m = nominal.m();
    let to_obs = |rec: &bench_plant::Recording, c: &str| {
        from_dataset(&crate::bench_generator::dataset(rec, m, c, s), m)
    };
    let train = to_obs(&g.train, "identification")?;
    let held = to_obs(&g.holdout, "validation")?;
    let truth: Vec<Effect> = kinds
        .iter()
        .filter_map(|k| k.effect().and_then(Effect::from_name))
        .collect();
    let out_of_catalogue = kinds.contains(&Kind::Rehoming);
    let t = g.truth.clone();
    evaluate(
        a,
        platform,
        &train,
        &held,
        "independent",
        label,
        seed,
        truth,
        out_of_catalogue,
        u,
        &move |rep, training_only| independent_magnitudes(&t, rep, training_only),
    )
}

fn independent_runs(
    a: &BenchConfig,
    platform: &Platform,
    out: &mut Summary,
) -> Result<(), BenchError> {
    let names = a
        .kinds
        .clone()
        .unwrap_or_else(default_independent_scenarios);
    for kinds in parse_independent(&names)? {
        let seeds = match kinds.as_slice() {
            [Kind::Baseline] => a.baseline_seeds,
            [_] => a.seeds,
            _ => a.pair_seeds,
        };
        for seed in a.first_seed..a.first_seed + seeds {
            out.runs.push(independent_run(a, platform, &kinds, seed)?);
        }
    }
    Ok(())
}

/// Runs the benchmark and returns what it measured (printing the per-run lines on stderr when
/// `verbose`).
pub fn measure(a: &BenchConfig) -> Result<Summary, BenchError> {
    let platform = load_platform(&a.platform)?;
    let mut out = Summary::default();
    if matches!(a.generator, Generator::SimPlant | Generator::Both) {
        sim_plant_runs(a, &platform, &mut out)?;
    }
    if matches!(a.generator, Generator::Independent | Generator::Both) {
        independent_runs(a, &platform, &mut out)?;
    }
    Ok(out)
}

/// Runs the benchmark and prints its tables (Markdown) on stdout.
pub fn run(a: &BenchConfig) -> Result<Summary, BenchError> {
    let s = measure(a)?;
    if let Some(path) = &a.candidates_csv {
        write_candidates(path, &s.runs)?;
    }
    for g in ["sim-plant", "independent"] {
        if s.of(g).next().is_some() {
            print_summary(&s, g, a);
        }
    }
    Ok(s)
}

fn print_summary(s: &Summary, generator: &str, a: &BenchConfig) {
    let runs: Vec<&RunResult> = s.of(generator).collect();
    let mut scenarios: Vec<&str> = Vec::new();
    for r in &runs {
        if !scenarios.contains(&r.scenario.as_str()) {
            scenarios.push(&r.scenario);
        }
    }
    confusion_matrix(&runs, &scenarios, generator, a);
    figures_table(s, &runs, generator);
    acceptance_table(s, &runs, generator);
}

/// The confusion matrix: scenario × effect named, with the runs where the true effect matters.
fn confusion_matrix(runs: &[&RunResult], scenarios: &[&str], generator: &str, a: &BenchConfig) {
    println!(
        "## Diagnosis benchmark, generator `{generator}`: {} scenarios, {} runs, {} identification poses (first seed {})\n",
        scenarios.len(),
        runs.len(),
        a.poses,
        a.first_seed
    );
    println!(
        "Confusion matrix: scenario (rows) × effect named (columns; a run counts in every column it names, `none` = nothing added). In brackets: runs where the true effect matters (its model ≥ {:.0} % better in held-out position or ≥ {:.0} % in force; for two effects: both do, each against the model with the other).\n",
        a.matters_pos * 100.0,
        a.matters_force * 100.0
    );
    let mut hdr = "| scenario | runs (matter) | none |".to_string();
    for e in Effect::ALL {
        hdr.push_str(&format!(" {} |", e.name()));
    }
    println!("{hdr}");
    println!("|---|---|---|{}", "---|".repeat(Effect::ALL.len()));
    for sc in scenarios {
        let mine: Vec<&&RunResult> = runs.iter().filter(|r| r.scenario == *sc).collect();
        let matter = |r: &RunResult| !r.matters.is_empty() && r.matters.iter().all(|m| *m);
        let cell = |f: &dyn Fn(&RunResult) -> bool| {
            let n = mine.iter().filter(|r| f(r)).count();
            let nm = mine.iter().filter(|r| f(r) && matter(r)).count();
            if n == 0 {
                " · |".to_string()
            } else {
                format!(" {n} ({nm}) |")
            }
        };
        let mut line = format!(
            "| {sc} | {} ({}) |",
            mine.len(),
            mine.iter().filter(|r| matter(r)).count()
        );
        line.push_str(&cell(&|r| r.chosen.is_empty()));
        for e in Effect::ALL {
            line.push_str(&cell(&|r| r.chosen.contains(&e)));
        }
        println!("{line}");
    }
}

/// The benchmark's figures: failures, effects named, baselines, held-out errors, the sizes
/// of the fitted effects against the truth's, the pipeline's time.
fn figures_table(s: &Summary, runs: &[&RunResult], generator: &str) {
    let (fk, n) = s.fk_failures(generator);
    let (np, _) = s.non_physical(generator);
    let (sn, sd) = s.single_named(generator);
    let (pn, pd) = s.pair_named(generator);
    let (bc, bd) = s.baselines_clean(generator);
    let (w, wd, worst) = s.within_true_model(generator);
    let (mean_s, max_s) = s.seconds(generator, false);
    let (mean_c, max_c) = s.seconds(generator, true);
    println!();
    println!("| figure | value |\n|---|---|");
    println!("| runs | {n} |");
    println!("| runs with an FK failure in any step | {fk}/{n} |");
    println!("| runs with a non-physical final parameter | {np}/{n} |");
    println!(
        "| single-effect runs where the effect matters: effect named | {} |",
        ratio(sn, sd)
    );
    println!(
        "| two-effect runs where both matter: both named | {} |",
        ratio(pn, pd)
    );
    println!("| baselines with nothing added | {} |", ratio(bc, bd));
    let ooc: Vec<&&RunResult> = runs.iter().filter(|r| r.out_of_catalogue).collect();
    if !ooc.is_empty() {
        println!(
            "| effect outside the catalogue (re-homing): nothing added / flagged as unexplained structure | {} / {} |",
            ratio(
                ooc.iter().filter(|r| r.chosen.is_empty()).count(),
                ooc.len()
            ),
            ratio(ooc.iter().filter(|r| r.structure).count(), ooc.len())
        );
    }
    let wrong: Vec<&&RunResult> = runs
        .iter()
        .filter(|r| !r.truth.is_empty() && r.chosen.iter().any(|c| !r.truth.contains(c)))
        .collect();
    println!(
        "| effect runs that also name an effect the plant does not carry | {} |",
        ratio(
            wrong.len(),
            runs.iter().filter(|r| !r.truth.is_empty()).count()
        )
    );
    let base: Vec<&&RunResult> = runs
        .iter()
        .filter(|r| r.truth.is_empty() && !r.out_of_catalogue)
        .collect();
    println!(
        "| baselines flagged with unexplained structure | {} |",
        ratio(base.iter().filter(|r| r.structure).count(), base.len())
    );
    println!(
        "| held-out position error within 10 % of the true-effect model | {} (worst ratio {worst:.2}) |",
        ratio(w, wd)
    );
    magnitude_rows(s, runs, generator);
    println!("| pipeline time per set, wall clock (mean / max) | {mean_s:.2} / {max_s:.2} s |");
    println!(
        "| pipeline time per set, CPU time of its thread (mean / max) | {mean_c:.2} / {max_c:.2} s |"
    );
}

/// The fitted effects' sizes against the truth's (drum scale and per cable, hysteresis, stored
/// rope), where the scenarios carry them.
fn magnitude_rows(s: &Summary, runs: &[&RunResult], generator: &str) {
    let (dn, dd) = s.magnitudes_within(generator, Effect::Drum);
    let (hn, hd) = s.magnitudes_within(generator, Effect::Hysteresis);
    if dd == 0 && hd == 0 {
        return;
    }
    println!(
        "| {DRUM_SIZE} within 20 % of the truth's (runs naming the drum of a drum-scale scenario) | {} |",
        ratio(dn, dd)
    );
    let sized: Vec<calibrate_diagnosis::magnitude::SizeCheck> = runs
        .iter()
        .flat_map(|r| r.magnitudes.iter())
        .filter_map(|m| m.size)
        .collect();
    if !sized.is_empty() {
        println!(
            "| … the truth within ±2σ of the fitted size / relative error median, max / 1σ relative to the true size median, max | {} / {:.0} %, {:.0} % / {:.0} %, {:.0} % |",
            ratio(
                sized.iter().filter(|c| c.within_two_sigma).count(),
                sized.len()
            ),
            100.0 * median(&sized.iter().map(|c| c.relative_error).collect::<Vec<_>>()),
            100.0 * sized.iter().map(|c| c.relative_error).fold(0.0, f64::max),
            100.0 * median(&sized.iter().map(|c| c.sigma / c.truth).collect::<Vec<_>>()),
            100.0 * sized.iter().map(|c| c.sigma / c.truth).fold(0.0, f64::max),
        );
    }
    let (pc, p2, pn) = s.drum_per_cable(generator);
    println!(
        "| {DRUM_PER_CABLE} within 20 % (‖ε − s‖/‖s‖) / the truth within ±2σ on every cable (no tolerance of their own) | {} / {} |",
        ratio(pc, pn),
        ratio(p2, pn)
    );
    let big: Vec<&MagnitudeCheck> = runs
        .iter()
        .flat_map(|r| r.magnitudes.iter())
        .filter(|m| m.what == DRUM_PER_CABLE && m.magnitude >= DRUM_RESOLVED)
        .collect();
    println!(
        "| … per cable within 20 %, runs with the largest \\|s_i\\| ≥ {:.2} % | {} |",
        DRUM_RESOLVED * 100.0,
        ratio(
            big.iter().filter(|m| m.relative_error <= 0.2).count(),
            big.len()
        )
    );
    println!(
        "| hysteresis h within 30 % of the truth (runs naming hysteresis) | {} |",
        ratio(hn, hd)
    );
    training_only_rows(runs);
    let all: Vec<&MagnitudeCheck> = runs.iter().flat_map(|r| r.magnitudes.iter()).collect();
    for e in [Effect::Hysteresis, Effect::Powertrain] {
        let c: Vec<&&MagnitudeCheck> = all.iter().filter(|m| m.effect == e).collect();
        if !c.is_empty() {
            println!(
                "| {}: fitted size within ±2σ of the truth (every component; the report's 1σ) | {} |",
                e.name(),
                ratio(c.iter().filter(|m| m.within_two_sigma).count(), c.len())
            );
        }
    }
    let pt: Vec<f64> = all
        .iter()
        .filter(|m| m.effect == Effect::Powertrain)
        .map(|m| m.relative_error)
        .collect();
    if !pt.is_empty() {
        println!(
            "| stored rope l_i: relative error median / max (no tolerance set) | {:.0} % / {:.0} % |",
            100.0 * median(&pt),
            100.0 * pt.iter().copied().fold(0.0, f64::max)
        );
    }
}

/// The sizes of the fit on the training samples alone, next to the report's final estimate on
/// every sample (the rows above).
fn training_only_rows(runs: &[&RunResult]) {
    let within = |what: &str, tol: f64| {
        let c: Vec<&MagnitudeCheck> = runs
            .iter()
            .flat_map(|r| r.training_magnitudes.iter())
            .filter(|m| m.what == what)
            .collect();
        let n = c.iter().filter(|m| m.relative_error <= tol).count();
        (n, c.len(), c.iter().filter(|m| m.within_two_sigma).count())
    };
    let (dn, dd, d2) = within(DRUM_SIZE, 0.2);
    let (hn, hd, _) = within("hysteresis h", 0.3);
    if dd + hd == 0 {
        return;
    }
    println!(
        "| training samples alone (before the final estimate on all samples): {DRUM_SIZE} within 20 % / the truth within ±2σ; hysteresis h within 30 % | {} / {}; {} |",
        ratio(dn, dd),
        ratio(d2, dd),
        ratio(hn, hd)
    );
}

/// The acceptance items with their targets, and the runs with a non-physical final parameter.
fn acceptance_table(s: &Summary, runs: &[&RunResult], generator: &str) {
    println!("\n| acceptance | measured | target | met |\n|---|---|---|---|");
    for c in s.acceptance(generator) {
        println!(
            "| {} | {} | {} | {} |",
            c.item,
            c.value,
            c.target,
            match c.met {
                Some(true) => "met",
                Some(false) => "**not met**",
                None => "not measured",
            }
        );
    }
    for r in runs.iter().filter(|r| !r.non_physical.is_empty()) {
        println!(
            "non-physical in {} seed {}: {}",
            r.scenario,
            r.seed,
            r.non_physical.join(", ")
        );
    }
    println!();
}

/// CPU time consumed by the calling thread, s.
fn thread_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given; CLOCK_THREAD_CPUTIME_ID exists
    // on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc == 0 {
        ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
    } else {
        f64::NAN
    }
}

/// The median by the stack's one quantile definition (nearest rank, [`crs_limits::quantile`]).
fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    quantile_sorted(&v, 0.5).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drum_run(per_cable: f64, size: f64) -> RunResult {
        let check = |what: &str, rel: f64, tolerance| MagnitudeCheck {
            effect: Effect::Drum,
            what: what.into(),
            relative_error: rel,
            tolerance,
            within_two_sigma: true,
            magnitude: 2e-3,
            size: None,
        };
        RunResult {
            generator: "independent",
            scenario: "drum-setup".into(),
            seed: 0,
            truth: vec![Effect::Drum],
            out_of_catalogue: false,
            u: vec![0.5],
            chosen: vec![Effect::Drum],
            forms: vec![Form::Standard],
            fk_failed: false,
            non_physical: vec![],
            base_pos: 4.0,
            final_pos: 3.0,
            true_pos: Some(3.0),
            matters: vec![true],
            seconds: 0.5,
            cpu_seconds: 0.5,
            structure: false,
            magnitudes: vec![
                check(DRUM_PER_CABLE, per_cable, None),
                check(DRUM_SIZE, size, Some(0.2)),
            ],
            training_magnitudes: vec![],
            rows: (120, 90),
            candidate_rows: vec![],
        }
    }

    /// The candidates file as a spreadsheet or pandas reads it: the documented columns, and a
    /// verdict with a comma and quotes comes back whole.
    #[test]
    fn the_candidates_csv_round_trips_through_a_csv_reader() {
        let row = CandidateRow {
            generator: "independent".into(),
            scenario: "drum-setup".into(),
            seed: 100,
            truth: "drum".into(),
            round: 1,
            effect: "drum".into(),
            pair: String::new(),
            form: "Scale".into(),
            n_params: 16,
            moved: true,
            fk_failed: false,
            gain_pos: "0.123456".into(),
            z_pos: String::new(),
            gain_force: "0.010000".into(),
            z_force: String::new(),
            score: "65.0000".into(),
            score_critical: "26.3000".into(),
            bic_before: "-1.000".into(),
            bic_after: "-2.000".into(),
            rms_gain: "0.300000".into(),
            verdict: "chosen: needed, \"LR 65\" > 26.3".into(),
        };
        let mut r = drum_run(0.1, 0.1);
        r.candidate_rows = vec![row.clone(), row];
        let path = std::env::temp_dir().join(format!("candidates-{}.csv", std::process::id()));
        write_candidates(&path, &[r]).unwrap();
        let mut rd = csv::Reader::from_path(&path).unwrap();
        let header: Vec<String> = rd.headers().unwrap().iter().map(String::from).collect();
        assert_eq!(
            header.join(","),
            "generator,scenario,seed,truth,round,effect,pair,form,n_params,moved,fk_failed,\
             gain_pos,z_pos,gain_force,z_force,score,score_critical,bic_before,bic_after,\
             rms_gain,verdict"
        );
        let rows: Vec<csv::StringRecord> = rd.records().map(Result::unwrap).collect();
        assert_eq!(rows.len(), 2);
        assert_eq!(&rows[0][20], "chosen: needed, \"LR 65\" > 26.3");
        assert_eq!(&rows[0][2], "100");
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn the_drum_item_of_the_acceptance_judges_the_size_and_counts_the_per_cable_apart() {
        // Ten runs: the size within 20 % in nine (the per-cable comparison in none), then one
        // more size outside: 9/10 is met, 9/11 is not.
        let mut s = Summary {
            runs: (0..10)
                .map(|k| drum_run(0.5, if k == 0 { 0.3 } else { 0.1 }))
                .collect(),
        };
        let item = |s: &Summary| {
            s.acceptance("independent")
                .into_iter()
                .find(|a| a.item.starts_with(DRUM_SIZE))
                .unwrap()
        };
        assert_eq!(s.magnitudes_within("independent", Effect::Drum), (9, 10));
        assert_eq!(s.drum_per_cable("independent"), (0, 10, 10));
        assert_eq!(item(&s).met, Some(true), "{:?}", item(&s));
        s.runs.push(drum_run(0.1, 0.25));
        assert_eq!(item(&s).met, Some(false), "{:?}", item(&s));
        // A size that could not be computed (NaN) is a miss, not a pass.
        s.runs.push(drum_run(0.1, f64::NAN));
        assert_eq!(s.magnitudes_within("independent", Effect::Drum), (9, 12));
    }
}
