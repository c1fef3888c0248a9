//! The simulated plant (ground-truth model ν̂_el of the meta-model, ch. 3.2, Fig. 3.2/3.7):
//! commanded controlled lengths in, the equilibrium the physical robot settles in out
//! (elastostatic forward kinematics, eq. 2.42–2.43, with the effects of [`crate::config`]),
//! plus sensor readings.

use crate::cable_law::{HysteresisState, PlantLaw};
use crate::config::{Effects, PlantConfig};
use cdpr_model::elastostatics;
use cdpr_model::forward::{
    FkError, FkOptions, FkSolution, WrenchResidual, elastostatic_with, elastostatic_with_law,
};
use cdpr_model::kinematics::{self, KinematicsError};
use cdpr_model::statics::{self, StaticsError};
use cdpr_model::{Data, Model, ModelError, Pose, Pulleys};
use nalgebra::{Vector3, Vector6};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

/// Iteration limit of the pose-dependent solver (linear convergence near the solution).
const MAX_ITERATIONS: usize = 200;
/// Largest change of a physical controlled length per quasi-static sub-step, m. The winches
/// move continuously, so a large command change is followed along a path (continuation):
/// the plant stays on the physical equilibrium branch and the hysteresis sees the path.
const MAX_SUBSTEP: f64 = 0.25;

