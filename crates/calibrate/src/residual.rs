//! Identification residuals and their analytic Jacobians.
//!
//! * Kinematic (eq. 4.8–4.10): ρ_q = φ(x_M, p) − q_θ per cable, with ∂q/∂(a_i, b_i) =
//!   u_i^T [I  −R_0P] (eq. 4.5–4.6).
//! * Elastostatic (eq. 4.38): the wrench closure ρ_w = w_ρw (A^T(x_M, p) f_M + w_e) and the
//!   elastostatic inverse kinematics ρ_q = w_ρq (φ_el(x_M, f_M, p) − q_θ), with
//!   φ_el = q (1 − f / k_F) (eq. 4.39) and its derivatives (eq. 4.40–4.41, 4.34–4.35).
//!
//! * Cartesian (eq. 4.3–4.4, optional): ρ_x = [r_ν − r_M; log(R_ν R_M^T)] with
//!   x_ν = ν(q_θ, p) the least-squares forward kinematics (eq. 2.11) of the commanded lengths,
//!   i.e. the pose error itself in metres and radians. Jacobian by the implicit function theorem
//!   at the FK optimum (Gauss–Newton, second-order residual terms dropped):
//!   ∂ξ/∂p = (A^T A)^{-1} Σ_i a_i ∂e_i/∂p with e_i = φ_i(x_ν, p) − q_θ,i and a_i the columns of
//!   A^T (eq. 2.30, 2.54), ξ the twist (δr, δθ world frame).
//!
//! All take q_θ = (1 + ε_i) q_cmd + δ_i (cable offsets δ, eq. 3.14 / 6.24; drum candidate ε)
//! and, for the candidates of calibrate-diagnosis (`effects`), the extended inverse model
//!   φ_el = q + (μg cos α)² q³ / (24 f²) − (q + l_i)/k_F,i · (g(f) − d H),
//!   g(f) = f + κ (f − f_s)² / (2 f_s),
//! with the external wrench w_e + [0; ((R − I) c) × f_e]. All extension terms vanish at zero.
//! Every column is analytic except the pulley radius (forward difference).

use crate::observation::Observation;
use crate::params::{CalModel, ParamId};
use cdpr_model::forward::{FkOptions, least_squares};
use cdpr_model::kinematics::differential;
use cdpr_model::pose::skew;
use cdpr_model::{Data, Model, kinematics};
use nalgebra::{DMatrix, Matrix3, Matrix6, RowVector3, Vector3};

/// Rotation vector (axis · angle) of a rotation matrix, the log map of SO(3); first-order equal
/// to the world-frame infinitesimal rotation δθ of the twist.
/// Computed from the skew part, v = vee((R − Rᵀ)/2) = sin θ · axis, scaled by θ / sin θ, so it
/// stays exact for the µrad-sized rotations of a converging fit (nalgebra's `scaled_axis`
/// returns zero below its epsilon). Pose errors here are far below π.
fn rotation_vector(r: &Matrix3<f64>) -> Vector3<f64> {
    let v = 0.5
        * Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
    let s = v.norm();
    let c = 0.5 * (r.trace() - 1.0);
    let theta = s.atan2(c);
    if s < 1e-12 { v } else { v * (theta / s) }
}

/// Which residual (eq. 4.8 or eq. 4.38).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Kind {
    Kinematic,
    Elastostatic,
    /// Pose residual through the forward kinematics (eq. 4.3–4.4); kinematic parameters only.
    Cartesian,
}

/// Residual weights w_ρ of eq. (4.38) (the spec uses 1 for the wrench and 1e4 for the
/// lengths, sec. 4.4): 1 mm of length error weighs as much as 10 N of wrench error.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Weights {
    pub wrench: f64,
    pub length: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Self {
            wrench: 1.0,
            length: 1e4,
        }
    }
}

/// Residual rows of one sample.
pub fn rows_per_sample(kind: Kind, m: usize, o: &Observation) -> usize {
    match kind {
        Kind::Kinematic => m,
        Kind::Cartesian => 6,
        Kind::Elastostatic => {
            if o.forces.is_some() {
                6 + m
            } else {
                m
            }
        }
    }
}

