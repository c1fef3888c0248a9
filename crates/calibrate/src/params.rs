//! The identified parameter set p = (a, b, k_F, w_e) of the elastostatic control model
//! (eq. 6.14) plus the cable offsets (eq. 3.14, 6.24) and the parameters of the candidate
//! model extensions of calibrate-diagnosis (`effects`). Every extension reduces exactly to the base model
//! when its parameters are zero (eq. 2.1).

use crate::observation::DirectionSource;
use cdpr_model::{Model, ModelError, ModelParams, Pulleys};
use nalgebra::{Vector3, Vector6};
use serde::Serialize;

/// Reference force of the tension-dependent stiffness candidate, N: the median operating force
/// at which the CRS nominal k_F was measured (eq. 6.19).
pub const STIFFNESS_REFERENCE_FORCE_N: f64 = 5000.0;

/// Smallest slope dg/df of the tension-dependent stiffness's load g(f) (see [`stiffness_load`]).
pub const STIFFNESS_MIN_SLOPE: f64 = 0.1;

/// The load of the tension-dependent stiffness candidate, g(f) = f + κ (f − f_s)²/(2 f_s), with
/// its derivatives (dg/df, dg/dκ). The parabola turns back at f_s (1 − 1/κ) (no elongation
/// decreases with the force); where its slope falls below [`STIFFNESS_MIN_SLOPE`] it is
/// continued by its tangent, so g grows with f everywhere — for κ ∈ [−0.9, 0.9] only at forces
/// beyond 10 kN (κ < 0) or below 0 (κ > 0) — and the forward kinematics never meets a
/// second root or a vanishing stiffness far from the operating forces.
#[inline]
pub fn stiffness_load(kappa: f64, f: f64) -> (f64, f64, f64) {
    let fs = STIFFNESS_REFERENCE_FORCE_N;
    let quad = |f: f64| {
        (
            f + kappa * (f - fs).powi(2) / (2.0 * fs),
            1.0 + kappa * (f - fs) / fs,
            (f - fs).powi(2) / (2.0 * fs),
        )
    };
    if kappa == 0.0 {
        return (f, 1.0, quad(f).2);
    }
    // dg/df = STIFFNESS_MIN_SLOPE at f_c.
    let fc = fs * (1.0 - (1.0 - STIFFNESS_MIN_SLOPE) / kappa);
    let beyond = if kappa > 0.0 { f < fc } else { f > fc };
    if beyond {
        let (gc, _, dk) = quad(fc);
        (gc + STIFFNESS_MIN_SLOPE * (f - fc), STIFFNESS_MIN_SLOPE, dk)
    } else {
        quad(f)
    }
}

/// Lowest physical cable stiffness k_F (N/m), see [`ParamId::bounds`].
pub const KF_MIN_N: f64 = 0.2e6;
/// Highest physical cable stiffness k_F (N/m).
pub const KF_MAX_N: f64 = 50e6;
/// Drum capacity bound on the rope stored in the powertrain (m): a CRS winch drum holds a
/// few tens of metres of rope beyond the workspace's longest cable.
pub const STORED_ROPE_MAX_M: f64 = 100.0;
/// Largest drum radius error |ε| (1).
pub const DRUM_EPS_MAX: f64 = 0.03;
/// Largest pulley radius (m).
pub const PULLEY_RADIUS_MAX_M: f64 = 0.5;
/// Largest length hysteresis half width |h| (m): a play of 2 cm in a winch is broken.
pub const HYSTERESIS_LENGTH_MAX_M: f64 = 0.02;
/// Largest drive-train series compliance (m/N): 100 m of stored rope at the nominal k_F.
pub const SERIES_COMPLIANCE_MAX_M_PER_N: f64 = 5e-5;

