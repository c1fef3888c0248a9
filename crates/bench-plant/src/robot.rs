//! The true robot: cables (frame exit, platform anchor, optional pulley, elastic law) and its
//! load, and the robot's potential energy around a pose.

use crate::cable::{CableError, Law, Span};
use glam::{DQuat, DVec3};
use plant_oracle::{PoseQ, Pulley};

/// Why the plant cannot answer.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlantError {
    #[error("cable {cable}: {err}")]
    Cable { cable: usize, err: CableError },
    #[error("cable {cable}: the anchor lies inside its pulley or on the swivel axis")]
    PulleyGeometry { cable: usize },
    #[error("no equilibrium after {iterations} Newton steps (last step {last_step:.3e})")]
    NotConverged { iterations: usize, last_step: f64 },
    #[error("every cable is slack: the platform has no equilibrium")]
    AllSlack,
    #[error("set-up: cable {cable} cannot be tensioned to {target_n:.0} N at the home pose")]
    SetUp { cable: usize, target_n: f64 },
    #[error("expected {expected} values, got {got}")]
    WrongLength { expected: usize, got: usize },
}

/// One cable of the true robot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cable {
    /// Frame exit point (where the rope leaves the frame or arrives on its pulley), world, m.
    pub exit: DVec3,
    /// Platform anchor, platform frame, m.
    pub anchor: DVec3,
    /// Pulley at the exit (radius, swivel axis: the direction the rope arrives in).
    pub pulley: Option<Pulley>,
    pub law: Law,
}

/// The load: a mass at a centre of gravity (its torque turns with the platform) plus a
/// constant world-frame force and torque (a torque has no potential; its virtual work
/// τ·δω enters the potential around each Newton step's base pose, which is all the
/// minimiser uses).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Load {
    pub mass: f64,
    /// Platform frame, m.
    pub cog: DVec3,
    pub gravity: f64,
    pub force: DVec3,
    pub torque: DVec3,
}

/// The true robot (immutable after construction).
#[derive(Clone, Debug, PartialEq)]
pub struct Robot {
    pub cables: Vec<Cable>,
    pub load: Load,
}

impl Robot {
    /// Normalises the pulley axes.
    pub fn new(mut cables: Vec<Cable>, load: Load) -> Self {
        for c in &mut cables {
            if let Some(p) = &mut c.pulley {
                p.axis = p.axis.normalize();
            }
        }
        Self { cables, load }
    }

    pub fn m(&self) -> usize {
        self.cables.len()
    }

    /// Cable `i`'s span at `pose`: plant-oracle's path length (pulley arc derived from the
    /// tangent condition) and the chord's end points.
    pub fn span(&self, i: usize, pose: &PoseQ) -> Result<Span, PlantError> {
        let c = &self.cables[i];
        let geom = plant_oracle::Cable {
            frame_exit: c.exit,
            anchor: c.anchor,
            pulley: c.pulley,
            k_f: 1.0,
        };
        let length = plant_oracle::cable_length(&geom, pose)
            .map_err(|_| PlantError::PulleyGeometry { cable: i })?;
        Ok(Span {
            length,
            exit: c.exit,
            end: pose.point(c.anchor),
        })
    }

    /// Tensions at the platform anchors (what load cells there read before their errors), N.
    pub fn tensions(&self, l_un: &[f64], pose: &PoseQ) -> Result<Vec<f64>, PlantError> {
        (0..self.m())
            .map(|i| {
                let s = self.span(i, pose)?;
                self.cables[i]
                    .law
                    .tension(l_un[i], &s)
                    .map_err(|err| PlantError::Cable { cable: i, err })
            })
            .collect()
    }

    /// Potential of the robot at `base` moved by the increment dx = (δr, δω) (world-frame
    /// translation and rotation vector), relative to `base` for the load: the cables' energies
    /// plus m g Δz_cog − F·δr − τ·δω.
    pub fn potential(&self, l_un: &[f64], base: &PoseQ, dx: &[f64; 6]) -> Result<f64, PlantError> {
        let dr = DVec3::new(dx[0], dx[1], dx[2]);
        let dw = DVec3::new(dx[3], dx[4], dx[5]);
        let pose = PoseQ {
            r: base.r + dr,
            q: (DQuat::from_scaled_axis(dw) * base.q).normalize(),
        };
        let mut u = 0.0;
        for (i, c) in self.cables.iter().enumerate() {
            let s = self.span(i, &pose)?;
            u += c
                .law
                .energy(l_un[i], &s)
                .map_err(|err| PlantError::Cable { cable: i, err })?;
        }
        let l = &self.load;
        let dz = dr.z + (pose.q * l.cog).z - (base.q * l.cog).z;
        u += l.mass * l.gravity * dz - l.force.dot(dr) - l.torque.dot(dw);
        Ok(u)
    }
}
