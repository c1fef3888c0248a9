//! The plant's equilibrium as the stationary point of its potential energy (principle of
//! virtual work), solved by damped Newton on the six pose coordinates.
//!
//! For a pose x = [r; φ] (eq. 2.2) the cables store the elastic energy E_i(q_i(x)) with
//! dE_i/dq = f_i (the plant's cable law; a slack cable stores none and pulls with f = 0) and the
//! loads do the work of their forces at their points of action. The generalised force
//!
//!   g(x) = ∂U/∂x = Σ_i f_i ∂q_i/∂x − Σ_k F_k · ∂p_k/∂x − [f_c; Σ_j τ_c,j ω_j]
//!
//! vanishes at the equilibrium: ∂q_i/∂x = −u_i · ∂p_B,i/∂x (see [`super::geometry`]), p_k are the
//! points where forces F_k act (the platform's weight at its centre of gravity, eq. 6.20–6.23;
//! under sag half of each rope span's weight at its platform anchor), [f_c; τ_c] is a constant
//! world-frame wrench (the platform's nominal w_e, or the load's extra wrench) and ω_j the
//! rotation rate per unit φ_j ([`super::rotation`]). For the ideal plant (linear cables,
//! constant force) U is the closed form of [`potential`] and the equilibrium is its minimum;
//! the constant torque and the sag shares are not conservative in these coordinates, so the
//! solver works on g, which is defined for all of them.
//!
//! The Hessian ∂g/∂x is taken by forward differences of g itself (no stiffness matrices
//! K_G, K_C of eq. 2.67–2.76) and kept while the steps contract well; the step is Newton's,
//! halved until ‖g‖ decreases. The solution is
//! accepted when the Cartesian residual wrench Σ f_i [u_i; b_i × u_i] + w_e (eq. 2.30) —
//! computed from the same cable vectors — is at round-off.

use super::geometry::{Cable, Geometry, GeometryError};
use super::rotation::Orientation;
use crate::cable_law::PlantLaw;
use cdpr_model::elastostatics::CableLaw;
use glam::DVec3;
use nalgebra::{Matrix6, Vector6};

/// Iterations allowed per solve (Newton and chord steps; 3–8 are typical).
const MAX_ITERATIONS: usize = 100;
/// Converged when max |g| ≤ this × force scale (Σ f + largest load + 1 N).
const GRADIENT_TOLERANCE: f64 = 1e-14;
/// Converged when an accepted Newton step is below this (m, rad): the pose is at round-off.
const STEP_TOLERANCE: f64 = 1e-13;
/// A solution whose residual wrench exceeds this × force scale is rejected.
const ACCEPTANCE: f64 = 1e-8;
/// Forward-difference step of the Hessian (m, rad). It only sets the convergence rate, not
/// the solution (g itself is analytic).
const HESSIAN_STEP: f64 = 1e-7;
/// Step halvings before the line search gives up (then the pose is at round-off).
const MAX_HALVINGS: usize = 40;

/// The loads on the platform.
#[derive(Clone, Debug, PartialEq)]
pub struct Loads {
    /// Constant world-frame wrench [f; τ] about the platform origin, N and N·m.
    pub constant: [f64; 6],
    /// The platform's weight m g⃗ (N, world frame) acting at its centre of gravity c^(P)
    /// (platform frame, m).
    pub weight: Option<(DVec3, DVec3)>,
    /// Rope weight per length μ g (N/m) under sag: half of each free span hangs at its
    /// platform anchor.
    pub rope_weight: Option<f64>,
}

/// The oracle's model: geometry, the linear law's k_F (used when the plant law is linear) and
/// the loads.
#[derive(Clone, Debug, PartialEq)]
pub struct OracleModel {
    pub geometry: Geometry,
    /// k_F = EA per cable, N (eq. 2.33–2.34).
    pub k_f: Vec<f64>,
    pub loads: Loads,
}

/// Why there is no equilibrium.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum EquilibriumError {
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    #[error("all cables are slack: no equilibrium")]
    AllSlack,
    #[error("the Hessian of the potential is singular (iteration {iteration})")]
    Singular { iteration: usize },
    #[error("no convergence after {iterations} iterations (residual wrench {residual:.3e})")]
    NotConverged { iterations: usize, residual: f64 },
}

