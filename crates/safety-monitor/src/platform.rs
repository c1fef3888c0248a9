//! The monitor's OWN reading of the platform TOML (`config/icosahedron.toml`, format documented
//! in crates/motion-core/src/config.rs). Written separately from motion-core on purpose (diverse
//! redundancy): only the parameters the monitor needs (geometry for the standard kinematics, the
//! workspace box) plus those the platform identity hashes (stiffness, load, force limits,
//! pulleys) are read. Everything is validated; an error names the file, the line and the key.

use crs_ipc::MAX_CABLES;
use glam::DVec3;
use serde::Deserialize;
use std::fmt;
use std::path::Path;
use toml::Spanned;

/// A platform file the monitor cannot use.
#[derive(Debug, Clone, PartialEq)]
pub struct PlatformError {
    pub file: String,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// Dotted key, e.g. `geometry.platform_anchors_m[3]`.
    pub key: String,
    pub message: String,
}

impl fmt::Display for PlatformError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if self.key.is_empty() {
            write!(f, ": {}", self.message)
        } else {
            write!(f, ": `{}`: {}", self.key, self.message)
        }
    }
}

impl std::error::Error for PlatformError {}

/// Operating box of the pose the monitor enforces (`[workspace]`), SI (m, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkspaceBox {
    pub position_min_m: DVec3,
    pub position_max_m: DVec3,
    pub rotation_min_rad: DVec3,
    pub rotation_max_rad: DVec3,
}

impl WorkspaceBox {
    /// The box widened by `margin_m` / `margin_rad` on every side.
    pub fn widened(&self, margin_m: f64, margin_rad: f64) -> Self {
        Self {
            position_min_m: self.position_min_m - DVec3::splat(margin_m),
            position_max_m: self.position_max_m + DVec3::splat(margin_m),
            rotation_min_rad: self.rotation_min_rad - DVec3::splat(margin_rad),
            rotation_max_rad: self.rotation_max_rad + DVec3::splat(margin_rad),
        }
    }

    /// True if every coordinate of `pose` = [x, y, z, φx, φy, φz] lies inside (NaN never does).
    pub fn contains(&self, pose: &[f64; 6]) -> bool {
        let lo = [self.position_min_m, self.rotation_min_rad];
        let hi = [self.position_max_m, self.rotation_max_rad];
        (0..6).all(|k| {
            let (l, h) = (lo[k / 3][k % 3], hi[k / 3][k % 3]);
            pose[k] >= l && pose[k] <= h
        })
    }
}

/// Pulley parameters (only hashed into the identity; the monitor checks against the standard
/// kinematics, sec. 5.6).
#[derive(Debug, Clone, PartialEq)]
pub struct PulleyParams {
    pub radius_m: Vec<f64>,
    /// Unit swivel axes (normalised here, as the motion core normalises them).
    pub axis: Vec<DVec3>,
}

/// The parameters the monitor read from the platform TOML.
#[derive(Debug, Clone, PartialEq)]
pub struct PlatformParams {
    pub name: String,
    /// Frame-side cable exit points a_i (world frame), m (eq. 2.4).
    pub frame_anchors_m: Vec<DVec3>,
    /// Platform anchor points b_i^(P) (platform frame), m (eq. 2.4, 2.6).
    pub platform_anchors_m: Vec<DVec3>,
    pub pulleys: Option<PulleyParams>,
    /// k_F per cable, N.
    pub k_f_n: Vec<f64>,
    /// External wrench [f; τ], N and N·m.
    pub wrench_n_nm: [f64; 6],
    pub f_min_n: f64,
    pub f_max_n: f64,
    pub workspace: WorkspaceBox,
    /// Table 5.1 motion limits (the `[limits]` table), SI: m/s, rad/s, m/s², rad/s².
    pub limits: MotionLimits,
}

/// Table 5.1: largest platform velocities and accelerations, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    pub linear_velocity_m_per_s: f64,
    pub angular_velocity_rad_per_s: f64,
    pub linear_acceleration_m_per_s2: f64,
    pub angular_acceleration_rad_per_s2: f64,
}

