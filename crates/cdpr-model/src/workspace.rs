//! Wrench-feasible workspace (eq. 3.29): the per-pose check, a constant-orientation grid
//! sampler (volume fraction and boundary points) and the workspace hull after Pott (2008):
//! line searches from a feasible centre along the vertices of a subdivided icosahedron.
//! Every sampler takes the test it applies: the closed form of eq. (3.41) (sufficient, the hard
//! loop's test) or the exact LP of [`crate::feasibility`] (necessary and sufficient).

use crate::feasibility::{self, ExactFeasibility, FeasibilityError};
use crate::kinematics::{self, KinematicsError};
use crate::model::{Data, Model};
use crate::pose::Pose;
use crate::statics::{self, ForceDistribution, StaticsError};
use nalgebra::{DVector, Vector3};

/// Which wrench-feasibility test a workspace computation applies (eq. 3.29).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeasibilityTest {
    /// The closed-form distribution of eq. (3.41) inside the limits: sufficient, not necessary.
    ClosedForm,
    /// Some distribution inside the limits exists (max-margin LP): necessary and sufficient.
    Exact,
}

impl FeasibilityTest {
    pub fn name(self) -> &'static str {
        match self {
            Self::ClosedForm => "closed form (eq. 3.41)",
            Self::Exact => "exact (LP, eq. 3.29)",
        }
    }
}

/// Why a pose could not be evaluated (counted as infeasible by the samplers).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WorkspaceError {
    #[error("inverse kinematics: {0}")]
    Kinematics(#[from] KinematicsError),
    #[error("statics: {0}")]
    Statics(#[from] StaticsError),
    #[error("exact feasibility: {0}")]
    Exact(#[from] FeasibilityError),
    #[error("elastostatics: {0}")]
    Elastostatics(#[from] crate::elastostatics::ElastostaticsError),
    #[error("the hull centre [{:.3}, {:.3}, {:.3}] m is not wrench feasible", .0.x, .0.y, .0.z)]
    CentreInfeasible(Vector3<f64>),
}

/// Axis-aligned box of platform positions, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionBox {
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
}

impl PositionBox {
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] <= self.max[k])
    }
    pub fn volume(&self) -> f64 {
        (self.max - self.min).iter().product()
    }
}

/// Wrench feasibility of a pose (eq. 3.29) with the closed-form distribution (eq. 3.41):
/// `Ok(fd)` with `fd.feasible`; `Err` when the inverse kinematics or statics fail (counted as
/// infeasible by the samplers). The closed form is a sufficient test: a pose it accepts is
/// wrench feasible. Allocation-free; `f_out` receives the forces.
pub fn check_pose(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    f_out: &mut [f64],
) -> Result<ForceDistribution, WorkspaceError> {
    kinematics::inverse(model, data, pose)?;
    let p = model.params();
    Ok(statics::force_distribution(
        data, &p.w_e, p.f_min, p.f_max, f_out,
    )?)
}

/// Exact wrench feasibility of a pose (eq. 3.29, [`feasibility::exact`]): some distribution
/// within [f_min, f_max] balances w_e. Analysis tool (allocates).
pub fn check_pose_exact(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
) -> Result<ExactFeasibility, WorkspaceError> {
    kinematics::inverse(model, data, pose)?;
    let p = model.params();
    let at = statics::structure_matrix(data);
    let w = DVector::from_column_slice(p.w_e.as_slice());
    Ok(feasibility::exact(&at, &w, p.f_min, p.f_max)?)
}

fn feasible(model: &Model, data: &mut Data, pose: &Pose, test: FeasibilityTest) -> bool {
    match test {
        FeasibilityTest::ClosedForm => {
            let mut f = std::mem::take(&mut data.scratch_a);
            let ok = check_pose(model, data, pose, &mut f).is_ok_and(|fd| fd.feasible);
            data.scratch_a = f;
            ok
        }
        FeasibilityTest::Exact => check_pose_exact(model, data, pose).is_ok_and(|e| e.feasible),
    }
}

/// Result of a grid sampling of the constant-orientation workspace.
#[derive(Clone, Debug, PartialEq)]
pub struct GridResult {
    /// Points per axis.
    pub resolution: [usize; 3],
    pub total: usize,
    pub feasible: usize,
    /// feasible / total: the fraction of the box that is wrench feasible.
    pub fraction: f64,
    /// Estimated feasible volume, m³ (fraction × box volume).
    pub volume: f64,
    /// Every grid point with its verdict.
    pub points: Vec<(Vector3<f64>, bool)>,
    /// Feasible points with at least one infeasible (or out-of-box) 6-neighbour.
    pub boundary: Vec<Vector3<f64>>,
}

