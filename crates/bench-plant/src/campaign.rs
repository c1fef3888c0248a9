//! The nominal controller and a measurement campaign on the plant: reference poses commanded
//! with the nominal geometry, each followed by a tension test (all cables shortened, then
//! returned), steps whose true forces leave the limits not sampled.

use crate::plant::{Plant, PlantState};
use glam::DVec3;
use plant_oracle::PoseQ;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// What the controller knows: the nominal robot (handed in by the caller from its platform
/// file; nothing of it is the plant's truth).
#[derive(Clone, Debug, PartialEq)]
pub struct Nominal {
    /// Frame anchors a_i, world, m.
    pub exits: Vec<DVec3>,
    /// Platform anchors b_i, platform frame, m.
    pub anchors: Vec<DVec3>,
    /// Cable stiffness k_F,i of the model, N.
    pub k_f: Vec<f64>,
    /// External wrench of the model [f; τ], N and N·m.
    pub wrench: [f64; 6],
    /// Set-up pose `[x, y, z, φx, φy, φz]` and initial tension f_ini, N.
    pub home: [f64; 6],
    pub f_ini: Vec<f64>,
    /// Force limits of operation and of a tension test, N.
    pub f_min: f64,
    pub f_max: f64,
    pub f_abs_max: f64,
}

impl Nominal {
    pub fn m(&self) -> usize {
        self.exits.len()
    }
}

/// The nominal kinematic controller: q_cmd = |a_i − r − R b_i| + q_off,i with the offsets that
/// reproduce the set-up commands at the home pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Controller {
    exits: Vec<DVec3>,
    anchors: Vec<DVec3>,
    q_off: Vec<f64>,
}

impl Controller {
    pub fn new(nominal: &Nominal, set_up_commands: &[f64]) -> Self {
        let mut c = Self {
            exits: nominal.exits.clone(),
            anchors: nominal.anchors.clone(),
            q_off: vec![0.0; nominal.m()],
        };
        let at_home = c.command(&nominal.home);
        c.q_off = set_up_commands
            .iter()
            .zip(&at_home)
            .map(|(q0, q)| q0 - q)
            .collect();
        c
    }

    /// Commanded lengths for the reference pose `x_ref`, m.
    pub fn command(&self, x_ref: &[f64; 6]) -> Vec<f64> {
        let p = PoseQ::from_array(*x_ref);
        self.exits
            .iter()
            .zip(&self.anchors)
            .zip(&self.q_off)
            .map(|((a, b), off)| (*a - p.point(*b)).length() + off)
            .collect()
    }
}

/// Campaign step of a row (the crs-dataset phase codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    Pose = 0,
    Tensioned = 1,
    Returned = 2,
}

/// One recorded row.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub sample: u64,
    pub pose_index: u64,
    pub phase: Phase,
    pub q_cmd: Vec<f64>,
    /// Measured pose `[x, y, z, φx, φy, φz]` and forces, N.
    pub pose: [f64; 6],
    pub forces: Vec<f64>,
    pub pose_ref: [f64; 6],
}

/// A step not sampled, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Skip {
    pub pose_index: usize,
    pub phase: Phase,
    pub reason: String,
}

/// A campaign: reference poses, each with an optional tension test.
#[derive(Clone, Debug, PartialEq)]
pub struct Campaign {
    /// Candidate reference poses in visiting order.
    pub poses: Vec<[f64; 6]>,
    /// Stop after this many poses were recorded (`None`: visit all): an engineer draws poses
    /// until the campaign has its size.
    pub reachable: Option<usize>,
    /// All cables shortened by this much and returned after each pose, m.
    pub tension_shortening: Option<f64>,
    /// Re-home the winches once this many poses were recorded (see
    /// [`crate::plant::PlantSpec::rehoming`]).
    pub rehome_after: Option<usize>,
}

/// What a campaign recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub rows: Vec<Row>,
    pub skipped: Vec<Skip>,
}

/// `count` reference poses uniform in the box [−1.5, 1.5] × [−1.5, 1.5] × [1.25, 2.0] m with
/// rotations uniform in ±5° (the experiments' sampling box, sec. 6.1).
pub fn random_poses(count: usize, seed: u64) -> Vec<[f64; 6]> {
    let mut rng = StdRng::seed_from_u64(seed);
    let (lo, hi) = ([-1.5, -1.5, 1.25], [1.5, 1.5, 2.0]);
    let rot = 5f64.to_radians();
    (0..count)
        .map(|_| {
            let mut x = [0.0; 6];
            for k in 0..3 {
                x[k] = lo[k] + (hi[k] - lo[k]) * rng.random::<f64>();
                x[3 + k] = rot * (2.0 * rng.random::<f64>() - 1.0);
            }
            x
        })
        .collect()
}

/// Runs `campaign` on `plant` with `controller`; forces checked against the nominal limits.
pub fn record(
    plant: &mut Plant,
    controller: &Controller,
    nominal: &Nominal,
    campaign: &Campaign,
) -> Recording {
    let mut rows = Vec::new();
    let mut skipped = Vec::new();
    let mut sample = 0u64;
    let mut recorded = 0;
    for (k, x_ref) in campaign.poses.iter().enumerate() {
        if campaign.reachable.is_some_and(|n| recorded >= n) {
            break;
        }
        if campaign.rehome_after == Some(recorded) {
            plant.rehome();
        }
        let q = controller.command(x_ref);
        let guess = PoseQ::from_array(*x_ref);
        let mut visit = |plant: &mut Plant, q: &[f64], phase: Phase, f_hi: f64| {
            let before: PlantState = plant.state();
            let result = plant
                .command(q, guess)
                .map_err(|e| e.to_string())
                .and_then(|eq| {
                    match eq
                        .tensions
                        .iter()
                        .enumerate()
                        .find(|(_, f)| **f < nominal.f_min || **f > f_hi)
                    {
                        Some((i, f)) => Err(format!(
                            "cable {} carries {f:.1} N, outside [{}, {f_hi}] N",
                            i + 1,
                            nominal.f_min
                        )),
                        None => Ok(eq),
                    }
                });
            match result {
                Ok(eq) => {
                    let r = plant.measure(&eq);
                    rows.push(Row {
                        sample,
                        pose_index: k as u64,
                        phase,
                        q_cmd: q.to_vec(),
                        pose: r.pose,
                        forces: r.forces,
                        pose_ref: *x_ref,
                    });
                    sample += 1;
                    true
                }
                Err(reason) => {
                    // The robot is not driven where its forces leave the limits.
                    plant.restore(&before);
                    skipped.push(Skip {
                        pose_index: k,
                        phase,
                        reason,
                    });
                    false
                }
            }
        };
        if !visit(plant, &q, Phase::Pose, nominal.f_max) {
            continue;
        }
        recorded += 1;
        if let Some(s) = campaign.tension_shortening {
            let qt: Vec<f64> = q.iter().map(|v| v - s).collect();
            // A tension test may exceed the operating limit but never the absolute one.
            if visit(plant, &qt, Phase::Tensioned, nominal.f_abs_max) {
                visit(plant, &q, Phase::Returned, nominal.f_max);
            }
        }
    }
    Recording { rows, skipped }
}
