//! The plant around the robot: winches (drum errors, re-homing), hysteresis with a state that
//! is held between commands, the set-up of the initial tension, and the sensors.

use crate::equilibrium::{self, Solution};
use crate::robot::{PlantError, Robot};
use plant_oracle::PoseQ;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

/// How a winch turns its commanded length q (its encoder's count in metres) into unstretched
/// rope length L. q₀ is the command at the set-up of the initial tension.
#[derive(Clone, Debug, PartialEq)]
pub enum Drum {
    /// L = q.
    Ideal,
    /// The effective drum radius is (1 + s_i) times the assumed one and the length is counted
    /// from the set-up: L = q + s (q − q₀).
    FromSetUp { scale: Vec<f64> },
    /// The same, counted from the encoder's zero: L = (1 + s) q.
    FromZero { scale: Vec<f64> },
    /// A second rope layer starts `boundary_i` metres of command beyond the set-up (negative:
    /// before it); beyond it every turn pays out (1 + s_i) times as much:
    /// L = q + s (max(0, q − q₀ − c) − max(0, −c)).
    LayerStep { step: Vec<f64>, boundary: Vec<f64> },
}

impl Drum {
    fn length(&self, i: usize, q: f64, q0: f64) -> f64 {
        match self {
            Drum::Ideal => q,
            Drum::FromSetUp { scale } => q + scale[i] * (q - q0),
            Drum::FromZero { scale } => (1.0 + scale[i]) * q,
            Drum::LayerStep { step, boundary } => {
                let c = boundary[i];
                q + step[i] * ((q - q0 - c).max(0.0) - (-c).max(0.0))
            }
        }
    }

    /// The command that pays out `l` at the set-up (where q = q₀ by definition).
    fn set_up_command(&self, i: usize, l: f64) -> f64 {
        match self {
            Drum::FromZero { scale } => l / (1.0 + scale[i]),
            _ => l,
        }
    }
}

/// What switches the hysteresis of a cable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HysteresisInput {
    /// The cable's commanded length (the winch's direction of motion).
    Command,
    /// The cable's force (loading or unloading).
    Force,
}

/// A length hysteresis: the rope acts ±h longer depending on the direction of its last move:
/// +h after lengthening (command up, or force down), −h after shortening. The direction
/// switches only when the input has reversed by more than `dead_band` (m for the command, N
/// for the force) from its extreme since the last switch; it is held while the input does not
/// move. Before the first move the cable is on neither branch (0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hysteresis {
    pub h: f64,
    pub input: HysteresisInput,
    pub dead_band: f64,
}

/// One cable's direction state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trigger {
    /// +1 after lengthening, −1 after shortening, 0 virgin.
    pub direction: f64,
    /// Extreme of the input since the last switch.
    extreme: f64,
}

impl Trigger {
    fn new(u: f64) -> Self {
        Self {
            direction: 0.0,
            extreme: u,
        }
    }

    /// The state after the input moved to `u` (a Schmitt trigger on the direction).
    fn after(self, u: f64, dead_band: f64) -> Self {
        let up = |u| Self {
            direction: 1.0,
            extreme: u,
        };
        let down = |u| Self {
            direction: -1.0,
            extreme: u,
        };
        match self.direction {
            d if d > 0.0 => {
                if u > self.extreme {
                    up(u)
                } else if u < self.extreme - dead_band {
                    down(u)
                } else {
                    self
                }
            }
            d if d < 0.0 => {
                if u < self.extreme {
                    down(u)
                } else if u > self.extreme + dead_band {
                    up(u)
                } else {
                    self
                }
            }
            _ => {
                if u > self.extreme + dead_band {
                    up(u)
                } else if u < self.extreme - dead_band {
                    down(u)
                } else {
                    self
                }
            }
        }
    }
}

/// Load cells (at the platform anchors) and the pose tracker.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensors {
    /// Reading = gain_i · tension + offset_i + N(0, force_noise).
    pub gain: Vec<f64>,
    pub offset: Vec<f64>,
    pub force_noise: f64,
    /// Tracker noise on x, y, z (m) and on the three angles (rad), 1σ.
    pub position_noise: f64,
    pub rotation_noise: f64,
}

