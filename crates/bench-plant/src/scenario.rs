//! The benchmark's scenarios: which effects a true plant carries and how large. Every plant
//! also differs from the nominal robot as a real one does (frame anchors a few cm, platform
//! anchors a few mm, rope stiffness ±10 %, the load a few per cent off) and is read through a
//! 2 mm / 0.05° tracker and 20 N load cells.
//!
//! Magnitudes are drawn log-uniformly between the smallest a 120-row campaign can hope to see
//! and the largest a robot of this size (14 × 10 × 8 m frame, ~600 kg load, 14 mm ropes on
//! 152 mm drums) shows; the ranges are listed per kind in [`Kind::range`].

use crate::cable::Law;
use crate::campaign::Nominal;
use crate::plant::{Drum, Hysteresis, HysteresisInput, PlantSpec, Sensors};
use crate::robot::{Cable, Load, Robot};
use glam::DVec3;
use plant_oracle::{PoseQ, Pulley};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// One effect variant of the benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// No effect beyond the real robot's geometry, stiffness and load deviations.
    Baseline,
    /// Drum radius error counted from the set-up: L = q + s (q − q₀).
    DrumFromSetUp,
    /// Drum radius error counted from the encoder's zero: L = (1 + s) q.
    DrumFromZero,
    /// A second rope layer within the workspace: a step of the drum's effective radius.
    DrumLayerStep,
    /// ±h length offset switched by the sign of the cable's last command change, held.
    HysteresisCommand,
    /// The same, switching only after the command reversed by more than 5 mm.
    HysteresisCommandDeadBand,
    /// ±h length offset switched by the direction of the cable's force (loading/unloading).
    HysteresisForce,
    /// The same, switching only after the force reversed by more than 300 N.
    HysteresisForceDeadBand,
    /// Rope stored in the drive train: f = EA (q − L)/(q + l_i).
    PowertrainRope,
    /// A compliant drive train (winch frame, pulleys): one series compliance c for all
    /// cables, the stiffness drop f = (q − L)/(q/EA + c).
    PowertrainCompliance,
    /// Constructional stretch: the rope is soft at low tension.
    Stiffness,
    /// The rope's weight: exact elastic catenaries.
    Sag,
    /// Pulleys at the frame exits, each with its own radius and a tilted swivel axis.
    Pulleys,
    /// Part of the load is a cabin whose centre of gravity is off the platform origin: its
    /// torque turns with the platform.
    LoadCog,
    /// Load-cell gain and offset errors.
    ForceSensors,
    /// The winches are re-homed half-way through the identification campaign with encoder
    /// errors of a few mm (the validation campaign has the new ones): no catalogue effect.
    Rehoming,
}

impl Kind {
    pub const ALL: [Kind; 16] = [
        Kind::Baseline,
        Kind::DrumFromSetUp,
        Kind::DrumFromZero,
        Kind::DrumLayerStep,
        Kind::HysteresisCommand,
        Kind::HysteresisCommandDeadBand,
        Kind::HysteresisForce,
        Kind::HysteresisForceDeadBand,
        Kind::PowertrainRope,
        Kind::PowertrainCompliance,
        Kind::Stiffness,
        Kind::Sag,
        Kind::Pulleys,
        Kind::LoadCog,
        Kind::ForceSensors,
        Kind::Rehoming,
    ];

