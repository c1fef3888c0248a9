//! Space-frame truss check by the matrix stiffness method (eq. 5.2–5.7, Karnovsky & Lebed 2010):
//! the icosahedron cabin's carbon rods under the cable forces of a pose and extra joint loads.
//!
//! Conventions (tension positive): member j joins nodes p → q with unit vector u_j (p to q) and
//! axial stiffness k_j = EA / L_j. Its elongation is u_j·(δx_q − δx_p) = (A_sf δx)_j, so row j of
//! A_sf holds −u_j^T at p and +u_j^T at q. Stiffness K_C,sf = A_sf^T K_sf A_sf (eq. 5.6 with no
//! initial load, so no geometric stiffness), joint displacements δx = K_C,sf^{-1} w_sf on the free
//! coordinates (fixed joints remove the rigid-body motion, eq. 5.6) and member forces
//! f_sf = K_sf A_sf δx (eq. 5.7). Equilibrium A_sf^T f_sf = w_sf + reactions is the spec's
//! eq. (5.2) with its sign convention for w_sf, checked node by node in the tests.
//!
//! The icosahedron has 12 joints and 30 rods, 3·12 − 6 = 30: statically determinate once the
//! six rigid-body motions are fixed (Maxwell's rule), so the member forces do not depend on the
//! rod stiffness (the spec gives no k_sf); displacements do.

use nalgebra::{DMatrix, DVector, Vector3};

/// Rated axial force of the cabin's carbon rods (compression by Euler case 2 buckling and
/// tension), N (sec. 5.2).
pub const ROD_RATING_N: f64 = 151_000.0;

/// Axial stiffness EA assumed for the carbon rods when none is given, N: the spec gives no
/// k_sf. A 60 × 3 mm tube of E = 120 GPa; member forces of the determinate icosahedron do not
/// depend on it, joint displacements scale with 1/EA.
pub const ROD_EA_DEFAULT_N: f64 = 6.4e7;

/// Why a truss could not be solved.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrussError {
    #[error("member {member} joins node {node}, but there are {nodes} nodes")]
    BadNode {
        member: usize,
        node: usize,
        nodes: usize,
    },
    #[error("member {0} has zero length")]
    ZeroLength(usize),
    #[error("member {0} has a non-positive or non-finite stiffness EA")]
    BadStiffness(usize),
    #[error("load vector has {got} entries, expected {expected} (3 per node)")]
    LoadLength { got: usize, expected: usize },
    #[error(
        "the stiffness matrix is singular on the free coordinates: the fixed joints leave a mechanism or a rigid-body motion"
    )]
    Mechanism,
}

/// A pin-jointed space truss.
#[derive(Clone, Debug, PartialEq)]
pub struct Truss {
    pub nodes: Vec<Vector3<f64>>,
    /// Members as (p, q) node pairs.
    pub members: Vec<(usize, usize)>,
    /// Axial stiffness EA per member, N.
    pub ea: Vec<f64>,
    /// Fixed coordinates per node (x, y, z).
    pub fixed: Vec<[bool; 3]>,
}

/// Result of [`solve`].
#[derive(Clone, Debug, PartialEq)]
pub struct TrussSolution {
    /// Member forces f_sf, N (tension > 0, compression < 0).
    pub member_forces: Vec<f64>,
    /// Joint displacements δx_sf, m.
    pub displacements: Vec<Vector3<f64>>,
    /// Support reactions at the fixed coordinates, N (zero where the loads balance).
    pub reactions: Vec<Vector3<f64>>,
}

impl Truss {
    /// A_sf (members × 3·nodes) and member lengths.
    pub fn structure_matrix(&self) -> Result<(DMatrix<f64>, Vec<f64>), TrussError> {
        let n = self.nodes.len();
        let mut a = DMatrix::zeros(self.members.len(), 3 * n);
        let mut lengths = Vec::with_capacity(self.members.len());
        for (j, &(p, q)) in self.members.iter().enumerate() {
            for node in [p, q] {
                if node >= n {
                    return Err(TrussError::BadNode {
                        member: j,
                        node,
                        nodes: n,
                    });
                }
            }
            let d = self.nodes[q] - self.nodes[p];
            let l = d.norm();
            if l < 1e-12 {
                return Err(TrussError::ZeroLength(j));
            }
            let u = d / l;
            for k in 0..3 {
                a[(j, 3 * p + k)] = -u[k];
                a[(j, 3 * q + k)] = u[k];
            }
            lengths.push(l);
        }
        Ok((a, lengths))
    }

