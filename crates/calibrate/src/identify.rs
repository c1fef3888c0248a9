//! Parameter identification: Levenberg–Marquardt on the residuals of [`crate::residual`] in
//! preconditioned variables z = W_pc^{-1} p (eq. 4.42), with ridge and lasso penalties
//! (eq. 4.32), the identifiability analysis of eq. (4.18–4.23) (singular values, cond(J)),
//! and parameter uncertainties from the Gauss–Newton covariance σ² (J^T J)^{-1}.

use crate::lm::{self, LmOptions, LsqProblem};
use crate::observation::Observation;
use crate::params::{CalModel, ParamId};
use crate::residual::{Columns, Evaluator, Kind, ResidualError, Weights};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// What to identify and how.
#[derive(Clone, Debug, PartialEq)]
pub struct FitSpec {
    pub kind: Kind,
    /// Free parameters (the rest stay at the start model's values).
    pub free: Vec<ParamId>,
    pub weights: Weights,
    /// Ridge penalty λ ‖z − z_start‖² on these parameters (z in preconditioned units).
    pub ridge: Vec<(ParamId, f64)>,
    /// Lasso penalty λ |z − z_start| on these parameters (iteratively reweighted).
    pub lasso: Vec<(ParamId, f64)>,
    /// A direction whose relative singular value σ_k/σ_1 is below this is unobservable; its
    /// dominant parameter is fixed (eq. 4.21–4.23).
    pub min_relative_singular_value: f64,
    /// Apply the preconditioning W_pc (eq. 4.42); without it the optimiser works in SI units.
    pub precondition: bool,
    pub lm: LmOptions,
    /// Screening fit (the diagnosis' candidates): the free parameters as given (the base fit's
    /// identifiability analysis already fixed what the data do not observe), no condition
    /// numbers or singular values (NaN / empty), 1σ from the normal matrix. Saves the two
    /// QR + SVD factorisations that dominate a fit of a few LM iterations.
    pub quick: bool,
}

impl FitSpec {
    pub fn new(kind: Kind, free: Vec<ParamId>) -> Self {
        Self {
            kind,
            free,
            weights: Weights::default(),
            ridge: Vec::new(),
            lasso: Vec::new(),
            min_relative_singular_value: 1e-8,
            precondition: true,
            lm: LmOptions::default(),
            quick: false,
        }
    }
}

/// Identification result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fit {
    pub kind: Kind,
    pub model: CalModel,
    /// Parameters that were identified.
    pub free: Vec<ParamId>,
    /// Parameters fixed because the data set does not observe them, with the reason.
    pub fixed_unobservable: Vec<(ParamId, String)>,
    /// ½‖r‖² of the data rows at the optimum.
    pub cost: f64,
    pub n_residuals: usize,
    pub iterations: usize,
    pub evaluations: usize,
    pub converged: bool,
    pub history: Vec<f64>,
    /// cond(J) of the data rows at the start, in SI units (no preconditioning, table 4.3 d).
    pub cond_start_unscaled: f64,
    /// cond(J W_pc) at the start (table 4.3 e).
    pub cond_start_scaled: f64,
    /// cond(J W_pc) at the optimum.
    pub cond_end_scaled: f64,
    /// Singular values of J W_pc at the optimum, descending (eq. 4.19–4.21).
    pub singular_values: Vec<f64>,
    /// 1σ uncertainty per free parameter (SI), from σ² (J^T J)^{-1}; NaN where the normal
    /// matrix gives none (listed in `unidentifiable`).
    pub std: Vec<f64>,
    /// Covariance of the free parameters (SI, row-major `free.len()`²), σ² (J^T J)^{-1}: the
    /// 1σ of a size made of several parameters (e.g. the drum's RMS over the cables) needs the
    /// correlations. Empty when the normal matrix is singular.
    #[serde(skip)]
    pub cov: Vec<f64>,
    /// Free parameters the data do not determine: no finite, positive 1σ (singular normal
    /// matrix or a zero column). The report names them instead of printing a number.
    pub unidentifiable: Vec<ParamId>,
    /// Free parameters that ended at (within 0.1 % of the range of) their physical bound
    /// ([`ParamId::bounds`]): the data pushed them there; their 1σ is not meaningful.
    pub at_bound: Vec<ParamId>,
    /// RMS of the wrench rows (N, N·m) and length rows (m) without weights.
    pub rms_wrench: f64,
    pub rms_length: f64,
}

