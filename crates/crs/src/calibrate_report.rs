//! The identification run shared by `crs calibrate run|demo` and the closed loop (`crs
//! calibrate loop`): its options, the pipeline with the progress spinner, and the report,
//! plots, calibrated.toml and side file it writes. A module of its own so that both commands
//! use it without importing each other.

use calibrate::Observation;
use calibrate::effects::Effect;
use calibrate::pipeline::{PipelineConfig, PipelineReport};
use calibrate::repeatability::RepeatabilityConfig;
use cdpr_model::config::Platform;
use clap::Args;
use crs_stack::calibration_output::{self, Identification};
use crs_stack::progress::Progress;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

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
    #[arg(long, default_value_t = calibrate::effects::SelectConfig::default().min_gain_pos)]
    pub(crate) min_gain_pos: f64,
    /// The same for the held-out mean force error ‖f_P − f_M‖ (fraction).
    #[arg(long, default_value_t = calibrate::effects::SelectConfig::default().min_gain_force)]
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

pub(crate) fn config(o: &Opts) -> Result<PipelineConfig, Box<dyn std::error::Error>> {
    let mut cfg = PipelineConfig::default();
    cfg.weights.wrench = o.w_wrench;
    cfg.weights.length = o.w_length;
    cfg.ridge_b = o.ridge_b;
    cfg.lasso_b = o.lasso_b;
    match o.ridge_kf {
        Some(l) if !(l.is_finite() && l >= 0.0) => {
            return Err(format!("--ridge-kf: {l} is not a finite λ ≥ 0").into());
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
                Effect::from_name(n.trim())
                    .ok_or_else(|| format!("--candidates: unknown effect `{n}`"))
            })
            .collect::<Result<_, _>>()?;
    }
    Ok(cfg)
}

/// The command line's progress: a spinner with the elapsed time on stderr.
#[derive(Default)]
pub(crate) struct Spinner(Option<ProgressBar>);

impl Progress for Spinner {
    fn start(&mut self, what: &str) {
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar.set_message(what.to_string());
        self.0 = Some(bar);
    }
    fn update(&mut self, what: String) {
        if let Some(b) = &self.0 {
            b.set_message(what);
        }
    }
    fn finish(&mut self) {
        if let Some(b) = self.0.take() {
            b.finish_and_clear();
        }
    }
}

/// Identifies from `base`, writes the report, plots, calibrated.toml and the side file into
/// `opts.out` (`crs_stack::calibration_output::identify`) and prints the stage table.
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