    /// K_C,sf = A_sf^T K_sf A_sf with K_sf = diag(EA_j / L_j) (eq. 5.6).
    pub fn stiffness(&self) -> Result<DMatrix<f64>, TrussError> {
        let (a, l) = self.structure_matrix()?;
        let k = self.member_stiffness(&l)?;
        Ok(a.transpose() * DMatrix::from_diagonal(&k) * a)
    }

    fn member_stiffness(&self, lengths: &[f64]) -> Result<DVector<f64>, TrussError> {
        let mut k = DVector::zeros(self.members.len());
        for j in 0..self.members.len() {
            let ea = self.ea.get(j).copied().unwrap_or(f64::NAN);
            if !(ea.is_finite() && ea > 0.0) {
                return Err(TrussError::BadStiffness(j));
            }
            k[j] = ea / lengths[j];
        }
        Ok(k)
    }
}

/// Solves eq. (5.6)–(5.7) for the joint loads `w` (3 per node, N).
pub fn solve(truss: &Truss, w: &[Vector3<f64>]) -> Result<TrussSolution, TrussError> {
    let n = truss.nodes.len();
    if w.len() != n {
        return Err(TrussError::LoadLength {
            got: 3 * w.len(),
            expected: 3 * n,
        });
    }
    let (a, l) = truss.structure_matrix()?;
    let k = truss.member_stiffness(&l)?;
    let kc = a.transpose() * DMatrix::from_diagonal(&k) * &a;
    let free: Vec<usize> = (0..3 * n)
        .filter(|&d| !truss.fixed.get(d / 3).is_some_and(|f| f[d % 3]))
        .collect();
    let kff = DMatrix::from_fn(free.len(), free.len(), |r, c| kc[(free[r], free[c])]);
    let wf = DVector::from_iterator(free.len(), free.iter().map(|&d| w[d / 3][d % 3]));
    // Cholesky fails on a singular (mechanism) or indefinite matrix; also refuse a condition
    // beyond what the forces could be trusted to.
    let chol = kff.clone().cholesky().ok_or(TrussError::Mechanism)?;
    let diag_max = kff.diagonal().max();
    let l_min = chol
        .l_dirty()
        .diagonal()
        .iter()
        .fold(f64::INFINITY, |m, v| m.min(v.abs()));
    if l_min * l_min < diag_max * 1e-12 {
        return Err(TrussError::Mechanism);
    }
    let xf = chol.solve(&wf);
    let mut dx = DVector::zeros(3 * n);
    for (i, &d) in free.iter().enumerate() {
        dx[d] = xf[i];
    }
    let f = DVector::from_iterator(k.len(), (0..k.len()).map(|j| k[j] * (a.row(j) * &dx)[0]));
    // Internal nodal forces A^T f equal the applied loads on free coordinates; on fixed ones the
    // difference is the support reaction (load carried into the support).
    let internal = a.transpose() * &f;
    let reactions = (0..n)
        .map(|i| {
            Vector3::from_fn(|k, _| {
                if truss.fixed[i][k] {
                    internal[3 * i + k] - w[i][k]
                } else {
                    0.0
                }
            })
        })
        .collect();
    Ok(TrussSolution {
        member_forces: f.iter().copied().collect(),
        displacements: (0..n)
            .map(|i| Vector3::new(dx[3 * i], dx[3 * i + 1], dx[3 * i + 2]))
            .collect(),
        reactions,
    })
}