/// One scalar parameter of [`CalModel`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum ParamId {
    /// Frame anchor a_i, coordinate k (m).
    A(usize, usize),
    /// Platform anchor b_i^(P), coordinate k (m).
    B(usize, usize),
    /// k_F,i (N).
    KF(usize),
    /// w_e component k (N, N·m).
    We(usize),
    /// Cable offset δ_i: q_θ = s_i q_cmd + δ_i (m).
    Offset(usize),
    /// Shared pulley radius r_p (m), pulley kinematics eq. 2.16–2.29.
    PulleyRadius,
    /// Rope stored in the powertrain l_i (m): compliance (q + l_i)/k_F,i (eq. 6.18).
    ExtraLength(usize),
    /// Tension-dependent stiffness κ (1): elongation ∝ f + κ (f − f_s)²/(2 f_s).
    StiffnessKappa,
    /// Hysteresis half width H (N): elongation ∝ f − d H, d = ±1 the direction of motion.
    Hysteresis,
    /// Length hysteresis h (m, signed): the rope acts h shorter while loading and h longer
    /// while unloading (a play in the winch or a friction offset), q_θ − d h.
    HysteresisLength,
    /// Series compliance of the drive train shared by all cables c_s (m/N): elongation
    /// f ((q + l_i)/k_F,i + c_s) (eq. 6.18's c_s).
    SeriesCompliance,
    /// Sag (μ g)² (N²/m²): chord shortening (μ g cos α)² q³ / (24 f²) (Irvine).
    SagW2,
    /// Drum radius error ε_i (1): q_θ = (1 + ε_i) q_cmd + δ_i.
    DrumScale(usize),
    /// Centre of gravity c (platform frame, m): τ(x) = τ_0 + ((R − I) c) × f_e.
    Cog(usize),
    /// Force-sensor gain error γ_i (1): f = (1 + γ_i) f_M + β_i.
    ForceGain(usize),
    /// Force-sensor offset β_i (N).
    ForceOffset(usize),
    /// Flexible per-cable length correction (m), NOT a physical effect: coefficient k of
    /// δq_i = β_i0 u + β_i1 u² + β_i2 v + β_i3 v², u = f_i/f_s − 1, v = q_i/(10 m)
    /// ([`flex_basis`]).
    Flex(usize, usize),
}

/// Number of terms of the flexible per-cable length correction.
pub const FLEX_TERMS: usize = 4;

/// Length of the flexible correction's normalisation, m.
pub const FLEX_LENGTH_M: f64 = 10.0;
/// Range of a flexible coefficient, m: it corrects mm-level structure (and a larger one could
/// make the elongation decrease with the force, dφ_el/df > 0, which no cable does).
pub const FLEX_MAX_M: f64 = 0.005;

/// Basis of the flexible per-cable length correction at force f and geometric length q, and
/// its derivatives by f and q: ([u, u², v, v²], [∂/∂f], [∂/∂q]) with u = f/f_s − 1,
/// v = q/(10 m). Force-linear (a series compliance, eq. 6.18's c_s), force-quadratic,
/// length-linear and length-quadratic terms. Together with the base model's compliance, drum
/// and offset some of them are nearly collinear: the correction is fitted for accuracy, its
/// coefficients are not meant to be interpreted (their 1σ says so).
#[inline]
pub fn flex_basis(f: f64, q: f64) -> ([f64; FLEX_TERMS], [f64; FLEX_TERMS], [f64; FLEX_TERMS]) {
    let fs = STIFFNESS_REFERENCE_FORCE_N;
    let u = f / fs - 1.0;
    let v = q / FLEX_LENGTH_M;
    (
        [u, u * u, v, v * v],
        [1.0 / fs, 2.0 * u / fs, 0.0, 0.0],
        [0.0, 0.0, 1.0 / FLEX_LENGTH_M, 2.0 * v / FLEX_LENGTH_M],
    )
}

/// Σ_k c_k b_k for the flexible correction (value and both derivatives).
#[inline]
pub fn flex_eval(c: &[f64; FLEX_TERMS], f: f64, q: f64) -> (f64, f64, f64) {
    let (b, bf, bq) = flex_basis(f, q);
    let dot = |x: &[f64; FLEX_TERMS]| c.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
    (dot(&b), dot(&bf), dot(&bq))
}

impl ParamId {
    /// Scale of the preconditioning matrix W_pc (eq. 4.42): the optimiser works in p / s.
    pub fn scale(&self) -> f64 {
        match self {
            ParamId::A(..) | ParamId::B(..) => 1.0,
            ParamId::KF(_) => 1e6,
            ParamId::We(_) => 1e3,
            ParamId::Offset(_) => 0.01,
            ParamId::PulleyRadius => 0.1,
            ParamId::ExtraLength(_) => 10.0,
            ParamId::StiffnessKappa => 0.1,
            ParamId::Hysteresis => 100.0,
            ParamId::HysteresisLength => 1e-3,
            ParamId::SeriesCompliance => 1e-6,
            ParamId::SagW2 => 100.0,
            ParamId::DrumScale(_) => 1e-3,
            ParamId::Cog(_) => 0.1,
            ParamId::ForceGain(_) => 0.01,
            ParamId::ForceOffset(_) => 10.0,
            ParamId::Flex(..) => 1e-3,
        }
    }