impl Fit {
    /// Covariance (SI, row-major) of the parameters `ps`, each free in this fit; `None` when one
    /// is not free, rests on its bound (no 1σ) or the normal matrix was singular.
    pub fn covariance_of(&self, ps: &[ParamId]) -> Option<Vec<f64>> {
        let n = self.free.len();
        if self.cov.len() != n * n {
            return None;
        }
        let idx: Vec<usize> = ps
            .iter()
            .map(|p| {
                self.free
                    .iter()
                    .position(|q| q == p)
                    .filter(|_| !self.at_bound.contains(p))
            })
            .collect::<Option<_>>()?;
        Some(
            idx.iter()
                .flat_map(|&a| idx.iter().map(move |&b| self.cov[a * n + b]))
                .collect(),
        )
    }
}

/// Why an identification failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("no free parameters")]
    NoParameters,
    #[error("no samples")]
    NoSamples,
    #[error(transparent)]
    Eval(#[from] EvalError),
    #[error(transparent)]
    Solver(#[from] lm::LmError<EvalError>),
}

/// Why the identification's residual cannot be evaluated at a parameter vector.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A bounded parameter left its physical range (LM treats the step as uphill).
    #[error("{} = {value:.4e} outside its physical range", param.name())]
    OutOfRange { param: ParamId, value: f64 },
    /// The model or a sample cannot be evaluated there.
    #[error(transparent)]
    Residual(#[from] ResidualError),
}

struct Problem<'a> {
    ev: Evaluator<'a>,
    start: CalModel,
    free: Vec<ParamId>,
    cols: Columns,
    scale: Vec<f64>,
    z_start: DVector<f64>,
    ridge: Vec<(usize, f64)>,
    lasso: Vec<(usize, f64)>,
    lasso_w: Vec<f64>,
    buf: Vec<f64>,
    buf2: Vec<f64>,
    /// Physical range per free parameter in z units (±∞ when unbounded), widened to contain
    /// the start value so a start outside (a user's odd nominal) is never rejected.
    bounds: Vec<(f64, f64)>,
}

const LASSO_EPS: f64 = 1e-3;

impl Problem<'_> {
    fn model_at(&self, z: &DVector<f64>) -> CalModel {
        let mut c = self.start.clone();
        for (k, id) in self.free.iter().enumerate() {
            c.set(*id, z[k] * self.scale[k]);
        }
        c
    }
    fn n_data(&self) -> usize {
        self.ev.rows
    }
}

impl LsqProblem for Problem<'_> {
    type Error = EvalError;

    fn n_residuals(&self) -> usize {
        self.ev.rows + self.ridge.len() + self.lasso.len()
    }

    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), EvalError> {
        // Bounded identification: LM keeps z in the box (projected steps, [`lm`]); a point
        // outside it anyway is outside the model's valid region.
        if let Some(k) =
            (0..z.len()).find(|&k| !(z[k] >= self.bounds[k].0 && z[k] <= self.bounds[k].1))
        {
            return Err(EvalError::OutOfRange {
                param: self.free[k],
                value: z[k] * self.scale[k],
            });
        }
        let c = self.model_at(z);
        let nd = self.n_data();
        self.ev.eval(&c, &mut self.buf, None)?;
        r.rows_mut(0, nd).copy_from_slice(&self.buf);
        for (k, (col, lam)) in self.ridge.iter().enumerate() {
            r[nd + k] = lam.sqrt() * (z[*col] - self.z_start[*col]);
        }
        let off = nd + self.ridge.len();
        for (k, (col, lam)) in self.lasso.iter().enumerate() {
            r[off + k] = (lam * self.lasso_w[k]).sqrt() * (z[*col] - self.z_start[*col]);
        }
        Ok(())
    }

    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), EvalError> {
        let c = self.model_at(z);
        let nd = self.n_data();
        let mut jd = DMatrix::zeros(nd, self.free.len());
        self.ev
            .eval(&c, &mut self.buf, Some((&mut jd, &self.cols)))?;
        // The pulley radius enters through the pulley kinematics: forward difference.
        if let Some(col) = self.cols.get(ParamId::PulleyRadius) {
            let h = 1e-7;
            let mut c2 = c.clone();
            c2.pulley_radius += h;
            self.ev.eval(&c2, &mut self.buf2, None)?;
            for row in 0..nd {
                jd[(row, col)] = (self.buf2[row] - self.buf[row]) / h;
            }
        }
        for (k, s) in self.scale.iter().enumerate() {
            let mut col = jd.column_mut(k);
            col *= *s;
        }
        j.view_mut((0, 0), (nd, self.free.len())).copy_from(&jd);
        for (k, (col, lam)) in self.ridge.iter().enumerate() {
            j[(nd + k, *col)] = lam.sqrt();
        }
        let off = nd + self.ridge.len();
        for (k, (col, lam)) in self.lasso.iter().enumerate() {
            j[(off + k, *col)] = (lam * self.lasso_w[k]).sqrt();
        }
        Ok(())
    }

    fn bounds(&self, k: usize) -> (f64, f64) {
        self.bounds[k]
    }

    fn start_iteration(&mut self, z: &DVector<f64>) -> bool {
        if self.lasso.is_empty() {
            return false;
        }
        for (k, (col, _)) in self.lasso.iter().enumerate() {
            self.lasso_w[k] = 1.0 / (z[*col] - self.z_start[*col]).abs().max(LASSO_EPS);
        }
        true
    }
}