/// Why a residual cannot be evaluated at a parameter set.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ResidualError {
    #[error("invalid model: {0}")]
    Model(#[from] cdpr_model::ModelError),
    #[error("sample {sample}: {err}")]
    Kinematics {
        sample: u64,
        err: cdpr_model::kinematics::KinematicsError,
    },
    #[error("sample {sample}: forward kinematics of the commanded lengths: {err}")]
    Forward {
        sample: u64,
        err: cdpr_model::forward::FkError,
    },
}

/// Column lookup: free parameter → Jacobian column (a dense table, the hot path of the
/// Jacobian assembly).
#[derive(Clone, Debug)]
pub struct Columns {
    table: Vec<Option<usize>>,
}

const MC: usize = cdpr_model::MAX_CABLES;

fn key(p: ParamId) -> usize {
    match p {
        ParamId::A(i, k) => 3 * i + k,
        ParamId::B(i, k) => 3 * MC + 3 * i + k,
        ParamId::KF(i) => 6 * MC + i,
        ParamId::We(k) => 7 * MC + k,
        ParamId::Offset(i) => 7 * MC + 6 + i,
        ParamId::PulleyRadius => 8 * MC + 6,
        ParamId::ExtraLength(i) => 8 * MC + 7 + i,
        ParamId::StiffnessKappa => 9 * MC + 7,
        ParamId::Hysteresis => 9 * MC + 8,
        ParamId::SagW2 => 9 * MC + 9,
        ParamId::DrumScale(i) => 9 * MC + 10 + i,
        ParamId::Cog(k) => 10 * MC + 10 + k,
        ParamId::ForceGain(i) => 10 * MC + 13 + i,
        ParamId::ForceOffset(i) => 11 * MC + 13 + i,
        ParamId::Flex(i, k) => 12 * MC + 13 + crate::params::FLEX_TERMS * i + k,
        ParamId::HysteresisLength => (12 + crate::params::FLEX_TERMS) * MC + 13,
        ParamId::SeriesCompliance => (12 + crate::params::FLEX_TERMS) * MC + 14,
    }
}

impl Columns {
    pub fn new(free: &[ParamId]) -> Self {
        let mut table = vec![None; (12 + crate::params::FLEX_TERMS) * MC + 15];
        for (c, p) in free.iter().enumerate() {
            table[key(*p)] = Some(c);
        }
        Self { table }
    }
    #[inline]
    pub fn get(&self, p: ParamId) -> Option<usize> {
        self.table[key(p)]
    }
}

/// The residual of all samples for a fixed parameter state.
pub struct Evaluator<'a> {
    pub kind: Kind,
    pub obs: &'a [Observation],
    pub weights: Weights,
    pub rows: usize,
}

impl<'a> Evaluator<'a> {
    pub fn new(kind: Kind, obs: &'a [Observation], m: usize, weights: Weights) -> Self {
        let rows = obs.iter().map(|o| rows_per_sample(kind, m, o)).sum();
        Self {
            kind,
            obs,
            weights,
            rows,
        }
    }

    /// Writes the residual into `r` (length `rows`) and, if given, the Jacobian columns of the
    /// free parameters (`cols`) into `jac` (rows × n_free, zeroed by the caller).
    pub fn eval(
        &self,
        cal: &CalModel,
        r: &mut [f64],
        mut jac: Option<(&mut DMatrix<f64>, &Columns)>,
    ) -> Result<(), ResidualError> {
        let model = cal.model()?;
        let mut data = Data::new(&model);
        let m = model.m();
        let mut row = 0;
        for o in self.obs {
            kinematics::inverse(&model, &mut data, &o.pose).map_err(|err| {
                ResidualError::Kinematics {
                    sample: o.sample,
                    err,
                }
            })?;
            let n = rows_per_sample(self.kind, m, o);
            let jr = jac.as_mut().map(|(j, c)| (&mut **j, *c));
            if self.kind == Kind::Cartesian {
                self.cartesian(cal, &model, &mut data, o, &mut r[row..row + n], jr, row)?;
                row += n;
                continue;
            }
            match (self.kind, &o.forces) {
                (Kind::Elastostatic, Some(fm)) => {
                    // Force-sensor candidate: f = (1 + γ) f_M + β (identity at zero).
                    let f: Vec<f64> = (0..m).map(|i| cal.force_from_reading(i, fm[i])).collect();
                    self.elastostatic(cal, &model, &data, o, &f, &mut r[row..row + n], jr, row)
                }
                _ => self.kinematic(cal, &data, o, &mut r[row..row + n], jr, row),
            }
            row += n;
        }
        Ok(())
    }

