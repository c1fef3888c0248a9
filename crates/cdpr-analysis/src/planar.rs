//! Planar cable robots (n = 2: a point mass in the plane; n = 3: a rigid body x, y, θ) with any
//! number m > n of cables, as in the spec's examples of chapters 3 and 4 (four cables, frame
//! anchors of eq. 3.40 / 4.24). Analysis tools, not hard-loop code: functions allocate.
//!
//! What the spatial model does for the CRS, this does in the plane, with the same equations:
//! inverse kinematics (eq. 2.3–2.8) with optional planar pulleys (sec. 2.3 / 3.8), the
//! structure matrix (eq. 2.30), the closed-form distribution (eq. 3.41) and the exact test
//! (eq. 3.29, [`cdpr_model::feasibility`]), the elastostatic forward kinematics with the linear
//! cable law k = k_F / q (eq. 2.33–2.36, 2.42), the wrench-feasible area W_WF (eq. 3.29), the
//! reachable workspace W_R of a kinematic controller on the elastic robot (eq. 3.33–3.35) and the
//! condition number of the identification Jacobian J_qa (eq. 4.23).

use cdpr_model::feasibility::{self, ExactFeasibility, FeasibilityError};
use cdpr_model::levenberg_marquardt as lm;
use nalgebra::{DMatrix, DVector, Dyn, Vector2};

/// Degrees of freedom of the planar platform.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanarDof {
    /// n = 2: a point mass (platform anchors b_i ignored).
    Point,
    /// n = 3: a rigid body with orientation θ.
    Rigid,
}

impl PlanarDof {
    pub fn n(self) -> usize {
        match self {
            Self::Point => 2,
            Self::Rigid => 3,
        }
    }
}

/// Why a planar model or computation failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanarError {
    #[error("a planar robot with {n} DOF needs more than {n} cables, got {m}")]
    TooFewCables { n: usize, m: usize },
    #[error("{what} has {got} entries but there are {m} cables")]
    LengthMismatch {
        what: &'static str,
        got: usize,
        m: usize,
    },
    #[error("w_e has {got} entries, the platform {n} DOF")]
    WrenchLength { got: usize, n: usize },
    #[error("{what} is not finite or not positive")]
    BadValue { what: &'static str },
    #[error("force limits must satisfy 0 <= f_min < f_max (got {f_min} N, {f_max} N)")]
    ForceLimits { f_min: f64, f_max: f64 },
    #[error("cable {0} has zero length at this pose")]
    ZeroLength(usize),
    #[error("the platform anchor of cable {0} is inside its pulley")]
    InsidePulley(usize),
    #[error(transparent)]
    Feasibility(#[from] FeasibilityError),
    #[error("the elastostatic forward kinematics did not converge (residual {residual:.3e} N)")]
    NotConverged { residual: f64 },
    #[error("all cables are slack")]
    AllSlack,
}

/// A planar pose: position r (m) and, for rigid platforms, orientation θ (rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarPose {
    pub r: Vector2<f64>,
    pub theta: f64,
}

impl PlanarPose {
    pub fn point(x: f64, y: f64) -> Self {
        Self {
            r: Vector2::new(x, y),
            theta: 0.0,
        }
    }
}

/// Parameters of a planar robot.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanarParams {
    pub dof: PlanarDof,
    /// Frame-side exit points a_i, m (eq. 3.40 / 4.24).
    pub a: Vec<Vector2<f64>>,
    /// Platform anchors b_i (platform frame), m; ignored for [`PlanarDof::Point`].
    pub b: Vec<Vector2<f64>>,
    /// Specific cable stiffness k_F per cable, N (k = k_F / q, eq. 2.33).
    pub k_f: Vec<f64>,
    /// External wrench (f_x, f_y[, τ]), N and N·m.
    pub w_e: DVector<f64>,
    pub f_min: f64,
    pub f_max: f64,
    /// Pulley radius r_p (m), 0 for point-like exits. The pulleys are placed so that their
    /// tangential outlet point is a_i at `pulley_reference` (sec. 3.8).
    pub pulley_radius: f64,
    pub pulley_reference: PlanarPose,
}

/// A validated planar robot (pulley centres and wrap sides derived once).
#[derive(Clone, Debug, PartialEq)]
pub struct PlanarModel {
    p: PlanarParams,
    /// Pulley centres c_i and wrap sides s_i = ±1 (empty without pulleys).
    centres: Vec<Vector2<f64>>,
    sides: Vec<f64>,
}

