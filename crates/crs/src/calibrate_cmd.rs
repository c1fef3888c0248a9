//! `crs calibrate …`: identification, residual diagnosis and model extension from measured
//! data sets (docs/data-format.md), with a Markdown/JSON/SVG report and the identified model
//! written back as a platform TOML (crates/calibrate, crates/calibrate-diagnosis, docs/calibration.md); the identification
//! run is `calibration_campaigns::calibration_output`, the diagnosis benchmark `calibration_campaigns::diagnosis_bench`.

use calibrate::Observation;
use calibrate_diagnosis::effects::Effect;
use calibrate_diagnosis::pipeline::{PipelineConfig, PipelineReport};
use calibrate_diagnosis::repeatability::RepeatabilityConfig;
use calibration_campaigns::calibration_output::{self, Identification};
use calibration_campaigns::diagnosis_bench::{BenchConfig, Generator, run as run_bench};
use calibration_campaigns::progress::Spinner;
use cdpr_model::config::Platform;
use clap::Args;
use std::path::PathBuf;

#[derive(clap::Subcommand, Debug)]
pub enum CalibrateCommand {
    /// Calibrate a platform from a recorded data set (and optionally a validation data set).
    Run {
        /// Nominal platform TOML (the start model p_N).
        #[arg(long)]
        platform: PathBuf,
        /// Identification data set (CSV, docs/data-format.md).
        #[arg(long)]
        data: PathBuf,
        /// Validation data set; without it, every `--holdout-every`-th pose is held out.
        #[arg(long)]
        validate: Option<PathBuf>,
        #[command(flatten)]
        opts: Opts,
    },
    /// Record identification and validation campaigns on the simulated plant, then calibrate
    /// (the CRS-like scenario of docs/calibration.md).
    Demo {
        /// Plant TOML (config/plant/*.toml).
        #[arg(long, default_value = "config/plant/crs-like.toml")]
        plant: PathBuf,
        /// Campaign TOML for the identification data.
        #[arg(long, default_value = "config/plant/campaign-91.toml")]
        campaign: PathBuf,
        /// Seed offset of the validation campaign's random poses.
        #[arg(long, default_value_t = 1000)]
        validation_seed_offset: u64,
        #[command(flatten)]
        opts: Opts,
    },
    /// The closed loop on the running stack: record a campaign with the nominal model, identify,
    /// deploy the identified model and a refitted surrogate, re-run the campaign, report the
    /// measured pose error before and after.
    Loop(crate::calibrate_loop_cmd::LoopArgs),
    /// Make a calibration campaign: feasible waypoint poses spread over the workspace with
    /// varied orientations, the whole plan verified with motion-core's checks.
    Campaign(crate::calibrate_loop_cmd::CampaignArgs),
    /// Diagnosis benchmark: single-effect scenarios on the simulated plant (every catalogue
    /// effect plus a baseline, several seeds, randomised magnitudes); prints the confusion
    /// matrix, FK failures and held-out error against the true-effect model.
    BenchDiagnosis(BenchArgs),
    /// Write one scenario of the independent benchmark plant (crates/bench-plant) as data sets:
    /// `identification.csv`, `validation.csv` (docs/data-format.md, for `crs calibrate run`)
    /// and `truth.json` (what the plant carries) in `--out`.
    Generate(GenerateArgs),
}

#[derive(Args, Debug)]
pub struct GenerateArgs {
    /// Nominal platform (the controller's model and the plant's nominal).
    #[arg(long, default_value = "config/crs-nominal.toml")]
    platform: PathBuf,
    /// Effect kinds (comma separated, one or two): baseline, drum-setup, drum-zero,
    /// drum-layer, hysteresis-command, hysteresis-command-deadband, hysteresis-force,
    /// hysteresis-force-deadband, powertrain-rope, powertrain-compliance, stiffness, sag,
    /// pulleys, load-cog, force-sensors, rehoming.
    #[arg(long, value_delimiter = ',', required = true)]
    scenario: Vec<String>,
    /// Magnitude of each kind as a fraction of its range (0 = barely detectable, 1 = the
    /// largest a robot of this size shows; log-uniform in between), comma separated.
    #[arg(long, value_delimiter = ',', default_value = "0.5")]
    magnitude: Vec<f64>,
    /// Seed of the plant's deviations, poses and noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Reachable poses of the identification campaign (each with a tension test); the
    /// validation campaign has 3/4 as many.
    #[arg(long, default_value_t = 40)]
    poses: usize,
    /// Output directory.
    #[arg(long, default_value = "bench-plant-out")]
    out: PathBuf,
    /// Write run N of `crs calibrate bench-diagnosis --generator independent` for this
    /// scenario instead (its plant seed and magnitudes; `--seed` and `--magnitude` are ignored).
    #[arg(long)]
    bench_seed: Option<u64>,
}

