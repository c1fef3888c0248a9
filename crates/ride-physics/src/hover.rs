//! The hover model of sec. 5.5, eq. (5.21): a Newton–Euler rigid body
//!
//!   [m E 0; 0 I] [ẍ; α] + [0; ω × I ω] = −[D_lin ẋ; D_rot ω] + [f_th + f_e + m g; τ_th + τ_e]
//!
//! driven by the pilot through thrust and the attitude assist, with the elastic safety walls
//! f_e, τ_e of eq. (5.22) ([`crate::walls`]). Model/Data split: [`HoverModel`] is the immutable
//! parameter set, [`HoverState`] the state, [`step`] one explicit step (semi-implicit Euler:
//! velocities first, positions with the new velocities; stable for the walls' ω_n·dt ≪ 1 at
//! 1 kHz).
//!
//! Inputs ([`PilotInput`]): the collective sets the thrust along the cabin's z axis,
//! T = m g (1 + authority·(2u − 1)) (0.5 = hover); roll, pitch and yaw command the cabin's attitude
//! (full stick = `attitude_command_max`), held by the PD assist "operating in the helicopter
//! fixed frame to assist the passenger" (sec. 5.5), τ_th = K_p (φ_cmd − φ) − K_d φ̇. A tilted
//! thrust accelerates the cabin horizontally: pitch +1 flies towards +x, roll +1 towards −y
//! (R = R_x R_y R_z, eq. 2.2).

use crate::pilot::PilotInput;
use crate::walls::Walls;
use cdpr_model::Pose;
use nalgebra::{Matrix3, Vector3};

/// Parameters of eq. (5.21)–(5.22).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HoverModel {
    /// m_P, kg, and I_P about the centre of gravity in cabin coordinates, kg·m² (the platform
    /// TOML's `[dynamics]`, eq. 5.13–5.14). The model moves the centre of gravity.
    pub mass_kg: f64,
    pub inertia_kg_m2: Matrix3<f64>,
    pub gravity_m_per_s2: f64,
    /// D_lin, per world axis, N·s/m.
    pub damping_linear: Vector3<f64>,
    /// D_rot, per axis, N·m·s/rad.
    pub damping_rotational: Vector3<f64>,
    /// Collective authority: the thrust spans m g (1 ± authority).
    pub collective_authority: f64,
    /// Attitude at full stick, rad (roll, pitch, yaw).
    pub attitude_command_max: Vector3<f64>,
    /// Attitude assist K_p (N·m/rad) and K_d (N·m·s/rad) per axis.
    pub assist_stiffness: Vector3<f64>,
    pub assist_damping: Vector3<f64>,
    /// Elastic safety walls on the position (eq. 5.22) and on the rotation coordinates.
    pub walls: Walls,
    pub rotation_walls: Walls,
}

/// The state of the hover model (Data).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HoverState {
    /// Time since start, s.
    pub t: f64,
    /// Position r (m) and velocity ṙ (m/s), world frame.
    pub r: Vector3<f64>,
    pub v: Vector3<f64>,
    /// Rotation coordinates φ (rad, R = R_x R_y R_z) and their rates φ̇ (rad/s).
    pub phi: Vector3<f64>,
    pub phi_dot: Vector3<f64>,
    /// Accelerations of the last step: r̈ (m/s²) and φ̈ (rad/s²).
    pub acc: Vector3<f64>,
    pub phi_ddot: Vector3<f64>,
    /// Wall force and torque of the last step (N, N·m), zero when clear of the walls.
    pub wall_force: Vector3<f64>,
    pub wall_torque: Vector3<f64>,
}

impl HoverState {
    /// At rest at `pose`.
    pub fn at_rest(pose: &Pose) -> Self {
        Self {
            r: pose.r,
            phi: pose.phi,
            ..Self::default()
        }
    }

    pub fn pose(&self) -> Pose {
        Pose::new(self.r, self.phi)
    }

    /// The pose as motion-core's cueing input takes it, [x, y, z, φx, φy, φz].
    pub fn pose_array(&self) -> [f64; 6] {
        self.pose().to_array()
    }

    /// True while a wall pushes.
    pub fn in_contact(&self) -> bool {
        self.wall_force != Vector3::zeros() || self.wall_torque != Vector3::zeros()
    }
}

/// The thrust T (N) for a collective input u ∈ [0, 1].
#[inline]
pub fn thrust(model: &HoverModel, collective: f64) -> f64 {
    model.mass_kg
        * model.gravity_m_per_s2
        * (1.0 + model.collective_authority * (2.0 * collective.clamp(0.0, 1.0) - 1.0))
}

/// One step of eq. (5.21) over `dt` seconds with pilot input `u` (clamped to its ranges).
/// Allocation-free.
pub fn step(model: &HoverModel, s: &mut HoverState, u: &PilotInput, dt: f64) {
    let pose = s.pose();
    let rot = pose.rotation();
    let jp = pose.angle_jacobian();
    let omega = jp * s.phi_dot;

    // Translation: m r̈ = −D_lin ṙ + f_th + f_e + m g.
    let f_th = rot * Vector3::new(0.0, 0.0, thrust(model, u.collective));
    let f_e = model.walls.force(&s.r, &s.v);
    let g = Vector3::new(0.0, 0.0, -model.mass_kg * model.gravity_m_per_s2);
    let f_d = -model.damping_linear.component_mul(&s.v);
    let acc = (f_th + f_e + g + f_d) / model.mass_kg;

    // Rotation: generalized forces along the coordinates φ (assist, walls) act as the torque
    // τ = J_P^{-T} Q (virtual work Q·δφ = τ·ω δt); the aerial damping acts on ω.
    let cmd = Vector3::new(u.roll, u.pitch, u.yaw).map(|x| x.clamp(-1.0, 1.0));
    let phi_cmd = cmd.component_mul(&model.attitude_command_max);
    let q_assist = model.assist_stiffness.component_mul(&(phi_cmd - s.phi))
        - model.assist_damping.component_mul(&s.phi_dot);
    let q_wall = model.rotation_walls.force(&s.phi, &s.phi_dot);
    let jp_inv_t = jp
        .try_inverse()
        .map(|m| m.transpose())
        .unwrap_or_else(Matrix3::identity);
    let tau = jp_inv_t * (q_assist + q_wall) - model.damping_rotational.component_mul(&omega);
    let i_w = rot * model.inertia_kg_m2 * rot.transpose();
    let alpha = i_w
        .try_inverse()
        .map(|inv| inv * (tau - omega.cross(&(i_w * omega))))
        .unwrap_or_else(Vector3::zeros);

    // Semi-implicit Euler.
    s.v += acc * dt;
    s.r += s.v * dt;
    let omega_new = omega + alpha * dt;
    let phi_dot_old = s.phi_dot;
    s.phi_dot = jp.try_inverse().map_or(phi_dot_old, |inv| inv * omega_new);
    s.phi += s.phi_dot * dt;
    s.acc = acc;
    s.phi_ddot = (s.phi_dot - phi_dot_old) / dt;
    s.wall_force = f_e;
    s.wall_torque = q_wall;
    s.t += dt;
}
