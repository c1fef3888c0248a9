//! What an identification run leaves on disk (`crs calibrate run|demo|loop`): report.md,
//! report.json, the plots, `calibrated.toml` (the last step that validated, never a failed one:
//! a failed computation never reaches the robot) and the side file with what the platform schema cannot express.

use calibrate::{FitError, Observation};
use calibrate_diagnosis::pipeline::{self, PipelineConfig, PipelineReport};
use calibrate_diagnosis::repeatability::{self, RepeatabilityConfig};
use calibrate_diagnosis::report;
use cdpr_model::config::{ConfigError, Platform, load_platform};
use std::path::{Path, PathBuf};

/// Why an identification or its output failed.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error(transparent)]
    Fit(#[from] FitError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    PlatformToml(#[from] report::PlatformTomlError),
    /// The platform TOML written does not load with the daemon's loader.
    #[error("written platform does not load: {0}")]
    WrittenDoesNotLoad(ConfigError),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The final step failed validation: what was written instead.
    #[error("the final calibration step \"{step}\" failed validation ({failure}); {what}")]
    FinalStepFailed {
        step: String,
        failure: String,
        what: String,
    },
}

/// The files [`write`] wrote.
pub struct Written {
    /// report.md.
    pub report: PathBuf,
    /// report.json's text (also printed by `--json`).
    pub json: String,
    /// calibrated.toml (exists only when a step validated).
    pub platform: PathBuf,
    /// The name of the step written to calibrated.toml, if any validated.
    pub written_step: Option<String>,
}

/// Writes the report, plots, calibrated.toml and the side file of `rep` into `out`; `eval` is
/// the set the plots show (held-out, or training when there is none), `command` the command
/// line quoted in the report.
pub fn write(
    base: &Platform,
    rep: &PipelineReport,
    eval: &[Observation],
    out: &Path,
    command: &str,
) -> Result<Written, OutputError> {
    std::fs::create_dir_all(out)?;
    let plots = report::plots(rep, eval);
    let mut names = Vec::new();
    for (name, svg) in &plots {
        std::fs::write(out.join(name), svg)?;
        names.push(name.clone());
    }
    let fin = rep.final_stage();
    let toml_path = out.join("calibrated.toml");
    let side_path = out.join("calibrated-effects.toml");
    // Never deploy a model that did not validate: write the last step whose FK converged on
    // every held-out sample, or nothing (a failed step is reported, never deployed). Stale outputs of an earlier run go too.
    let _ = std::fs::remove_file(&toml_path);
    let _ = std::fs::remove_file(&side_path);
    let written = rep.last_validated_stage();
    let mut md = report::markdown(rep, command, &names);
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
            report::platform_toml(base, &st.model, &format!("{}-calibrated", base.name))?,
        )?;
        std::fs::write(&side_path, report::side_file(&st.model, &chosen))?;
        // The written platform must load with the daemon's loader.
        load_platform(&toml_path).map_err(OutputError::WrittenDoesNotLoad)?;
        md.push_str(&format!(
            "\n## Output\n\n* Identified platform (step \"{}\"): `{}` (loads with `cdpr_model::config::load_platform`).\n* Side file (cable offsets and extension parameters the platform schema cannot express): `{}`.\n",
            st.name,
            toml_path.display(),
            side_path.display()
        ));
    } else {
        md.push_str("\n## Output\n\n* No step validated: no calibrated platform was written.\n");
    }
    std::fs::write(out.join("report.md"), &md)?;
    let json = serde_json::to_string_pretty(rep)?;
    std::fs::write(out.join("report.json"), &json)?;
    Ok(Written {
        report: out.join("report.md"),
        json,
        platform: toml_path,
        written_step: written.map(|st| st.name.clone()),
    })
}