fn generate(a: GenerateArgs) -> Result<(), Box<dyn std::error::Error>> {
    use calibration_campaigns::bench_generator::{kinds, write_scenario};
    let k = kinds(&a.scenario)?;
    let (seed, u) = match a.bench_seed {
        Some(n) => calibration_campaigns::diagnosis_bench::independent_draw(&k, n),
        None if a.magnitude.len() == 1 && k.len() > 1 => (a.seed, vec![a.magnitude[0]; k.len()]),
        None => (a.seed, a.magnitude.clone()),
    };
    let g = write_scenario(&a.platform, &k, &u, seed, a.poses, &a.out)?;
    println!(
        "{}: {} identification rows, {} validation rows ({} / {} steps outside the force limits not sampled); truth in {}",
        a.out.display(),
        g.train.rows.len(),
        g.holdout.rows.len(),
        g.train.skipped.len(),
        g.holdout.skipped.len(),
        a.out.join("truth.json").display()
    );
    for (kind, mag) in g.truth.kinds.iter().zip(&g.truth.magnitudes) {
        let (_, _, unit, what) = kind.range();
        println!("  {}: {what} = {mag:.4e} {unit}", kind.name());
    }
    Ok(())
}

#[derive(Args, Debug)]
pub struct Opts {
    /// Output directory for report.md, report.json, plots, calibrated.toml.
    #[arg(long, default_value = "calibration-out")]
    pub(crate) out: PathBuf,
    /// Hold out poses with pose_index % N == N − 1 when no validation set is given.
    #[arg(long, default_value_t = 4)]
    pub(crate) holdout_every: u64,
    /// Weight of the wrench rows w_ρ,w (eq. 4.38).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) w_wrench: f64,
    /// Weight of the length rows w_ρ,q (eq. 4.38).
    #[arg(long, default_value_t = 1e4)]
    pub(crate) w_length: f64,
    /// Ridge λ on the platform anchors b (eq. 4.32, sec. 6.5).
    #[arg(long, default_value_t = 0.0)]
    pub(crate) ridge_b: f64,
    /// Lasso λ on the platform anchors b (eq. 4.32).
    #[arg(long, default_value_t = 0.0)]
    pub(crate) lasso_b: f64,
    /// Ridge λ on the cable stiffnesses k_F towards the nominal (eq. 4.32; k_F in 1e6 N).
    /// Default: chosen from 0, 10, 100, 1000, 10000 by the held-out position and force errors
    /// (report.md lists the sweep).
    #[arg(long)]
    pub(crate) ridge_kf: Option<f64>,
    /// Candidate effects (comma separated): pulleys, powertrain, stiffness, hysteresis, sag, drum,
    /// load_cog, force_sensors.
    #[arg(long, value_delimiter = ',')]
    pub(crate) candidates: Option<Vec<String>>,
    /// Minimum reduction of the held-out mean position error (through the FK) for an effect
    /// to be added (fraction); default from baseline data, see docs/calibration.md.
    #[arg(long, default_value_t = calibrate_diagnosis::effects::SelectConfig::default().min_gain_pos)]
    pub(crate) min_gain_pos: f64,
    /// The same for the held-out mean force error ‖f_P − f_M‖ (fraction).
    #[arg(long, default_value_t = calibrate_diagnosis::effects::SelectConfig::default().min_gain_force)]
    pub(crate) min_gain_force: f64,
    /// Repeatability: the optimal elastostatic fit again from K random frame-anchor starts
    /// (eq. 6.8) and once on the held-out set (eq. 6.10); 0 = off.
    #[arg(long, default_value_t = 0)]
    pub(crate) multi_start: usize,
    /// Repeatability: the whole pipeline on B bootstrap resamples of the training poses (how
    /// often each effect is chosen, spread of k_F and the extension parameters); 0 = off.
    #[arg(long, default_value_t = 0)]
    pub(crate) bootstrap: usize,
    /// Seed of the random starts and resamples.
    #[arg(long, default_value_t = 1)]
    pub(crate) repeat_seed: u64,
    /// After the diagnosis, also fit a flexible per-cable length correction (polynomial in
    /// force and length, not a physical effect) as its own, labelled step: for when accuracy
    /// matters more than explanation.
    #[arg(long)]
    pub(crate) flexible: bool,
    /// Skip the residual diagnosis / model extension.
    #[arg(long)]
    pub(crate) no_extension: bool,
    /// Also fit the kinematic parameters on the Cartesian residual through the forward
    /// kinematics (eq. 4.3–4.4), reported as the stage "optimal kinematic (Cartesian residual)".
    #[arg(long)]
    pub(crate) cartesian: bool,
    /// Also print the report as JSON on stdout.
    #[arg(long)]
    pub(crate) json: bool,
}