/// Everything about the true plant.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantSpec {
    pub robot: Robot,
    pub drum: Drum,
    pub hysteresis: Option<Hysteresis>,
    /// Encoder offsets after a re-homing (m, added to the paid-out length once
    /// [`Plant::rehome`] was called).
    pub rehoming: Option<Vec<f64>>,
    pub sensors: Sensors,
}

/// The plant's history: what makes its answer depend on the past.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantState {
    pub pose: PoseQ,
    pub triggers: Vec<Trigger>,
    pub rehomed: bool,
}

/// An equilibrium reached.
#[derive(Clone, Debug, PartialEq)]
pub struct Equilibrium {
    pub pose: PoseQ,
    /// True tension at each platform anchor, N.
    pub tensions: Vec<f64>,
}

/// What the sensors read: pose `[x, y, z, φx, φy, φz]` (R = R_x R_y R_z) and forces, N.
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    pub pose: [f64; 6],
    pub forces: Vec<f64>,
}

/// The running plant.
#[derive(Clone, Debug)]
pub struct Plant {
    spec: PlantSpec,
    /// Commands at the set-up, m.
    q0: Vec<f64>,
    state: PlantState,
    rng: StdRng,
}

impl Plant {
    /// Sets the initial tension as an operator does: the platform held at `home`, each winch
    /// wound until its cable carries `f_ini_i`; then released, the platform settles where the
    /// tensions balance the load (the set-up is noise-free and deterministic, so every
    /// campaign on the same plant starts from the same commands). `seed` drives the sensor noise.
    pub fn set_up(
        spec: PlantSpec,
        home: [f64; 6],
        f_ini: &[f64],
        seed: u64,
    ) -> Result<Self, PlantError> {
        let m = spec.robot.m();
        if f_ini.len() != m {
            return Err(PlantError::WrongLength {
                expected: m,
                got: f_ini.len(),
            });
        }
        let pose = PoseQ::from_array(home);
        let mut l0 = vec![0.0; m];
        for i in 0..m {
            l0[i] = tension_length(&spec.robot, i, &pose, f_ini[i])?;
        }
        let q0: Vec<f64> = (0..m).map(|i| spec.drum.set_up_command(i, l0[i])).collect();
        let sol = equilibrium::solve(&spec.robot, &l0, pose)?;
        let triggers = (0..m)
            .map(|i| {
                Trigger::new(match spec.hysteresis.map(|h| h.input) {
                    Some(HysteresisInput::Force) => -sol.tensions[i],
                    _ => q0[i],
                })
            })
            .collect();
        Ok(Self {
            spec,
            q0,
            state: PlantState {
                pose: sol.pose,
                triggers,
                rehomed: false,
            },
            rng: StdRng::seed_from_u64(seed),
        })
    }

    pub fn spec(&self) -> &PlantSpec {
        &self.spec
    }

    pub fn m(&self) -> usize {
        self.spec.robot.m()
    }

    /// The winch commands at the set-up, m.
    pub fn set_up_commands(&self) -> &[f64] {
        &self.q0
    }

    pub fn state(&self) -> PlantState {
        self.state.clone()
    }

    pub fn restore(&mut self, s: &PlantState) {
        self.state = s.clone();
    }

    /// The winches are re-homed: from now on their encoders carry the offsets of
    /// [`PlantSpec::rehoming`] (nothing when it is `None`).
    pub fn rehome(&mut self) {
        self.state.rehomed = true;
    }

    fn lengths(&self, q_cmd: &[f64], triggers: &[Trigger]) -> Vec<f64> {
        (0..self.m())
            .map(|i| {
                let mut l = self.spec.drum.length(i, q_cmd[i], self.q0[i]);
                if self.state.rehomed
                    && let Some(off) = &self.spec.rehoming
                {
                    l += off[i];
                }
                if let Some(h) = &self.spec.hysteresis {
                    l += h.h * triggers[i].direction;
                }
                l
            })
            .collect()
    }