/// Samples `bounds` on a regular grid (`resolution` points per axis, ≥ 2) at constant
/// orientation `phi` (rad) with the closed-form test.
pub fn sample_grid(
    model: &Model,
    bounds: &PositionBox,
    phi: &Vector3<f64>,
    resolution: [usize; 3],
) -> GridResult {
    sample_grid_with(model, bounds, phi, resolution, FeasibilityTest::ClosedForm)
}

/// [`sample_grid`] with the chosen feasibility test.
pub fn sample_grid_with(
    model: &Model,
    bounds: &PositionBox,
    phi: &Vector3<f64>,
    resolution: [usize; 3],
    test: FeasibilityTest,
) -> GridResult {
    let mut data = Data::new(model);
    let [nx, ny, nz] = resolution.map(|n| n.max(2));
    let idx = |i: usize, j: usize, k: usize| (i * ny + j) * nz + k;
    let mut points = Vec::with_capacity(nx * ny * nz);
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let t = Vector3::new(
                    i as f64 / (nx - 1) as f64,
                    j as f64 / (ny - 1) as f64,
                    k as f64 / (nz - 1) as f64,
                );
                let r = bounds.min + (bounds.max - bounds.min).component_mul(&t);
                let ok = feasible(model, &mut data, &Pose::new(r, *phi), test);
                points.push((r, ok));
            }
        }
    }
    let mut boundary = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let (r, ok) = points[idx(i, j, k)];
                if !ok {
                    continue;
                }
                let edge = i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1;
                let neighbour_out = edge
                    || !points[idx(i - 1, j, k)].1
                    || !points[idx(i + 1, j, k)].1
                    || !points[idx(i, j - 1, k)].1
                    || !points[idx(i, j + 1, k)].1
                    || !points[idx(i, j, k - 1)].1
                    || !points[idx(i, j, k + 1)].1;
                if neighbour_out {
                    boundary.push(r);
                }
            }
        }
    }
    let total = points.len();
    let n_ok = points.iter().filter(|p| p.1).count();
    let fraction = n_ok as f64 / total as f64;
    GridResult {
        resolution: [nx, ny, nz],
        total,
        feasible: n_ok,
        fraction,
        volume: fraction * bounds.volume(),
        points,
        boundary,
    }
}

/// The workspace hull after Pott (2008): boundary points found by bisection along rays from a
/// feasible centre through the vertices of a subdivided icosahedron, and the volume of the
/// star-shaped polyhedron they span.
#[derive(Clone, Debug, PartialEq)]
pub struct Hull {
    pub center: Vector3<f64>,
    pub vertices: Vec<Vector3<f64>>,
    pub triangles: Vec<[usize; 3]>,
    /// Volume of the polyhedron, m³.
    pub volume: f64,
}

/// Computes the hull around `center` at orientation `phi`. `subdivisions` refines the
/// icosahedron (0: 12 rays, 1: 42, 2: 162, 3: 642); `max_radius` bounds the ray search (m) and
/// `tolerance` is the bisection tolerance (m). Errors if `center` itself is not feasible.
/// Closed-form test.
pub fn hull(
    model: &Model,
    center: &Vector3<f64>,
    phi: &Vector3<f64>,
    subdivisions: usize,
    max_radius: f64,
    tolerance: f64,
) -> Result<Hull, WorkspaceError> {
    hull_with(
        model,
        center,
        phi,
        subdivisions,
        max_radius,
        tolerance,
        FeasibilityTest::ClosedForm,
    )
}

/// [`hull`] with the chosen feasibility test.
pub fn hull_with(
    model: &Model,
    center: &Vector3<f64>,
    phi: &Vector3<f64>,
    subdivisions: usize,
    max_radius: f64,
    tolerance: f64,
    test: FeasibilityTest,
) -> Result<Hull, WorkspaceError> {
    let mut data = Data::new(model);
    if !feasible(model, &mut data, &Pose::new(*center, *phi), test) {
        return Err(WorkspaceError::CentreInfeasible(*center));
    }
    let (dirs, triangles) = icosphere(subdivisions);
    let mut vertices = Vec::with_capacity(dirs.len());
    for d in &dirs {
        // Ray search: step out until infeasible, then bisect the last interval.
        let mut lo = 0.0;
        let mut hi = max_radius;
        let steps = 32;
        for s in 1..=steps {
            let t = max_radius * s as f64 / steps as f64;
            if !feasible(model, &mut data, &Pose::new(center + d * t, *phi), test) {
                hi = t;
                break;
            }
            lo = t;
        }
        if lo < hi {
            while hi - lo > tolerance {
                let mid = 0.5 * (lo + hi);
                if feasible(model, &mut data, &Pose::new(center + d * mid, *phi), test) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        vertices.push(center + d * lo);
    }
    let volume = triangles
        .iter()
        .map(|t| {
            let (a, b, c) = (
                vertices[t[0]] - center,
                vertices[t[1]] - center,
                vertices[t[2]] - center,
            );
            a.dot(&b.cross(&c)).abs() / 6.0
        })
        .sum();
    Ok(Hull {
        center: *center,
        vertices,
        triangles,
        volume,
    })
}

/// Unit icosphere: vertices and outward triangles.
fn icosphere(subdivisions: usize) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<Vector3<f64>> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vector3::new(p[0], p[1], p[2]).normalize())
    .collect();
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache = std::collections::HashMap::new();
        let mut mid = |a: usize, b: usize, v: &mut Vec<Vector3<f64>>| -> usize {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                v.push(((v[a] + v[b]) * 0.5).normalize());
                v.len() - 1
            })
        };
        let mut nf = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let ab = mid(a, b, &mut v);
            let bc = mid(b, c, &mut v);
            let ca = mid(c, a, &mut v);
            nf.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    (v, f)
}