impl PlatformParams {
    /// Number of cables m.
    pub fn cables(&self) -> usize {
        self.frame_anchors_m.len()
    }
}

#[derive(Deserialize)]
struct Raw {
    platform: RawMeta,
    geometry: RawGeometry,
    pulleys: Option<RawPulleys>,
    elasticity: RawElasticity,
    load: RawLoad,
    forces: RawForces,
    workspace: RawWorkspace,
    limits: RawLimits,
}

#[derive(Deserialize)]
struct RawLimits {
    linear_velocity_max_m_per_s: Spanned<f64>,
    angular_velocity_max_deg_per_s: Spanned<f64>,
    linear_acceleration_max_m_per_s2: Spanned<f64>,
    angular_acceleration_max_deg_per_s2: Spanned<f64>,
}

#[derive(Deserialize)]
struct RawMeta {
    name: Spanned<String>,
}

// Kinematic tables: unknown keys are refused (a key the monitor does not understand could
// change the geometry).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGeometry {
    frame_anchors_m: Spanned<Vec<[f64; 3]>>,
    platform_anchors_m: Spanned<Vec<[f64; 3]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPulleys {
    radius_m: Spanned<OneOrMany>,
    swivel_axes: Spanned<Vec<[f64; 3]>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    One(f64),
    Many(Vec<f64>),
}

#[derive(Deserialize)]
struct RawElasticity {
    k_f_n: Spanned<OneOrMany>,
}

#[derive(Deserialize)]
struct RawLoad {
    wrench_n_nm: Spanned<[f64; 6]>,
}

#[derive(Deserialize)]
struct RawForces {
    f_min_n: Spanned<f64>,
    f_max_n: Spanned<f64>,
}

#[derive(Deserialize)]
struct RawWorkspace {
    position_min_m: Spanned<[f64; 3]>,
    position_max_m: Spanned<[f64; 3]>,
    rotation_min_deg: Spanned<[f64; 3]>,
    rotation_max_deg: Spanned<[f64; 3]>,
}

struct Ctx<'a> {
    text: &'a str,
    file: &'a str,
}

impl Ctx<'_> {
    fn err<T>(
        &self,
        span: std::ops::Range<usize>,
        key: impl Into<String>,
        msg: impl Into<String>,
    ) -> Result<T, PlatformError> {
        let upto = &self.text[..span.start.min(self.text.len())];
        Err(PlatformError {
            file: self.file.to_string(),
            line: Some(upto.matches('\n').count() + 1),
            key: key.into(),
            message: msg.into(),
        })
    }

    fn finite<T>(&self, v: &Spanned<T>, key: &str, xs: &[f64]) -> Result<(), PlatformError> {
        match xs.iter().position(|x| !x.is_finite()) {
            Some(i) => self.err(v.span(), format!("{key}[{i}]"), "must be a finite number"),
            None => Ok(()),
        }
    }

    fn per_cable(
        &self,
        v: &Spanned<OneOrMany>,
        key: &str,
        m: usize,
    ) -> Result<Vec<f64>, PlatformError> {
        let xs = match v.get_ref() {
            OneOrMany::One(x) => vec![*x; m],
            OneOrMany::Many(xs) if xs.len() == m => xs.clone(),
            OneOrMany::Many(xs) => {
                return self.err(
                    v.span(),
                    key,
                    format!("has {} entries but there are {m} cables", xs.len()),
                );
            }
        };
        self.finite(v, key, &xs)?;
        Ok(xs)
    }
}

fn flat(rows: &[[f64; 3]]) -> Vec<f64> {
    rows.iter().flatten().copied().collect()
}

fn v3(a: &[f64; 3]) -> DVec3 {
    DVec3::new(a[0], a[1], a[2])
}

