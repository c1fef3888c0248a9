//! The explicit accept step of a (re)calibrated platform. The monitor runs
//! only the platform file whose SHA-256 its configuration pins (`[monitor] platform_sha256`);
//! a calibration writes a NEW platform file and never touches the monitor's accepted copy.
//! `safety-monitor accept NEW.toml` parses the candidate with the monitor's own parser, shows
//! every parameter that differs from the platform the monitor runs now, and only with `--yes`
//! writes the accepted copy beside the monitor configuration (`accepted/<config stem>.platform.toml`)
//! and points `[monitor] platform` / `platform_sha256` at it. The edited configuration is
//! loaded by the monitor's own loader before it replaces the old one.

use crate::config::{self, sha256_of};
use crate::identity::{hex, platform_identity};
use crate::platform::{PlatformError, PlatformParams, load_platform, parse_platform};
use std::path::{Path, PathBuf};

/// Why an accept run failed; nothing of the monitor's configuration has changed unless the
/// variant says so.
#[derive(Debug, thiserror::Error)]
pub enum AcceptError {
    /// Reading or writing `path` failed.
    #[error("{}: {source}", path.display())]
    File {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Creating the `accepted/` directory or moving a finished file into place failed.
    #[error("{source}")]
    Place {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The monitor configuration has no `[monitor] platform` key.
    #[error("{}: no [monitor] platform", config.display())]
    NoPlatformKey { config: PathBuf },
    /// The candidate platform file is not UTF-8 text.
    #[error("{}: not UTF-8 text", candidate.display())]
    NotUtf8 { candidate: PathBuf },
    /// The monitor's own parser refuses the candidate.
    #[error(transparent)]
    Candidate(#[from] PlatformError),
    /// The edited configuration does not load with the monitor's loader (the old one stays).
    #[error("the accepted configuration would not load: {0}")]
    EditedConfig(#[source] config::ConfigError),
}

fn file_err(path: &Path) -> impl FnOnce(std::io::Error) -> AcceptError + '_ {
    move |source| AcceptError::File {
        path: path.to_path_buf(),
        source,
    }
}

fn place_err(path: &Path) -> impl FnOnce(std::io::Error) -> AcceptError + '_ {
    move |source| AcceptError::Place {
        path: path.to_path_buf(),
        source,
    }
}

/// What an accept run found (and did).
#[derive(Debug, Clone)]
pub struct AcceptReport {
    /// The platform the monitor runs now, and whether its file still has the pinned hash.
    pub current: PathBuf,
    pub current_status: &'static str,
    /// One line per differing parameter: `name: old -> new`.
    pub diff: Vec<String>,
    pub new_sha256: String,
    pub new_identity: String,
    /// Where the accepted copy was written (None: shown only).
    pub written: Option<PathBuf>,
}

fn diff_into(out: &mut Vec<String>, name: &str, a: &[f64], b: &[f64]) {
    if a.len() != b.len() {
        out.push(format!("{name}: {} values -> {} values", a.len(), b.len()));
        return;
    }
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        if x.to_bits() != y.to_bits() {
            let idx = if a.len() > 1 {
                format!("[{i}]")
            } else {
                String::new()
            };
            out.push(format!("{name}{idx}: {x} -> {y}"));
        }
    }
}

fn flat(v: &[glam::DVec3]) -> Vec<f64> {
    v.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

/// Every parameter of `new` that differs from `old`, in SI units as the monitor uses them.
pub fn diff(old: &PlatformParams, new: &PlatformParams) -> Vec<String> {
    let mut d = Vec::new();
    if old.name != new.name {
        d.push(format!("platform.name: {:?} -> {:?}", old.name, new.name));
    }
    diff_into(
        &mut d,
        "geometry.frame_anchors_m (x,y,z per cable)",
        &flat(&old.frame_anchors_m),
        &flat(&new.frame_anchors_m),
    );
    diff_into(
        &mut d,
        "geometry.platform_anchors_m (x,y,z per cable)",
        &flat(&old.platform_anchors_m),
        &flat(&new.platform_anchors_m),
    );
    diff_into(&mut d, "elasticity.k_f_n", &old.k_f_n, &new.k_f_n);
    diff_into(
        &mut d,
        "load.wrench_n_nm",
        &old.wrench_n_nm,
        &new.wrench_n_nm,
    );
    diff_into(&mut d, "forces.f_min_n", &[old.f_min_n], &[new.f_min_n]);
    diff_into(&mut d, "forces.f_max_n", &[old.f_max_n], &[new.f_max_n]);
    match (&old.pulleys, &new.pulleys) {
        (None, None) => {}
        (Some(a), Some(b)) => {
            diff_into(&mut d, "pulleys.radius_m", &a.radius_m, &b.radius_m);
            diff_into(
                &mut d,
                "pulleys.swivel_axes (unit)",
                &flat(&a.axis),
                &flat(&b.axis),
            );
        }
        (a, b) => d.push(format!(
            "pulleys: {} -> {}",
            if a.is_some() { "present" } else { "none" },
            if b.is_some() { "present" } else { "none" }
        )),
    }
    let (wa, wb) = (&old.workspace, &new.workspace);
    diff_into(
        &mut d,
        "workspace.position_min_m",
        &flat(&[wa.position_min_m]),
        &flat(&[wb.position_min_m]),
    );
    diff_into(
        &mut d,
        "workspace.position_max_m",
        &flat(&[wa.position_max_m]),
        &flat(&[wb.position_max_m]),
    );
    diff_into(
        &mut d,
        "workspace.rotation_min (rad)",
        &flat(&[wa.rotation_min_rad]),
        &flat(&[wb.rotation_min_rad]),
    );
    diff_into(
        &mut d,
        "workspace.rotation_max (rad)",
        &flat(&[wa.rotation_max_rad]),
        &flat(&[wb.rotation_max_rad]),
    );
    let (la, lb) = (&old.limits, &new.limits);
    diff_into(
        &mut d,
        "limits.linear_velocity (m/s)",
        &[la.linear_velocity_m_per_s],
        &[lb.linear_velocity_m_per_s],
    );
    diff_into(
        &mut d,
        "limits.angular_velocity (rad/s)",
        &[la.angular_velocity_rad_per_s],
        &[lb.angular_velocity_rad_per_s],
    );
    diff_into(
        &mut d,
        "limits.linear_acceleration (m/s²)",
        &[la.linear_acceleration_m_per_s2],
        &[lb.linear_acceleration_m_per_s2],
    );
    diff_into(
        &mut d,
        "limits.angular_acceleration (rad/s²)",
        &[la.angular_acceleration_rad_per_s2],
        &[lb.angular_acceleration_rad_per_s2],
    );
    d
}

/// The value of `key` in the `[monitor]` table of the raw config text.
fn monitor_key(text: &str, key: &str) -> Option<String> {
    let t: toml::Table = toml::from_str(text).ok()?;
    t.get("monitor")?
        .as_table()?
        .get(key)?
        .as_str()
        .map(str::to_string)
}

/// `config` with `[monitor] platform` and `platform_sha256` set (other lines unchanged).
fn with_platform(text: &str, platform: &str, sha: &str) -> String {
    let mut out = Vec::new();
    let mut section = String::new();
    let (mut set_p, mut set_h) = (false, false);
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            if section == "monitor" && set_p && !set_h {
                out.push(format!("platform_sha256 = {sha:?}"));
                set_h = true;
            }
            section = t
                .trim_end()
                .trim_matches(|c| c == '[' || c == ']')
                .to_string();
        }
        if section == "monitor" && t.starts_with("platform =") {
            out.push(format!("platform = {platform:?}"));
            set_p = true;
            continue;
        }
        if section == "monitor" && t.starts_with("platform_sha256") {
            out.push(format!("platform_sha256 = {sha:?}"));
            set_h = true;
            continue;
        }
        out.push(line.to_string());
    }
    if section == "monitor" && set_p && !set_h {
        out.push(format!("platform_sha256 = {sha:?}"));
    }
    out.join("\n") + "\n"
}