    /// Physical range of the parameter in SI units, or `None` when it has none (geometry,
    /// offsets, the external wrench). The identification cannot leave it: a step outside is
    /// rejected like a step outside the model's valid region (see [`crate::identify`] and
    /// docs/calibration.md, "Bounded identification", for where each range comes from).
    pub fn bounds(&self) -> Option<(f64, f64)> {
        match self {
            // Steel-rope axial stiffness of a CRS-sized cable including the powertrain: the
            // nominal 2 MN/m (eq. 6.19) within a factor 10 down and 25 up: no k_F
            // outside [0.2, 50] MN/m is physical for these ropes.
            ParamId::KF(_) => Some((KF_MIN_N, KF_MAX_N)),
            // Rope stored on the drum and in the powertrain: ≥ 0, at most the drum capacity.
            ParamId::ExtraLength(_) => Some((0.0, STORED_ROPE_MAX_M)),
            // Drum radius error: a wrong drum or rope diameter, a few per cent at most.
            ParamId::DrumScale(_) => Some((-DRUM_EPS_MAX, DRUM_EPS_MAX)),
            // Pulley radius: ≥ 0 and no larger than a pulley of a robot this size.
            ParamId::PulleyRadius => Some((0.0, PULLEY_RADIUS_MAX_M)),
            // Tension-dependent stiffness: the elongation stays increasing in f over the
            // operating range (|κ| < 1 keeps dg/df = 1 + κ (f − f_s)/f_s > 0 for f < 2 f_s).
            ParamId::StiffnessKappa => Some((-0.9, 0.9)),
            // Hysteresis half width: ≥ 0 (the band has a sign by definition), a fraction of
            // the reference force.
            ParamId::Hysteresis => Some((0.0, 0.5 * STIFFNESS_REFERENCE_FORCE_N)),
            // Length hysteresis: either sign (a play lags, a friction offset may lead).
            ParamId::HysteresisLength => Some((-HYSTERESIS_LENGTH_MAX_M, HYSTERESIS_LENGTH_MAX_M)),
            // A compliance is ≥ 0; 100 m of rope at the nominal k_F at most.
            ParamId::SeriesCompliance => Some((0.0, SERIES_COMPLIANCE_MAX_M_PER_N)),
            // Sag (μ g)² ≥ 0, μ ≤ 5 kg/m (far heavier than a CRS rope).
            ParamId::SagW2 => Some((0.0, (5.0f64 * 9.81).powi(2))),
            // Centre of gravity within the platform's size.
            ParamId::Cog(_) => Some((-2.0, 2.0)),
            // Force-sensor gain error: a load cell off by more than 30 % is broken, not
            // miscalibrated.
            ParamId::ForceGain(_) => Some((-0.3, 0.3)),
            ParamId::Flex(..) => Some((-FLEX_MAX_M, FLEX_MAX_M)),
            ParamId::A(..)
            | ParamId::B(..)
            | ParamId::We(_)
            | ParamId::Offset(_)
            | ParamId::ForceOffset(_) => None,
        }
    }

    /// Human-readable name with 1-based cable numbers, e.g. `a_3.y`.
    pub fn name(&self) -> String {
        const XYZ: [&str; 3] = ["x", "y", "z"];
        const W: [&str; 6] = ["f_x", "f_y", "f_z", "tau_x", "tau_y", "tau_z"];
        match *self {
            ParamId::A(i, k) => format!("a_{}.{}", i + 1, XYZ[k]),
            ParamId::B(i, k) => format!("b_{}.{}", i + 1, XYZ[k]),
            ParamId::KF(i) => format!("k_F{}", i + 1),
            ParamId::We(k) => format!("w_e.{}", W[k]),
            ParamId::Offset(i) => format!("q_off_{}", i + 1),
            ParamId::PulleyRadius => "r_p".into(),
            ParamId::ExtraLength(i) => format!("l_extra_{}", i + 1),
            ParamId::StiffnessKappa => "kappa".into(),
            ParamId::Hysteresis => "H_hyst".into(),
            ParamId::HysteresisLength => "h_hyst".into(),
            ParamId::SeriesCompliance => "c_s".into(),
            ParamId::SagW2 => "sag_w2".into(),
            ParamId::DrumScale(i) => format!("drum_eps_{}", i + 1),
            ParamId::Cog(k) => format!("cog.{}", XYZ[k]),
            ParamId::ForceGain(i) => format!("force_gain_{}", i + 1),
            ParamId::ForceOffset(i) => format!("force_offset_{}", i + 1),
            ParamId::Flex(i, k) => format!("flex_{}.{}", i + 1, ["u", "u2", "v", "v2"][k]),
        }
    }

