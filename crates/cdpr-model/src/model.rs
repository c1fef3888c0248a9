//! The immutable robot model (geometry, stiffness, wrench, force limits) and the preallocated
//! per-thread workspace `Data` (Model/Data split as in Pinocchio: hot paths never allocate).

use nalgebra::{Vector3, Vector6};
use sha2::{Digest, Sha256};

/// Smallest number of cables for a fully constrained spatial robot with n = 6 (m ≥ n + 1).
pub const MIN_CABLES: usize = 7;
/// Largest number of cables the fixed-capacity IPC payloads carry.
pub use crs_limits::MAX_CABLES;

/// Pulley parameters of eq. (2.18): radius r_p and swivel axis u_Az per cable.
///
/// Convention (fig. 2.8): the cable arrives at the exit point a_i travelling along +u_Az
/// (from the winch side), is tangent there to the pulley circle whose centre is
/// p_M = a_i + r_p u_Ax, wraps by β_i and leaves at the contact point p_A towards p_B.
/// With r_p = 0 the model is the standard one exactly (eq. 2.1).
#[derive(Clone, Debug, PartialEq)]
pub struct Pulleys {
    /// Pulley radius r_p per cable, m.
    pub radius: Vec<f64>,
    /// Unit swivel axis u_Az per cable (world frame).
    pub axis: Vec<Vector3<f64>>,
}

/// All parameters of the control model p = (a, b, r_p, u_Az, k_F, w_e) plus force limits.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelParams {
    /// Frame-side cable exit points a_i (world frame), m (eq. 2.4).
    pub a: Vec<Vector3<f64>>,
    /// Platform anchor points b_i^(P) (platform frame), m (eq. 2.4, 2.6).
    pub b: Vec<Vector3<f64>>,
    /// Optional pulley kinematics (sec. 2.3); `None` is the standard model.
    pub pulleys: Option<Pulleys>,
    /// Specific cable stiffness k_F = EA per cable, N (stiffness k = k_F / q, eq. 2.33–2.34).
    pub k_f: Vec<f64>,
    /// External wrench w_e = [f_e; τ_e] acting on the platform, N and N·m (eq. 2.30).
    pub w_e: Vector6<f64>,
    /// Lower operating force limit f_min, N (eq. 3.29).
    pub f_min: f64,
    /// Upper operating force limit f_max, N (eq. 3.29).
    pub f_max: f64,
}

/// Why a parameter set does not describe a valid robot.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("need at least {MIN_CABLES} cables for 6 DOF, got {0}")]
    TooFewCables(usize),
    #[error("at most {MAX_CABLES} cables are supported, got {0}")]
    TooManyCables(usize),
    #[error("{what} has {got} entries but there are {m} cables")]
    LengthMismatch {
        what: &'static str,
        got: usize,
        m: usize,
    },
    #[error("{what}[{index}] is not finite")]
    NotFinite { what: &'static str, index: usize },
    #[error("{what}[{i}] and {what}[{j}] coincide (anchor points must be distinct)")]
    DuplicateAnchor {
        what: &'static str,
        i: usize,
        j: usize,
    },
    #[error("k_f[{0}] must be > 0")]
    NonPositiveStiffness(usize),
    #[error("pulley radius[{0}] must be >= 0")]
    NegativePulleyRadius(usize),
    #[error("pulley axis[{0}] must be a non-zero vector")]
    ZeroPulleyAxis(usize),
    #[error("force limits must satisfy 0 <= f_min < f_max (got {f_min} N, {f_max} N)")]
    ForceLimits { f_min: f64, f_max: f64 },
}

/// Validated, immutable robot model.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    p: ModelParams,
}

impl Model {
    /// Validates the parameters (finite, m ≥ 7, distinct anchors, positive stiffness, ordered
    /// limits) and normalises the pulley axes.
    pub fn new(mut p: ModelParams) -> Result<Self, ModelError> {
        let m = p.a.len();
        if m < MIN_CABLES {
            return Err(ModelError::TooFewCables(m));
        }
        if m > MAX_CABLES {
            return Err(ModelError::TooManyCables(m));
        }
        let check_len = |what, got| {
            if got != m {
                Err(ModelError::LengthMismatch { what, got, m })
            } else {
                Ok(())
            }
        };
        check_len("b", p.b.len())?;
        check_len("k_f", p.k_f.len())?;
        for (what, pts) in [("a", &p.a), ("b", &p.b)] {
            for (i, v) in pts.iter().enumerate() {
                if !v.iter().all(|c| c.is_finite()) {
                    return Err(ModelError::NotFinite { what, index: i });
                }
            }
            for i in 0..m {
                for j in i + 1..m {
                    if (pts[i] - pts[j]).norm() < 1e-9 {
                        return Err(ModelError::DuplicateAnchor { what, i, j });
                    }
                }
            }
        }
        for (i, k) in p.k_f.iter().enumerate() {
            if !k.is_finite() {
                return Err(ModelError::NotFinite {
                    what: "k_f",
                    index: i,
                });
            }
            if *k <= 0.0 {
                return Err(ModelError::NonPositiveStiffness(i));
            }
        }
        for (i, w) in p.w_e.iter().enumerate() {
            if !w.is_finite() {
                return Err(ModelError::NotFinite {
                    what: "w_e",
                    index: i,
                });
            }
        }
        if !(p.f_min.is_finite() && p.f_max.is_finite() && p.f_min >= 0.0 && p.f_min < p.f_max) {
            return Err(ModelError::ForceLimits {
                f_min: p.f_min,
                f_max: p.f_max,
            });
        }
        if let Some(pl) = &mut p.pulleys {
            check_len("pulley radius", pl.radius.len())?;
            check_len("pulley axis", pl.axis.len())?;
            for (i, r) in pl.radius.iter().enumerate() {
                if !r.is_finite() {
                    return Err(ModelError::NotFinite {
                        what: "pulley radius",
                        index: i,
                    });
                }
                if *r < 0.0 {
                    return Err(ModelError::NegativePulleyRadius(i));
                }
            }
            for (i, ax) in pl.axis.iter_mut().enumerate() {
                if !ax.iter().all(|c| c.is_finite()) {
                    return Err(ModelError::NotFinite {
                        what: "pulley axis",
                        index: i,
                    });
                }
                let n = ax.norm();
                if n < 1e-12 {
                    return Err(ModelError::ZeroPulleyAxis(i));
                }
                *ax /= n;
            }
        }
        Ok(Self { p })
    }

