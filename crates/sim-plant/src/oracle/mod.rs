//! The plant as an independent oracle: its ground truth computed by its own code, so that an
//! error in the model library's equations shows up as a disagreement between controller and
//! plant instead of appearing in both.
//!
//! What is **shared** with the model library (`cdpr-model`) is data only: the platform TOML
//! (anchors a_i, b_i^(P), k_F, w_e, the platform's own pulleys) is loaded by its loader into a
//! `Model`, and the plant reads those numbers from it ([`OracleModel::from_config`]). The
//! plant's non-linear cable laws ([`crate::cable_law`]) are sim-plant's own code behind the
//! library's `CableLaw` trait (an interface, no equation).
//!
//! What is **not** shared — every equation on the truth path is written here, differently:
//! * the rotation R(φ) and its derivatives from the exponential form of the elemental
//!   rotations with glam ([`rotation`]), not the angle Jacobian J_P of eq. 2.45–2.46;
//! * the pulley kinematics as a tangent construction in the pulley plane ([`geometry`],
//!   eq. 2.17–2.22 as quantities), not the library's atan2/Rodrigues forms (eq. 2.19, 2.27);
//! * the length gradient ∂q/∂x = −u·∂p_B/∂x from the envelope argument, not the pulley
//!   differentials of eq. 2.83–2.87;
//! * the equilibrium as the stationary point of the potential energy (virtual work) in pose
//!   coordinates, solved by Newton with a finite-difference Hessian of the gradient
//!   ([`equilibrium`]), not the Levenberg–Marquardt ν_el on the wrench residual with the
//!   stiffness K_G − K_C (eq. 2.42–2.43, 2.67–2.76);
//! * the linear cable law f = k_F (q − q_θ)/q (eq. 2.33–2.36) and its inverse, and the
//!   tension projection of eq. 3.19.
//!
//! Tests (`tests/oracle.rs`) cross-check lengths, forces and equilibrium poses against the
//! model library on the ideal plant to round-off and show that a deliberately mismatched
//! input (a pulley radius or an anchor changed in one side only) is detected.

pub mod equilibrium;
pub mod geometry;
pub mod rotation;

pub use equilibrium::{
    EquilibriumError, Loads, OracleModel, Solution, State, Workspace, place, potential,
    project_tension, solve, tension,
};
pub use geometry::{Cable, Geometry, GeometryError, Pulley};
pub use rotation::Orientation;

use crate::config::PlantConfig;
use glam::DVec3;

fn dvec(v: &nalgebra::Vector3<f64>) -> DVec3 {
    DVec3::new(v.x, v.y, v.z)
}

impl OracleModel {
    /// The physical plant's geometry and loads from the platform data and the effects:
    /// a_i + Δa_i, b_i^(P) + Δb_i (effect 1), the pulley effect's radii and axes or else the
    /// platform's own pulleys (effect 2), the load's weight at its centre of gravity and extra
    /// wrench or else the platform's nominal wrench (effect 7), the rope weight under sag
    /// (effect 5).
    pub fn from_config(config: &PlantConfig) -> Self {
        let p = config.platform.model.params();
        let fx = &config.effects;
        let mut frame: Vec<DVec3> = p.a.iter().map(dvec).collect();
        let mut platform: Vec<DVec3> = p.b.iter().map(dvec).collect();
        if let Some(g) = &fx.geometry {
            for (a, d) in frame.iter_mut().zip(&g.frame_anchor_offsets) {
                *a += dvec(d);
            }
            for (b, d) in platform.iter_mut().zip(&g.platform_anchor_offsets) {
                *b += dvec(d);
            }
        }
        let pulleys = match (&fx.pulleys, &p.pulleys) {
            (Some(e), _) => Some(pulleys(&e.radius, &e.axis)),
            (None, Some(pl)) => Some(pulleys(&pl.radius, &pl.axis)),
            (None, None) => None,
        };
        let loads = match &fx.load {
            Some(l) => Loads {
                constant: std::array::from_fn(|k| l.extra_wrench[k]),
                weight: Some((
                    DVec3::new(0.0, 0.0, -l.mass * l.gravity),
                    dvec(&l.center_of_gravity),
                )),
                rope_weight: None,
            },
            None => Loads {
                constant: std::array::from_fn(|k| p.w_e[k]),
                weight: None,
                rope_weight: None,
            },
        };
        Self {
            geometry: Geometry {
                frame,
                platform,
                pulleys,
            },
            k_f: p.k_f.clone(),
            loads: Loads {
                rope_weight: fx.sag.map(|s| s.mass_per_length * s.gravity),
                ..loads
            },
        }
    }

    pub fn m(&self) -> usize {
        self.geometry.m()
    }
}

/// Pulleys with unit axes (the plant config validated them non-zero).
fn pulleys(radius: &[f64], axis: &[nalgebra::Vector3<f64>]) -> Vec<Pulley> {
    radius
        .iter()
        .zip(axis)
        .map(|(r, a)| {
            let a = dvec(a);
            Pulley {
                radius: *r,
                axis: a / a.length(),
            }
        })
        .collect()
}