    /// True for parameters of the base model (a, b, k_F, w_e, offsets).
    pub fn is_base(&self) -> bool {
        matches!(
            self,
            ParamId::A(..) | ParamId::B(..) | ParamId::KF(_) | ParamId::We(_) | ParamId::Offset(_)
        )
    }
}

/// The full parameter state of a (possibly extended) control model.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CalModel {
    pub a: Vec<Vector3<f64>>,
    pub b: Vec<Vector3<f64>>,
    pub k_f: Vec<f64>,
    pub w_e: Vector6<f64>,
    pub f_min: f64,
    pub f_max: f64,
    /// δ_i, m.
    pub offset: Vec<f64>,
    /// Pulley kinematics switched on (radius `pulley_radius`, axes `pulley_axis`).
    pub pulleys: bool,
    pub pulley_radius: f64,
    pub pulley_axis: Vec<Vector3<f64>>,
    pub extra_length: Vec<f64>,
    pub stiffness_kappa: f64,
    pub hysteresis: f64,
    /// Length hysteresis h (m), [`ParamId::HysteresisLength`].
    pub hysteresis_length: f64,
    /// Where both hysteresis terms take the direction of motion from.
    pub hysteresis_source: DirectionSource,
    /// Drive-train series compliance c_s (m/N), [`ParamId::SeriesCompliance`].
    pub series_compliance: f64,
    pub sag_w2: f64,
    pub drum_scale: Vec<f64>,
    pub cog: Vector3<f64>,
    /// Force-sensor gain errors γ_i and offsets β_i (N): f = (1 + γ_i) f_M + β_i.
    pub force_gain: Vec<f64>,
    pub force_offset: Vec<f64>,
    /// Flexible per-cable length correction β_ik (m), [`ParamId::Flex`]; zero = off.
    pub flex: Vec<[f64; FLEX_TERMS]>,
}

impl CalModel {
    /// The base model of a motion-core model: extensions at zero, offsets zero. A model with
    /// pulleys keeps them (the pulley candidate is then already part of the base).
    pub fn from_model(model: &Model) -> Self {
        let p = model.params();
        let m = model.m();
        let (pulleys, radius, axis) = match &p.pulleys {
            Some(pl) => (
                true,
                pl.radius.iter().sum::<f64>() / m as f64,
                pl.axis.clone(),
            ),
            None => (false, 0.0, vec![Vector3::z(); m]),
        };
        Self {
            a: p.a.clone(),
            b: p.b.clone(),
            k_f: p.k_f.clone(),
            w_e: p.w_e,
            f_min: p.f_min,
            f_max: p.f_max,
            offset: vec![0.0; m],
            pulleys,
            pulley_radius: radius,
            pulley_axis: axis,
            extra_length: vec![0.0; m],
            stiffness_kappa: 0.0,
            hysteresis: 0.0,
            hysteresis_length: 0.0,
            hysteresis_source: DirectionSource::Force,
            series_compliance: 0.0,
            sag_w2: 0.0,
            drum_scale: vec![0.0; m],
            cog: Vector3::zeros(),
            force_gain: vec![0.0; m],
            force_offset: vec![0.0; m],
            flex: vec![[0.0; FLEX_TERMS]; m],
        }
    }

    pub fn m(&self) -> usize {
        self.a.len()
    }

    /// The motion-core model of the geometry (a, b, pulleys), k_F and w_e.
    pub fn model(&self) -> Result<Model, ModelError> {
        Model::new(ModelParams {
            a: self.a.clone(),
            b: self.b.clone(),
            pulleys: self.pulleys.then(|| Pulleys {
                radius: vec![self.pulley_radius; self.m()],
                axis: self.pulley_axis.clone(),
            }),
            k_f: self.k_f.clone(),
            w_e: self.w_e,
            f_min: self.f_min,
            f_max: self.f_max,
        })
    }

    pub fn get(&self, id: ParamId) -> f64 {
        match id {
            ParamId::A(i, k) => self.a[i][k],
            ParamId::B(i, k) => self.b[i][k],
            ParamId::KF(i) => self.k_f[i],
            ParamId::We(k) => self.w_e[k],
            ParamId::Offset(i) => self.offset[i],
            ParamId::PulleyRadius => self.pulley_radius,
            ParamId::ExtraLength(i) => self.extra_length[i],
            ParamId::StiffnessKappa => self.stiffness_kappa,
            ParamId::Hysteresis => self.hysteresis,
            ParamId::HysteresisLength => self.hysteresis_length,
            ParamId::SeriesCompliance => self.series_compliance,
            ParamId::SagW2 => self.sag_w2,
            ParamId::DrumScale(i) => self.drum_scale[i],
            ParamId::Cog(k) => self.cog[k],
            ParamId::ForceGain(i) => self.force_gain[i],
            ParamId::ForceOffset(i) => self.force_offset[i],
            ParamId::Flex(i, k) => self.flex[i][k],
        }
    }