    fn kinematic(
        &self,
        cal: &CalModel,
        data: &Data,
        o: &Observation,
        r: &mut [f64],
        jac: Option<(&mut DMatrix<f64>, &Columns)>,
        row0: usize,
    ) {
        let w = self.weights.length;
        let rot = o.pose.rotation();
        for i in 0..cal.m() {
            r[i] = w * (data.q[i] - cal.q_theta(i, o.q_cmd[i]));
        }
        if let Some((j, cols)) = jac {
            for i in 0..cal.m() {
                let (dqa, dqb) = differential::length_parameter_jacobian(data, &o.pose, i);
                let _ = rot;
                put3(j, cols, row0 + i, |k| ParamId::A(i, k), &(dqa * w));
                put3(j, cols, row0 + i, |k| ParamId::B(i, k), &(dqb * w));
                put(j, cols, row0 + i, ParamId::Offset(i), -w);
                put(j, cols, row0 + i, ParamId::DrumScale(i), -w * o.q_cmd[i]);
            }
        }
    }

    /// Eq. (4.3–4.4): the pose error of the forward kinematics ν(q_θ, p) against x_M. `data`
    /// is left with the inverse kinematics at ν(q_θ, p).
    #[allow(clippy::too_many_arguments)]
    fn cartesian(
        &self,
        cal: &CalModel,
        model: &Model,
        data: &mut Data,
        o: &Observation,
        r: &mut [f64],
        jac: Option<(&mut DMatrix<f64>, &Columns)>,
        row0: usize,
    ) -> Result<(), ResidualError> {
        let m = cal.m();
        let w = self.weights.length;
        let q_theta: Vec<f64> = (0..m).map(|i| cal.q_theta(i, o.q_cmd[i])).collect();
        let opts = FkOptions {
            max_iterations: 200,
            ..FkOptions::default()
        };
        // Start at the measured pose: the model's solution is near it (mm), and the same start
        // for every evaluation keeps the residual a smooth function of p.
        let sol = least_squares(model, data, &q_theta, &o.pose, &opts).map_err(|err| {
            ResidualError::Forward {
                sample: o.sample,
                err,
            }
        })?;
        let x = sol.pose;
        let dr = x.r - o.pose.r;
        let dth = rotation_vector(&(x.rotation() * o.pose.rotation().transpose()));
        for k in 0..3 {
            r[k] = w * dr[k];
            r[3 + k] = w * dth[k];
        }
        let Some((j, cols)) = jac else { return Ok(()) };
        // ∂ξ/∂p = (AᵀA)⁻¹ Σ_i a_i ∂e_i/∂p: one 6-vector per cable and parameter kind.
        let mut ata = Matrix6::zeros();
        for i in 0..m {
            ata += data.at[i] * data.at[i].transpose();
        }
        let Some(inv) = ata.try_inverse() else {
            return Err(ResidualError::Forward {
                sample: o.sample,
                err: cdpr_model::forward::FkError::Singular { iteration: 0 },
            });
        };
        for i in 0..m {
            let g = inv * data.at[i] * w; // ∂ρ/∂e_i
            let (dqa, dqb) = differential::length_parameter_jacobian(data, &x, i);
            for k in 0..3 {
                if let Some(c) = cols.get(ParamId::A(i, k)) {
                    for row in 0..6 {
                        j[(row0 + row, c)] += g[row] * dqa[k];
                    }
                }
                if let Some(c) = cols.get(ParamId::B(i, k)) {
                    for row in 0..6 {
                        j[(row0 + row, c)] += g[row] * dqb[k];
                    }
                }
            }
            // e_i = φ_i − (1 + ε_i) q_cmd,i − δ_i.
            for (p, de) in [
                (ParamId::Offset(i), -1.0),
                (ParamId::DrumScale(i), -o.q_cmd[i]),
            ] {
                if let Some(c) = cols.get(p) {
                    for row in 0..6 {
                        j[(row0 + row, c)] += g[row] * de;
                    }
                }
            }
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn elastostatic(
        &self,
        cal: &CalModel,
        model: &Model,
        data: &Data,
        o: &Observation,
        f: &[f64],
        r: &mut [f64],
        jac: Option<(&mut DMatrix<f64>, &Columns)>,
        row0: usize,
    ) {
        let (ww, wq) = (self.weights.wrench, self.weights.length);
        let m = cal.m();
        let rot = o.pose.rotation();
        // Wrench closure, eq. (4.38) first part.
        let w_ext = cal.wrench_at(&rot);
        let mut w = w_ext;
        for i in 0..m {
            w += data.at[i] * f[i];
        }
        for k in 0..6 {
            r[k] = ww * w[k];
        }
        // Elastostatic inverse kinematics, eq. (4.38) second part / eq. (4.39).
        let mut dphi_dq = vec![0.0; m];
        let mut dphi_df = vec![0.0; m];
        for i in 0..m {
            let q = data.q[i];
            let fi = f[i];
            let cos2 = 1.0 - data.u[i].z * data.u[i].z;
            let (g, dg, _) = crate::params::stiffness_load(cal.stiffness_kappa, fi);
            let load = g - o.loading(cal.hysteresis_source, i) * cal.hysteresis;
            let c = cal.compliance(i, q);
            let sag = cal.sag_w2 * cos2 * q.powi(3) / (24.0 * fi * fi);
            // The flexible correction (not a physical effect; zero unless fitted).
            let (flex, dflex_df, dflex_dq) = cal.flex_term(i, fi, q);
            let phi = q + sag - c * load + flex;
            r[6 + i] = wq * (phi - cal.q_theta_of(i, o));
            dphi_dq[i] = 1.0 + 3.0 * sag / q - load / cal.k_f[i] + dflex_dq;
            dphi_df[i] = -2.0 * sag / fi - c * dg + dflex_df;
        }
        let Some((j, cols)) = jac else { return };
        // Wrench rows.
        let rm_i = rot - Matrix3::identity();
        let lever = rm_i * cal.cog;
        for k in 0..6 {
            put(j, cols, row0 + k, ParamId::We(k), ww);
        }
        if cal.cog != Vector3::zeros() {
            // ∂/∂f_e of ((R − I) c) × f_e = skew((R − I) c).
            let s = skew(&lever);
            for a in 0..3 {
                for b in 0..3 {
                    put(j, cols, row0 + 3 + a, ParamId::We(b), ww * s[(a, b)]);
                }
            }
        }
        {
            // ∂/∂c of ((R − I) c) × f_e = −skew(f_e)(R − I).
            let fe = Vector3::new(cal.w_e[0], cal.w_e[1], cal.w_e[2]);
            let d = -skew(&fe) * rm_i;
            for a in 0..3 {
                for b in 0..3 {
                    put(j, cols, row0 + 3 + a, ParamId::Cog(b), ww * d[(a, b)]);
                }
            }
        }
        for i in 0..m {
            let ju = differential::unit_vector_jacobian(model, data, i);
            let du_dr: Matrix3<f64> = ju.fixed_view::<3, 3>(0, 0).into_owned();
            // u depends on p_B − a_i: ∂u/∂a = −∂u/∂r, ∂u/∂b^(P) = ∂u/∂r · R.
            let du_da = -du_dr;
            let du_db = du_dr * rot;
            let bw = data.b_world[i];
            let sb = skew(&bw);
            let dm_da = sb * du_da;
            let dm_db = sb * du_db - skew(&data.u[i]) * rot;
            for k in 0..3 {
                for a in 0..3 {
                    put(
                        j,
                        cols,
                        row0 + a,
                        ParamId::A(i, k),
                        ww * f[i] * du_da[(a, k)],
                    );
                    put(
                        j,
                        cols,
                        row0 + 3 + a,
                        ParamId::A(i, k),
                        ww * f[i] * dm_da[(a, k)],
                    );
                    put(
                        j,
                        cols,
                        row0 + a,
                        ParamId::B(i, k),
                        ww * f[i] * du_db[(a, k)],
                    );
                    put(
                        j,
                        cols,
                        row0 + 3 + a,
                        ParamId::B(i, k),
                        ww * f[i] * dm_db[(a, k)],
                    );
                }
            }
            // Length rows, eq. (4.40–4.41).
            let ri = row0 + 6 + i;
            let (dqa, dqb) = differential::length_parameter_jacobian(data, &o.pose, i);
            put3(
                j,
                cols,
                ri,
                |k| ParamId::A(i, k),
                &(dqa * (wq * dphi_dq[i])),
            );
            put3(
                j,
                cols,
                ri,
                |k| ParamId::B(i, k),
                &(dqb * (wq * dphi_dq[i])),
            );
            let q = data.q[i];
            let fi = f[i];
            let (g, _, dg_dkappa) = crate::params::stiffness_load(cal.stiffness_kappa, fi);
            let d_load = o.loading(cal.hysteresis_source, i);
            let load = g - d_load * cal.hysteresis;
            let kf = cal.k_f[i];
            let c = cal.compliance(i, q);
            let cos2 = 1.0 - data.u[i].z * data.u[i].z;
            put(
                j,
                cols,
                ri,
                ParamId::KF(i),
                wq * (q + cal.extra_length[i]) / kf * load / kf,
            );
            put(j, cols, ri, ParamId::Offset(i), -wq);
            put(j, cols, ri, ParamId::DrumScale(i), -wq * o.q_cmd[i]);
            put(j, cols, ri, ParamId::ExtraLength(i), -wq * load / kf);
            put(j, cols, ri, ParamId::SeriesCompliance, -wq * load);
            put(j, cols, ri, ParamId::HysteresisLength, wq * d_load);
            put(j, cols, ri, ParamId::StiffnessKappa, -wq * c * dg_dkappa);
            put(j, cols, ri, ParamId::Hysteresis, wq * c * d_load);
            put(
                j,
                cols,
                ri,
                ParamId::SagW2,
                wq * cos2 * q.powi(3) / (24.0 * fi * fi),
            );
            if cols.get(ParamId::Flex(i, 0)).is_some() {
                let (b, _, _) = crate::params::flex_basis(fi, q);
                for (k, bk) in b.iter().enumerate() {
                    put(j, cols, ri, ParamId::Flex(i, k), wq * bk);
                }
            }
            // Force-sensor candidate: ∂f/∂γ_i = f_M, ∂f/∂β_i = 1 (wrench and length rows).
            if cols.get(ParamId::ForceGain(i)).is_some()
                || cols.get(ParamId::ForceOffset(i)).is_some()
            {
                let f_m = o.forces.as_ref().map_or(0.0, |v| v[i]);
                for (id, df) in [(ParamId::ForceGain(i), f_m), (ParamId::ForceOffset(i), 1.0)] {
                    for a in 0..6 {
                        put(j, cols, row0 + a, id, ww * data.at[i][a] * df);
                    }
                    put(j, cols, ri, id, wq * dphi_df[i] * df);
                }
            }
        }
    }
}

#[inline]
fn put(j: &mut DMatrix<f64>, cols: &Columns, row: usize, p: ParamId, v: f64) {
    if let Some(c) = cols.get(p) {
        j[(row, c)] += v;
    }
}

#[inline]
fn put3(
    j: &mut DMatrix<f64>,
    cols: &Columns,
    row: usize,
    id: impl Fn(usize) -> ParamId,
    v: &RowVector3<f64>,
) {
    for k in 0..3 {
        put(j, cols, row, id(k), v[k]);
    }
}