/// What happened at one reference pose of a reachable-workspace analysis.
#[derive(Clone, Debug, PartialEq)]
pub enum Reach {
    /// The elastic robot settled at `pose` with `forces`.
    Settled {
        pose: Pose,
        forces: Vec<f64>,
        /// f_min ≤ f ≤ f_max on every cable (eq. 3.34).
        within_limits: bool,
        /// |Δr| (m) the pose moves under the wrench step of the analysis, linear prediction
        /// Δx = −K_wx⁻¹ Δw (eq. 2.76–2.78, 3.23) at the settled pose; None if K_wx is
        /// singular there.
        compliance_dr_m: Option<f64>,
        /// The linear prediction of the pose error, Δx = C_xw (A^T f(q_θ) + w_e) at the
        /// reference pose (eq. 3.16, 3.23–3.24), as a position vector (m); compare with
        /// `pose.r − reference.r` for the linearisation error (fig. 3.11b). None if the
        /// inverse kinematics or K_wx failed at the reference pose.
        linear_dr: Option<Vector3<f64>>,
    },
    /// The elastostatic forward kinematics did not converge (counted as not reachable).
    FkFailed(String),
}

/// Reachable workspace W_R (eq. 3.33–3.35) of a controller commanding its model's lengths on an
/// elastic robot.
#[derive(Clone, Debug, PartialEq)]
pub struct ReachableAnalysis {
    /// The tension state at the set-up pose (eq. 3.14, 3.19), N.
    pub f_ini: Vec<f64>,
    /// Per reference pose: its outcome.
    pub points: Vec<(Pose, Reach)>,
}

impl ReachableAnalysis {
    /// Reference poses whose emerging forces stay within the limits.
    pub fn reachable(&self) -> usize {
        self.points
            .iter()
            .filter(|(_, r)| {
                matches!(
                    r,
                    Reach::Settled {
                        within_limits: true,
                        ..
                    }
                )
            })
            .count()
    }
    pub fn fk_failures(&self) -> usize {
        self.points
            .iter()
            .filter(|(_, r)| matches!(r, Reach::FkFailed(_)))
            .count()
    }
    /// Reachable poses where the linear prediction of eq. (3.24) could not be computed
    /// (singular K_wx or failed inverse kinematics at the reference pose).
    pub fn linear_failures(&self) -> usize {
        self.points
            .iter()
            .filter(|(_, r)| {
                matches!(
                    r,
                    Reach::Settled {
                        within_limits: true,
                        linear_dr: None,
                        ..
                    }
                )
            })
            .count()
    }

    /// Linearisation error of eq. (3.24): mean and largest |Δr_linear − (r_M − r)| over the
    /// reachable poses whose prediction exists ([`Self::linear_failures`] counts the others),
    /// m (None if none).
    pub fn linearisation_error(&self) -> Option<(f64, f64)> {
        let e: Vec<f64> = self
            .points
            .iter()
            .filter_map(|(x, r)| match r {
                Reach::Settled {
                    pose,
                    within_limits: true,
                    linear_dr: Some(dr),
                    ..
                } => Some((dr - (pose.r - x.r)).norm()),
                _ => None,
            })
            .collect();
        (!e.is_empty()).then(|| {
            (
                e.iter().sum::<f64>() / e.len() as f64,
                e.iter().copied().fold(0.0, f64::max),
            )
        })
    }

    /// Mean and largest position error |r_M − r| over the reachable poses, m (None if none).
    pub fn position_error(&self) -> Option<(f64, f64)> {
        let e: Vec<f64> = self
            .points
            .iter()
            .filter_map(|(x, r)| match r {
                Reach::Settled {
                    pose,
                    within_limits: true,
                    ..
                } => Some((pose.r - x.r).norm()),
                _ => None,
            })
            .collect();
        (!e.is_empty()).then(|| {
            (
                e.iter().sum::<f64>() / e.len() as f64,
                e.iter().copied().fold(0.0, f64::max),
            )
        })
    }
}