    pub fn set(&mut self, id: ParamId, v: f64) {
        match id {
            ParamId::A(i, k) => self.a[i][k] = v,
            ParamId::B(i, k) => self.b[i][k] = v,
            ParamId::KF(i) => self.k_f[i] = v,
            ParamId::We(k) => self.w_e[k] = v,
            ParamId::Offset(i) => self.offset[i] = v,
            ParamId::PulleyRadius => self.pulley_radius = v,
            ParamId::ExtraLength(i) => self.extra_length[i] = v,
            ParamId::StiffnessKappa => self.stiffness_kappa = v,
            ParamId::Hysteresis => self.hysteresis = v,
            ParamId::HysteresisLength => self.hysteresis_length = v,
            ParamId::SeriesCompliance => self.series_compliance = v,
            ParamId::SagW2 => self.sag_w2 = v,
            ParamId::DrumScale(i) => self.drum_scale[i] = v,
            ParamId::Cog(k) => self.cog[k] = v,
            ParamId::ForceGain(i) => self.force_gain[i] = v,
            ParamId::ForceOffset(i) => self.force_offset[i] = v,
            ParamId::Flex(i, k) => self.flex[i][k] = v,
        }
    }

    /// The flexible correction of cable i at force f, geometric length q (m), and its
    /// derivatives by f and q.
    #[inline]
    pub fn flex_term(&self, i: usize, f: f64, q: f64) -> (f64, f64, f64) {
        flex_eval(&self.flex[i], f, q)
    }

    /// Physical controlled length from the command: q_θ = (1 + ε_i) q_cmd + δ_i.
    #[inline]
    pub fn q_theta(&self, i: usize, q_cmd: f64) -> f64 {
        (1.0 + self.drum_scale[i]) * q_cmd + self.offset[i]
    }

    /// q_θ of sample `o`'s cable i with the length hysteresis: q_θ − d h, d = +1 loading.
    #[inline]
    pub fn q_theta_of(&self, i: usize, o: &crate::observation::Observation) -> f64 {
        self.q_theta(i, o.q_cmd[i]) - self.hysteresis_length * o.loading(self.hysteresis_source, i)
    }

    /// Compliance of cable i's rope and drive train at free length q: (q + l_i)/k_F,i + c_s.
    #[inline]
    pub fn compliance(&self, i: usize, q: f64) -> f64 {
        (q + self.extra_length[i]) / self.k_f[i] + self.series_compliance
    }

    /// Cable force from a force-sensor reading: f = (1 + γ_i) f_M + β_i.
    #[inline]
    pub fn force_from_reading(&self, i: usize, f_m: f64) -> f64 {
        (1.0 + self.force_gain[i]) * f_m + self.force_offset[i]
    }

    /// Force-sensor reading of a cable force (inverse of [`CalModel::force_from_reading`]).
    #[inline]
    pub fn reading_from_force(&self, i: usize, f: f64) -> f64 {
        (f - self.force_offset[i]) / (1.0 + self.force_gain[i])
    }

    /// External wrench at a pose: w_e + [0; ((R − I) c) × f_e] (load/COG candidate).
    pub fn wrench_at(&self, rot: &nalgebra::Matrix3<f64>) -> Vector6<f64> {
        let mut w = self.w_e;
        if self.cog != Vector3::zeros() {
            let fe = Vector3::new(w[0], w[1], w[2]);
            let t = ((rot - nalgebra::Matrix3::identity()) * self.cog).cross(&fe);
            w[3] += t.x;
            w[4] += t.y;
            w[5] += t.z;
        }
        w
    }
}

/// Parameter groups for selection lists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    A,
    B,
    KF,
    We,
    Offset,
}

/// The ids of a group for m cables.
pub fn group(g: Group, m: usize) -> Vec<ParamId> {
    match g {
        Group::A => (0..m)
            .flat_map(|i| (0..3).map(move |k| ParamId::A(i, k)))
            .collect(),
        Group::B => (0..m)
            .flat_map(|i| (0..3).map(move |k| ParamId::B(i, k)))
            .collect(),
        Group::KF => (0..m).map(ParamId::KF).collect(),
        Group::We => (0..6).map(ParamId::We).collect(),
        Group::Offset => (0..m).map(ParamId::Offset).collect(),
    }
}