/// Everything the oracle knows at one pose.
#[derive(Clone, Debug)]
pub struct State {
    /// Pose [r_x, r_y, r_z, φ_x, φ_y, φ_z], m and rad.
    pub x: [f64; 6],
    pub rotation: Orientation,
    pub cables: Vec<Cable>,
    /// Cable forces, N (slack: 0).
    pub f: Vec<f64>,
    /// The external wrench at the platform origin, world frame (the loads, with sag the rope
    /// share), N and N·m.
    pub wrench: [f64; 6],
    /// Generalised external force Q_ext = Σ F_k·∂p_k/∂x + [f_c; τ_c·ω].
    pub load_force: [f64; 6],
    /// g = ∂U/∂x.
    pub gradient: [f64; 6],
    /// Σ f_i [u_i; b_i × u_i] + w_e, N and N·m.
    pub residual: [f64; 6],
}

impl State {
    pub fn new(m: usize) -> Self {
        Self {
            x: [0.0; 6],
            rotation: Orientation::at([0.0; 3]),
            cables: vec![Cable::default(); m],
            f: vec![0.0; m],
            wrench: [0.0; 6],
            load_force: [0.0; 6],
            gradient: [0.0; 6],
            residual: [0.0; 6],
        }
    }

    /// Σ f + largest load component + 1 N: the scale of the tolerances.
    fn force_scale(&self) -> f64 {
        self.f.iter().sum::<f64>() + self.wrench.iter().fold(0.0f64, |a, v| a.max(v.abs())) + 1.0
    }
}

/// Solver scratch: the state at the current pose and one for trial poses.
#[derive(Clone, Debug)]
pub struct Workspace {
    pub at: State,
    trial: State,
    /// The last Hessian that contracted well (a start for the next solve; `None` = take one).
    hessian: Option<nalgebra::LU<f64, nalgebra::U6, nalgebra::U6>>,
}

impl Workspace {
    pub fn new(m: usize) -> Self {
        Self {
            at: State::new(m),
            trial: State::new(m),
            hessian: None,
        }
    }

    /// Forgets the kept Hessian: the next solve takes a new one (the plant does this at the
    /// start of every command, so an answer depends only on its state and the command).
    pub fn forget_hessian(&mut self) {
        self.hessian = None;
    }
}

/// A converged equilibrium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    pub x: [f64; 6],
    /// Newton iterations.
    pub iterations: usize,
    /// ‖Σ f_i [u_i; b_i × u_i] + w_e‖₂ at x, N and N·m.
    pub residual_norm: f64,
}

fn push_point_force(st: &mut State, force: DVec3, p_platform: DVec3) {
    let dp = st.rotation.point_derivatives(p_platform);
    for (q, d) in st.load_force.iter_mut().zip(dp) {
        *q += force.dot(d);
    }
    let moment = (st.rotation.r * p_platform).cross(force);
    for k in 0..3 {
        st.wrench[k] += force[k];
        st.wrench[3 + k] += moment[k];
    }
}

/// Places the platform at x: orientation, every cable, the loads (wrench and generalised
/// force). Forces are set by [`tension`].
pub fn place(model: &OracleModel, x: &[f64; 6], st: &mut State) -> Result<(), GeometryError> {
    if !x.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinitePose);
    }
    st.x = *x;
    st.rotation = Orientation::at([x[3], x[4], x[5]]);
    let r = DVec3::new(x[0], x[1], x[2]);
    let g = &model.geometry;
    for i in 0..g.m() {
        let p_b = r + st.rotation.r * g.platform[i]; // eq. (2.6)
        st.cables[i] = g.cable(i, p_b)?;
    }
    let c = model.loads.constant;
    st.wrench = c;
    let tau = DVec3::new(c[3], c[4], c[5]);
    st.load_force = [
        c[0],
        c[1],
        c[2],
        tau.dot(st.rotation.omega(0)),
        tau.dot(st.rotation.omega(1)),
        tau.dot(st.rotation.omega(2)),
    ];
    if let Some((weight, cog)) = model.loads.weight {
        push_point_force(st, weight, cog);
    }
    if let Some(w) = model.loads.rope_weight {
        for i in 0..g.m() {
            let share = DVec3::new(0.0, 0.0, -0.5 * w * st.cables[i].q_free);
            push_point_force(st, share, g.platform[i]);
        }
    }
    Ok(())
}

/// Force of cable i: the linear law f = k_F (q − q_θ)/q (eq. 2.33, 2.35–2.36) written here
/// when the plant's law is linear, else the plant's own law ([`PlantLaw`], sim-plant code);
/// slack (f ≤ 0) carries nothing.
fn cable_tension(model: &OracleModel, law: &PlantLaw, i: usize, q: f64, q_theta: f64) -> f64 {
    let f = if law.is_linear() {
        model.k_f[i] * (q - q_theta) / q
    } else {
        CableLaw::force(law, i, q, q_theta).f
    };
    f.max(0.0)
}