/// The set-up tension of the spatial robot: `f_ini` projected onto the equilibrium at `x_ini`
/// (f_0 = −A^{+T} w_e + (I − A^{+T} A^T) f_ini, eq. 3.19), or the closed form of eq. (3.41)
/// there when none is given.
pub fn setup_tension(
    model: &Model,
    x_ini: &Pose,
    f_ini: Option<&[f64]>,
) -> Result<Vec<f64>, WorkspaceError> {
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, x_ini)?;
    let p = model.params();
    let m = model.m();
    let mut f = vec![0.0; m];
    match f_ini {
        Some(fi) => {
            let (mut fe, mut fint) = (vec![0.0; m], vec![0.0; m]);
            statics::split_internal_external(&data, &p.w_e, fi, &mut fe, &mut fint)?;
            for i in 0..m {
                f[i] = fe[i] + fint[i];
            }
        }
        None => {
            statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
        }
    }
    Ok(f)
}

/// W_R of eq. (3.33)–(3.35) with the full elastostatic forward kinematics (eq. 2.42): the
/// controller commands the lengths of `control` (e.g. the standard kinematics φ), with the cable
/// offsets set at `x_ini` so that `truth` holds `f_ini` there (eq. 3.14); at every reference pose
/// x the truth robot settles at x_M with forces f_M (eq. 3.35 without linearisation), and x is
/// reachable when f_min ≤ f_M ≤ f_max (eq. 3.34). `dw` is the wrench step whose linear pose
/// response (eq. 3.23) is reported per pose as the sensitivity map.
pub fn reachable_kinematic(
    truth: &Model,
    control: &Model,
    x_ini: &Pose,
    f_ini: &[f64],
    references: &[Pose],
    dw: &nalgebra::Vector6<f64>,
) -> Result<ReachableAnalysis, WorkspaceError> {
    use crate::elastostatics::{self, Stiffness};
    use crate::forward::{self, FkOptions};
    let m = truth.m();
    let mut dt = Data::new(truth);
    let mut dc = Data::new(control);
    let mut qt_ini = vec![0.0; m];
    elastostatics::inverse(truth, &mut dt, x_ini, f_ini, &mut qt_ini)?;
    kinematics::inverse(control, &mut dc, x_ini)?;
    let offset: Vec<f64> = (0..m).map(|i| dc.q[i] - qt_ini[i]).collect();
    let p = truth.params();
    let opts = FkOptions::default();
    let mut q_theta = vec![0.0; m];
    let mut points = Vec::with_capacity(references.len());
    for x in references {
        if let Err(e) = kinematics::inverse(control, &mut dc, x) {
            points.push((*x, Reach::FkFailed(format!("control model: {e}"))));
            continue;
        }
        for i in 0..m {
            q_theta[i] = dc.q[i] - offset[i];
        }
        // Linear prediction (eq. 3.16, 3.23–3.24): residual wrench of the commanded lengths at
        // the reference pose, mapped through the compliance there.
        let linear_dr = match kinematics::inverse(truth, &mut dt, x) {
            Ok(()) => {
                elastostatics::cable_forces(&mut dt, &truth.linear_law(), &q_theta);
                let mut dw_res = p.w_e;
                for i in 0..m {
                    dw_res += dt.at[i] * dt.f[i];
                }
                Stiffness::at(truth, &dt)
                    .k_wx
                    .lu()
                    .solve(&(-dw_res))
                    .map(|dx| Vector3::new(dx[0], dx[1], dx[2]))
            }
            Err(_) => None,
        };
        let outcome = match forward::elastostatic(truth, &mut dt, &q_theta, x, &opts) {
            Ok(sol) => {
                let forces = dt.f.clone();
                let within_limits = forces.iter().all(|f| *f >= p.f_min && *f <= p.f_max);
                // Δx = −K_wx⁻¹ Δw at the settled pose (data holds its forces and derivatives).
                let s = Stiffness::at(truth, &dt);
                let dr = s
                    .k_wx
                    .lu()
                    .solve(&(-dw))
                    .map(|dx| nalgebra::Vector3::new(dx[0], dx[1], dx[2]).norm());
                Reach::Settled {
                    pose: sol.pose,
                    forces,
                    within_limits,
                    compliance_dr_m: dr,
                    linear_dr,
                }
            }
            Err(e) => Reach::FkFailed(e.to_string()),
        };
        points.push((*x, outcome));
    }
    Ok(ReachableAnalysis {
        f_ini: f_ini.to_vec(),
        points,
    })
}