/// A pipeline option of `crs calibrate run` out of its range.
#[derive(Debug, thiserror::Error)]
pub(crate) enum OptsError {
    #[error("--ridge-kf: {0} is not a finite λ ≥ 0")]
    RidgeKf(f64),
    #[error("--candidates: unknown effect `{0}`")]
    UnknownCandidate(String),
}

pub(crate) fn config(o: &Opts) -> Result<PipelineConfig, OptsError> {
    let mut cfg = PipelineConfig::default();
    cfg.weights.wrench = o.w_wrench;
    cfg.weights.length = o.w_length;
    cfg.ridge_b = o.ridge_b;
    cfg.lasso_b = o.lasso_b;
    match o.ridge_kf {
        Some(l) if !(l.is_finite() && l >= 0.0) => {
            return Err(OptsError::RidgeKf(l));
        }
        Some(l) => cfg.ridge_kf = l,
        None => cfg.ridge_kf_auto = true,
    }
    cfg.no_extension = o.no_extension;
    cfg.flexible = o.flexible;
    cfg.cartesian = o.cartesian;
    cfg.select.min_gain_pos = o.min_gain_pos;
    cfg.select.min_gain_force = o.min_gain_force;
    if let Some(c) = &o.candidates {
        cfg.select.candidates = c
            .iter()
            .map(|n| {
                Effect::from_name(n.trim()).ok_or_else(|| OptsError::UnknownCandidate(n.clone()))
            })
            .collect::<Result<_, _>>()?;
    }
    Ok(cfg)
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Nominal platform (the control model and the plant's nominal).
    #[arg(long, default_value = "config/crs-nominal.toml")]
    platform: PathBuf,
    /// Plant whose effect magnitudes are the 1× reference.
    #[arg(long, default_value = "config/plant/crs-like.toml")]
    plant: PathBuf,
    /// Seeds per scenario.
    #[arg(long, default_value_t = 5)]
    seeds: u64,
    /// Random poses of the identification campaign (each with a tension test: 2 rows per pose
    /// plus the return); the validation campaign has 3/4 of them.
    #[arg(long, default_value_t = 40)]
    poses: usize,
    /// Scenarios (comma separated): baseline and catalogue effect names; default all.
    #[arg(long, value_delimiter = ',')]
    scenarios: Option<Vec<String>>,
    /// A scenario's effect "matters" when the true-effect model cuts the held-out mean
    /// position error of the base model by at least this fraction ...
    #[arg(long, default_value_t = 0.05)]
    matters_pos: f64,
    /// ... or its held-out mean force error by at least this fraction. Both sit above what a
    /// catalogue candidate gains on data without any effect (≤ 1.3 % position, ≤ 12.1 % force
    /// on 20 baseline sets), so "matters" means "can be told from the noise of the fit".
    #[arg(long, default_value_t = 0.15)]
    matters_force: f64,
    /// Seeds of the baseline scenario (no effect): the false-addition rate needs more than the
    /// effect scenarios' seeds to be a rate.
    #[arg(long, default_value_t = 20)]
    baseline_seeds: u64,
    /// First seed: another value draws other magnitudes, poses and noise (the selection's
    /// thresholds were set on seeds 0–19 of the baseline, so a run from another first seed is
    /// an out-of-sample check of them).
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
    /// Print every candidate's evidence (round, held-out gains, verdict) of runs where the
    /// true effect matters but was not chosen, or where another effect was chosen.
    #[arg(long)]
    explain_misses: bool,
    /// Scenario generator: `independent` (crates/bench-plant: the effects written a second time,
    /// sharing no code or parameterization with the candidates — the acceptance), `sim-plant`
    /// (the simulated plant, same parameterization as the candidates), or `both`.
    #[arg(long, default_value = "both", value_parser = ["independent", "sim-plant", "both"])]
    generator: String,
    /// Independent generator's scenarios (comma separated): kinds (`drum-setup`, …, see `crs
    /// calibrate generate --help`) and pairs `a+b`; default every kind and six pairs.
    #[arg(long, value_delimiter = ',')]
    kinds: Option<Vec<String>>,
    /// Seeds per two-effect scenario of the independent generator.
    #[arg(long, default_value_t = 5)]
    pair_seeds: u64,
    /// Write every candidate's evidence (each round of each run) to this CSV file: the data
    /// the selection thresholds are set on.
    #[arg(long)]
    candidates_csv: Option<PathBuf>,
}

fn bench(a: BenchArgs) -> Result<(), Box<dyn std::error::Error>> {
    run_bench(&BenchConfig {
        platform: a.platform,
        plant: a.plant,
        seeds: a.seeds,
        poses: a.poses,
        scenarios: a.scenarios,
        matters_pos: a.matters_pos,
        matters_force: a.matters_force,
        baseline_seeds: a.baseline_seeds,
        first_seed: a.first_seed,
        explain_misses: a.explain_misses,
        generator: match a.generator.as_str() {
            "independent" => Generator::Independent,
            "sim-plant" => Generator::SimPlant,
            _ => Generator::Both,
        },
        kinds: a.kinds,
        pair_seeds: a.pair_seeds,
        verbose: true,
        candidates_csv: a.candidates_csv,
    })?;
    Ok(())
}

/// Identifies from `base`, writes the report, plots, calibrated.toml and the side file into
/// `opts.out` (`calibration_campaigns::calibration_output::identify`) and prints the stage table.
pub(crate) fn calibrate_and_report(
    base: &Platform,
    train: &[Observation],
    holdout: &[Observation],
    opts: &Opts,
    command: &str,
) -> Result<PipelineReport, Box<dyn std::error::Error>> {
    let cfg = config(opts)?;
    let id = Identification {
        pipeline: &cfg,
        repeatability: (opts.multi_start > 0 || opts.bootstrap > 0).then_some(
            RepeatabilityConfig {
                multi_starts: opts.multi_start,
                bootstrap: opts.bootstrap,
                seed: opts.repeat_seed,
            },
        ),
        out: &opts.out,
        command,
    };
    Ok(calibration_output::identify_and_report(
        base,
        train,
        holdout,
        &id,
        opts.json,
        &mut Spinner::default(),
    )?)
}

pub fn run(cmd: CalibrateCommand) -> Result<(), Box<dyn std::error::Error>> {
    let command: String = std::env::args().collect::<Vec<_>>().join(" ");
    match cmd {
        CalibrateCommand::Run {
            platform,
            data,
            validate,
            opts,
        } => {
            let (base, train, holdout) = calibration_output::load_run_data(
                &platform,
                &data,
                validate.as_deref(),
                opts.holdout_every,
            )?;
            calibrate_and_report(&base, &train, &holdout, &opts, &command).map(|_| ())
        }
        CalibrateCommand::Demo {
            plant,
            campaign,
            validation_seed_offset,
            opts,
        } => {
            let demo = calibration_campaigns::calibration_demo::record(
                &plant,
                &campaign,
                validation_seed_offset,
                &opts.out,
                &mut Spinner::default(),
            )?;
            let (base, train, holdout) = (&demo.base, &demo.identification, &demo.validation);
            calibrate_and_report(base, train, holdout, &opts, &command).map(|_| ())
        }
        CalibrateCommand::Loop(a) => crate::calibrate_loop_cmd::run_loop(a, &command),
        CalibrateCommand::Campaign(a) => crate::calibrate_loop_cmd::run_campaign(a),
        CalibrateCommand::BenchDiagnosis(a) => bench(a),
        CalibrateCommand::Generate(a) => generate(a),
    }
}
