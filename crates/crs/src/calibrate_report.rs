//! The identification run shared by `crs calibrate run|demo` and the closed loop (`crs
//! calibrate loop`): its options, the pipeline with the progress spinner, and the report,
//! plots, calibrated.toml and side file it writes. A module of its own so that both commands
//! use it without importing each other.

use calibrate::effects::Effect;
use calibrate::pipeline::{self, PipelineConfig, PipelineReport};
use calibrate::{Observation, report};
use cdpr_model::config::{Platform, load_platform};
use clap::Args;
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

pub(crate) fn spinner(msg: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar.set_message(msg.to_string());
    bar
}

/// Identifies from `base`, writes the report, plots, calibrated.toml and the side file into
/// `opts.out`; returns the pipeline report.
pub(crate) fn calibrate_and_report(
    base: &Platform,
    train: &[Observation],
    holdout: &[Observation],
    opts: &Opts,
    command: &str,
) -> Result<PipelineReport, Box<dyn std::error::Error>> {
    let cfg = config(opts)?;
    let bar = spinner("identifying");
    let mut rep: PipelineReport =
        pipeline::run(&base.model, train, holdout, &cfg, &mut |stage, it, cost| {
            if cost.is_finite() {
                bar.set_message(format!("{stage}: iteration {it}, cost {cost:.4e}"));
            } else {
                bar.set_message(stage.to_string());
            }
        })?;
    if opts.multi_start > 0 || opts.bootstrap > 0 {
        let rc = calibrate::repeatability::RepeatabilityConfig {
            multi_starts: opts.multi_start,
            bootstrap: opts.bootstrap,
            seed: opts.repeat_seed,
        };
        rep.repeatability = Some(calibrate::repeatability::assess(
            &base.model,
            train,
            holdout,
            &cfg,
            &rep,
            &rc,
            &mut |what, k| bar.set_message(format!("{what} {}", k + 1)),
        ));
    }
    bar.finish_and_clear();
    std::fs::create_dir_all(&opts.out)?;
    let eval = if holdout.is_empty() { train } else { holdout };
    let plots = report::plots(&rep, eval);
    let mut names = Vec::new();
    for (name, svg) in &plots {
        std::fs::write(opts.out.join(name), svg)?;
        names.push(name.clone());
    }
    let fin = rep.final_stage();
    let toml_path = opts.out.join("calibrated.toml");
    let side_path = opts.out.join("calibrated-effects.toml");
    // Never deploy a model that did not validate: write the last step whose FK converged on
    // every held-out sample, or nothing (issue 13). Stale outputs of an earlier run go too.
    let _ = std::fs::remove_file(&toml_path);
    let _ = std::fs::remove_file(&side_path);
    let written = rep.last_validated_stage();
    let mut md = report::markdown(&rep, command, &names);
    if let Some(st) = written {
        // The chosen effects belong to the final step only.
        let chosen = if std::ptr::eq(st, fin) {
            rep.selection
                .as_ref()
                .map(|s| s.chosen.clone())
                .unwrap_or_default()
        } else {
            Vec::new()
        };
        std::fs::write(
            &toml_path,
            report::platform_toml(base, &st.model, &format!("{}-calibrated", base.name)),
        )?;
        std::fs::write(&side_path, report::side_file(&st.model, &chosen))?;
        // The written platform must load with the daemon's loader.
        load_platform(&toml_path).map_err(|e| format!("written platform does not load: {e}"))?;
        md.push_str(&format!(
            "\n## Output\n\n* Identified platform (step \"{}\"): `{}` (loads with `cdpr_model::config::load_platform`).\n* Side file (cable offsets and extension parameters the platform schema cannot express): `{}`.\n",
            st.name,
            toml_path.display(),
            side_path.display()
        ));
    } else {
        md.push_str("\n## Output\n\n* No step validated: no calibrated platform was written.\n");
    }
    std::fs::write(opts.out.join("report.md"), &md)?;
    let json = serde_json::to_string_pretty(&rep)?;
    std::fs::write(opts.out.join("report.json"), &json)?;
    if opts.json {
        println!("{json}");
    } else {
        println!("{}", report::stage_table(&rep));
        println!("report: {}", opts.out.join("report.md").display());
    }
    for (name, text) in rep.failed_stages() {
        eprintln!("calibration step \"{name}\" failed: {text} held-out samples");
    }
    if fin.failed() {
        let what = match written {
            Some(st) => format!(
                "{} holds the last validated step, \"{}\"",
                toml_path.display(),
                st.name
            ),
            None => "no calibrated platform was written".into(),
        };
        return Err(format!(
            "the final calibration step \"{}\" failed validation ({}); {what}",
            fin.name,
            fin.holdout.failure_text().unwrap_or_default()
        )
        .into());
    }
    Ok(rep)
}