    /// Commands the winches to `q_cmd` (m) and returns the equilibrium the robot settles in,
    /// searched from `guess`. The winches move monotonically from the last command to this
    /// one, so a command-switched hysteresis sees the sign of the change; a force-switched one
    /// is resolved by re-solving until the branches agree with the force changes they cause
    /// (switching a cable's branch only moves its force further the same way). The state
    /// advances only on success.
    pub fn command(&mut self, q_cmd: &[f64], guess: PoseQ) -> Result<Equilibrium, PlantError> {
        let m = self.m();
        if q_cmd.len() != m {
            return Err(PlantError::WrongLength {
                expected: m,
                got: q_cmd.len(),
            });
        }
        let committed = self.state.triggers.clone();
        let mut triggers = committed.clone();
        let hyst = self.spec.hysteresis;
        if let Some(h) = hyst
            && h.input == HysteresisInput::Command
        {
            for i in 0..m {
                triggers[i] = committed[i].after(q_cmd[i], h.dead_band);
            }
        }
        let mut sol: Solution =
            equilibrium::solve(&self.spec.robot, &self.lengths(q_cmd, &triggers), guess)?;
        if let Some(h) = hyst
            && h.input == HysteresisInput::Force
        {
            for _ in 0..10 {
                let next: Vec<Trigger> = (0..m)
                    .map(|i| committed[i].after(-sol.tensions[i], h.dead_band))
                    .collect();
                if next
                    .iter()
                    .zip(&triggers)
                    .all(|(a, b)| a.direction == b.direction)
                {
                    triggers = next;
                    break;
                }
                triggers = next;
                sol = equilibrium::solve(
                    &self.spec.robot,
                    &self.lengths(q_cmd, &triggers),
                    sol.pose,
                )?;
            }
        }
        self.state.triggers = triggers;
        self.state.pose = sol.pose;
        Ok(Equilibrium {
            pose: sol.pose,
            tensions: sol.tensions,
        })
    }

    /// The sensors' reading of an equilibrium (draws from the plant's noise generator).
    pub fn measure(&mut self, eq: &Equilibrium) -> Reading {
        let s = &self.spec.sensors;
        let mut pose = eq.pose.to_array();
        for (k, v) in pose.iter_mut().enumerate() {
            let sigma = if k < 3 {
                s.position_noise
            } else {
                s.rotation_noise
            };
            *v += gaussian(&mut self.rng, sigma);
        }
        let forces = eq
            .tensions
            .iter()
            .enumerate()
            .map(|(i, f)| s.gain[i] * f + s.offset[i] + gaussian(&mut self.rng, s.force_noise))
            .collect();
        Reading { pose, forces }
    }
}

fn gaussian(rng: &mut StdRng, sigma: f64) -> f64 {
    match Normal::new(0.0, sigma) {
        Ok(n) if sigma > 0.0 => n.sample(rng),
        _ => 0.0,
    }
}

/// Unstretched length of cable `i` that carries `target` N at `pose` (tension falls as the
/// rope gets longer): bisection with secant steps on [0.9 q, 1.05 q].
fn tension_length(robot: &Robot, i: usize, pose: &PoseQ, target: f64) -> Result<f64, PlantError> {
    let span = robot.span(i, pose)?;
    let law = robot.cables[i].law;
    let f = |l: f64| {
        law.tension(l, &span)
            .map(|t| t - target)
            .map_err(|err| PlantError::Cable { cable: i, err })
    };
    let (mut lo, mut hi) = (0.9 * span.length, 1.05 * span.length);
    let (mut flo, mut fhi) = (f(lo)?, f(hi)?);
    if !(flo > 0.0 && fhi < 0.0) {
        return Err(PlantError::SetUp {
            cable: i,
            target_n: target,
        });
    }
    for _ in 0..200 {
        let mut mid = lo + flo * (hi - lo) / (flo - fhi);
        if !(mid > lo && mid < hi) || (hi - lo) > 1e-3 * span.length {
            mid = 0.5 * (lo + hi);
        }
        let fm = f(mid)?;
        if fm > 0.0 {
            lo = mid;
            flo = fm;
        } else {
            hi = mid;
            fhi = fm;
        }
        if hi - lo < 1e-13 * span.length || fm == 0.0 {
            return Ok(mid);
        }
    }
    Ok(0.5 * (lo + hi))
}