/// Reads and validates the platform TOML at `path`.
pub fn load_platform(path: &Path) -> Result<PlatformParams, PlatformError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| PlatformError {
        file: file.clone(),
        line: None,
        key: String::new(),
        message: format!("cannot read: {e}"),
    })?;
    parse_platform(&text, &file)
}

/// Parses and validates platform TOML text (`file` names it in errors).
pub fn parse_platform(text: &str, file: &str) -> Result<PlatformParams, PlatformError> {
    let cx = Ctx { text, file };
    let raw: Raw = toml::from_str(text).map_err(|e| PlatformError {
        file: file.to_string(),
        line: e
            .span()
            .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1),
        key: String::new(),
        message: e.message().trim().to_string(),
    })?;
    let g = &raw.geometry;
    let a_rows = g.frame_anchors_m.get_ref();
    let b_rows = g.platform_anchors_m.get_ref();
    let m = a_rows.len();
    if m == 0 || m > MAX_CABLES {
        return cx.err(
            g.frame_anchors_m.span(),
            "geometry.frame_anchors_m",
            format!("needs 1..={MAX_CABLES} rows, got {m}"),
        );
    }
    cx.finite(
        &g.frame_anchors_m,
        "geometry.frame_anchors_m",
        &flat(a_rows),
    )?;
    cx.finite(
        &g.platform_anchors_m,
        "geometry.platform_anchors_m",
        &flat(b_rows),
    )?;
    if b_rows.len() != m {
        return cx.err(
            g.platform_anchors_m.span(),
            "geometry.platform_anchors_m",
            format!("has {} rows but there are {m} cables", b_rows.len()),
        );
    }
    let pulleys = match &raw.pulleys {
        None => None,
        Some(p) => {
            let radius_m = cx.per_cable(&p.radius_m, "pulleys.radius_m", m)?;
            if let Some(i) = radius_m.iter().position(|r| *r < 0.0) {
                return cx.err(
                    p.radius_m.span(),
                    format!("pulleys.radius_m[{i}]"),
                    "must be >= 0",
                );
            }
            let rows = p.swivel_axes.get_ref();
            if rows.len() != m {
                return cx.err(
                    p.swivel_axes.span(),
                    "pulleys.swivel_axes",
                    format!("has {} rows but there are {m} cables", rows.len()),
                );
            }
            cx.finite(&p.swivel_axes, "pulleys.swivel_axes", &flat(rows))?;
            let mut axis = Vec::with_capacity(m);
            for (i, r) in rows.iter().enumerate() {
                // Normalised component-wise by the Euclidean norm (same arithmetic as the
                // motion core, so the identity hashes agree bit for bit).
                let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                if n.is_nan() || n < 1e-12 {
                    return cx.err(
                        p.swivel_axes.span(),
                        format!("pulleys.swivel_axes[{i}]"),
                        "must be a non-zero vector",
                    );
                }
                axis.push(DVec3::new(r[0] / n, r[1] / n, r[2] / n));
            }
            Some(PulleyParams { radius_m, axis })
        }
    };
    let k_f_n = cx.per_cable(&raw.elasticity.k_f_n, "elasticity.k_f_n", m)?;
    if let Some(i) = k_f_n.iter().position(|k| *k <= 0.0) {
        return cx.err(
            raw.elasticity.k_f_n.span(),
            format!("elasticity.k_f_n[{i}]"),
            "must be > 0",
        );
    }
    let w = *raw.load.wrench_n_nm.get_ref();
    cx.finite(&raw.load.wrench_n_nm, "load.wrench_n_nm", &w)?;
    let (f_min_n, f_max_n) = (*raw.forces.f_min_n.get_ref(), *raw.forces.f_max_n.get_ref());
    if !(f_min_n.is_finite() && f_max_n.is_finite() && f_min_n >= 0.0 && f_min_n < f_max_n) {
        return cx.err(
            raw.forces.f_min_n.span(),
            "forces.f_min_n",
            format!("must satisfy 0 <= f_min_n < f_max_n (got {f_min_n} N, {f_max_n} N)"),
        );
    }
    let ws = &raw.workspace;
    for (v, key) in [
        (&ws.position_min_m, "workspace.position_min_m"),
        (&ws.position_max_m, "workspace.position_max_m"),
        (&ws.rotation_min_deg, "workspace.rotation_min_deg"),
        (&ws.rotation_max_deg, "workspace.rotation_max_deg"),
    ] {
        cx.finite(v, key, v.get_ref())?;
    }
    for k in 0..3 {
        if ws.position_min_m.get_ref()[k] >= ws.position_max_m.get_ref()[k] {
            return cx.err(
                ws.position_max_m.span(),
                format!("workspace.position_max_m[{k}]"),
                "must be greater than workspace.position_min_m",
            );
        }
        if ws.rotation_min_deg.get_ref()[k] > ws.rotation_max_deg.get_ref()[k] {
            return cx.err(
                ws.rotation_max_deg.span(),
                format!("workspace.rotation_max_deg[{k}]"),
                "must be >= workspace.rotation_min_deg",
            );
        }
    }
    let l = &raw.limits;
    for (v, key) in [
        (
            &l.linear_velocity_max_m_per_s,
            "limits.linear_velocity_max_m_per_s",
        ),
        (
            &l.angular_velocity_max_deg_per_s,
            "limits.angular_velocity_max_deg_per_s",
        ),
        (
            &l.linear_acceleration_max_m_per_s2,
            "limits.linear_acceleration_max_m_per_s2",
        ),
        (
            &l.angular_acceleration_max_deg_per_s2,
            "limits.angular_acceleration_max_deg_per_s2",
        ),
    ] {
        let x = *v.get_ref();
        if !(x.is_finite() && x > 0.0) {
            return cx.err(
                v.span(),
                key,
                format!("must be a finite number > 0, got {x}"),
            );
        }
    }
    let deg = std::f64::consts::PI / 180.0;
    let limits = MotionLimits {
        linear_velocity_m_per_s: *l.linear_velocity_max_m_per_s.get_ref(),
        angular_velocity_rad_per_s: *l.angular_velocity_max_deg_per_s.get_ref() * deg,
        linear_acceleration_m_per_s2: *l.linear_acceleration_max_m_per_s2.get_ref(),
        angular_acceleration_rad_per_s2: *l.angular_acceleration_max_deg_per_s2.get_ref() * deg,
    };
    let name = raw.platform.name.get_ref().trim().to_string();
    if name.is_empty() {
        return cx.err(
            raw.platform.name.span(),
            "platform.name",
            "must not be empty",
        );
    }
    let frame_anchors_m: Vec<DVec3> = a_rows.iter().map(v3).collect();
    let platform_anchors_m: Vec<DVec3> = b_rows.iter().map(v3).collect();
    for (key, pts, span) in [
        (
            "geometry.frame_anchors_m",
            &frame_anchors_m,
            g.frame_anchors_m.span(),
        ),
        (
            "geometry.platform_anchors_m",
            &platform_anchors_m,
            g.platform_anchors_m.span(),
        ),
    ] {
        for i in 0..m {
            for j in i + 1..m {
                if pts[i].distance(pts[j]) < 1e-9 {
                    return cx.err(
                        span,
                        format!("{key}[{j}]"),
                        format!("coincides with row {i} (anchor points must be distinct)"),
                    );
                }
            }
        }
    }
    Ok(PlatformParams {
        name,
        frame_anchors_m,
        platform_anchors_m,
        pulleys,
        k_f_n,
        wrench_n_nm: w,
        f_min_n,
        f_max_n,
        workspace: WorkspaceBox {
            position_min_m: v3(ws.position_min_m.get_ref()),
            position_max_m: v3(ws.position_max_m.get_ref()),
            rotation_min_rad: v3(ws.rotation_min_deg.get_ref()) * (std::f64::consts::PI / 180.0),
            rotation_max_rad: v3(ws.rotation_max_deg.get_ref()) * (std::f64::consts::PI / 180.0),
        },
        limits,
    })
}
