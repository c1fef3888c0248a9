//! Operator platform TOML (`config/*.toml`): parsing and validation into a [`Platform`].
//!
//! Units are SI and named in every key (`_m`, `_n`, `_n_nm`); angles an operator types are in
//! degrees (`_deg`) and converted here, at the edge. Unknown keys are rejected. Every error
//! names the file, the key and the line.

use crate::dynamics::{GRAVITY_M_PER_S2, RigidBody};
use crate::model::{Model, ModelError, ModelParams, Pulleys};
use crate::pose::Pose;
use crate::workspace::PositionBox;
use nalgebra::{Vector3, Vector6};
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use std::fmt;
use std::ops::Range;
use std::path::Path;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// A configuration error with its location (`file:line:column: `key`: message`): the stack's
/// one type for it, from `config-diagnostics`.
pub use config_diagnostics::ConfigError;

/// Table 5.1 motion limits, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionLimits {
    pub linear_velocity_max: f64,
    pub angular_velocity_max: f64,
    pub linear_acceleration_max: f64,
    pub angular_acceleration_max: f64,
}

/// Configured operating region: a position box and per-axis rotation bounds (rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Region {
    pub position: PositionBox,
    pub rotation_min: Vector3<f64>,
    pub rotation_max: Vector3<f64>,
}

impl Region {
    pub fn contains(&self, pose: &Pose) -> bool {
        self.position.contains(&pose.r)
            && (0..3)
                .all(|k| pose.phi[k] >= self.rotation_min[k] && pose.phi[k] <= self.rotation_max[k])
    }
}

/// Winch and rope data (table 5.1), SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WinchData {
    pub drum_diameter: f64,
    pub rope_diameter: f64,
}

/// A named cable subset for section wrenches (eq. 5.11), 0-based indices.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    pub name: String,
    pub cables: Vec<usize>,
}

/// Everything a platform TOML describes.
#[derive(Clone, Debug, PartialEq)]
pub struct Platform {
    pub name: String,
    pub description: String,
    pub model: Model,
    /// Absolute cable force limit (breaking/overload), N (table 5.1: 14000 N).
    pub f_abs_max: f64,
    pub limits: MotionLimits,
    pub winch: WinchData,
    pub region: Region,
    /// Set-up ("home") pose at which the initial tension is set.
    pub home: Pose,
    /// Optional initial cable forces at the home pose, N (eq. 6.2 / 6.22).
    pub f_ini: Option<Vec<f64>>,
    pub sections: Vec<Section>,
    /// Mass properties of the platform with its payload (`[dynamics]`, eq. 5.13–5.16), for the
    /// dynamic wrench w = w_e + w_in; `None`: the platform is checked statically only.
    pub dynamics: Option<RigidBody>,
}

impl Platform {
    /// Identity of everything the safety monitor checks the stream against: the
    /// model ([`Model::identity`]: geometry, pulleys, stiffness, load, force limits), the
    /// operating region (workspace box) and the motion limits (table 5.1), SHA-256 over
    /// `"crs-platform-v2"`, the model identity, then position min/max (m), rotation min/max
    /// (rad), then linear/angular velocity and acceleration limits (SI), exact f64 bits, little
    /// endian. motion-core announces it; the safety monitor recomputes it with its own parser
    /// (`safety_monitor::identity`) and trips on a mismatch.
    pub fn identity(&self) -> [u8; 32] {
        use sha2::{Digest, Sha256};
        let mut h = Sha256::new();
        h.update(b"crs-platform-v2");
        h.update(self.model.identity());
        let r = &self.region;
        for v in [
            r.position.min,
            r.position.max,
            r.rotation_min,
            r.rotation_max,
        ] {
            v.iter().for_each(|c| h.update(c.to_bits().to_le_bytes()));
        }
        let l = &self.limits;
        for c in [
            l.linear_velocity_max,
            l.angular_velocity_max,
            l.linear_acceleration_max,
            l.angular_acceleration_max,
        ] {
            h.update(c.to_bits().to_le_bytes());
        }
        h.finalize().into()
    }