/// Cable state at a pose: lengths q (m), unit vectors u_i from the platform anchor towards the
/// exit (tangent) point, the exit points and the platform anchors in the world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanarCables {
    pub q: Vec<f64>,
    pub u: Vec<Vector2<f64>>,
    pub exit: Vec<Vector2<f64>>,
    pub anchor: Vec<Vector2<f64>>,
}

fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

fn rot(theta: f64, v: &Vector2<f64>) -> Vector2<f64> {
    let (s, c) = theta.sin_cos();
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

impl PlanarModel {
    pub fn new(p: PlanarParams) -> Result<Self, PlanarError> {
        let (n, m) = (p.dof.n(), p.a.len());
        if m <= n {
            return Err(PlanarError::TooFewCables { n, m });
        }
        if p.dof == PlanarDof::Rigid && p.b.len() != m {
            return Err(PlanarError::LengthMismatch {
                what: "b",
                got: p.b.len(),
                m,
            });
        }
        if p.k_f.len() != m {
            return Err(PlanarError::LengthMismatch {
                what: "k_f",
                got: p.k_f.len(),
                m,
            });
        }
        if p.w_e.len() != n {
            return Err(PlanarError::WrenchLength {
                got: p.w_e.len(),
                n,
            });
        }
        if p.k_f.iter().any(|k| !(k.is_finite() && *k > 0.0)) {
            return Err(PlanarError::BadValue { what: "k_f" });
        }
        if !(p.pulley_radius.is_finite() && p.pulley_radius >= 0.0) {
            return Err(PlanarError::BadValue {
                what: "pulley_radius",
            });
        }
        if !(p.f_min.is_finite() && p.f_max.is_finite() && 0.0 <= p.f_min && p.f_min < p.f_max) {
            return Err(PlanarError::ForceLimits {
                f_min: p.f_min,
                f_max: p.f_max,
            });
        }
        let mut model = Self {
            p,
            centres: Vec::new(),
            sides: Vec::new(),
        };
        if model.p.pulley_radius > 0.0 {
            // Place each pulley so its outlet is a_i at the reference pose (sec. 3.8): the centre
            // sits r_p off the cable line on the side of the frame's centroid (the pulley is
            // mounted on the inside of the frame post and the cable runs to it along the post),
            // and the wrap side is the one whose tangent point is a_i there. The spec does not say
            // which side; with the centre outside, the workspace grows slightly instead of
            // shrinking (docs/analysis.md).
            let rho = model.p.pulley_radius;
            let centroid = model.p.a.iter().sum::<Vector2<f64>>() / m as f64;
            let anchors = model.anchors(&model.p.pulley_reference);
            for i in 0..m {
                let a = model.p.a[i];
                let u0 = (anchors[i] - a).normalize();
                let mut nrm = Vector2::new(-u0.y, u0.x);
                if nrm.dot(&(centroid - a)) < 0.0 {
                    nrm = -nrm;
                }
                let c = a + nrm * rho;
                let side = [1.0, -1.0]
                    .into_iter()
                    .min_by(|&s1, &s2| {
                        let t1 = tangent(&c, rho, s1, &anchors[i]).map(|t| (t - a).norm());
                        let t2 = tangent(&c, rho, s2, &anchors[i]).map(|t| (t - a).norm());
                        t1.unwrap_or(f64::INFINITY)
                            .total_cmp(&t2.unwrap_or(f64::INFINITY))
                    })
                    .unwrap_or(1.0);
                model.centres.push(c);
                model.sides.push(side);
            }
        }
        Ok(model)
    }

    pub fn params(&self) -> &PlanarParams {
        &self.p
    }
    pub fn m(&self) -> usize {
        self.p.a.len()
    }
    pub fn n(&self) -> usize {
        self.p.dof.n()
    }

    /// The same robot with other force limits / stiffness / wrench / pulleys.
    pub fn with(&self, edit: impl FnOnce(&mut PlanarParams)) -> Result<Self, PlanarError> {
        let mut p = self.p.clone();
        edit(&mut p);
        Self::new(p)
    }

    fn anchors(&self, pose: &PlanarPose) -> Vec<Vector2<f64>> {
        (0..self.m())
            .map(|i| match self.p.dof {
                PlanarDof::Point => pose.r,
                PlanarDof::Rigid => pose.r + rot(pose.theta, &self.p.b[i]),
            })
            .collect()
    }

    /// Convex hull of the frame anchors (counter-clockwise), the physical frame outline.
    pub fn frame_polygon(&self) -> Vec<Vector2<f64>> {
        let c = self.p.a.iter().sum::<Vector2<f64>>() / self.m() as f64;
        let mut pts = self.p.a.clone();
        pts.sort_by(|p, q| {
            (p.y - c.y)
                .atan2(p.x - c.x)
                .total_cmp(&(q.y - c.y).atan2(q.x - c.x))
        });
        pts
    }
}

/// Tangent point on a circle (centre c, radius ρ) of the line through `b`, on wrap side `s`.
fn tangent(c: &Vector2<f64>, rho: f64, s: f64, b: &Vector2<f64>) -> Option<Vector2<f64>> {
    let d = b - c;
    let dn = d.norm();
    if dn <= rho {
        return None;
    }
    let alpha = (rho / dn).acos();
    Some(c + rot(s * alpha, &(d / dn)) * rho)
}

/// Inverse kinematics (eq. 2.3–2.8; with pulleys q = q_f + r_p β, eq. 2.17, in the plane).
pub fn inverse(model: &PlanarModel, pose: &PlanarPose) -> Result<PlanarCables, PlanarError> {
    let m = model.m();
    let anchors = model.anchors(pose);
    let mut out = PlanarCables {
        q: Vec::with_capacity(m),
        u: Vec::with_capacity(m),
        exit: Vec::with_capacity(m),
        anchor: anchors.clone(),
    };
    let rho = model.p.pulley_radius;
    for i in 0..m {
        let (exit, arc) = if rho > 0.0 {
            let c = model.centres[i];
            let s = model.sides[i];
            let t = tangent(&c, rho, s, &anchors[i]).ok_or(PlanarError::InsidePulley(i))?;
            // Wrap angle relative to the reference outlet a_i (β = 0 there).
            let a0 = model.p.a[i] - c;
            let t0 = t - c;
            let beta = cross(&a0, &t0).atan2(a0.dot(&t0));
            (t, -s * rho * beta)
        } else {
            (model.p.a[i], 0.0)
        };
        let l = exit - anchors[i];
        let qf = l.norm();
        if qf < 1e-12 {
            return Err(PlanarError::ZeroLength(i));
        }
        out.q.push(qf + arc);
        out.u.push(l / qf);
        out.exit.push(exit);
    }
    Ok(out)
}

/// Structure matrix A^T (n × m), columns [u_i] or [u_i; (R b_i) × u_i] (eq. 2.30).
pub fn structure_matrix(model: &PlanarModel, pose: &PlanarPose, c: &PlanarCables) -> DMatrix<f64> {
    let (n, m) = (model.n(), model.m());
    DMatrix::from_fn(n, m, |row, i| match row {
        0 => c.u[i].x,
        1 => c.u[i].y,
        _ => cross(&(c.anchor[i] - pose.r), &c.u[i]),
    })
}

/// Closed-form distribution f = f_m − A^{+T}(w_e + A^T f_m) (eq. 3.41) and its margin
/// min(f − f_min, f_max − f) (feasible iff ≥ 0).
pub fn closed_form(
    model: &PlanarModel,
    at: &DMatrix<f64>,
) -> Result<(DVector<f64>, f64), PlanarError> {
    let p = &model.p;
    let fm = DVector::from_element(model.m(), 0.5 * (p.f_min + p.f_max));
    let chol = (at * at.transpose())
        .cholesky()
        .ok_or(PlanarError::Feasibility(FeasibilityError::Singular))?;
    let f = &fm - at.transpose() * chol.solve(&(&p.w_e + at * &fm));
    let margin = f
        .iter()
        .map(|fi| (fi - p.f_min).min(p.f_max - fi))
        .fold(f64::INFINITY, f64::min);
    Ok((f, margin))
}

/// Exact wrench feasibility of eq. (3.29) at a pose.
pub fn exact(model: &PlanarModel, at: &DMatrix<f64>) -> Result<ExactFeasibility, PlanarError> {
    let p = &model.p;
    Ok(feasibility::exact(at, &p.w_e, p.f_min, p.f_max)?)
}

/// Elastostatic forward kinematics (eq. 2.42): the pose where A^T f + w_e = 0 with
/// f_i = max(0, k_F,i (q_i − q_θ,i) / q_i) (eq. 2.33–2.36, slack cables carry nothing), by the
/// library's Levenberg–Marquardt on ½|γ|² (eq. 2.12–2.15) with a central-difference Jacobian
/// (n ≤ 3). Returns pose and forces.
pub fn elastostatic_fk(
    model: &PlanarModel,
    q_theta: &[f64],
    guess: &PlanarPose,
) -> Result<(PlanarPose, DVector<f64>), PlanarError> {
    let n = model.n();
    let z0 = DVector::from_iterator(n, [guess.r.x, guess.r.y, guess.theta].into_iter().take(n));
    let mut problem = PlanarEquilibrium {
        model,
        q_theta,
        tol: 1e-7 * model.p.f_max.max(1.0),
        last: DVector::zeros(n),
    };
    let settings = lm::Settings {
        max_iterations: 200,
        max_trials: 20,
        initial_damping: 1e-3,
        decrease: 1.0 / 0.3,
        min_damping: 1e-12,
        increase: 10.0,
        max_damping: f64::INFINITY,
        damping: lm::Damping::Levenberg,
        on_singular: lm::OnSingular::IncreaseDamping,
        gradient_tolerance: None,
    };
    let out = lm::solve(&mut problem, z0, &settings).map_err(|e| match e {
        lm::LmError::Start(e) | lm::LmError::Problem { source: e, .. } => e,
        lm::LmError::Singular { .. }
        | lm::LmError::NonFiniteStart
        | lm::LmError::NonFiniteGradient { .. } => PlanarError::BadValue {
            what: "the equilibrium residual",
        },
    })?;
    let (g, f) = planar_residual(model, q_theta, &out.point)?;
    if g.norm() >= problem.tol {
        return Err(PlanarError::NotConverged { residual: g.norm() });
    }
    Ok((to_pose(model, &out.point), f))
}

/// γ(z) = A^T f + w_e and the forces f at the pose coordinates z.
fn planar_residual(
    model: &PlanarModel,
    q_theta: &[f64],
    z: &DVector<f64>,
) -> Result<(DVector<f64>, DVector<f64>), PlanarError> {
    let pose = to_pose(model, z);
    let c = inverse(model, &pose)?;
    let f = DVector::from_iterator(
        model.m(),
        (0..model.m()).map(|i| (model.p.k_f[i] * (c.q[i] - q_theta[i]) / c.q[i]).max(0.0)),
    );
    if f.iter().all(|fi| *fi == 0.0) {
        return Err(PlanarError::AllSlack);
    }
    let at = structure_matrix(model, &pose, &c);
    Ok((at * &f + &model.p.w_e, f))
}

/// The planar ν_el as a least-squares problem: residual γ, central-difference Jacobian.
struct PlanarEquilibrium<'a> {
    model: &'a PlanarModel,
    q_theta: &'a [f64],
    /// Converged when |γ| < this (N).
    tol: f64,
    /// γ of the last evaluated point.
    last: DVector<f64>,
}

