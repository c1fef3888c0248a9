//! Plant TOML (`config/plant/*.toml`): the nominal platform it is built on plus one named,
//! parameterised block per physical effect. A block is off unless it is present with
//! `enabled = true`. Units are SI and named in every key; angles an operator types are in
//! degrees (`_deg`) and converted here. Unknown keys are rejected; every error names the file,
//! the key and the line (motion-core's [`ConfigError`]).

use cdpr_model::Pose;
use cdpr_model::config::{ConfigError, Platform, load_platform};
use nalgebra::{Vector3, Vector6};
use serde::Deserialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Effect 1: physical anchor points differ from the nominal ones (assembly errors, ch. 3.2).
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryDeviation {
    /// Δa_i added to the nominal frame anchors a_i, world frame, m.
    pub frame_anchor_offsets: Vec<Vector3<f64>>,
    /// Δb_i added to the nominal platform anchors b_i^(P), platform frame, m.
    pub platform_anchor_offsets: Vec<Vector3<f64>>,
}

/// Effect 2: pulley kinematics of the physical robot (eq. 2.16–2.29).
#[derive(Clone, Debug, PartialEq)]
pub struct PulleyEffect {
    /// Pulley radius r_p per cable, m.
    pub radius: Vec<f64>,
    /// Swivel axis u_Az per cable (world frame, any length > 0).
    pub axis: Vec<Vector3<f64>>,
}

/// Effect 3: powertrain compliance. The cable is longer than the free length q by the rope
/// stored in the drive train (l_extra, 12–25 m on the CRS, sec. 5.1), and further compliances
/// (frame, pulleys, winch) are in series (eq. 6.18): c_i = (q_i + l_extra,i)/k_F,i + c_s,i.
#[derive(Clone, Debug, PartialEq)]
pub struct Powertrain {
    /// Specific stiffness EA of the rope, N (replaces the platform's k_F for the plant).
    pub k_f: Vec<f64>,
    /// Rope length inside the drive train, m.
    pub extra_length: Vec<f64>,
    /// Series compliance of the rest of the powertrain, m/N (eq. 6.18).
    pub series_compliance: Vec<f64>,
}

/// Effect 4a: tension-dependent stiffness k(f) = k_lin ((f + f_0)/(f_ref + f_0))^n, equal to
/// the linear stiffness 1/c_i at the reference force (the CRS nominal k_F was picked at the
/// median force of 5000 N, eq. 6.19). n = 0 is the linear law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TensionStiffness {
    /// Exponent n, 0 ≤ n < 1.
    pub exponent: f64,
    /// Force offset f_0 > 0, N (stiffness at zero force is k_lin (f_0/(f_ref+f_0))^n).
    pub force_offset: f64,
    /// Reference force f_ref > 0 where k(f) equals the linear stiffness, N.
    pub reference_force: f64,
}

/// Effect 4b: hysteresis, separate loading and unloading paths (Fig. 5.7): a Prandtl stop
/// operator (an elastic–perfectly-plastic Jenkins element) in parallel with the elastic
/// backbone. On loading the force lies up to `half_width` above the backbone, on unloading up
/// to `half_width` below it; the operator's state persists between plant steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hysteresis {
    /// Half width of the hysteresis band, N (the loop is 2 × this wide).
    pub half_width: f64,
    /// Stiffness of the stop operator relative to the cable's linear stiffness (> 0).
    pub stiffness_ratio: f64,
}

/// Effect 5: cable sag of heavy cables (parabolic elastic catenary, Irvine 1981, whose tangent
/// compliance is Ernst's equivalent modulus, Ernst 1965).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sag {
    /// Rope mass per length μ, kg/m (14 mm steel wire rope ≈ 0.8 kg/m).
    pub mass_per_length: f64,
    /// Gravitational acceleration g, m/s².
    pub gravity: f64,
}