/// Controlled length q_θ that carries force f at geometric length q: the inverse of
/// [`cable_tension`] (linear: q_θ = q (1 − f/k_F), eq. 2.37).
pub fn controlled_length(model: &OracleModel, law: &PlantLaw, i: usize, q: f64, f: f64) -> f64 {
    if law.is_linear() {
        q * (1.0 - f / model.k_f[i])
    } else {
        CableLaw::controlled_length(law, i, q, f)
    }
}

/// Chord inclinations of the placed cables into the law (sag, effect 5): cos² α = 1 − u_z².
pub fn set_chords(law: &mut PlantLaw, st: &State) {
    for (c2, c) in law.sag_cos2.iter_mut().zip(&st.cables) {
        *c2 = (1.0 - c.u.z * c.u.z).max(0.0);
    }
}

/// Forces at the placed pose for controlled lengths q_θ, the gradient g and the residual
/// wrench.
pub fn tension(model: &OracleModel, law: &mut PlantLaw, q_theta: &[f64], st: &mut State) {
    set_chords(law, st);
    st.gradient = st.load_force.map(|v| -v);
    st.residual = st.wrench;
    for (i, &q_t) in q_theta.iter().enumerate().take(st.cables.len()) {
        let c = st.cables[i];
        let f = cable_tension(model, law, i, c.q, q_t);
        st.f[i] = f;
        if f == 0.0 {
            continue;
        }
        // ∂q_i/∂x_j = −u_i · ∂p_B,i/∂x_j
        let dp = st.rotation.point_derivatives(model.geometry.platform[i]);
        for (g, d) in st.gradient.iter_mut().zip(dp) {
            *g -= f * c.u.dot(d);
        }
        let moment = (c.p_anchor - DVec3::new(st.x[0], st.x[1], st.x[2])).cross(c.u);
        for k in 0..3 {
            st.residual[k] += f * c.u[k];
            st.residual[3 + k] += f * moment[k];
        }
    }
}

fn evaluate(
    model: &OracleModel,
    law: &mut PlantLaw,
    q_theta: &[f64],
    x: &[f64; 6],
    st: &mut State,
) -> Result<(), GeometryError> {
    place(model, x, st)?;
    tension(model, law, q_theta, st);
    Ok(())
}

fn norm2(v: &[f64; 6]) -> f64 {
    v.iter().map(|a| a * a).sum()
}

fn amax(v: &[f64; 6]) -> f64 {
    v.iter().fold(0.0f64, |a, b| a.max(b.abs()))
}