impl lm::Problem<Dyn> for PlanarEquilibrium<'_> {
    type Point = DVector<f64>;
    type Error = PlanarError;

    fn dim(&self) -> Dyn {
        Dyn(self.model.n())
    }

    fn cost(&mut self, z: &DVector<f64>) -> Result<f64, PlanarError> {
        self.last = planar_residual(self.model, self.q_theta, z)?.0;
        Ok(0.5 * self.last.norm_squared())
    }

    fn begin(&mut self, _z: &DVector<f64>, _cost: &mut f64) -> Result<lm::Flow, PlanarError> {
        Ok(if self.last.norm() < self.tol {
            lm::Flow::Done
        } else {
            lm::Flow::Continue
        })
    }

    fn normal_equations(
        &mut self,
        z: &DVector<f64>,
        jtj: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
    ) -> Result<(), PlanarError> {
        let n = z.len();
        let h = 1e-7;
        let mut jac = DMatrix::zeros(n, n);
        for k in 0..n {
            let mut zp = z.clone();
            let mut zm = z.clone();
            zp[k] += h;
            zm[k] -= h;
            let gp = planar_residual(self.model, self.q_theta, &zp)?.0;
            let gm = planar_residual(self.model, self.q_theta, &zm)?.0;
            jac.set_column(k, &((gp - gm) / (2.0 * h)));
        }
        jtj.copy_from(&(jac.transpose() * &jac));
        g.copy_from(&(jac.transpose() * &self.last));
        Ok(())
    }

    fn retract(&self, z: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
        z + step
    }

    fn accepts(&mut self, cost: f64, cost_new: f64) -> bool {
        cost_new < cost
    }

    fn accepted(&mut self, _step: &lm::Accepted<'_, DVector<f64>, Dyn>) -> bool {
        // Only the residual tolerance ends the solve.
        false
    }
}