/// The icosahedron cabin's space frame fitted to the platform anchors b_i (platform frame):
/// a regular icosahedron with its poles on z whose circumradius is the anchors' mean radius and
/// whose azimuth is fitted to them; joints within 0.25 edge lengths of an anchor are placed at the
/// anchor (the universal-joint centres of fig. 5.9a). Returns the truss (30 rods, EA each) and
/// the joint index of every cable. Fixed joints: a 3-2-1 support on joints that carry no cable
/// where possible (exactly the six rigid-body motions, so balanced loads give zero reactions).
pub fn icosahedron_cabin(b: &[Vector3<f64>], ea: f64) -> Result<(Truss, Vec<usize>), TrussError> {
    let radius = b.iter().map(|v| v.norm()).sum::<f64>() / b.len().max(1) as f64;
    let zr = radius / 5f64.sqrt();
    let rr = 2.0 * radius / 5f64.sqrt();
    // Azimuth phase: fit the upper-ring anchors (z > 0) modulo 72°.
    let step = 72f64.to_radians();
    let (mut sx, mut sy) = (0.0, 0.0);
    for v in b.iter().filter(|v| v.z > 0.3 * zr && v.z < 0.9 * radius) {
        let ang = v.y.atan2(v.x) * 5.0; // 5·angle is 72°-periodic → phase
        sx += ang.cos();
        sy += ang.sin();
    }
    let phase = if sx == 0.0 && sy == 0.0 {
        0.0
    } else {
        sy.atan2(sx) / 5.0
    };
    let mut nodes = vec![Vector3::new(0.0, 0.0, radius)];
    for k in 0..5 {
        let t = phase + step * k as f64;
        nodes.push(Vector3::new(rr * t.cos(), rr * t.sin(), zr));
    }
    for k in 0..5 {
        let t = phase + step * (k as f64 + 0.5);
        nodes.push(Vector3::new(rr * t.cos(), rr * t.sin(), -zr));
    }
    nodes.push(Vector3::new(0.0, 0.0, -radius));
    let edge = radius / (2.0 * std::f64::consts::PI / 5.0).sin();
    let mut members = Vec::new();
    for p in 0..12 {
        for q in p + 1..12 {
            if ((nodes[q] - nodes[p]).norm() - edge).abs() < 0.1 * edge {
                members.push((p, q));
            }
        }
    }
    debug_assert_eq!(members.len(), 30);
    // Cables to joints; move those joints onto the anchors.
    let mut cable_node = Vec::with_capacity(b.len());
    for bi in b {
        let (k, d) = nodes
            .iter()
            .enumerate()
            .map(|(k, nd)| (k, (nd - bi).norm()))
            .fold(
                (0, f64::INFINITY),
                |acc, x| if x.1 < acc.1 { x } else { acc },
            );
        cable_node.push(k);
        if d < 0.25 * edge {
            nodes[k] = *bi;
        }
    }
    // 3-2-1 support on the joints without cables (poles first), else on any joints.
    let mut free_joints: Vec<usize> = (0..12).filter(|k| !cable_node.contains(k)).collect();
    free_joints.extend((0..12).filter(|k| cable_node.contains(k)));
    let (j1, j2) = (free_joints[0], free_joints[1]);
    // Third support: the first joint not on the line j1–j2.
    let axis = (nodes[j2] - nodes[j1]).normalize();
    let j3 = *free_joints[2..]
        .iter()
        .find(|&&k| (nodes[k] - nodes[j1]).cross(&axis).norm() > 0.1 * edge)
        .unwrap_or(&free_joints[2]);
    let mut fixed = vec![[false; 3]; 12];
    fixed[j1] = [true; 3];
    // j2: the two coordinates most perpendicular to the line j1–j2 (rotation about the other two axes).
    let along = (0..3)
        .max_by(|&i, &j| axis[i].abs().total_cmp(&axis[j].abs()))
        .unwrap_or(2);
    for k in 0..3 {
        fixed[j2][k] = k != along;
    }
    // j3: the coordinate that best blocks rotation about the line j1–j2.
    let t = axis.cross(&(nodes[j3] - nodes[j1])).normalize();
    let blk = (0..3)
        .max_by(|&i, &j| t[i].abs().total_cmp(&t[j].abs()))
        .unwrap_or(0);
    fixed[j3][blk] = true;
    let truss = Truss {
        nodes,
        ea: vec![ea; members.len()],
        members,
        fixed,
    };
    Ok((truss, cable_node))
}