/// Effect 6: winch/drum errors. The physical controlled length is
/// q_θ,i = s_i q_cmd,i + o_i: s_i = effective/nominal drum radius, o_i = encoder (homing) offset.
#[derive(Clone, Debug, PartialEq)]
pub struct WinchErrors {
    pub length_scale: Vec<f64>,
    /// Encoder offsets o_i, m.
    pub encoder_offset: Vec<f64>,
}

/// Effect 7: the physical platform load. Gravity of `mass` acts at the centre of gravity
/// (platform frame), so the torque turns with the platform; `extra_wrench` is a constant
/// world-frame wrench on top. Replaces the platform's nominal wrench (eq. 6.20–6.23).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Load {
    /// Platform mass, kg.
    pub mass: f64,
    /// Centre of gravity in the platform frame, m.
    pub center_of_gravity: Vector3<f64>,
    /// Extra constant wrench [f; τ] in the world frame, N and N·m.
    pub extra_wrench: Vector6<f64>,
    /// g, m/s².
    pub gravity: f64,
}

/// Effect 8a: pose tracker (e.g. Vicon) noise, zero-mean Gaussian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tracker {
    /// Standard deviation per position coordinate, m.
    pub position_noise: f64,
    /// Standard deviation per rotation angle, rad.
    pub rotation_noise: f64,
}

/// Effect 8b: force sensors, reading = gain_i f_i + offset_i + N(0, σ²).
#[derive(Clone, Debug, PartialEq)]
pub struct ForceSensors {
    /// σ, N.
    pub noise: f64,
    /// Offsets, N.
    pub offset: Vec<f64>,
    pub gain: Vec<f64>,
}

/// The switchable effects; `None` = off.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Effects {
    pub geometry: Option<GeometryDeviation>,
    pub pulleys: Option<PulleyEffect>,
    pub powertrain: Option<Powertrain>,
    pub stiffness: Option<TensionStiffness>,
    pub hysteresis: Option<Hysteresis>,
    pub sag: Option<Sag>,
    pub winch: Option<WinchErrors>,
    pub load: Option<Load>,
    pub tracker: Option<Tracker>,
    pub force_sensors: Option<ForceSensors>,
}

impl Effects {
    /// Names of the effects that are on (for logs; never written into data sets).
    pub fn enabled_names(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        let mut add = |on: bool, n| {
            if on {
                v.push(n)
            }
        };
        add(self.geometry.is_some(), "geometry_deviation");
        add(self.pulleys.is_some(), "pulleys");
        add(self.powertrain.is_some(), "powertrain");
        add(self.stiffness.is_some(), "stiffness");
        add(self.hysteresis.is_some(), "hysteresis");
        add(self.sag.is_some(), "sag");
        add(self.winch.is_some(), "winch_errors");
        add(self.load.is_some(), "load");
        add(self.tracker.is_some(), "tracker");
        add(self.force_sensors.is_some(), "force_sensors");
        v
    }
}

/// A parsed plant description.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantConfig {
    pub name: String,
    /// Path of the nominal platform TOML it was built on.
    pub platform_path: PathBuf,
    /// The nominal platform (geometry, k_F, wrench, force limits, home, f_ini).
    pub platform: Platform,
    /// Seed of the sensor-noise RNG.
    pub seed: u64,
    pub effects: Effects,
}