fn to_pose(model: &PlanarModel, z: &DVector<f64>) -> PlanarPose {
    PlanarPose {
        r: Vector2::new(z[0], z[1]),
        theta: if model.n() == 3 { z[2] } else { 0.0 },
    }
}

/// Is `r` strictly inside the (convex) frame outline? (On the outline a cable has zero length
/// or lies along the frame: not a platform position.)
pub fn inside_frame(model: &PlanarModel, r: &Vector2<f64>) -> bool {
    let poly = model.frame_polygon();
    (0..poly.len()).all(|k| {
        let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
        cross(&(q - p), &(r - p)) > 1e-9
    })
}

/// A regular grid of positions with spacing `h` (m) in a box, kept where inside the frame.
pub fn frame_grid(
    model: &PlanarModel,
    min: Vector2<f64>,
    max: Vector2<f64>,
    h: f64,
) -> Vec<Vector2<f64>> {
    let nx = ((max.x - min.x) / h).floor() as usize + 1;
    let ny = ((max.y - min.y) / h).floor() as usize + 1;
    let mut pts = Vec::with_capacity(nx * ny);
    for i in 0..nx {
        for j in 0..ny {
            let r = Vector2::new(min.x + i as f64 * h, min.y + j as f64 * h);
            if inside_frame(model, &r) {
                pts.push(r);
            }
        }
    }
    pts
}