    pub fn params(&self) -> &ModelParams {
        &self.p
    }

    /// Number of cables m.
    pub fn m(&self) -> usize {
        self.p.a.len()
    }

    pub fn has_pulleys(&self) -> bool {
        self.p.pulleys.is_some()
    }

    /// A copy of this model with other parameters (validated again).
    pub fn with_params(&self, f: impl FnOnce(&mut ModelParams)) -> Result<Model, ModelError> {
        let mut p = self.p.clone();
        f(&mut p);
        Model::new(p)
    }

    /// Identity of the model: SHA-256 over a canonical serialisation of every parameter
    /// (exact f64 bits). Processes compare it to be sure they run the same platform.
    pub fn identity(&self) -> [u8; 32] {
        let mut h = Sha256::new();
        h.update(b"crs-model-v1");
        h.update((self.m() as u64).to_le_bytes());
        let mut put = |v: f64| h.update(v.to_bits().to_le_bytes());
        for v in self.p.a.iter().chain(self.p.b.iter()) {
            v.iter().for_each(|c| put(*c));
        }
        self.p.k_f.iter().for_each(|c| put(*c));
        self.p.w_e.iter().for_each(|c| put(*c));
        put(self.p.f_min);
        put(self.p.f_max);
        match &self.p.pulleys {
            None => put(-1.0),
            Some(pl) => {
                pl.radius.iter().for_each(|c| put(*c));
                for ax in &pl.axis {
                    ax.iter().for_each(|c| put(*c));
                }
            }
        }
        h.finalize().into()
    }

    /// Hex form of [`Model::identity`].
    pub fn identity_hex(&self) -> String {
        self.identity().iter().map(|b| format!("{b:02x}")).collect()
    }
}

/// Preallocated per-cable workspace. Filled by [`crate::kinematics::inverse`] and the
/// elastostatic functions; every vector has length m.
#[derive(Clone, Debug)]
pub struct Data {
    /// Total cable length q_i (standard: ‖l_i‖, pulley: q_f + β r_p, eq. 2.7 / 2.17), m.
    pub q: Vec<f64>,
    /// Free cable length q_f,i between contact point and platform, m (eq. 2.22).
    pub q_free: Vec<f64>,
    /// Pulley wrap angle β_i, rad (eq. 2.19); 0 for the standard model.
    pub beta: Vec<f64>,
    /// Cable vector l_i from p_B to the exit/contact point, m (eq. 2.5 / 2.26).
    pub l: Vec<Vector3<f64>>,
    /// Cable unit vector u_i = l_i / q_f,i (eq. 2.8).
    pub u: Vec<Vector3<f64>>,
    /// Platform vector b_i = R b_i^(P) in the world frame, m (eq. 2.6).
    pub b_world: Vec<Vector3<f64>>,
    /// Exit point of the cable towards the platform: a_i (standard) or p_A,i (pulley), m.
    pub p_exit: Vec<Vector3<f64>>,
    /// Columns v_i = [u_i; b_i × u_i] of the structure matrix A^T (eq. 2.30, 2.68).
    pub at: Vec<Vector6<f64>>,
    /// Pulley plane direction u_Ax,i (unit, ⟂ u_Az towards p_B); zero for the standard model.
    pub pulley_ux: Vec<Vector3<f64>>,
    /// Distance b_xy,i of p_B from the swivel axis, m (eq. 2.21).
    pub pulley_bxy: Vec<f64>,
    /// Cable forces f_i, N (eq. 2.36), written by the elastostatic functions.
    pub f: Vec<f64>,
    /// ∂f_i/∂q_i, N/m (eq. 2.71), written by the elastostatic functions.
    pub df_dq: Vec<f64>,
    /// ∂f_i/∂q_θ,i, N/m (eq. 2.72), written by the elastostatic functions.
    pub df_dqt: Vec<f64>,
    /// Scratch vectors of length m for solvers.
    pub scratch_a: Vec<f64>,
    pub scratch_b: Vec<f64>,
}

impl Data {
    pub fn new(model: &Model) -> Self {
        let m = model.m();
        let z3 = vec![Vector3::zeros(); m];
        Self {
            q: vec![0.0; m],
            q_free: vec![0.0; m],
            beta: vec![0.0; m],
            l: z3.clone(),
            u: z3.clone(),
            b_world: z3.clone(),
            // The standard model's exit point is a_i; the pulley model overwrites it.
            p_exit: model.params().a.clone(),
            at: vec![Vector6::zeros(); m],
            pulley_ux: z3,
            pulley_bxy: vec![0.0; m],
            f: vec![0.0; m],
            df_dq: vec![0.0; m],
            df_dqt: vec![0.0; m],
            scratch_a: vec![0.0; m],
            scratch_b: vec![0.0; m],
        }
    }

    pub fn m(&self) -> usize {
        self.q.len()
    }
}