/// Shows (and with `apply` performs) the acceptance of `candidate` for the monitor
/// configuration `config_path`.
pub fn accept(
    config_path: &Path,
    candidate: &Path,
    apply: bool,
) -> Result<AcceptReport, AcceptError> {
    let text = std::fs::read_to_string(config_path).map_err(file_err(config_path))?;
    let platform_key =
        monitor_key(&text, "platform").ok_or_else(|| AcceptError::NoPlatformKey {
            config: config_path.to_path_buf(),
        })?;
    let pinned = monitor_key(&text, "platform_sha256").unwrap_or_default();
    let dir = config_path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let current = dir.join(&platform_key);
    let new_bytes = std::fs::read(candidate).map_err(file_err(candidate))?;
    let new_text = String::from_utf8(new_bytes.clone()).map_err(|_| AcceptError::NotUtf8 {
        candidate: candidate.to_path_buf(),
    })?;
    let new = parse_platform(&new_text, &candidate.display().to_string())?;
    let new_sha256 = hex(&sha256_of(&new_bytes));
    let (current_status, old) = match std::fs::read(&current) {
        Err(_) => ("missing", None),
        Ok(b) => {
            let status = if pinned.is_empty() {
                "not accepted (no platform_sha256)"
            } else if pinned.eq_ignore_ascii_case(&hex(&sha256_of(&b))) {
                "accepted"
            } else {
                "CHANGED since it was accepted"
            };
            (status, load_platform(&current).ok())
        }
    };
    let diff = match &old {
        Some(o) => diff(o, &new),
        None => vec!["(no readable current platform: every parameter is new)".into()],
    };
    let mut report = AcceptReport {
        current: current.clone(),
        current_status,
        diff,
        new_sha256: new_sha256.clone(),
        new_identity: hex(&platform_identity(&new)),
        written: None,
    };
    if !apply {
        return Ok(report);
    }
    let stem = config_path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "safety-monitor".into());
    let rel = format!("accepted/{stem}.platform.toml");
    let copy = dir.join(&rel);
    let copy_dir = copy.parent().unwrap_or(&dir);
    std::fs::create_dir_all(copy_dir).map_err(place_err(copy_dir))?;
    let tmp_copy = copy.with_extension("toml.new");
    std::fs::write(&tmp_copy, &new_bytes).map_err(file_err(&tmp_copy))?;
    std::fs::rename(&tmp_copy, &copy).map_err(place_err(&copy))?;
    // The edited configuration must load with the monitor's own loader before it replaces
    // the old one (checked as a temporary file in the same directory: same relative paths).
    let edited = with_platform(&text, &rel, &new_sha256);
    let tmp_cfg = dir.join(format!(".{stem}.accept.toml"));
    std::fs::write(&tmp_cfg, &edited).map_err(file_err(&tmp_cfg))?;
    if let Err(e) = config::load(&tmp_cfg) {
        let _ = std::fs::remove_file(&tmp_cfg);
        return Err(AcceptError::EditedConfig(e));
    }
    std::fs::rename(&tmp_cfg, config_path).map_err(place_err(config_path))?;
    report.written = Some(copy);
    Ok(report)
}