/// Data-row Jacobian (SI units) of `free` at `cal`.
pub fn jacobian(
    kind: Kind,
    cal: &CalModel,
    obs: &[Observation],
    weights: Weights,
    free: &[ParamId],
) -> Result<DMatrix<f64>, FitError> {
    let mut p = make_problem(kind, cal, obs, weights, free, &[], &[], false);
    let z = p.z_start.clone();
    let mut j = DMatrix::zeros(p.n_residuals(), free.len());
    let mut r = DVector::zeros(p.n_residuals());
    p.residual(&z, &mut r)?;
    p.jacobian(&z, &mut j)?;
    Ok(j)
}

/// Weighted data residual at `cal` (for held-out scoring).
pub fn residual(
    kind: Kind,
    cal: &CalModel,
    obs: &[Observation],
    weights: Weights,
) -> Result<Vec<f64>, FitError> {
    let ev = Evaluator::new(kind, obs, cal.m(), weights);
    let mut r = vec![0.0; ev.rows];
    ev.eval(cal, &mut r, None).map_err(EvalError::from)?;
    Ok(r)
}

#[allow(clippy::too_many_arguments)]
fn make_problem<'a>(
    kind: Kind,
    cal: &CalModel,
    obs: &'a [Observation],
    weights: Weights,
    free: &[ParamId],
    ridge: &[(ParamId, f64)],
    lasso: &[(ParamId, f64)],
    precondition: bool,
) -> Problem<'a> {
    let ev = Evaluator::new(kind, obs, cal.m(), weights);
    let scale: Vec<f64> = free
        .iter()
        .map(|p| if precondition { p.scale() } else { 1.0 })
        .collect();
    let z_start = DVector::from_iterator(
        free.len(),
        free.iter().zip(&scale).map(|(p, s)| cal.get(*p) / s),
    );
    let pos = |id: &ParamId| free.iter().position(|p| p == id);
    let ridge: Vec<(usize, f64)> = ridge
        .iter()
        .filter_map(|(id, l)| pos(id).map(|c| (c, *l)))
        .collect();
    let lasso: Vec<(usize, f64)> = lasso
        .iter()
        .filter_map(|(id, l)| pos(id).map(|c| (c, *l)))
        .collect();
    let rows = ev.rows;
    let bounds = free
        .iter()
        .zip(&scale)
        .zip(z_start.iter())
        .map(|((p, s), z0)| match p.bounds() {
            Some((lo, hi)) => ((lo / s).min(*z0), (hi / s).max(*z0)),
            None => (f64::NEG_INFINITY, f64::INFINITY),
        })
        .collect();
    Problem {
        bounds,
        ev,
        start: cal.clone(),
        free: free.to_vec(),
        cols: Columns::new(free),
        scale,
        z_start,
        lasso_w: vec![1.0 / LASSO_EPS; lasso.len()],
        ridge,
        lasso,
        buf: vec![0.0; rows],
        buf2: vec![0.0; rows],
    }
}

/// Condition number σ_1/σ_r of a matrix and its singular values (eq. 4.18, 4.23).
pub fn condition(j: &DMatrix<f64>) -> (f64, Vec<f64>) {
    let svd = tall_svd(j, false);
    let mut s: Vec<f64> = svd.singular_values.iter().copied().collect();
    s.sort_by(|a, b| b.total_cmp(a));
    let cond = match (s.first(), s.last()) {
        (Some(a), Some(b)) if *b > 0.0 => a / b,
        (Some(_), Some(_)) => f64::INFINITY,
        _ => f64::NAN,
    };
    (cond, s)
}

/// SVD of a tall matrix through its QR factor (J = Q R ⇒ same singular values and right
/// singular vectors as R): n_p × n_p instead of n_rows × n_p work for the SVD itself.
fn tall_svd(j: &DMatrix<f64>, vectors: bool) -> nalgebra::SVD<f64, nalgebra::Dyn, nalgebra::Dyn> {
    if j.nrows() > j.ncols() {
        let r = j.clone().qr().r();
        r.svd(false, vectors)
    } else {
        j.clone().svd(false, vectors)
    }
}