    pub fn name(&self) -> &'static str {
        match self {
            Kind::Baseline => "baseline",
            Kind::DrumFromSetUp => "drum-setup",
            Kind::DrumFromZero => "drum-zero",
            Kind::DrumLayerStep => "drum-layer",
            Kind::HysteresisCommand => "hysteresis-command",
            Kind::HysteresisCommandDeadBand => "hysteresis-command-deadband",
            Kind::HysteresisForce => "hysteresis-force",
            Kind::HysteresisForceDeadBand => "hysteresis-force-deadband",
            Kind::PowertrainRope => "powertrain-rope",
            Kind::PowertrainCompliance => "powertrain-compliance",
            Kind::Stiffness => "stiffness",
            Kind::Sag => "sag",
            Kind::Pulleys => "pulleys",
            Kind::LoadCog => "load-cog",
            Kind::ForceSensors => "force-sensors",
            Kind::Rehoming => "rehoming",
        }
    }

    pub fn from_name(s: &str) -> Option<Kind> {
        Kind::ALL.iter().copied().find(|k| k.name() == s)
    }

    /// The physical effect it is an instance of (a calibration engineer's word for it), or
    /// `None` for the baseline and for effects outside any catalogue (re-homing).
    pub fn effect(&self) -> Option<&'static str> {
        match self {
            Kind::Baseline | Kind::Rehoming => None,
            Kind::DrumFromSetUp | Kind::DrumFromZero | Kind::DrumLayerStep => Some("drum"),
            Kind::HysteresisCommand
            | Kind::HysteresisCommandDeadBand
            | Kind::HysteresisForce
            | Kind::HysteresisForceDeadBand => Some("hysteresis"),
            Kind::PowertrainRope | Kind::PowertrainCompliance => Some("powertrain"),
            Kind::Stiffness => Some("stiffness"),
            Kind::Sag => Some("sag"),
            Kind::Pulleys => Some("pulleys"),
            Kind::LoadCog => Some("load_cog"),
            Kind::ForceSensors => Some("force_sensors"),
        }
    }

    /// Magnitude range (smallest, largest), its unit and what it is.
    pub fn range(&self) -> (f64, f64, &'static str, &'static str) {
        match self {
            Kind::Baseline => (0.0, 0.0, "", "none"),
            Kind::DrumFromSetUp | Kind::DrumFromZero => {
                (3e-4, 6e-3, "1", "largest drum scale |s_i|")
            }
            Kind::DrumLayerStep => (1e-3, 1e-2, "1", "layer step of the paid-out length"),
            Kind::HysteresisCommand
            | Kind::HysteresisCommandDeadBand
            | Kind::HysteresisForce
            | Kind::HysteresisForceDeadBand => (2e-4, 3e-3, "m", "hysteresis half width h"),
            Kind::PowertrainRope => (2.0, 20.0, "m", "largest stored rope l_i"),
            Kind::PowertrainCompliance => (1e-6, 1e-5, "m/N", "drive-train compliance c"),
            Kind::Stiffness => (1e-4, 8e-4, "1", "constructional strain ε₀"),
            Kind::Sag => (0.3, 2.5, "kg/m", "rope mass per length μ"),
            Kind::Pulleys => (0.04, 0.25, "m", "pulley radius r"),
            Kind::LoadCog => (0.05, 0.5, "m", "cabin centre of gravity |c|"),
            Kind::ForceSensors => (2e-3, 3e-2, "1", "largest load-cell gain error |γ_i|"),
            Kind::Rehoming => (1e-3, 8e-3, "m", "largest re-homing encoder error"),
        }
    }

    /// The magnitude at fraction `u` ∈ [0, 1] of its range (log-uniform).
    pub fn magnitude(&self, u: f64) -> f64 {
        let (lo, hi, ..) = self.range();
        if lo <= 0.0 {
            0.0
        } else {
            lo * (hi / lo).powf(u.clamp(0.0, 1.0))
        }
    }
}

/// A true value of one effect (for comparison with what a calibration finds).
#[derive(Clone, Debug, PartialEq)]
pub struct TrueValue {
    pub kind: Kind,
    /// e.g. "s" (drum scale), "h" (hysteresis, m), "l" (stored rope, m).
    pub name: &'static str,
    /// Per cable, or one entry for a shared value.
    pub values: Vec<f64>,
}

/// A true plant and what is true about it.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    pub spec: PlantSpec,
    pub kinds: Vec<Kind>,
    /// Drawn magnitude per kind (in the unit of [`Kind::range`]).
    pub magnitudes: Vec<f64>,
    pub values: Vec<TrueValue>,
    /// The winches are re-homed half-way through the identification campaign (before the
    /// validation campaign in any case).
    pub rehome_half_way: bool,
}

/// Tracker noise (1σ): a Vicon-class system on a robot of this size.
pub const POSITION_NOISE_M: f64 = 0.002;
pub const ROTATION_NOISE_RAD: f64 = 0.05 * std::f64::consts::PI / 180.0;
/// Load-cell noise (1σ), N.
pub const FORCE_NOISE_N: f64 = 20.0;
/// Standard gravity, m/s².
const G: f64 = 9.80665;

fn sym(rng: &mut StdRng, a: f64) -> f64 {
    a * (2.0 * rng.random::<f64>() - 1.0)
}

fn sign(rng: &mut StdRng) -> f64 {
    if rng.random::<bool>() { 1.0 } else { -1.0 }
}