/// The equilibrium for controlled lengths q_θ from the start pose `guess`. On success
/// `ws.at` holds the state at the solution and the law's chord angles are those of the
/// solution.
pub fn solve(
    model: &OracleModel,
    law: &mut PlantLaw,
    q_theta: &[f64],
    guess: &[f64; 6],
    ws: &mut Workspace,
) -> Result<Solution, EquilibriumError> {
    let mut x = *guess;
    evaluate(model, law, q_theta, &x, &mut ws.at)?;
    // `ws.at` is evaluated at x and the law's chord angles are x's.
    let mut law_at_x = true;
    let mut iterations = 0;
    // The Hessian is taken at the first iteration (or kept from the previous solve) and kept while Newton's steps contract
    // well (a chord method: g is exact, so this changes the rate, not the solution); it is
    // taken again when a step contracts ‖g‖ by less than 4 or the full step is rejected.
    let mut hessian = ws.hessian.take();
    for it in 1..=MAX_ITERATIONS {
        if ws.at.f.iter().all(|f| *f == 0.0) {
            return Err(EquilibriumError::AllSlack);
        }
        if amax(&ws.at.gradient) <= GRADIENT_TOLERANCE * ws.at.force_scale() {
            break;
        }
        iterations = it;
        let fresh = hessian.is_none();
        let lu = match hessian.take() {
            Some(lu) => lu,
            None => {
                // H_jk = ∂g_j/∂x_k by forward differences of g.
                let mut h = Matrix6::zeros();
                for k in 0..6 {
                    let mut xk = x;
                    xk[k] += HESSIAN_STEP;
                    evaluate(model, law, q_theta, &xk, &mut ws.trial)?;
                    for j in 0..6 {
                        h[(j, k)] = (ws.trial.gradient[j] - ws.at.gradient[j]) / HESSIAN_STEP;
                    }
                }
                law_at_x = false;
                h.lu()
            }
        };
        let g = Vector6::from_column_slice(&ws.at.gradient);
        let step = lu
            .solve(&(-g))
            .filter(|s| s.iter().all(|v| v.is_finite()))
            .ok_or(EquilibriumError::Singular { iteration: it })?;
        let merit = norm2(&ws.at.gradient);
        let mut alpha = 1.0;
        let mut accepted = false;
        for _ in 0..MAX_HALVINGS {
            let trial: [f64; 6] = std::array::from_fn(|j| x[j] + alpha * step[j]);
            let ok = evaluate(model, law, q_theta, &trial, &mut ws.trial).is_ok()
                && norm2(&ws.trial.gradient) < merit;
            law_at_x = false;
            if ok {
                x = trial;
                std::mem::swap(&mut ws.at, &mut ws.trial);
                law_at_x = true;
                accepted = true;
                break;
            }
            if !fresh {
                break; // an old Hessian: take a new one before shortening the step
            }
            alpha *= 0.5;
        }
        if !accepted {
            if fresh {
                break; // no decrease along Newton's direction: g is at its round-off floor
            }
            continue;
        }
        if alpha * step.amax() < STEP_TOLERANCE {
            break;
        }
        if alpha == 1.0 && norm2(&ws.at.gradient) * 16.0 <= merit {
            hessian = Some(lu);
        }
    }
    ws.hessian = hessian;
    if !law_at_x {
        evaluate(model, law, q_theta, &x, &mut ws.at)?;
    }
    if ws.at.f.iter().all(|f| *f == 0.0) {
        return Err(EquilibriumError::AllSlack);
    }
    let residual_norm = norm2(&ws.at.residual).sqrt();
    if amax(&ws.at.residual) > ACCEPTANCE * ws.at.force_scale() {
        return Err(EquilibriumError::NotConverged {
            iterations,
            residual: residual_norm,
        });
    }
    Ok(Solution {
        x,
        iterations,
        residual_norm,
    })
}

/// The forces that hold the placed pose: f_ini corrected by the least change that closes the
/// wrench, f_0 = f_ini − A (AᵀA)⁻¹ (Aᵀ f_ini + w_e) (eq. 3.19, 2.38–2.40), with the columns
/// [u_i; b_i × u_i] of Aᵀ from the oracle's cables. `None` when AᵀA is singular.
pub fn project_tension(st: &State, f_ini: &[f64]) -> Option<Vec<f64>> {
    let r = DVec3::new(st.x[0], st.x[1], st.x[2]);
    let columns: Vec<Vector6<f64>> = st
        .cables
        .iter()
        .map(|c| {
            let moment = (c.p_anchor - r).cross(c.u);
            Vector6::new(c.u.x, c.u.y, c.u.z, moment.x, moment.y, moment.z)
        })
        .collect();
    let mut gram = Matrix6::zeros();
    let mut unbalanced = Vector6::from_column_slice(&st.wrench);
    for (v, f) in columns.iter().zip(f_ini) {
        gram += v * v.transpose();
        unbalanced += v * *f;
    }
    let y = gram.cholesky()?.solve(&unbalanced);
    Some(
        columns
            .iter()
            .zip(f_ini)
            .map(|(v, f)| f - v.dot(&y))
            .collect(),
    )
}

/// The potential energy U(x) of the ideal plant (linear cables, loads without constant torque
/// or sag): U = Σ_i k_F,i (q_i − q_θ,i − q_θ,i ln(q_i/q_θ,i)) over the taut cables (the integral
/// of f = k_F (q − q_θ)/q from q_θ) − f_c·r − m g⃗·p_G. `None` when U does not exist in this form.
pub fn potential(model: &OracleModel, q_theta: &[f64], st: &State) -> Option<f64> {
    let c = model.loads.constant;
    if model.loads.rope_weight.is_some() || c[3] != 0.0 || c[4] != 0.0 || c[5] != 0.0 {
        return None;
    }
    let mut u = 0.0;
    for (i, cable) in st.cables.iter().enumerate() {
        let (q, qt) = (cable.q, q_theta[i]);
        if q > qt {
            u += model.k_f[i] * (q - qt - qt * (q / qt).ln());
        }
    }
    let r = DVec3::new(st.x[0], st.x[1], st.x[2]);
    u -= DVec3::new(c[0], c[1], c[2]).dot(r);
    if let Some((weight, cog)) = model.loads.weight {
        u -= weight.dot(r + st.rotation.r * cog);
    }
    Some(u)
}