/// Joint loads w_sf of the cabin (eq. 5.5) in the platform frame: cable i pulls its joint with
/// f_i along R^T u_i (u_i from the platform towards the frame, world frame); the force part of the
/// external wrench w_e (world frame) acts at the platform origin, so it is shared by the joints
/// with the least-norm weights c (Σ c_k = 1, Σ c_k x_k = 0: no moment about the origin, nearly
/// equal shares on the near-symmetric frame); `joint_load` (world frame, N) is added at every joint, the
/// spec's 10 kN of equipment per joint (fig. 5.10b). Loads that do not balance (joint loads, a
/// torque in w_e) show up as support reactions.
pub fn cabin_loads(
    truss: &Truss,
    cable_node: &[usize],
    rotation: &nalgebra::Matrix3<f64>,
    u_world: &[Vector3<f64>],
    f: &[f64],
    w_e_force: &Vector3<f64>,
    joint_load: &Vector3<f64>,
) -> Vec<Vector3<f64>> {
    let n = truss.nodes.len();
    let rt = rotation.transpose();
    let m = DMatrix::from_fn(
        4,
        n,
        |r, k| if r == 0 { 1.0 } else { truss.nodes[k][r - 1] },
    );
    let e1 = DVector::from_vec(vec![1.0, 0.0, 0.0, 0.0]);
    // Nodes spanning 3-D make M M^T invertible; fall back to equal shares otherwise.
    let c = (&m * m.transpose())
        .cholesky()
        .map(|ch| m.transpose() * ch.solve(&e1))
        .unwrap_or_else(|| DVector::from_element(n, 1.0 / n as f64));
    let mut w: Vec<Vector3<f64>> = (0..n)
        .map(|k| rt * (w_e_force * c[k] + joint_load))
        .collect();
    for (i, &node) in cable_node.iter().enumerate() {
        w[node] += rt * u_world[i] * f[i];
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tripod_under_a_vertical_load_matches_the_hand_solution() {
        // Three legs from supports at radius r (120° apart) to an apex at height h, load P down:
        // by symmetry every leg carries F = −P·L / (3h) (compression), L = √(r² + h²).
        let (r, h, p) = (1.0, 2.0, 9000.0);
        let mut nodes = vec![Vector3::new(0.0, 0.0, h)];
        for k in 0..3 {
            let t = 2.0 * std::f64::consts::PI * k as f64 / 3.0;
            nodes.push(Vector3::new(r * t.cos(), r * t.sin(), 0.0));
        }
        let truss = Truss {
            nodes,
            members: vec![(0, 1), (0, 2), (0, 3)],
            ea: vec![1e7; 3],
            fixed: vec![[false; 3], [true; 3], [true; 3], [true; 3]],
        };
        let mut w = vec![Vector3::zeros(); 4];
        w[0] = Vector3::new(0.0, 0.0, -p);
        let s = solve(&truss, &w).unwrap();
        let l = (r * r + h * h).sqrt();
        for f in &s.member_forces {
            assert!((f + p * l / (3.0 * h)).abs() < 1e-6, "{f}");
        }
        // The supports carry the load: reactions sum to +P upwards.
        let rz: f64 = s.reactions.iter().map(|v| v.z).sum();
        assert!((rz - p).abs() < 1e-6, "{rz}");
    }

    #[test]
    fn a_mechanism_is_an_error() {
        let truss = Truss {
            nodes: vec![Vector3::zeros(), Vector3::new(1.0, 0.0, 0.0)],
            members: vec![(0, 1)],
            ea: vec![1e6],
            fixed: vec![[true; 3], [false; 3]],
        };
        assert_eq!(
            solve(&truss, &[Vector3::zeros(), Vector3::new(0.0, 1.0, 0.0)]).unwrap_err(),
            TrussError::Mechanism
        );
    }
}