/// Priority for fixing an unobservable parameter: platform geometry first (ch. 6.3), then
/// extensions, then the frame.
fn fix_priority(p: &ParamId) -> f64 {
    match p {
        ParamId::B(..) => 1.0,
        ParamId::A(..) => 0.8,
        _ => 0.9,
    }
}

/// Identifies the free parameters of `spec` from `start` on `obs`.
pub fn fit(
    start: &CalModel,
    obs: &[Observation],
    spec: &FitSpec,
    on_iteration: &mut dyn FnMut(usize, f64),
) -> Result<Fit, FitError> {
    if obs.is_empty() {
        return Err(FitError::NoSamples);
    }
    let mut free = spec.free.clone();
    let regularised: Vec<ParamId> = spec
        .ridge
        .iter()
        .chain(&spec.lasso)
        .map(|(p, _)| *p)
        .collect();
    // Identifiability (eq. 4.18–4.23): fix the dominant parameter of every direction the data
    // rows do not observe (regularised parameters are held by their penalty instead).
    let mut fixed = Vec::new();
    let mut cond_unscaled = f64::NAN;
    let mut cond_scaled = f64::NAN;
    if free.is_empty() {
        return Err(FitError::NoParameters);
    }
    loop {
        // A screening fit keeps the free parameters it is given (see `FitSpec::quick`).
        if spec.quick {
            break;
        }
        if free.is_empty() {
            return Err(FitError::NoParameters);
        }
        let mut ju = jacobian(spec.kind, start, obs, spec.weights, &free)?;
        cond_unscaled = condition(&ju).0;
        for (k, p) in free.iter().enumerate() {
            let s = if spec.precondition { p.scale() } else { 1.0 };
            let mut c = ju.column_mut(k);
            c *= s;
        }
        // Regularised parameters: append their penalty rows for the observability test.
        let reg: Vec<(usize, f64)> = spec
            .ridge
            .iter()
            .chain(&spec.lasso)
            .filter_map(|(id, l)| free.iter().position(|p| p == id).map(|c| (c, *l)))
            .collect();
        let nd = ju.nrows();
        let mut js = ju.clone().resize_vertically(nd + reg.len(), 0.0);
        for (k, (c, l)) in reg.iter().enumerate() {
            js[(nd + k, *c)] = l.sqrt();
        }
        let quick = tall_svd(&js, false);
        let s = &quick.singular_values;
        let smax = s.amax();
        let (_, smin) =
            s.iter().enumerate().fold(
                (0, f64::INFINITY),
                |a, (k, v)| if *v < a.1 { (k, *v) } else { a },
            );
        cond_scaled = if reg.is_empty() {
            let mut v: Vec<f64> = s.iter().copied().collect();
            v.sort_by(|a, b| b.total_cmp(a));
            match (v.first(), v.last()) {
                (Some(a), Some(b)) if *b > 0.0 => a / b,
                _ => f64::INFINITY,
            }
        } else {
            condition(&ju).0
        };
        if smin > spec.min_relative_singular_value * smax || free.len() == 1 {
            break;
        }
        let svd = tall_svd(&js, true);
        let s = &svd.singular_values;
        let kmin = s
            .iter()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |a, (k, v)| if *v < a.1 { (k, *v) } else { a },
            )
            .0;
        let Some(vt) = svd.v_t.as_ref() else { break };
        let v = vt.row(kmin);
        let (pick, _) = free
            .iter()
            .enumerate()
            .filter(|(_, p)| !regularised.contains(p))
            .fold((usize::MAX, 0.0), |best, (k, p)| {
                let score = v[k].abs() * fix_priority(p);
                if score > best.1 + 1e-12 {
                    (k, score)
                } else {
                    best
                }
            });
        if pick == usize::MAX {
            break;
        }
        let id = free.remove(pick);
        fixed.push((
            id,
            format!(
                "unobservable: σ_min/σ_1 = {:.1e} (direction weight {:.2})",
                smin / smax,
                v[pick].abs()
            ),
        ));
    }
    let mut prob = make_problem(
        spec.kind,
        start,
        obs,
        spec.weights,
        &free,
        &spec.ridge,
        &spec.lasso,
        spec.precondition,
    );
    let z0 = prob.z_start.clone();
    let res = lm::solve(&mut prob, z0, &spec.lm, on_iteration)?;
    let model = prob.model_at(&res.z);
    let nd = prob.n_data();
    let data_r = res.residual.rows(0, nd);
    let cost = 0.5 * data_r.norm_squared();
    let mut j = DMatrix::zeros(prob.n_residuals(), free.len());
    let mut rbuf = DVector::zeros(prob.n_residuals());
    prob.residual(&res.z, &mut rbuf)?;
    prob.jacobian(&res.z, &mut j)?;
    let jd = j.rows(0, nd).into_owned();
    let (cond_end, sv) = if spec.quick {
        (f64::NAN, Vec::new())
    } else {
        condition(&jd)
    };
    // Covariance from the full (regularised) normal matrix.
    let dof = (nd as f64 - free.len() as f64).max(1.0);
    let sigma2 = 2.0 * cost / dof;
    let n = free.len();
    let (std, cov): (Vec<f64>, Vec<f64>) = match (j.transpose() * &j).try_inverse() {
        Some(inv) => (
            (0..n)
                .map(|k| (sigma2 * inv[(k, k)]).max(0.0).sqrt() * prob.scale[k])
                .collect(),
            (0..n * n)
                .map(|x| sigma2 * inv[(x / n, x % n)] * prob.scale[x / n] * prob.scale[x % n])
                .collect(),
        ),
        None => (vec![f64::NAN; n], Vec::new()),
    };
    let std: Vec<f64> = std
        .into_iter()
        .map(|v: f64| {
            if v.is_finite() && v > 0.0 {
                v
            } else {
                f64::NAN
            }
        })
        .collect();
    let unidentifiable = free
        .iter()
        .zip(&std)
        .filter(|(_, v)| v.is_nan())
        .map(|(p, _)| *p)
        .collect();
    let at_bound = free
        .iter()
        .enumerate()
        .filter(|(k, _)| {
            let (lo, hi) = prob.bounds[*k];
            let z = res.z[*k];
            lo.is_finite() && hi.is_finite() && {
                let tol = 1e-3 * (hi - lo);
                z - lo <= tol || hi - z <= tol
            }
        })
        .map(|(_, p)| *p)
        .collect();
    let (rms_wrench, rms_length) =
        split_rms(spec.kind, obs, model.m(), spec.weights, data_r.as_slice());
    Ok(Fit {
        unidentifiable,
        at_bound,
        kind: spec.kind,
        model,
        free,
        fixed_unobservable: fixed,
        cost,
        n_residuals: nd,
        iterations: res.iterations,
        evaluations: res.evaluations,
        converged: res.converged,
        history: res.history,
        cond_start_unscaled: cond_unscaled,
        cond_start_scaled: cond_scaled,
        cond_end_scaled: cond_end,
        singular_values: sv,
        std,
        cov,
        rms_wrench,
        rms_length,
    })
}