/// Which test decides feasibility of an area.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaTest {
    ClosedForm,
    Exact,
}

/// Wrench-feasible area W_WF (eq. 3.29) at orientation θ over grid cells of size h²: the
/// number of feasible grid points times h². Points the model cannot evaluate count as
/// infeasible and are counted in the second value.
pub fn feasible_area(
    model: &PlanarModel,
    grid: &[Vector2<f64>],
    h: f64,
    theta: f64,
    test: AreaTest,
) -> (f64, usize) {
    let mut n_ok = 0usize;
    let mut n_err = 0usize;
    for r in grid {
        let pose = PlanarPose { r: *r, theta };
        let ok = inverse(model, &pose).and_then(|c| {
            let at = structure_matrix(model, &pose, &c);
            match test {
                AreaTest::ClosedForm => closed_form(model, &at).map(|(_, m)| m >= 0.0),
                AreaTest::Exact => exact(model, &at).map(|e| e.feasible),
            }
        });
        match ok {
            Ok(true) => n_ok += 1,
            Ok(false) => {}
            Err(_) => n_err += 1,
        }
    }
    (n_ok as f64 * h * h, n_err)
}

/// The reachable workspace W_R (eq. 3.33–3.35) of a kinematic controller on an elastic robot.
#[derive(Clone, Debug, PartialEq)]
pub struct Reachable {
    /// Initial tension f_ini (eq. 3.41 at x_ini), N.
    pub f_ini: DVector<f64>,
    /// Area of reference poses x whose emerging forces stay in [f_min, f_max], m².
    pub area_m2: f64,
    /// Mean and largest pose error |x_M − x| over W_R, m.
    pub mean_error_m: f64,
    pub max_error_m: f64,
    /// Grid points where the elastostatic FK failed (counted as not reachable).
    pub fk_failures: usize,
}

