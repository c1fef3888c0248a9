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