/// Why the plant has no equilibrium or cannot be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlantError {
    #[error("plant model is invalid: {0}")]
    Model(#[from] ModelError),
    #[error("expected {expected} commanded lengths, got {got}")]
    WrongLength { expected: usize, got: usize },
    #[error("commanded length of cable {cable} is not finite")]
    NonFinite { cable: usize },
    #[error("no equilibrium: {0}")]
    NoEquilibrium(#[from] FkError),
    #[error("kinematics: {0}")]
    Kinematics(#[from] KinematicsError),
    #[error("statics: {0}")]
    Statics(#[from] StaticsError),
    #[error("initial tension cannot be realised: cable {cable} would carry {force:.1} N")]
    InfeasibleTension { cable: usize, force: f64 },
}

/// The state the physical robot settles in for one command.
#[derive(Clone, Debug, PartialEq)]
pub struct Equilibrium {
    /// Actual platform pose x̂ (eq. 2.2).
    pub pose: Pose,
    /// Actual cable forces f̂, N (slack cables 0).
    pub forces: Vec<f64>,
    /// Physical controlled lengths after the winch/drum errors, m.
    pub q_theta: Vec<f64>,
    /// Geometric cable lengths at x̂ on the physical model, m.
    pub lengths: Vec<f64>,
    /// External wrench acting on the platform at x̂ (load plus, with sag, the rope-weight
    /// share), N and N·m.
    pub wrench: Vector6<f64>,
    /// Levenberg–Marquardt iterations of the last inner solve.
    pub iterations: usize,
    /// ‖A^T f + w_e‖ at x̂ (N, N·m).
    pub residual_norm: f64,
}

/// What the sensors read for one equilibrium.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorReading {
    /// Pose from the tracker (exact when the tracker effect is off).
    pub pose: Pose,
    /// Force sensor readings, N (exact when the force-sensor effect is off).
    pub forces: Vec<f64>,
}

/// Result of setting the initial tension (eq. 3.14, 3.19, 6.22–6.24).
#[derive(Clone, Debug, PartialEq)]
pub struct TensionSetup {
    /// Commanded lengths that hold the platform at the set-up pose, m.
    pub q_cmd: Vec<f64>,
    /// The cable forces there: f_ini projected onto the plant's equilibrium (eq. 3.19), N.
    pub forces: Vec<f64>,
}

/// Everything that makes the plant's answer depend on its history.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantState {
    pub pose: Pose,
    pub hysteresis: HysteresisState,
    /// Physical controlled lengths of the last equilibrium (None before the first step).
    pub q_theta: Option<Vec<f64>>,
}

/// The simulated plant.
#[derive(Clone, Debug)]
pub struct Plant {
    config: PlantConfig,
    model: Model,
    data: Data,
    law: PlantLaw,
    /// Last equilibrium pose (warm start).
    pose: Pose,
    /// External wrench used in the current solve.
    w_e: Vector6<f64>,
    q_phys: Vec<f64>,
    /// Physical controlled lengths of the last equilibrium.
    last_q: Option<Vec<f64>>,
    /// Sub-step target (scratch).
    q_target: Vec<f64>,
    opts: FkOptions,
    rng: StdRng,
}

impl Plant {
    /// Builds the plant: physical geometry (effects 1, 2), cable law (3–5), load (7).
    pub fn new(config: PlantConfig) -> Result<Self, PlantError> {
        let fx = &config.effects;
        let model = physical_model(&config.platform.model, fx)?;
        let data = Data::new(&model);
        let law = PlantLaw::new(&config.platform.model.params().k_f, fx);
        let m = model.m();
        let rng = StdRng::seed_from_u64(config.seed);
        let pose = config.platform.home;
        let w_e = model.params().w_e;
        Ok(Self {
            config,
            model,
            data,
            law,
            pose,
            w_e,
            q_phys: vec![0.0; m],
            last_q: None,
            q_target: vec![0.0; m],
            opts: FkOptions::default(),
            rng,
        })
    }

    pub fn m(&self) -> usize {
        self.model.m()
    }

    pub fn config(&self) -> &PlantConfig {
        &self.config
    }

    /// The physical model (geometry and pulleys of the plant, for tests and analysis).
    pub fn physical_model(&self) -> &Model {
        &self.model
    }

    /// Restarts the sensor-noise RNG.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = StdRng::seed_from_u64(seed);
    }

    pub fn state(&self) -> PlantState {
        PlantState {
            pose: self.pose,
            hysteresis: self.law.hysteresis_state(),
            q_theta: self.last_q.clone(),
        }
    }

    pub fn restore(&mut self, st: &PlantState) {
        self.pose = st.pose;
        self.last_q.clone_from(&st.q_theta);
        self.law.set_hysteresis_state(&st.hysteresis);
    }

    /// The platform load at pose x (effect 7, or the platform's nominal wrench). With sag on,
    /// the solver adds the rope-weight share (see [`Equilibrium::wrench`] for the total).
    pub fn wrench_at(&self, x: &Pose) -> Vector6<f64> {
        load_at(&self.config, &self.model, x)
    }

    fn pose_dependent(&self) -> bool {
        self.law.has_sag()
            || self
                .config
                .effects
                .load
                .is_some_and(|l| l.center_of_gravity != Vector3::zeros())
    }

    /// Sets the pose-dependent inputs (chord angles, wrench) from the kinematics at x.
    fn freeze_at(&mut self, x: &Pose) -> Result<(), PlantError> {
        kinematics::inverse(&self.model, &mut self.data, x)?;
        self.w_e = sag_inputs(&self.config, &self.model, &self.data, &mut self.law, x);
        Ok(())
    }

    /// Physical controlled lengths from the commands (effect 6): q_θ = s q_cmd + o.
    fn winch(&self, i: usize, q_cmd: f64) -> f64 {
        match &self.config.effects.winch {
            None => q_cmd,
            Some(w) => w.length_scale[i] * q_cmd + w.encoder_offset[i],
        }
    }

    fn winch_inverse(&self, i: usize, q_theta: f64) -> f64 {
        match &self.config.effects.winch {
            None => q_theta,
            Some(w) => (q_theta - w.encoder_offset[i]) / w.length_scale[i],
        }
    }

    /// Commands the controlled cable lengths q_θ,cmd (m) and returns the equilibrium the
    /// robot settles in. The hysteresis state advances only on success; on error the plant
    /// keeps its previous state.
    pub fn step(&mut self, q_theta_cmd: &[f64]) -> Result<Equilibrium, PlantError> {
        let m = self.m();
        if q_theta_cmd.len() != m {
            return Err(PlantError::WrongLength {
                expected: m,
                got: q_theta_cmd.len(),
            });
        }
        if let Some(cable) = q_theta_cmd.iter().position(|v| !v.is_finite()) {
            return Err(PlantError::NonFinite { cable });
        }
        for (i, q) in q_theta_cmd.iter().enumerate() {
            let v = self.winch(i, *q);
            self.q_target[i] = v;
        }
        let saved = self.state();
        let result = self.follow();
        let sol = match result {
            Ok(sol) => sol,
            Err(e) => {
                self.restore(&saved);
                return Err(e);
            }
        };
        Ok(Equilibrium {
            pose: sol.pose,
            forces: self.data.f.clone(),
            q_theta: self.q_phys.clone(),
            lengths: self.data.q.clone(),
            wrench: self.w_e,
            iterations: sol.iterations,
            residual_norm: sol.residual_norm,
        })
    }

    /// Follows the command from the last equilibrium to `q_target` in quasi-static sub-steps,
    /// committing the hysteresis after each. Leaves `q_phys` = `q_target`.
    fn follow(&mut self) -> Result<FkSolution, PlantError> {
        let m = self.m();
        let n_sub = match &self.last_q {
            Some(last) => {
                let d = (0..m)
                    .map(|i| (self.q_target[i] - last[i]).abs())
                    .fold(0.0, f64::max);
                ((d / MAX_SUBSTEP).ceil() as usize).clamp(1, 10_000)
            }
            None => 1,
        };
        let last = self.last_q.clone();
        let mut sol = None;
        for k in 1..=n_sub {
            let t = k as f64 / n_sub as f64;
            for i in 0..m {
                self.q_phys[i] = match &last {
                    Some(l) if k < n_sub => l[i] + t * (self.q_target[i] - l[i]),
                    _ => self.q_target[i],
                };
            }
            let s = self.solve(self.pose)?;
            // data holds the kinematics and forces at s.pose: commit the hysteresis state.
            for i in 0..m {
                let e = self.law.elastic_input(i, self.data.q[i], self.q_phys[i]);
                self.law.commit(i, e);
            }
            self.pose = s.pose;
            sol = Some(s);
        }
        self.last_q = Some(self.q_target.clone());
        sol.ok_or(PlantError::NoEquilibrium(FkError::AllSlack))
    }

    fn solve(&mut self, guess: Pose) -> Result<FkSolution, PlantError> {
        if !self.pose_dependent() {
            // Constant wrench and chord-independent law: motion-core's ν_el as is.
            self.w_e = self.wrench_at(&guess);
            return Ok(elastostatic_with_law(
                &self.model,
                &mut self.data,
                &self.law,
                &self.w_e,
                &self.q_phys,
                &guess,
                &self.opts,
            )?);
        }
        self.solve_pose_dependent(guess)
    }

    /// ν_el for pose-dependent inputs: the model's ν_el on the exact residual
    /// ρ(x) = A^T f + w_e(x) (eq. 2.43), with the chord angles (sag) and the gravity torque
    /// (load) evaluated at the trial pose x itself; its Jacobian K_G − K_C (eq. 2.74, 2.76)
    /// holds those inputs frozen, and the neglected ∂(chord angle, gravity torque)/∂x terms are
    /// small, so it still converges to the exact equilibrium, only not quadratically.
    fn solve_pose_dependent(&mut self, guess: Pose) -> Result<FkSolution, PlantError> {
        let opts = FkOptions {
            max_iterations: MAX_ITERATIONS,
            ..self.opts
        };
        let Self {
            config,
            model,
            data,
            law,
            w_e,
            q_phys,
            ..
        } = self;
        let residual = |data: &mut Data, x: &Pose| {
            kinematics::inverse(model, data, x)?;
            *w_e = sag_inputs(config, model, data, law, x);
            elastostatics::cable_forces(data, &*law, q_phys);
            Ok(WrenchResidual {
                rho: statics::cable_wrench(data, &data.f) + *w_e,
                load: w_e.amax(),
            })
        };
        elastostatic_with(model, data, residual, &guess, &opts).map_err(|e| match e {
            // A pose the kinematics refuse is the plant's kinematics error, as in `freeze_at`.
            FkError::Kinematics(k) => PlantError::Kinematics(k),
            e => PlantError::NoEquilibrium(e),
        })
    }

    /// Sensor readings of an equilibrium (effect 8): tracker noise on every pose coordinate,
    /// force readings gain·f + offset + noise. Draws from the plant's seeded RNG.
    pub fn measure(&mut self, eq: &Equilibrium) -> SensorReading {
        let mut x = eq.pose.to_array();
        if let Some(t) = self.config.effects.tracker {
            for (k, v) in x.iter_mut().enumerate() {
                let sigma = if k < 3 {
                    t.position_noise
                } else {
                    t.rotation_noise
                };
                *v += gaussian(&mut self.rng, sigma);
            }
        }
        let mut forces = eq.forces.clone();
        if let Some(fs) = &self.config.effects.force_sensors {
            for (i, f) in forces.iter_mut().enumerate() {
                *f = fs.gain[i] * *f + fs.offset[i] + gaussian(&mut self.rng, fs.noise);
            }
        }
        SensorReading {
            pose: Pose::from_array(x),
            forces,
        }
    }

    /// Sets the initial tension state at `pose` (the operator holds the platform there and
    /// adjusts the cable offsets, sec. 6.1): projects `f_ini` onto the plant's equilibrium
    /// f_0 = −A^{+T} w_e + (I − A^{+T} A^T) f_ini (eq. 3.19), resets the hysteresis to the
    /// settled (virgin) state and returns the commands q = φ̂_el(x_ini, f_0) that hold it
    /// (the plant side of eq. 3.14 / 6.24). The plant's warm start moves to `pose`.
    pub fn setup_tension(
        &mut self,
        pose: &Pose,
        f_ini: &[f64],
    ) -> Result<TensionSetup, PlantError> {
        let m = self.m();
        if f_ini.len() != m {
            return Err(PlantError::WrongLength {
                expected: m,
                got: f_ini.len(),
            });
        }
        self.freeze_at(pose)?;
        kinematics::inverse(&self.model, &mut self.data, pose)?;
        let mut f_ext = vec![0.0; m];
        let mut f_int = vec![0.0; m];
        statics::split_internal_external(&self.data, &self.w_e, f_ini, &mut f_ext, &mut f_int)?;
        let forces: Vec<f64> = f_ext.iter().zip(&f_int).map(|(a, b)| a + b).collect();
        if let Some((cable, &force)) = forces.iter().enumerate().find(|(_, f)| **f <= 0.0) {
            return Err(PlantError::InfeasibleTension { cable, force });
        }
        let mut q_cmd = vec![0.0; m];
        for i in 0..m {
            self.law.reset_at_force(i, forces[i]);
            let qt = cdpr_model::elastostatics::CableLaw::controlled_length(
                &self.law,
                i,
                self.data.q[i],
                forces[i],
            );
            q_cmd[i] = self.winch_inverse(i, qt);
        }
        self.pose = *pose;
        self.last_q = Some((0..m).map(|i| self.winch(i, q_cmd[i])).collect());
        Ok(TensionSetup { q_cmd, forces })
    }
}

