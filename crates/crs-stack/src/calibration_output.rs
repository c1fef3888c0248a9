//! What an identification run leaves on disk (`crs calibrate run|demo|loop`): report.md,
//! report.json, the plots, `calibrated.toml` (the last step that validated, never a failed one:
//! issue 13) and the side file with what the platform schema cannot express.

use calibrate::pipeline::PipelineReport;
use calibrate::{Observation, report};
use cdpr_model::config::{Platform, load_platform};
use std::path::{Path, PathBuf};

type BoxErr = Box<dyn std::error::Error>;

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
) -> Result<Written, BoxErr> {
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
    // every held-out sample, or nothing (issue 13). Stale outputs of an earlier run go too.
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