    /// Hex form of [`Platform::identity`].
    pub fn identity_hex(&self) -> String {
        self.identity().iter().map(|b| format!("{b:02x}")).collect()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlatform {
    platform: RawMeta,
    geometry: RawGeometry,
    pulleys: Option<RawPulleys>,
    elasticity: RawElasticity,
    load: RawLoad,
    forces: RawForces,
    limits: RawLimits,
    winch: RawWinch,
    workspace: RawWorkspace,
    home: RawHome,
    #[serde(default)]
    sections: RawSections,
    dynamics: Option<RawDynamics>,
}

/// `[dynamics]`: the cabin's mass properties and an optional `[dynamics.payload]`, combined
/// into one rigid body (eq. 5.13–5.14: stator and cabin inertias).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDynamics {
    mass_kg: Spanned<f64>,
    center_of_gravity_m: Spanned<Fixed<3>>,
    inertia_kg_m2: Spanned<Fixed<3>>,
    payload: Option<RawBody>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBody {
    mass_kg: Spanned<f64>,
    center_of_gravity_m: Spanned<Fixed<3>>,
    /// Principal moments [I_xx, I_yy, I_zz] about the COG along the platform axes, kg·m².
    inertia_kg_m2: Spanned<Fixed<3>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMeta {
    name: Spanned<String>,
    #[serde(default)]
    description: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGeometry {
    frame_anchors_m: Rows,
    platform_anchors_m: Rows,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPulleys {
    radius_m: Spanned<PerCable>,
    swivel_axes: Rows,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum PerCable {
    All(f64),
    Each(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawElasticity {
    /// k_F = EA, N.
    k_f_n: Spanned<PerCable>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLoad {
    wrench_n_nm: Spanned<Fixed<6>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawForces {
    f_min_n: Spanned<f64>,
    f_max_n: Spanned<f64>,
    f_abs_max_n: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    linear_velocity_max_m_per_s: Spanned<f64>,
    angular_velocity_max_deg_per_s: Spanned<f64>,
    linear_acceleration_max_m_per_s2: Spanned<f64>,
    angular_acceleration_max_deg_per_s2: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWinch {
    drum_diameter_m: Spanned<f64>,
    rope_diameter_m: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorkspace {
    position_min_m: Spanned<Fixed<3>>,
    position_max_m: Spanned<Fixed<3>>,
    rotation_min_deg: Spanned<Fixed<3>>,
    rotation_max_deg: Spanned<Fixed<3>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHome {
    position_m: Spanned<Fixed<3>>,
    rotation_deg: Spanned<Fixed<3>>,
    f_ini_n: Option<Spanned<Vec<f64>>>,
}

/// Exactly `N` numbers (a point, an axis, a wrench), each kept with its own span so that a bad
/// one is located at itself. Not serde's `[f64; N]`: under `toml` that reads the first `N`
/// elements and ignores the rest, so a row typed with a fourth coordinate loaded silently.
#[derive(Clone, Debug)]
struct Fixed<const N: usize> {
    values: [f64; N],
    spans: [Range<usize>; N],
}

impl<const N: usize> std::ops::Deref for Fixed<N> {
    type Target = [f64; N];
    fn deref(&self) -> &[f64; N] {
        &self.values
    }
}

impl<const N: usize> Fixed<N> {
    /// Every element finite; a bad one is named `key[i]` at its own line and column.
    fn finite(&self, loc: &Locator, key: &str) -> Result<(), ConfigError> {
        match self.values.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(loc.err(
                self.spans[i].clone(),
                format!("{key}[{i}]"),
                "must be a finite number",
            )),
            None => Ok(()),
        }
    }
}

impl<'de, const N: usize> Deserialize<'de> for Fixed<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Elements<const N: usize>;
        impl<'de, const N: usize> Visitor<'de> for Elements<N> {
            type Value = Fixed<N>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                write!(f, "an array of length {N}")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Fixed<N>, A::Error> {
                let mut read: Vec<Spanned<f64>> = Vec::with_capacity(N);
                while let Some(x) = seq.next_element::<Spanned<f64>>()? {
                    read.push(x);
                }
                if read.len() != N {
                    return Err(de::Error::invalid_length(read.len(), &self));
                }
                let mut out = Fixed {
                    values: [0.0; N],
                    spans: std::array::from_fn(|_| 0..0),
                };
                for (i, x) in read.into_iter().enumerate() {
                    out.spans[i] = x.span();
                    out.values[i] = x.into_inner();
                }
                Ok(out)
            }
        }
        d.deserialize_seq(Elements::<N>)
    }
}

/// Rows of exactly three numbers (anchor points, pulley axes), each row and element with its
/// span.
type Rows = Spanned<Vec<Spanned<Fixed<3>>>>;
/// `[sections]`: a name per group of cables (numbered from 1).
type RawSections = std::collections::BTreeMap<String, Spanned<Vec<i64>>>;

/// Every element of every row finite; a bad one is named `key[row][column]` (the element the
/// operator must fix, as the safety monitor's own reader names it) at its line and column.
fn finite_rows(loc: &Locator, rows: &Rows, key: &str) -> Result<(), ConfigError> {
    for (i, row) in rows.get_ref().iter().enumerate() {
        row.get_ref().finite(loc, &format!("{key}[{i}]"))?;
    }
    Ok(())
}

/// The path (`geometry.frame_anchors_m[2][1]`) of the innermost value of `text`, other than a
/// table, whose span holds byte `at`; None if there is none (a syntax error, a header, a key).
/// serde's errors carry the span of the value they refuse but no path down to it.
fn value_path(text: &str, at: usize) -> Option<String> {
    fn within(v: &Spanned<DeValue>, path: String, at: usize) -> Option<String> {
        let span = v.span();
        match v.get_ref() {
            DeValue::Table(t) => in_table(t, &path, at),
            _ if !span.contains(&at) => None,
            DeValue::Array(xs) => Some(
                xs.iter()
                    .enumerate()
                    .find_map(|(i, x)| within(x, format!("{path}[{i}]"), at))
                    .unwrap_or(path),
            ),
            _ => Some(path),
        }
    }
    fn in_table(t: &DeTable, path: &str, at: usize) -> Option<String> {
        t.iter().find_map(|(k, v)| {
            let key = if path.is_empty() {
                k.get_ref().to_string()
            } else {
                format!("{path}.{}", k.get_ref())
            };
            within(v, key, at)
        })
    }
    let doc = DeTable::parse(text).ok()?;
    in_table(doc.get_ref(), "", at)
}

/// Reads and validates a platform TOML file.
pub fn load_platform(path: impl AsRef<Path>) -> Result<Platform, ConfigError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
        file: file.clone(),
        line: None,
        column: None,
        key: String::new(),
        message: format!("cannot read: {e}"),
    })?;
    parse_platform(&text, &file)
}

/// Parses and validates platform TOML text; `file` names it in errors.
pub fn parse_platform(text: &str, file: &str) -> Result<Platform, ConfigError> {
    let loc = Locator { text, file };
    let raw: RawPlatform = toml::from_str(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map(|s| config_diagnostics::line_col(loc.text, s.start))
            .unzip();
        ConfigError {
            file: file.to_string(),
            line,
            column,
            // The refused value's path down to the element (a string inside the third anchor
            // is `geometry.frame_anchors_m[2][1]`); none for a syntax error, a missing or an
            // unknown key.
            key: e
                .span()
                .and_then(|s| value_path(text, s.start))
                .unwrap_or_default(),
            message: e.message().trim().to_string(),
        }
    })?;
    build(raw, &loc)
}

/// The platform loader's checks over one file's text; locating an error is
/// `config_diagnostics`' job (one implementation for every loader).
struct Locator<'a> {
    text: &'a str,
    file: &'a str,
}

impl Locator<'_> {
    fn err(
        &self,
        span: Range<usize>,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> ConfigError {
        config_diagnostics::Locator::new(self.text, self.file).err(span, key, message)
    }

    fn finite<T>(&self, v: &Spanned<T>, key: &str, values: &[f64]) -> Result<(), ConfigError> {
        match values.iter().position(|x| !x.is_finite()) {
            Some(i) if values.len() > 1 => {
                Err(self.err(v.span(), format!("{key}[{i}]"), "must be a finite number"))
            }
            Some(_) => Err(self.err(v.span(), key, "must be a finite number")),
            None => Ok(()),
        }
    }

    fn positive(&self, v: &Spanned<f64>, key: &str) -> Result<f64, ConfigError> {
        let x = *v.get_ref();
        self.finite(v, key, &[x])?;
        if x <= 0.0 {
            return Err(self.err(v.span(), key, format!("must be > 0, got {x}")));
        }
        Ok(x)
    }
}

fn per_cable(
    loc: &Locator,
    v: &Spanned<PerCable>,
    key: &str,
    m: usize,
) -> Result<Vec<f64>, ConfigError> {
    let vals = match v.get_ref() {
        PerCable::All(x) => {
            loc.finite(v, key, &[*x])?;
            vec![*x; m]
        }
        PerCable::Each(xs) => {
            if xs.len() != m {
                return Err(loc.err(
                    v.span(),
                    key,
                    format!("has {} entries but there are {m} cables", xs.len()),
                ));
            }
            xs.clone()
        }
    };
    loc.finite(v, key, &vals)?;
    Ok(vals)
}

fn vec3(a: &[f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

/// Each section of the platform file checks itself (`validate`) and yields its part of the
/// platform; `build` only puts the parts together, in the order the errors are reported.
fn build(raw: RawPlatform, loc: &Locator) -> Result<Platform, ConfigError> {
    let anchors = raw.geometry.validate(loc)?;
    let m = anchors.frame.len();
    let pulleys = match &raw.pulleys {
        None => None,
        Some(p) => Some(p.validate(loc, m)?),
    };
    let k_f = per_cable(loc, &raw.elasticity.k_f_n, "elasticity.k_f_n", m)?;
    let w = raw.load.wrench_n_nm.get_ref();
    w.finite(loc, "load.wrench_n_nm")?;
    let forces = raw.forces.validate(loc)?;
    let params = ModelParams {
        a: anchors.frame,
        b: anchors.platform,
        pulleys,
        k_f,
        w_e: Vector6::from_column_slice(&w[..]),
        f_min: forces.f_min,
        f_max: forces.f_max,
    };
    let model = Model::new(params).map_err(|e| model_error(loc, &raw, e))?;
    let limits = raw.limits.validate(loc)?;
    let winch = raw.winch.validate(loc)?;
    let region = raw.workspace.validate(loc)?;
    let (home, f_ini) = raw.home.validate(loc, &region, m, forces.f_abs_max)?;
    let sections = sections(loc, &raw.sections, m)?;
    let dynamics = match &raw.dynamics {
        None => None,
        Some(d) => Some(dynamics(loc, d, model.params().w_e)?),
    };
    let name = raw.platform.name.get_ref().trim().to_string();
    if name.is_empty() {
        return Err(loc.err(
            raw.platform.name.span(),
            "platform.name",
            "must not be empty",
        ));
    }
    Ok(Platform {
        name,
        description: raw.platform.description.clone(),
        model,
        f_abs_max: forces.f_abs_max,
        limits,
        winch,
        region,
        home,
        f_ini,
        sections,
        dynamics,
    })
}

/// The anchors of `[geometry]`: a_i on the frame, b_i on the platform (eq. 2.1).
struct Anchors {
    frame: Vec<Vector3<f64>>,
    platform: Vec<Vector3<f64>>,
}

/// The force limits of `[forces]`, checked against each other.
struct ForceLimits {
    f_min: f64,
    f_max: f64,
    f_abs_max: f64,
}

impl RawGeometry {
    /// The frame and platform anchors a_i, b_i (eq. 2.1), one row per cable each.
    fn validate(&self, loc: &Locator) -> Result<Anchors, ConfigError> {
        let m = self.frame_anchors_m.get_ref().len();
        finite_rows(loc, &self.frame_anchors_m, "geometry.frame_anchors_m")?;
        finite_rows(loc, &self.platform_anchors_m, "geometry.platform_anchors_m")?;
        if self.platform_anchors_m.get_ref().len() != m {
            return Err(loc.err(
                self.platform_anchors_m.span(),
                "geometry.platform_anchors_m",
                format!(
                    "has {} rows but geometry.frame_anchors_m has {m}",
                    self.platform_anchors_m.get_ref().len()
                ),
            ));
        }
        let rows = |r: &Rows| r.get_ref().iter().map(|r| vec3(r.get_ref())).collect();
        Ok(Anchors {
            frame: rows(&self.frame_anchors_m),
            platform: rows(&self.platform_anchors_m),
        })
    }
}

impl RawPulleys {
    fn validate(&self, loc: &Locator, m: usize) -> Result<Pulleys, ConfigError> {
        let radius = per_cable(loc, &self.radius_m, "pulleys.radius_m", m)?;
        if let Some(i) = radius.iter().position(|r| *r < 0.0) {
            return Err(loc.err(
                self.radius_m.span(),
                format!("pulleys.radius_m[{i}]"),
                "must be >= 0",
            ));
        }
        let axes = self.swivel_axes.get_ref();
        if axes.len() != m {
            return Err(loc.err(
                self.swivel_axes.span(),
                "pulleys.swivel_axes",
                format!("has {} rows but there are {m} cables", axes.len()),
            ));
        }
        finite_rows(loc, &self.swivel_axes, "pulleys.swivel_axes")?;
        Ok(Pulleys {
            radius,
            axis: axes.iter().map(|r| vec3(r.get_ref())).collect(),
        })
    }
}

impl RawForces {
    fn validate(&self, loc: &Locator) -> Result<ForceLimits, ConfigError> {
        let f_min = *self.f_min_n.get_ref();
        loc.finite(&self.f_min_n, "forces.f_min_n", &[f_min])?;
        let f_max = loc.positive(&self.f_max_n, "forces.f_max_n")?;
        let f_abs_max = loc.positive(&self.f_abs_max_n, "forces.f_abs_max_n")?;
        if f_min < 0.0 || f_min >= f_max {
            return Err(loc.err(
                self.f_min_n.span(),
                "forces.f_min_n",
                format!("must satisfy 0 <= f_min_n < f_max_n ({f_min} N vs {f_max} N)"),
            ));
        }
        if f_max > f_abs_max {
            return Err(loc.err(
                self.f_max_n.span(),
                "forces.f_max_n",
                format!("must not exceed forces.f_abs_max_n ({f_max} N > {f_abs_max} N)"),
            ));
        }
        Ok(ForceLimits {
            f_min,
            f_max,
            f_abs_max,
        })
    }
}

impl RawLimits {
    /// The motion limits in SI units (degrees converted to radians here, at the edge).
    fn validate(&self, loc: &Locator) -> Result<MotionLimits, ConfigError> {
        Ok(MotionLimits {
            linear_velocity_max: loc.positive(
                &self.linear_velocity_max_m_per_s,
                "limits.linear_velocity_max_m_per_s",
            )?,
            angular_velocity_max: loc
                .positive(
                    &self.angular_velocity_max_deg_per_s,
                    "limits.angular_velocity_max_deg_per_s",
                )?
                .to_radians(),
            linear_acceleration_max: loc.positive(
                &self.linear_acceleration_max_m_per_s2,
                "limits.linear_acceleration_max_m_per_s2",
            )?,
            angular_acceleration_max: loc
                .positive(
                    &self.angular_acceleration_max_deg_per_s2,
                    "limits.angular_acceleration_max_deg_per_s2",
                )?
                .to_radians(),
        })
    }
}

impl RawWinch {
    fn validate(&self, loc: &Locator) -> Result<WinchData, ConfigError> {
        Ok(WinchData {
            drum_diameter: loc.positive(&self.drum_diameter_m, "winch.drum_diameter_m")?,
            rope_diameter: loc.positive(&self.rope_diameter_m, "winch.rope_diameter_m")?,
        })
    }
}

impl RawWorkspace {
    /// The workspace region: a position box and rotation bounds (radians inside).
    fn validate(&self, loc: &Locator) -> Result<Region, ConfigError> {
        for (v, key) in [
            (&self.position_min_m, "workspace.position_min_m"),
            (&self.position_max_m, "workspace.position_max_m"),
            (&self.rotation_min_deg, "workspace.rotation_min_deg"),
            (&self.rotation_max_deg, "workspace.rotation_max_deg"),
        ] {
            v.get_ref().finite(loc, key)?;
        }
        for k in 0..3 {
            if self.position_min_m.get_ref()[k] >= self.position_max_m.get_ref()[k] {
                return Err(loc.err(
                    self.position_max_m.span(),
                    format!("workspace.position_max_m[{k}]"),
                    "must be greater than workspace.position_min_m",
                ));
            }
            if self.rotation_min_deg.get_ref()[k] > self.rotation_max_deg.get_ref()[k] {
                return Err(loc.err(
                    self.rotation_max_deg.span(),
                    format!("workspace.rotation_max_deg[{k}]"),
                    "must be >= workspace.rotation_min_deg",
                ));
            }
        }
        Ok(Region {
            position: PositionBox {
                min: vec3(self.position_min_m.get_ref()),
                max: vec3(self.position_max_m.get_ref()),
            },
            rotation_min: vec3(self.rotation_min_deg.get_ref()).map(f64::to_radians),
            rotation_max: vec3(self.rotation_max_deg.get_ref()).map(f64::to_radians),
        })
    }
}

impl RawHome {
    /// The home pose (inside the workspace region) and the optional initial cable forces.
    fn validate(
        &self,
        loc: &Locator,
        region: &Region,
        m: usize,
        f_abs_max: f64,
    ) -> Result<(Pose, Option<Vec<f64>>), ConfigError> {
        self.position_m.get_ref().finite(loc, "home.position_m")?;
        self.rotation_deg
            .get_ref()
            .finite(loc, "home.rotation_deg")?;
        let home = Pose::new(
            vec3(self.position_m.get_ref()),
            vec3(self.rotation_deg.get_ref()).map(f64::to_radians),
        );
        if !region.contains(&home) {
            return Err(loc.err(
                self.position_m.span(),
                "home",
                "the home pose lies outside the workspace region",
            ));
        }
        let Some(v) = &self.f_ini_n else {
            return Ok((home, None));
        };
        let f = v.get_ref();
        if f.len() != m {
            return Err(loc.err(
                v.span(),
                "home.f_ini_n",
                format!("has {} entries but there are {m} cables", f.len()),
            ));
        }
        loc.finite(v, "home.f_ini_n", f)?;
        if let Some(i) = f.iter().position(|x| *x <= 0.0 || *x > f_abs_max) {
            return Err(loc.err(
                v.span(),
                format!("home.f_ini_n[{i}]"),
                format!("must lie in (0, f_abs_max_n], got {} N", f[i]),
            ));
        }
        Ok((home, Some(f.clone())))
    }
}

/// `[sections]`: named groups of cables, numbered 1..=m in the file, 0-based inside.
fn sections(loc: &Locator, raw: &RawSections, m: usize) -> Result<Vec<Section>, ConfigError> {
    let mut sections = Vec::new();
    for (name, cables) in raw {
        let mut idx = Vec::new();
        for c in cables.get_ref() {
            if *c < 1 || *c as usize > m {
                return Err(loc.err(
                    cables.span(),
                    format!("sections.{name}"),
                    format!("cable {c} does not exist (cables are numbered 1..={m})"),
                ));
            }
            let i = (*c - 1) as usize;
            if idx.contains(&i) {
                return Err(loc.err(
                    cables.span(),
                    format!("sections.{name}"),
                    format!("cable {c} listed twice"),
                ));
            }
            idx.push(i);
        }
        sections.push(Section {
            name: name.clone(),
            cables: idx,
        });
    }
    Ok(sections)
}

fn body(loc: &Locator, b: &RawBody, key: &str) -> Result<RigidBody, ConfigError> {
    let mass = loc.positive(&b.mass_kg, &format!("{key}.mass_kg"))?;
    let c = &b.center_of_gravity_m;
    c.get_ref()
        .finite(loc, &format!("{key}.center_of_gravity_m"))?;
    let i = &b.inertia_kg_m2;
    i.get_ref().finite(loc, &format!("{key}.inertia_kg_m2"))?;
    RigidBody::new(
        mass,
        vec3(c.get_ref()),
        nalgebra::Matrix3::from_diagonal(&vec3(i.get_ref())),
    )
    .map_err(|e| loc.err(i.span(), format!("{key}.inertia_kg_m2"), e.to_string()))
}

/// The platform with payload; its weight must be the static load's (w_e, eq. 5.12): the
/// dynamic and the static wrench describe the same body, so a contradiction is refused.
fn dynamics(loc: &Locator, d: &RawDynamics, w_e: Vector6<f64>) -> Result<RigidBody, ConfigError> {
    let cabin = RawBody {
        mass_kg: d.mass_kg.clone(),
        center_of_gravity_m: d.center_of_gravity_m.clone(),
        inertia_kg_m2: d.inertia_kg_m2.clone(),
    };
    let mut total = body(loc, &cabin, "dynamics")?;
    if let Some(p) = &d.payload {
        total = total.combined(&body(loc, p, "dynamics.payload")?);
    }
    let weight = total.weight_wrench(&Pose::default());
    let tol_f = 0.02 * weight[2].abs();
    if (weight[2] - w_e[2]).abs() > tol_f {
        return Err(loc.err(
            d.mass_kg.span(),
            "dynamics.mass_kg",
            format!(
                "the platform with payload weighs {:.0} N ({:.1} kg × {GRAVITY_M_PER_S2} m/s²), but load.wrench_n_nm carries {:.0} N: they must agree within 2 %",
                -weight[2], total.mass_kg, -w_e[2]
            ),
        ));
    }
    // The torque of a 1 cm error of the centre of gravity.
    let tol_t = 0.01 * weight[2].abs();
    if (weight.fixed_rows::<3>(3) - w_e.fixed_rows::<3>(3)).norm() > tol_t {
        return Err(loc.err(
            d.center_of_gravity_m.span(),
            "dynamics.center_of_gravity_m",
            format!(
                "the weight at the centre of gravity [{:.3}, {:.3}, {:.3}] m exerts a torque [{:.0}, {:.0}, {:.0}] N·m, but load.wrench_n_nm carries [{:.0}, {:.0}, {:.0}] N·m",
                total.cog_m.x, total.cog_m.y, total.cog_m.z, weight[3], weight[4], weight[5], w_e[3],
                w_e[4], w_e[5]
            ),
        ));
    }
    Ok(total)
}

/// The span of row `i` of an array of rows, else of the whole array.
fn row_span(rows: &Rows, i: usize) -> Range<usize> {
    rows.get_ref()
        .get(i)
        .map_or_else(|| rows.span(), |r| r.span())
}

fn model_error(loc: &Locator, raw: &RawPlatform, e: ModelError) -> ConfigError {
    let g = &raw.geometry;
    let (span, key) = match &e {
        ModelError::TooFewCables(_) | ModelError::TooManyCables(_) => (
            g.frame_anchors_m.span(),
            "geometry.frame_anchors_m".to_string(),
        ),
        // The later of the two coinciding rows (the one typed as a copy), at that row, as the
        // monitor's reader names it.
        ModelError::DuplicateAnchor { what: "a", j, .. } => (
            row_span(&g.frame_anchors_m, *j),
            format!("geometry.frame_anchors_m[{j}]"),
        ),
        ModelError::DuplicateAnchor { j, .. } => (
            row_span(&g.platform_anchors_m, *j),
            format!("geometry.platform_anchors_m[{j}]"),
        ),
        ModelError::NonPositiveStiffness(i) => (
            raw.elasticity.k_f_n.span(),
            format!("elasticity.k_f_n[{i}]"),
        ),
        // The row the operator must fix (`pulleys.swivel_axes[2]`, as the monitor names it).
        ModelError::ZeroPulleyAxis(i) => match raw.pulleys.as_ref().and_then(|p| {
            let row = p.swivel_axes.get_ref().get(*i)?;
            Some(row.span())
        }) {
            Some(span) => (span, format!("pulleys.swivel_axes[{i}]")),
            None => (0..0, "pulleys".into()),
        },
        ModelError::NegativePulleyRadius(i) => match &raw.pulleys {
            Some(p) => (p.radius_m.span(), format!("pulleys.radius_m[{i}]")),
            None => (0..0, "pulleys".into()),
        },
        ModelError::ForceLimits { .. } => (raw.forces.f_min_n.span(), "forces".into()),
        ModelError::LengthMismatch { what, .. } | ModelError::NotFinite { what, .. } => {
            (g.frame_anchors_m.span(), what.to_string())
        }
    };
    loc.err(span, key, e.to_string())
}