/// The platform load at pose x (effect 7, or the platform's nominal wrench).
fn load_at(config: &PlantConfig, model: &Model, x: &Pose) -> Vector6<f64> {
    match &config.effects.load {
        None => model.params().w_e,
        Some(l) => {
            let fg = Vector3::new(0.0, 0.0, -l.mass * l.gravity);
            let tau = (x.rotation() * l.center_of_gravity).cross(&fg);
            Vector6::new(fg.x, fg.y, fg.z, tau.x, tau.y, tau.z) + l.extra_wrench
        }
    }
}

/// With the kinematics of x in `data`: sets the chord angles of the sag law and returns the
/// wrench, with the share of the rope weight the platform carries under sag (effect 5): half
/// of each free span's weight μ g q_f,i hangs at its platform anchor b_i (parabolic span, the
/// other half at the pulley), w += Σ [−½ μ g q_f,i e_z; b_i × (−½ μ g q_f,i e_z)].
fn sag_inputs(
    config: &PlantConfig,
    model: &Model,
    data: &Data,
    law: &mut PlantLaw,
    x: &Pose,
) -> Vector6<f64> {
    let mut w_e = load_at(config, model, x);
    if let Some(sag) = config.effects.sag {
        for i in 0..model.m() {
            let uz = data.u[i].z;
            law.sag_cos2[i] = (1.0 - uz * uz).max(0.0);
            let g = Vector3::new(
                0.0,
                0.0,
                -0.5 * sag.mass_per_length * sag.gravity * data.q_free[i],
            );
            let tau = data.b_world[i].cross(&g);
            w_e += Vector6::new(g.x, g.y, g.z, tau.x, tau.y, tau.z);
        }
    }
    w_e
}

fn gaussian(rng: &mut StdRng, sigma: f64) -> f64 {
    if sigma > 0.0 {
        // sigma > 0 and finite (validated), so Normal::new cannot fail.
        Normal::new(0.0, sigma)
            .map(|n| n.sample(rng))
            .unwrap_or(0.0)
    } else {
        0.0
    }
}

/// The physical model: nominal parameters with geometry deviations (effect 1) and pulleys
/// (effect 2). With both off it is the nominal model itself.
fn physical_model(nominal: &Model, fx: &Effects) -> Result<Model, ModelError> {
    if fx.geometry.is_none() && fx.pulleys.is_none() {
        return Ok(nominal.clone());
    }
    nominal.with_params(|p| {
        if let Some(g) = &fx.geometry {
            for (a, d) in p.a.iter_mut().zip(&g.frame_anchor_offsets) {
                *a += d;
            }
            for (b, d) in p.b.iter_mut().zip(&g.platform_anchor_offsets) {
                *b += d;
            }
        }
        if let Some(pl) = &fx.pulleys {
            p.pulleys = Some(Pulleys {
                radius: pl.radius.clone(),
                axis: pl.axis.clone(),
            });
        }
    })
}