/// W_R of eq. (3.33)–(3.35) with the full elastostatic forward kinematics: the controller
/// commands the lengths of its kinematic model `control` (no pulleys: φ), the cable offsets are
/// set at `x_ini` so that the `truth` robot holds the closed-form distribution f_ini there
/// (eq. 3.14, 3.41); at every reference pose x on the grid the truth robot settles at x_M with
/// forces f_M, and x is reachable when f_min ≤ f_M ≤ f_max.
pub fn reachable(
    truth: &PlanarModel,
    control: &PlanarModel,
    x_ini: &PlanarPose,
    grid: &[Vector2<f64>],
    h: f64,
) -> Result<Reachable, PlanarError> {
    let m = truth.m();
    let ct = inverse(truth, x_ini)?;
    let at = structure_matrix(truth, x_ini, &ct);
    let (f_ini, _) = closed_form(truth, &at)?;
    let cc = inverse(control, x_ini)?;
    // q_θ(x_ini) of the truth robot holding f_ini (inverse of f = k_F (q − q_θ)/q), and the
    // controller's constant offset between its model length and that q_θ.
    let offset: Vec<f64> = (0..m)
        .map(|i| cc.q[i] - ct.q[i] * (1.0 - f_ini[i] / truth.p.k_f[i]))
        .collect();
    let (mut n_ok, mut fails) = (0usize, 0usize);
    let (mut sum_e, mut max_e) = (0.0, 0.0f64);
    let p = &truth.p;
    for r in grid {
        let x = PlanarPose {
            r: *r,
            theta: x_ini.theta,
        };
        let Ok(c) = inverse(control, &x) else {
            fails += 1;
            continue;
        };
        let q_theta: Vec<f64> = (0..m).map(|i| c.q[i] - offset[i]).collect();
        match elastostatic_fk(truth, &q_theta, &x) {
            Ok((xm, f)) => {
                if f.iter().all(|fi| *fi >= p.f_min && *fi <= p.f_max) {
                    n_ok += 1;
                    let e = (xm.r - x.r).norm();
                    sum_e += e;
                    max_e = max_e.max(e);
                }
            }
            Err(_) => fails += 1,
        }
    }
    Ok(Reachable {
        f_ini,
        area_m2: n_ok as f64 * h * h,
        mean_error_m: if n_ok > 0 {
            sum_e / n_ok as f64
        } else {
            f64::NAN
        },
        max_error_m: max_e,
        fk_failures: fails,
    })
}

/// Condition number σ_1/σ_r (eq. 4.23) of the identification Jacobian J_qa = ∂q/∂a stacked
/// over the sample poses (standard kinematics: ∂q_i/∂a_i = u_i^T, eq. 4.5).
pub fn condition_number_qa(
    model: &PlanarModel,
    samples: &[PlanarPose],
) -> Result<f64, PlanarError> {
    let m = model.m();
    let mut j = DMatrix::zeros(samples.len() * m, 2 * m);
    for (s, pose) in samples.iter().enumerate() {
        let c = inverse(&model.with(|p| p.pulley_radius = 0.0)?, pose)?;
        for i in 0..m {
            j[(s * m + i, 2 * i)] = c.u[i].x;
            j[(s * m + i, 2 * i + 1)] = c.u[i].y;
        }
    }
    let sv = j.singular_values();
    let (hi, lo) = sv
        .iter()
        .fold((0.0f64, f64::INFINITY), |(h, l), &v| (h.max(v), l.min(v)));
    Ok(hi / lo)
}

/// The spec's planar example (eq. 3.40 / 4.24, table 4.1): a 200 kg point mass
/// (w_e = [0, −1962] N) in four cables, f ∈ [1000, 8000] N (fig. 3.18a / 3.20),
/// k_F = 2000 kN/m (eq. 3.36), pulleys referenced at x_ini = [0, 5.2] m (eq. 3.37).
pub fn spec_example() -> PlanarModel {
    let a = [(-6.0, 8.0), (5.0, 8.0), (-5.0, 0.0), (5.0, 0.5)];
    PlanarModel::new(PlanarParams {
        dof: PlanarDof::Point,
        a: a.iter().map(|&(x, y)| Vector2::new(x, y)).collect(),
        b: Vec::new(),
        k_f: vec![2.0e6; 4],
        w_e: DVector::from_vec(vec![0.0, -1962.0]),
        f_min: 1000.0,
        f_max: 8000.0,
        pulley_radius: 0.0,
        pulley_reference: PlanarPose::point(0.0, 5.2),
    })
    .expect("the spec's example is a valid planar robot")
}

/// Sample grid of eq. (4.25)/(4.27): `nx` × `ny` equidistant points of a box.
pub fn sample_grid(min: (f64, f64), max: (f64, f64), nx: usize, ny: usize) -> Vec<PlanarPose> {
    let lin = |a: f64, b: f64, n: usize, k: usize| {
        if n < 2 {
            a
        } else {
            a + (b - a) * k as f64 / (n - 1) as f64
        }
    };
    let mut v = Vec::with_capacity(nx * ny);
    for i in 0..nx {
        for j in 0..ny {
            v.push(PlanarPose::point(
                lin(min.0, max.0, nx, i),
                lin(min.1, max.1, ny, j),
            ));
        }
    }
    v
}