/// Unweighted RMS of the wrench rows and of the length rows of a weighted residual.
pub fn split_rms(kind: Kind, obs: &[Observation], m: usize, w: Weights, r: &[f64]) -> (f64, f64) {
    let (mut sw, mut nw, mut sl, mut nl) = (0.0, 0usize, 0.0, 0usize);
    let mut row = 0;
    for o in obs {
        let n = crate::residual::rows_per_sample(kind, m, o);
        // Cartesian rows are all pose rows (weighted like the lengths); the others end with
        // the m length rows after the wrench rows.
        let nwr = if kind == Kind::Cartesian { 0 } else { n - m };
        for k in 0..nwr {
            sw += (r[row + k] / w.wrench).powi(2);
            nw += 1;
        }
        for k in nwr..n {
            sl += (r[row + k] / w.length).powi(2);
            nl += 1;
        }
        row += n;
    }
    let rms = |s: f64, n: usize| if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
    (rms(sw, nw), rms(sl, nl))
}

/// Offsets δ_i from the measured data with the model fixed (eq. 3.14 / 6.24 with the measured
/// poses and forces instead of the single set-up pose): δ_i = mean_j(φ(_el)(x_Mj, f_Mj) − q_cmd,ij).
pub fn estimate_offsets(
    kind: Kind,
    cal: &mut CalModel,
    obs: &[Observation],
    w: Weights,
) -> Result<(), FitError> {
    let m = cal.m();
    cal.offset.iter_mut().for_each(|d| *d = 0.0);
    let unit = Weights {
        wrench: w.wrench,
        length: 1.0,
    };
    let r = residual(kind, cal, obs, unit)?;
    let mut sum = vec![0.0; m];
    let mut row = 0;
    for o in obs {
        let n = crate::residual::rows_per_sample(kind, m, o);
        for i in 0..m {
            sum[i] += r[row + n - m + i];
        }
        row += n;
    }
    for i in 0..m {
        cal.offset[i] = sum[i] / obs.len() as f64;
    }
    Ok(())
}