/// Builds the true plant for `kinds` (one or two effects; `Baseline` alone for none) at
/// magnitude fractions `u` (one per kind), drawing everything else from `seed`.
pub fn build(nominal: &Nominal, kinds: &[Kind], u: &[f64], seed: u64) -> Truth {
    let m = nominal.m();
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5EED_BE4C_u64.rotate_left(17));
    // The real robot: assembly and survey errors no effect is about.
    let exits: Vec<DVec3> = nominal
        .exits
        .iter()
        .map(|a| {
            *a + DVec3::new(
                sym(&mut rng, 0.15),
                sym(&mut rng, 0.15),
                sym(&mut rng, 0.15),
            )
        })
        .collect();
    let anchors: Vec<DVec3> = nominal
        .anchors
        .iter()
        .map(|b| {
            *b + DVec3::new(
                sym(&mut rng, 0.005),
                sym(&mut rng, 0.005),
                sym(&mut rng, 0.005),
            )
        })
        .collect();
    let ea: Vec<f64> = nominal
        .k_f
        .iter()
        .map(|k| k * (1.0 + sym(&mut rng, 0.1)))
        .collect();
    let w = nominal.wrench;
    let mut force = DVec3::new(
        w[0] + sym(&mut rng, 30.0),
        w[1] + sym(&mut rng, 30.0),
        w[2] * (1.0 + sym(&mut rng, 0.03)),
    );
    let mut torque = DVec3::new(
        w[3] + sym(&mut rng, 40.0),
        w[4] + sym(&mut rng, 40.0),
        w[5] + sym(&mut rng, 20.0),
    );
    let mut laws: Vec<Law> = ea
        .iter()
        .map(|&ea| Law::Linear { ea, extra: 0.0 })
        .collect();
    let mut pulleys: Vec<Option<Pulley>> = vec![None; m];
    let mut drum = Drum::Ideal;
    let mut hysteresis = None;
    let mut rehoming = None;
    let mut rehome_half_way = false;
    let mut load = Load {
        mass: 0.0,
        cog: DVec3::ZERO,
        gravity: G,
        force: DVec3::ZERO,
        torque: DVec3::ZERO,
    };
    let mut gain = vec![1.0; m];
    let mut offset = vec![0.0; m];
    let mut values = Vec::new();
    let mut magnitudes = Vec::new();
    for (kind, &uk) in kinds.iter().zip(u) {
        let a = kind.magnitude(uk);
        magnitudes.push(a);
        // Per-cable magnitudes: the largest is `a`, the others spread below it.
        let per_cable = |rng: &mut StdRng, signed: bool| -> Vec<f64> {
            let mut v: Vec<f64> = (0..m)
                .map(|_| {
                    a * (0.4 + 0.6 * rng.random::<f64>()) * if signed { sign(rng) } else { 1.0 }
                })
                .collect();
            let k = rng.random_range(0..m);
            v[k] = a * v[k].signum();
            v
        };
        match kind {
            Kind::Baseline => {}
            Kind::DrumFromSetUp | Kind::DrumFromZero => {
                let s = per_cable(&mut rng, true);
                values.push(TrueValue {
                    kind: *kind,
                    name: "s",
                    values: s.clone(),
                });
                drum = if *kind == Kind::DrumFromSetUp {
                    Drum::FromSetUp { scale: s }
                } else {
                    Drum::FromZero { scale: s }
                };
            }
            Kind::DrumLayerStep => {
                let step = per_cable(&mut rng, false);
                let boundary: Vec<f64> = (0..m).map(|_| sym(&mut rng, 0.4)).collect();
                values.push(TrueValue {
                    kind: *kind,
                    name: "layer step",
                    values: step.clone(),
                });
                drum = Drum::LayerStep { step, boundary };
            }
            Kind::HysteresisCommand
            | Kind::HysteresisCommandDeadBand
            | Kind::HysteresisForce
            | Kind::HysteresisForceDeadBand => {
                let (input, dead_band) = match kind {
                    Kind::HysteresisCommand => (HysteresisInput::Command, 0.0),
                    Kind::HysteresisCommandDeadBand => (HysteresisInput::Command, 0.005),
                    Kind::HysteresisForce => (HysteresisInput::Force, 0.0),
                    _ => (HysteresisInput::Force, 300.0),
                };
                values.push(TrueValue {
                    kind: *kind,
                    name: "h",
                    values: vec![a],
                });
                hysteresis = Some(Hysteresis {
                    h: a,
                    input,
                    dead_band,
                });
            }
            Kind::PowertrainRope | Kind::PowertrainCompliance => {
                let extra: Vec<f64> = if *kind == Kind::PowertrainRope {
                    per_cable(&mut rng, false)
                } else {
                    // f = (q − L)/(q/EA + c) = EA (q − L)/(q + EA c).
                    ea.iter().map(|e| e * a).collect()
                };
                values.push(TrueValue {
                    kind: *kind,
                    name: "l",
                    values: extra.clone(),
                });
                for (law, l) in laws.iter_mut().zip(&extra) {
                    if let Law::Linear { extra, .. } = law {
                        *extra = *l;
                    }
                }
            }
            Kind::Stiffness => {
                values.push(TrueValue {
                    kind: *kind,
                    name: "eps0",
                    values: vec![a],
                });
                for (law, e) in laws.iter_mut().zip(&ea) {
                    // The secant stiffness at the working strain (~2.5e-3) stays that of the
                    // rope: EA grows by the strain the constructional stretch takes there.
                    let ea_hi = e * (1.0 + a / 2.5e-3);
                    let extra = match law {
                        Law::Linear { extra, .. } => *extra,
                        _ => 0.0,
                    };
                    *law = Law::Stiffening {
                        ea: ea_hi,
                        extra,
                        eps0: a,
                    };
                }
            }
            Kind::Sag => {
                values.push(TrueValue {
                    kind: *kind,
                    name: "mu",
                    values: vec![a],
                });
                for (law, e) in laws.iter_mut().zip(&ea) {
                    *law = Law::Catenary {
                        ea: *e,
                        weight_per_m: a * G,
                    };
                }
            }
            Kind::Pulleys => {
                let r: Vec<f64> = (0..m)
                    .map(|_| a * (0.9 + 0.2 * rng.random::<f64>()))
                    .collect();
                for (p, ri) in pulleys.iter_mut().zip(&r) {
                    let tilt = 5f64.to_radians() * rng.random::<f64>();
                    let az = std::f64::consts::TAU * rng.random::<f64>();
                    let axis = DVec3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
                    *p = Some(Pulley { radius: *ri, axis });
                }
                values.push(TrueValue {
                    kind: *kind,
                    name: "r",
                    values: r,
                });
            }
            Kind::LoadCog => {
                // A 600 kg cabin at c; the constant part is reduced so that the load at the
                // home pose is unchanged (what the nominal wrench describes).
                let dir = DVec3::new(sym(&mut rng, 1.0), sym(&mut rng, 1.0), sym(&mut rng, 1.0))
                    .normalize_or(DVec3::Z);
                let c = dir * a;
                let mass = 600.0;
                let home = PoseQ::from_array(nominal.home);
                let fg = DVec3::new(0.0, 0.0, -mass * G);
                force -= fg;
                torque -= (home.q * c).cross(fg);
                load.mass = mass;
                load.cog = c;
                values.push(TrueValue {
                    kind: *kind,
                    name: "c",
                    values: vec![c.x, c.y, c.z],
                });
            }
            Kind::ForceSensors => {
                let g = per_cable(&mut rng, true);
                for i in 0..m {
                    gain[i] = 1.0 + g[i];
                    offset[i] = sym(&mut rng, a * 2500.0);
                }
                values.push(TrueValue {
                    kind: *kind,
                    name: "gain error",
                    values: g,
                });
            }
            Kind::Rehoming => {
                let off: Vec<f64> = (0..m).map(|_| sym(&mut rng, a)).collect();
                values.push(TrueValue {
                    kind: *kind,
                    name: "encoder offset",
                    values: off.clone(),
                });
                rehoming = Some(off);
                rehome_half_way = true;
            }
        }
    }
    load.force = force;
    load.torque = torque;
    let cables = (0..m)
        .map(|i| Cable {
            exit: exits[i],
            anchor: anchors[i],
            pulley: pulleys[i],
            law: laws[i],
        })
        .collect();
    Truth {
        spec: PlantSpec {
            robot: Robot::new(cables, load),
            drum,
            hysteresis,
            rehoming,
            sensors: Sensors {
                gain,
                offset,
                force_noise: FORCE_NOISE_N,
                position_noise: POSITION_NOISE_M,
                rotation_noise: ROTATION_NOISE_RAD,
            },
        },
        kinds: kinds.to_vec(),
        magnitudes,
        values,
        rehome_half_way,
    }
}