impl PlantConfig {
    /// The ideal plant of a platform: all effects off (the control model's own physics).
    pub fn ideal(platform: Platform, platform_path: PathBuf) -> Self {
        Self {
            name: format!("{}-ideal", platform.name),
            platform_path,
            platform,
            seed: 0,
            effects: Effects::default(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Raw TOML

#[derive(Deserialize)]
#[serde(untagged)]
pub(crate) enum PerCable {
    All(f64),
    Each(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    plant: RawMeta,
    geometry_deviation: Option<RawGeometry>,
    pulleys: Option<RawPulleys>,
    powertrain: Option<RawPowertrain>,
    stiffness: Option<RawStiffness>,
    hysteresis: Option<RawHysteresis>,
    sag: Option<RawSag>,
    winch_errors: Option<RawWinch>,
    load: Option<RawLoad>,
    tracker: Option<RawTracker>,
    force_sensors: Option<RawForceSensors>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMeta {
    name: Spanned<String>,
    #[serde(default)]
    #[allow(dead_code)]
    description: String,
    platform: Spanned<String>,
    #[serde(default)]
    seed: u64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGeometry {
    enabled: bool,
    frame_anchor_offsets_m: Option<Spanned<Vec<Spanned<Vec<f64>>>>>,
    platform_anchor_offsets_m: Option<Spanned<Vec<Spanned<Vec<f64>>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPulleys {
    enabled: bool,
    radius_m: Spanned<PerCable>,
    swivel_axes: Spanned<Vec<Spanned<Vec<f64>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPowertrain {
    enabled: bool,
    cable_k_f_n: Option<Spanned<PerCable>>,
    extra_length_m: Spanned<PerCable>,
    #[serde(default)]
    series_compliance_m_per_n: Option<Spanned<PerCable>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStiffness {
    enabled: bool,
    exponent: Spanned<f64>,
    force_offset_n: Spanned<f64>,
    reference_force_n: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHysteresis {
    enabled: bool,
    half_width_n: Spanned<f64>,
    stiffness_ratio: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSag {
    enabled: bool,
    mass_per_length_kg_per_m: Spanned<f64>,
    gravity_m_per_s2: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWinch {
    enabled: bool,
    length_scale: Option<Spanned<PerCable>>,
    encoder_offset_m: Option<Spanned<PerCable>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLoad {
    enabled: bool,
    mass_kg: Spanned<f64>,
    center_of_gravity_m: Spanned<Vec<f64>>,
    extra_wrench_n_nm: Option<Spanned<Vec<f64>>>,
    gravity_m_per_s2: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTracker {
    enabled: bool,
    position_noise_m: Spanned<f64>,
    rotation_noise_deg: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawForceSensors {
    enabled: bool,
    noise_n: Spanned<f64>,
    offset_n: Option<Spanned<PerCable>>,
    gain: Option<Spanned<PerCable>>,
}

pub(crate) const STANDARD_GRAVITY: f64 = 9.81;

/// Error locator over a TOML text (1-based line/column from byte spans).
pub(crate) struct Locator<'a> {
    pub text: &'a str,
    pub file: &'a str,
}

impl Locator<'_> {
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        config_diagnostics::line_col(self.text, offset)
    }

    pub fn err(
        &self,
        span: Range<usize>,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> ConfigError {
        config_diagnostics::Locator::new(self.text, self.file).err(span, key, message)
    }

    pub fn toml_err(&self, e: toml::de::Error) -> ConfigError {
        config_diagnostics::Locator::new(self.text, self.file).toml(&e)
    }

    /// A finite scalar within [lo, hi] (bounds inclusive unless `open_lo`).
    pub fn scalar(
        &self,
        v: &Spanned<f64>,
        key: &str,
        lo: f64,
        hi: f64,
        open_lo: bool,
    ) -> Result<f64, ConfigError> {
        let x = *v.get_ref();
        let ok = x.is_finite() && (if open_lo { x > lo } else { x >= lo }) && x <= hi;
        if !ok {
            let lo_s = if open_lo { ">" } else { ">=" };
            return Err(self.err(
                v.span(),
                key,
                format!("must be finite, {lo_s} {lo} and <= {hi}, got {x}"),
            ));
        }
        Ok(x)
    }

    pub fn per_cable(
        &self,
        v: &Spanned<PerCable>,
        key: &str,
        m: usize,
        lo: f64,
        open_lo: bool,
    ) -> Result<Vec<f64>, ConfigError> {
        let vals = match v.get_ref() {
            PerCable::All(x) => vec![*x; m],
            PerCable::Each(xs) => {
                if xs.len() != m {
                    return Err(self.err(
                        v.span(),
                        key,
                        format!("has {} entries but there are {m} cables", xs.len()),
                    ));
                }
                xs.clone()
            }
        };
        for (i, x) in vals.iter().enumerate() {
            let ok = x.is_finite() && if open_lo { *x > lo } else { *x >= lo };
            if !ok {
                let lo_s = if open_lo { ">" } else { ">=" };
                return Err(self.err(
                    v.span(),
                    format!("{key}[{i}]"),
                    format!("must be finite and {lo_s} {lo}, got {x}"),
                ));
            }
        }
        Ok(vals)
    }

    /// One row per cable, each exactly three finite numbers; a bad row is named `key[i]` at
    /// its own line and column. (Not serde's `[f64; 3]`: under `toml` it reads the first three
    /// elements and ignores the rest, so a row typed with a fourth coordinate loaded silently.)
    pub fn vec3s(
        &self,
        v: &Spanned<Vec<Spanned<Vec<f64>>>>,
        key: &str,
        m: usize,
    ) -> Result<Vec<Vector3<f64>>, ConfigError> {
        let xs = v.get_ref();
        if xs.len() != m {
            return Err(self.err(
                v.span(),
                key,
                format!("has {} entries but there are {m} cables", xs.len()),
            ));
        }
        xs.iter()
            .enumerate()
            .map(|(i, row)| self.fixed::<3>(row, &format!("{key}[{i}]")))
            .map(|r| r.map(|p| Vector3::new(p[0], p[1], p[2])))
            .collect()
    }

    /// Exactly `N` finite numbers, or an error naming `key` at the array.
    pub fn fixed<const N: usize>(
        &self,
        v: &Spanned<Vec<f64>>,
        key: &str,
    ) -> Result<[f64; N], ConfigError> {
        let xs = v.get_ref();
        let arr: [f64; N] = xs.as_slice().try_into().map_err(|_| {
            self.err(
                v.span(),
                key,
                format!("has {} values, expected {N}", xs.len()),
            )
        })?;
        if !arr.iter().all(|c| c.is_finite()) {
            return Err(self.err(v.span(), key, "must be finite"));
        }
        Ok(arr)
    }
}

/// Reads and validates a plant TOML. The `plant.platform` path is relative to the file.
pub fn load_plant(path: impl AsRef<Path>) -> Result<PlantConfig, ConfigError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
        file: file.clone(),
        line: None,
        column: None,
        key: String::new(),
        message: format!("cannot read: {e}"),
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse_plant(&text, &file, base)
}

/// Parses plant TOML text; `file` names it in errors, `base_dir` resolves `plant.platform`.
pub fn parse_plant(text: &str, file: &str, base_dir: &Path) -> Result<PlantConfig, ConfigError> {
    let loc = Locator { text, file };
    let raw: RawPlant = toml::from_str(text).map_err(|e| loc.toml_err(e))?;
    let platform_path = base_dir.join(raw.plant.platform.get_ref());
    let platform = load_platform(&platform_path).map_err(|e| {
        let (line, column) = loc.line_col(raw.plant.platform.span().start);
        ConfigError {
            file: file.to_string(),
            line: Some(line),
            column: Some(column),
            key: "plant.platform".into(),
            message: format!("cannot load platform: {e}"),
        }
    })?;
    if raw.plant.name.get_ref().trim().is_empty() {
        return Err(loc.err(raw.plant.name.span(), "plant.name", "must not be empty"));
    }
    let m = platform.model.m();
    let k_f = &platform.model.params().k_f;
    let fx = Effects {
        geometry: raw
            .geometry_deviation
            .filter(|g| g.enabled)
            .map(|g| geometry(&loc, &g, m))
            .transpose()?,
        pulleys: raw
            .pulleys
            .filter(|p| p.enabled)
            .map(|p| pulleys(&loc, &p, m))
            .transpose()?,
        powertrain: raw
            .powertrain
            .filter(|p| p.enabled)
            .map(|p| powertrain(&loc, &p, m, k_f))
            .transpose()?,
        stiffness: raw
            .stiffness
            .filter(|s| s.enabled)
            .map(|s| stiffness(&loc, &s))
            .transpose()?,
        hysteresis: raw
            .hysteresis
            .filter(|h| h.enabled)
            .map(|h| hysteresis(&loc, &h))
            .transpose()?,
        sag: raw
            .sag
            .filter(|s| s.enabled)
            .map(|s| sag(&loc, &s))
            .transpose()?,
        winch: raw
            .winch_errors
            .filter(|w| w.enabled)
            .map(|w| winch(&loc, &w, m))
            .transpose()?,
        load: raw
            .load
            .filter(|l| l.enabled)
            .map(|l| load(&loc, &l))
            .transpose()?,
        tracker: raw
            .tracker
            .filter(|t| t.enabled)
            .map(|t| tracker(&loc, &t))
            .transpose()?,
        force_sensors: raw
            .force_sensors
            .filter(|f| f.enabled)
            .map(|f| force_sensors(&loc, &f, m))
            .transpose()?,
    };
    Ok(PlantConfig {
        name: raw.plant.name.into_inner(),
        platform_path,
        platform,
        seed: raw.plant.seed,
        effects: fx,
    })
}

// One function per effect section: its values checked against their ranges, errors naming the
// key and its line.

fn geometry(loc: &Locator, g: &RawGeometry, m: usize) -> Result<GeometryDeviation, ConfigError> {
    let zeros = vec![Vector3::zeros(); m];
    let da = match &g.frame_anchor_offsets_m {
        Some(v) => loc.vec3s(v, "geometry_deviation.frame_anchor_offsets_m", m)?,
        None => zeros.clone(),
    };
    let db = match &g.platform_anchor_offsets_m {
        Some(v) => loc.vec3s(v, "geometry_deviation.platform_anchor_offsets_m", m)?,
        None => zeros,
    };
    Ok(GeometryDeviation {
        frame_anchor_offsets: da,
        platform_anchor_offsets: db,
    })
}

fn pulleys(loc: &Locator, p: &RawPulleys, m: usize) -> Result<PulleyEffect, ConfigError> {
    let radius = loc.per_cable(&p.radius_m, "pulleys.radius_m", m, 0.0, false)?;
    let axis = loc.vec3s(&p.swivel_axes, "pulleys.swivel_axes", m)?;
    if let Some(i) = axis.iter().position(|a| a.norm() < 1e-12) {
        return Err(loc.err(
            p.swivel_axes.span(),
            format!("pulleys.swivel_axes[{i}]"),
            "must be a non-zero vector",
        ));
    }
    Ok(PulleyEffect { radius, axis })
}

fn powertrain(
    loc: &Locator,
    p: &RawPowertrain,
    m: usize,
    platform_k_f: &[f64],
) -> Result<Powertrain, ConfigError> {
    let k_f = match &p.cable_k_f_n {
        Some(v) => loc.per_cable(v, "powertrain.cable_k_f_n", m, 0.0, true)?,
        None => platform_k_f.to_vec(),
    };
    let extra_length = loc.per_cable(
        &p.extra_length_m,
        "powertrain.extra_length_m",
        m,
        0.0,
        false,
    )?;
    let series_compliance = match &p.series_compliance_m_per_n {
        Some(v) => loc.per_cable(v, "powertrain.series_compliance_m_per_n", m, 0.0, false)?,
        None => vec![0.0; m],
    };
    Ok(Powertrain {
        k_f,
        extra_length,
        series_compliance,
    })
}

fn stiffness(loc: &Locator, s: &RawStiffness) -> Result<TensionStiffness, ConfigError> {
    Ok(TensionStiffness {
        exponent: loc.scalar(&s.exponent, "stiffness.exponent", 0.0, 0.95, false)?,
        force_offset: loc.scalar(
            &s.force_offset_n,
            "stiffness.force_offset_n",
            0.0,
            1e7,
            true,
        )?,
        reference_force: loc.scalar(
            &s.reference_force_n,
            "stiffness.reference_force_n",
            0.0,
            1e7,
            true,
        )?,
    })
}

fn hysteresis(loc: &Locator, h: &RawHysteresis) -> Result<Hysteresis, ConfigError> {
    Ok(Hysteresis {
        half_width: loc.scalar(&h.half_width_n, "hysteresis.half_width_n", 0.0, 1e6, false)?,
        stiffness_ratio: loc.scalar(
            &h.stiffness_ratio,
            "hysteresis.stiffness_ratio",
            0.0,
            1e3,
            true,
        )?,
    })
}

fn sag(loc: &Locator, s: &RawSag) -> Result<Sag, ConfigError> {
    Ok(Sag {
        mass_per_length: loc.scalar(
            &s.mass_per_length_kg_per_m,
            "sag.mass_per_length_kg_per_m",
            0.0,
            1e3,
            true,
        )?,
        gravity: match &s.gravity_m_per_s2 {
            Some(g) => loc.scalar(g, "sag.gravity_m_per_s2", 0.0, 100.0, true)?,
            None => STANDARD_GRAVITY,
        },
    })
}

fn winch(loc: &Locator, w: &RawWinch, m: usize) -> Result<WinchErrors, ConfigError> {
    Ok(WinchErrors {
        length_scale: match &w.length_scale {
            Some(v) => loc.per_cable(v, "winch_errors.length_scale", m, 0.0, true)?,
            None => vec![1.0; m],
        },
        encoder_offset: match &w.encoder_offset_m {
            Some(v) => loc.per_cable(
                v,
                "winch_errors.encoder_offset_m",
                m,
                f64::NEG_INFINITY,
                true,
            )?,
            None => vec![0.0; m],
        },
    })
}

fn load(loc: &Locator, l: &RawLoad) -> Result<Load, ConfigError> {
    let c = loc.fixed::<3>(&l.center_of_gravity_m, "load.center_of_gravity_m")?;
    let w = match &l.extra_wrench_n_nm {
        Some(w) => Vector6::from_row_slice(&loc.fixed::<6>(w, "load.extra_wrench_n_nm")?),
        None => Vector6::zeros(),
    };
    Ok(Load {
        mass: loc.scalar(&l.mass_kg, "load.mass_kg", 0.0, 1e6, false)?,
        center_of_gravity: Vector3::new(c[0], c[1], c[2]),
        extra_wrench: w,
        gravity: match &l.gravity_m_per_s2 {
            Some(g) => loc.scalar(g, "load.gravity_m_per_s2", 0.0, 100.0, true)?,
            None => STANDARD_GRAVITY,
        },
    })
}

fn tracker(loc: &Locator, t: &RawTracker) -> Result<Tracker, ConfigError> {
    Ok(Tracker {
        position_noise: loc.scalar(
            &t.position_noise_m,
            "tracker.position_noise_m",
            0.0,
            1.0,
            false,
        )?,
        rotation_noise: loc
            .scalar(
                &t.rotation_noise_deg,
                "tracker.rotation_noise_deg",
                0.0,
                90.0,
                false,
            )?
            .to_radians(),
    })
}

fn force_sensors(
    loc: &Locator,
    f: &RawForceSensors,
    m: usize,
) -> Result<ForceSensors, ConfigError> {
    Ok(ForceSensors {
        noise: loc.scalar(&f.noise_n, "force_sensors.noise_n", 0.0, 1e6, false)?,
        offset: match &f.offset_n {
            Some(v) => loc.per_cable(v, "force_sensors.offset_n", m, f64::NEG_INFINITY, true)?,
            None => vec![0.0; m],
        },
        gain: match &f.gain {
            Some(v) => loc.per_cable(v, "force_sensors.gain", m, 0.0, true)?,
            None => vec![1.0; m],
        },
    })
}

/// Pose from position (m) and rotation (deg) arrays: the operator-facing edge conversion.
pub(crate) fn pose_deg(p: [f64; 3], r_deg: [f64; 3]) -> Pose {
    Pose::from_array([
        p[0],
        p[1],
        p[2],
        r_deg[0].to_radians(),
        r_deg[1].to_radians(),
        r_deg[2].to_radians(),
    ])
}
