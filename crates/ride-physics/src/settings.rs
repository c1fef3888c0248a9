//! The ride TOML (`config/ride-helicopter.toml`): aerial damping, collective authority,
//! attitude assist and the elastic safety walls (eq. 5.21–5.22), turned into a
//! [`HoverModel`] for one platform: mass and inertia from its `[dynamics]` (eq. 5.13–5.14),
//! the walls inside its operating region by the configured margins (the walls' give must stay
//! inside the region: the hard loop refuses any reference outside it). Unknown keys are
//! rejected; errors name the file, the key and, for syntax errors, the line.

use crate::hover::HoverModel;
use crate::walls::Walls;
use cdpr_model::config::Platform;
use cdpr_model::dynamics::GRAVITY_M_PER_S2;
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::Path;

/// The ride TOML, validated, in SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct HoverSettings {
    pub wall_margin_m: Vector3<f64>,
    pub wall_margin_rad: Vector3<f64>,
    pub wall_stiffness_n_per_m: f64,
    pub wall_damping_n_s_per_m: f64,
    pub rotation_wall_stiffness_n_m_per_rad: f64,
    pub rotation_wall_damping_n_m_s_per_rad: f64,
    pub damping_linear: Vector3<f64>,
    pub damping_rotational: Vector3<f64>,
    pub collective_authority: f64,
    pub attitude_command_max_rad: Vector3<f64>,
    pub assist_natural_frequency_rad_per_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    walls: RawWalls,
    damping: RawDamping,
    controls: RawControls,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWalls {
    margin_m: [f64; 3],
    margin_deg: [f64; 3],
    stiffness_n_per_m: f64,
    damping_n_s_per_m: f64,
    rotation_stiffness_n_m_per_rad: f64,
    rotation_damping_n_m_s_per_rad: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDamping {
    linear_n_s_per_m: [f64; 3],
    rotational_n_m_s_per_rad: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawControls {
    collective_authority: f64,
    attitude_command_max_deg: [f64; 3],
    assist_natural_frequency_rad_per_s: f64,
}

/// Why the ride TOML or the platform cannot make a hover model.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{file}{}: {}{message}", line.map_or(String::new(), |l| format!(":{l}")), if key.is_empty() { String::new() } else { format!("`{key}`: ") })]
pub struct SettingsError {
    pub file: String,
    pub line: Option<usize>,
    pub key: String,
    pub message: String,
}

impl HoverSettings {
    pub fn load(path: &Path) -> Result<Self, SettingsError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SettingsError {
            file: file.clone(),
            line: None,
            key: String::new(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, &file)
    }

    pub fn parse(text: &str, file: &str) -> Result<Self, SettingsError> {
        let raw: Raw = toml::from_str(text).map_err(|e| SettingsError {
            file: file.into(),
            line: e
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1),
            key: String::new(),
            message: e.message().trim().to_string(),
        })?;
        let err = |key: &str, message: String| SettingsError {
            file: file.into(),
            line: None,
            key: key.into(),
            message,
        };
        let pos = |x: f64, key: &str| {
            if x.is_finite() && x > 0.0 {
                Ok(x)
            } else {
                Err(err(key, format!("must be a finite number > 0, got {x}")))
            }
        };
        let pos3 = |v: [f64; 3], key: &str| -> Result<Vector3<f64>, SettingsError> {
            for (k, x) in v.iter().enumerate() {
                pos(*x, &format!("{key}[{k}]"))?;
            }
            Ok(Vector3::from(v))
        };
        let a = raw.controls.collective_authority;
        if !(a > 0.0 && a < 1.0) {
            return Err(err(
                "controls.collective_authority",
                format!("must lie in (0, 1) (thrust m g (1 ± authority)), got {a}"),
            ));
        }
        Ok(Self {
            wall_margin_m: pos3(raw.walls.margin_m, "walls.margin_m")?,
            wall_margin_rad: pos3(raw.walls.margin_deg, "walls.margin_deg")?.map(f64::to_radians),
            wall_stiffness_n_per_m: pos(raw.walls.stiffness_n_per_m, "walls.stiffness_n_per_m")?,
            wall_damping_n_s_per_m: pos(raw.walls.damping_n_s_per_m, "walls.damping_n_s_per_m")?,
            rotation_wall_stiffness_n_m_per_rad: pos(
                raw.walls.rotation_stiffness_n_m_per_rad,
                "walls.rotation_stiffness_n_m_per_rad",
            )?,
            rotation_wall_damping_n_m_s_per_rad: pos(
                raw.walls.rotation_damping_n_m_s_per_rad,
                "walls.rotation_damping_n_m_s_per_rad",
            )?,
            damping_linear: pos3(raw.damping.linear_n_s_per_m, "damping.linear_n_s_per_m")?,
            damping_rotational: pos3(
                raw.damping.rotational_n_m_s_per_rad,
                "damping.rotational_n_m_s_per_rad",
            )?,
            collective_authority: a,
            attitude_command_max_rad: pos3(
                raw.controls.attitude_command_max_deg,
                "controls.attitude_command_max_deg",
            )?
            .map(f64::to_radians),
            assist_natural_frequency_rad_per_s: pos(
                raw.controls.assist_natural_frequency_rad_per_s,
                "controls.assist_natural_frequency_rad_per_s",
            )?,
        })
    }

    /// The hover model for `platform`: its `[dynamics]` mass and inertia, walls at its region
    /// shrunk by the margins, the assist critically damped at the configured natural frequency
    /// (K_p = I ω_n², K_d = 2 I ω_n per axis). Refused when the platform has no `[dynamics]`,
    /// the walls would be empty, the home pose lies outside them, or full stick commands an
    /// attitude beyond the rotation walls.
    pub fn model(&self, platform: &Platform, file: &str) -> Result<HoverModel, SettingsError> {
        let err = |key: &str, message: String| SettingsError {
            file: file.into(),
            line: None,
            key: key.into(),
            message,
        };
        let body = platform.dynamics.ok_or_else(|| {
            err(
                "",
                format!(
                    "platform `{}` has no [dynamics] (mass, inertia): the hover model needs them",
                    platform.name
                ),
            )
        })?;
        let reg = &platform.region;
        let walls = Walls {
            min: reg.position.min + self.wall_margin_m,
            max: reg.position.max - self.wall_margin_m,
            stiffness: self.wall_stiffness_n_per_m,
            damping: self.wall_damping_n_s_per_m,
        };
        let rotation_walls = Walls {
            min: reg.rotation_min + self.wall_margin_rad,
            max: reg.rotation_max - self.wall_margin_rad,
            stiffness: self.rotation_wall_stiffness_n_m_per_rad,
            damping: self.rotation_wall_damping_n_m_s_per_rad,
        };
        for k in 0..3 {
            if walls.min[k] >= walls.max[k] {
                return Err(err(
                    &format!("walls.margin_m[{k}]"),
                    format!(
                        "leaves no room inside the operating region of `{}`",
                        platform.name
                    ),
                ));
            }
            if rotation_walls.min[k] > rotation_walls.max[k] {
                return Err(err(
                    &format!("walls.margin_deg[{k}]"),
                    format!(
                        "leaves no room inside the rotation range of `{}`",
                        platform.name
                    ),
                ));
            }
            let c = self.attitude_command_max_rad[k];
            if c > rotation_walls.max[k] || -c < rotation_walls.min[k] {
                return Err(err(
                    &format!("controls.attitude_command_max_deg[{k}]"),
                    format!(
                        "full stick ({:.2}°) lies beyond the rotation walls [{:.2}, {:.2}]°",
                        c.to_degrees(),
                        rotation_walls.min[k].to_degrees(),
                        rotation_walls.max[k].to_degrees()
                    ),
                ));
            }
        }
        let h = platform.home.r;
        if (0..3).any(|k| h[k] < walls.min[k] || h[k] > walls.max[k]) {
            return Err(err(
                "walls.margin_m",
                "the home pose lies outside the walls".into(),
            ));
        }
        let i = body.inertia_kg_m2;
        let principal = Vector3::new(i[(0, 0)], i[(1, 1)], i[(2, 2)]);
        let w = self.assist_natural_frequency_rad_per_s;
        Ok(HoverModel {
            mass_kg: body.mass_kg,
            inertia_kg_m2: i,
            gravity_m_per_s2: GRAVITY_M_PER_S2,
            damping_linear: self.damping_linear,
            damping_rotational: self.damping_rotational,
            collective_authority: self.collective_authority,
            attitude_command_max: self.attitude_command_max_rad,
            assist_stiffness: principal * w * w,
            assist_damping: principal * 2.0 * w,
            walls,
            rotation_walls,
        })
    }
}