/// Why the data of an identification could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error(transparent)]
    Platform(#[from] ConfigError),
    #[error(transparent)]
    Dataset(#[from] crs_dataset::DatasetError),
    /// The data set (named) does not fit the platform.
    #[error("{}: {source}", path.display())]
    Observations {
        path: PathBuf,
        source: calibrate::observation::ObservationError,
    },
}

/// The observations of the data set `path` for a platform of `m` cables.
pub fn load_observations(path: &Path, m: usize) -> Result<Vec<Observation>, DataError> {
    let ds = crs_dataset::load_dataset(path)?;
    calibrate::from_dataset(&ds, m).map_err(|source| DataError::Observations {
        path: path.to_path_buf(),
        source,
    })
}

/// The nominal platform `platform` and the training and held-out observations of `crs calibrate
/// run`: the data set `data` and the validation set `validate`, or without one every
/// `holdout_every`-th pose of `data` held out.
pub fn load_run_data(
    platform: &Path,
    data: &Path,
    validate: Option<&Path>,
    holdout_every: u64,
) -> Result<(Platform, Vec<Observation>, Vec<Observation>), DataError> {
    let base = load_platform(platform)?;
    let m = base.model.m();
    let obs = load_observations(data, m)?;
    let (train, holdout) = match validate {
        Some(v) => (obs, load_observations(v, m)?),
        None => calibrate::split(&obs, holdout_every),
    };
    Ok((base, train, holdout))
}

/// What one identification run does besides the data: the pipeline, the optional
/// repeatability assessment, the output directory and the command quoted in the report.
pub struct Identification<'a> {
    pub pipeline: &'a PipelineConfig,
    /// Multi-start / bootstrap repeatability (eq. 6.8, 6.10); None = off.
    pub repeatability: Option<RepeatabilityConfig>,
    pub out: &'a Path,
    pub command: &'a str,
}

/// Identifies from `base` on `train` (validated on `holdout`, or on `train` when empty),
/// assesses the repeatability when asked, and writes the report, plots, calibrated.toml and the
/// side file into `id.out` ([`write()`]). `progress` hears each stage's iterations and cost (cost
/// not finite: a stage starts) as a line of text. A final step that failed validation is an
/// error after the files are written ([`OutputError::FinalStepFailed`]).
pub fn identify(
    base: &Platform,
    train: &[Observation],
    holdout: &[Observation],
    id: &Identification<'_>,
    progress: &mut dyn FnMut(String),
) -> Result<(PipelineReport, Written), OutputError> {
    let mut rep = pipeline::run(
        &base.model,
        train,
        holdout,
        id.pipeline,
        &mut |stage, it, cost| {
            if cost.is_finite() {
                progress(format!("{stage}: iteration {it}, cost {cost:.4e}"));
            } else {
                progress(stage.to_string());
            }
        },
    )?;
    if let Some(rc) = &id.repeatability {
        rep.repeatability = Some(repeatability::assess(
            &base.model,
            train,
            holdout,
            id.pipeline,
            &rep,
            rc,
            &mut |what, k| progress(format!("{what} {}", k + 1)),
        ));
    }
    let eval = if holdout.is_empty() { train } else { holdout };
    let out = write(base, &rep, eval, id.out, id.command)?;
    Ok((rep, out))
}

/// [`OutputError::FinalStepFailed`] when the final step of `rep` failed validation, saying
/// what [`write()`] wrote instead.
pub fn final_step_check(rep: &PipelineReport, out: &Written) -> Result<(), OutputError> {
    let fin = rep.final_stage();
    if !fin.failed() {
        return Ok(());
    }
    let what = match &out.written_step {
        Some(st) => format!(
            "{} holds the last validated step, \"{st}\"",
            out.platform.display()
        ),
        None => "no calibrated platform was written".into(),
    };
    Err(OutputError::FinalStepFailed {
        step: fin.name.clone(),
        failure: fin.holdout.failure_text().unwrap_or_default(),
        what,
    })
}

/// [`identify`] as `crs calibrate run` shows it: progress while it runs, then the stage table
/// and the report's path (or, with `json`, report.json's text) on stdout and the failed steps on
/// stderr; a final step that failed validation is an error ([`final_step_check`]).
pub fn identify_and_report(
    base: &Platform,
    train: &[Observation],
    holdout: &[Observation],
    id: &Identification<'_>,
    json: bool,
    progress: &mut dyn crate::progress::Progress,
) -> Result<PipelineReport, OutputError> {
    progress.start("identifying");
    let (rep, out) = identify(base, train, holdout, id, &mut |m| progress.update(m))?;
    progress.finish();
    if json {
        println!("{}", out.json);
    } else {
        println!("{}", report::stage_table(&rep));
        println!("report: {}", out.report.display());
    }
    for (name, text) in rep.failed_stages() {
        eprintln!("calibration step \"{name}\" failed: {text} held-out samples");
    }
    final_step_check(&rep, &out)?;
    Ok(rep)
}
