//! The independent plant against plant-oracle's own minimiser, and its effects' mechanics.

use bench_plant::cable::Law;
use bench_plant::plant::{Drum, Hysteresis, HysteresisInput, PlantSpec, Sensors};
use bench_plant::robot::{Cable, Load, Robot};
use bench_plant::{Kind, Nominal, Plant, equilibrium, generate};
use glam::DVec3;
use plant_oracle::PoseQ;

/// The CRS nominal robot of config/crs-nominal.toml (eq. 6.1, 6.19–6.22), typed in here: this
/// crate reads no platform files.
fn crs() -> Nominal {
    let a = [
        [-5.247, 7.865, 6.437],
        [-5.246, 7.853, -1.210],
        [5.263, 7.581, 6.484],
        [5.267, 7.568, -0.651],
        [5.140, -6.415, 6.513],
        [5.148, -6.430, -0.633],
        [-5.638, -6.503, 6.501],
        [-5.636, -6.517, -1.144],
    ];
    let b = [
        [0.233, 0.404, 0.771],
        [0.327, 0.120, -1.072],
        [-0.327, 0.050, 0.883],
        [-0.233, 0.453, -0.958],
        [-0.327, -0.050, 0.883],
        [-0.233, -0.453, -0.958],
        [0.233, -0.404, 0.771],
        [0.327, -0.120, -1.072],
    ];
    Nominal {
        exits: a.iter().map(|v| DVec3::from_array(*v)).collect(),
        anchors: b.iter().map(|v| DVec3::from_array(*v)).collect(),
        k_f: vec![2.0e6; 8],
        wrench: [0.0, 0.0, -5500.0, 0.0, -480.0, 0.0],
        home: [0.0, 0.0, 1.5, 0.0, 0.0, 0.0],
        f_ini: vec![
            3678.0, 2169.0, 4250.0, 1708.0, 3985.0, 2394.0, 4715.0, 1684.0,
        ],
        f_min: 1000.0,
        f_max: 9000.0,
        f_abs_max: 14000.0,
    }
}

fn plain_robot(n: &Nominal, load: Load) -> Robot {
    Robot::new(
        (0..n.m())
            .map(|i| Cable {
                exit: n.exits[i],
                anchor: n.anchors[i],
                pulley: None,
                law: Law::Linear {
                    ea: n.k_f[i],
                    extra: 0.0,
                },
            })
            .collect(),
        load,
    )
}

/// Two minimisers of the same potential (this crate's and plant-oracle's) reach the same pose,
/// with a cabin at a centre of gravity and pulleys.
#[test]
fn the_equilibrium_is_plant_oracles() {
    let n = crs();
    let load = Load {
        mass: 560.0,
        cog: DVec3::new(-0.09, 0.02, -0.3),
        gravity: 9.81,
        force: DVec3::new(20.0, -15.0, 0.0),
        torque: DVec3::ZERO,
    };
    let mut robot = plain_robot(&n, load);
    for c in robot.cables.iter_mut().step_by(2) {
        c.pulley = Some(plant_oracle::Pulley {
            radius: 0.16,
            axis: DVec3::new(0.05, 0.0, 1.0).normalize(),
        });
    }
    let home = PoseQ::from_array(n.home);
    let l_un: Vec<f64> = (0..8)
        .map(|i| robot.span(i, &home).unwrap().length * 0.9985)
        .collect();
    let guess = PoseQ::from_array([0.05, -0.03, 1.52, 0.01, -0.02, 0.015]);
    let mine = equilibrium::solve(&robot, &l_un, guess).unwrap();
    let oracle_robot = plant_oracle::Robot::new(
        robot
            .cables
            .iter()
            .map(|c| plant_oracle::Cable {
                frame_exit: c.exit,
                anchor: c.anchor,
                pulley: c.pulley,
                k_f: c.law.ea(),
            })
            .collect(),
        plant_oracle::Load {
            mass: load.mass,
            center_of_gravity: load.cog,
            gravity: load.gravity,
            force: load.force,
        },
        0.0,
    )
    .unwrap();
    let theirs = plant_oracle::equilibrium(
        &oracle_robot,
        &l_un,
        guess.to_array(),
        &plant_oracle::Options::default(),
    )
    .unwrap();
    let x = mine.pose.to_array();
    for k in 0..6 {
        assert!(
            (x[k] - theirs.pose[k]).abs() < 1e-9,
            "{k}: {x:?} vs {:?}",
            theirs.pose
        );
    }
    for (f, g) in mine.tensions.iter().zip(&theirs.forces) {
        assert!((f - g).abs() < 1e-4, "{f} vs {g}");
    }
}

fn spec(robot: Robot, drum: Drum, hysteresis: Option<Hysteresis>) -> PlantSpec {
    PlantSpec {
        robot,
        drum,
        hysteresis,
        rehoming: None,
        sensors: Sensors {
            gain: vec![1.0; 8],
            offset: vec![0.0; 8],
            force_noise: 0.0,
            position_noise: 0.0,
            rotation_noise: 0.0,
        },
    }
}

fn crs_load(n: &Nominal) -> Load {
    Load {
        mass: 0.0,
        cog: DVec3::ZERO,
        gravity: 9.81,
        force: DVec3::new(n.wrench[0], n.wrench[1], n.wrench[2]),
        torque: DVec3::new(n.wrench[3], n.wrench[4], n.wrench[5]),
    }
}

/// The set-up winds every cable to f_ini at the home pose; released, the platform settles
/// where the constant load balances (a constant torque too, which has no potential).
#[test]
fn the_set_up_tensions_the_cables_and_the_platform_settles() {
    let n = crs();
    let plant = Plant::set_up(
        spec(plain_robot(&n, crs_load(&n)), Drum::Ideal, None),
        n.home,
        &n.f_ini,
        1,
    )
    .unwrap();
    let robot = &plant.spec().robot;
    let home = PoseQ::from_array(n.home);
    let f = robot.tensions(plant.set_up_commands(), &home).unwrap();
    for (a, b) in f.iter().zip(&n.f_ini) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    // Released: the balance of forces and moments from the potential's gradient is zero.
    let st = plant.state();
    let u = |dx: &[f64; 6]| {
        robot
            .potential(plant.set_up_commands(), &st.pose, dx)
            .unwrap()
    };
    for k in 0..6 {
        let mut p = [0.0; 6];
        p[k] = 1e-6;
        let up = u(&p);
        p[k] = -1e-6;
        let g = (up - u(&p)) / 2e-6;
        assert!(g.abs() < 1e-2, "∂U/∂x_{k} = {g}");
    }
    let moved = (st.pose.r - home.r).length();
    assert!(moved > 1e-5 && moved < 0.05, "{moved}");
}

/// The drum maps: from the set-up the paid-out length is the command there; from zero it
/// scales the whole count; a layer step bends it beyond the boundary only.
#[test]
fn drum_variants_pay_out_what_they_say() {
    let n = crs();
    let robot = plain_robot(&n, crs_load(&n));
    let s = vec![0.004; 8];
    let mut p = Plant::set_up(
        spec(robot.clone(), Drum::FromSetUp { scale: s.clone() }, None),
        n.home,
        &n.f_ini,
        1,
    )
    .unwrap();
    let q0 = p.set_up_commands().to_vec();
    let ideal = Plant::set_up(spec(robot.clone(), Drum::Ideal, None), n.home, &n.f_ini, 1).unwrap();
    // At the set-up pose every variant holds the same rope: same commands as the ideal drum.
    for (a, b) in q0.iter().zip(ideal.set_up_commands()) {
        assert!((a - b).abs() < 1e-12);
    }
    let zero = Plant::set_up(
        spec(robot, Drum::FromZero { scale: s }, None),
        n.home,
        &n.f_ini,
        1,
    )
    .unwrap();
    for (a, b) in zero.set_up_commands().iter().zip(&q0) {
        assert!((a * 1.004 - b).abs() < 1e-12);
    }
    // One metre more command pays out 1.004 m more rope: the cables get longer than commanded
    // and the platform hangs lower than with the ideal drum.
    let q: Vec<f64> = q0.iter().map(|v| v + 0.02).collect();
    let e = p.command(&q, PoseQ::from_array(n.home)).unwrap();
    let mut ideal = ideal;
    let e0 = ideal.command(&q, PoseQ::from_array(n.home)).unwrap();
    assert!(
        e.pose.r.z < e0.pose.r.z,
        "{} vs {}",
        e.pose.r.z,
        e0.pose.r.z
    );
}

/// Command-switched hysteresis: +h after lengthening, −h after shortening, held while the
/// command stays; with a dead band a reversal smaller than it does not switch.
#[test]
fn hysteresis_switches_with_the_command_and_holds() {
    let n = crs();
    let robot = plain_robot(&n, crs_load(&n));
    let h = 0.002;
    let hyst = |dead_band| {
        Some(Hysteresis {
            h,
            input: HysteresisInput::Command,
            dead_band,
        })
    };
    let guess = PoseQ::from_array(n.home);
    let mut p = Plant::set_up(
        spec(robot.clone(), Drum::Ideal, hyst(0.0)),
        n.home,
        &n.f_ini,
        1,
    )
    .unwrap();
    let mut ideal =
        Plant::set_up(spec(robot.clone(), Drum::Ideal, None), n.home, &n.f_ini, 1).unwrap();
    let q0 = p.set_up_commands().to_vec();
    let long: Vec<f64> = q0.iter().map(|v| v + 0.01).collect();
    let short: Vec<f64> = q0.iter().map(|v| v - 0.01).collect();
    p.command(&long, guess).unwrap();
    assert!(p.state().triggers.iter().all(|t| t.direction == 1.0));
    // Back to q0 from above: shortening, −h; the same command again: held.
    let a = p.command(&q0, guess).unwrap();
    assert!(p.state().triggers.iter().all(|t| t.direction == -1.0));
    let b = p.command(&q0, guess).unwrap();
    assert_eq!(a, b);
    // −h is a shorter rope: more tension than the ideal drum at the same command.
    let ref_eq = ideal.command(&q0, guess).unwrap();
    let sum = |e: &bench_plant::plant::Equilibrium| e.tensions.iter().sum::<f64>();
    assert!(
        sum(&a) > sum(&ref_eq) + 100.0,
        "{} vs {}",
        sum(&a),
        sum(&ref_eq)
    );
    p.command(&short, guess).unwrap();
    assert!(p.state().triggers.iter().all(|t| t.direction == -1.0));
    // Dead band 5 mm: a 3 mm reversal does not switch, a 6 mm one does.
    let mut d = Plant::set_up(spec(robot, Drum::Ideal, hyst(0.005)), n.home, &n.f_ini, 1).unwrap();
    d.command(&short, guess).unwrap();
    assert!(d.state().triggers.iter().all(|t| t.direction == -1.0));
    let up3: Vec<f64> = short.iter().map(|v| v + 0.003).collect();
    d.command(&up3, guess).unwrap();
    assert!(d.state().triggers.iter().all(|t| t.direction == -1.0));
    let up6: Vec<f64> = short.iter().map(|v| v + 0.006).collect();
    d.command(&up6, guess).unwrap();
    assert!(d.state().triggers.iter().all(|t| t.direction == 1.0));
}

/// Force-switched hysteresis settles on the branches its own force changes select: after all
/// cables are shortened every force rose (loading, −h) and vice versa.
#[test]
fn hysteresis_switches_with_the_force() {
    let n = crs();
    let robot = plain_robot(&n, crs_load(&n));
    let mut p = Plant::set_up(
        spec(
            robot,
            Drum::Ideal,
            Some(Hysteresis {
                h: 0.002,
                input: HysteresisInput::Force,
                dead_band: 0.0,
            }),
        ),
        n.home,
        &n.f_ini,
        1,
    )
    .unwrap();
    let guess = PoseQ::from_array(n.home);
    let q0 = p.set_up_commands().to_vec();
    let short: Vec<f64> = q0.iter().map(|v| v - 0.03).collect();
    p.command(&short, guess).unwrap();
    assert!(p.state().triggers.iter().all(|t| t.direction == -1.0));
    p.command(&q0, guess).unwrap();
    assert!(p.state().triggers.iter().all(|t| t.direction == 1.0));
}

/// A whole scenario records rows for identification and validation, skipping what leaves the
/// force limits, in every kind.
#[test]
fn every_kind_records_a_campaign() {
    let n = crs();
    for kind in Kind::ALL {
        let g = generate(&n, &[kind], &[0.5], 7, 8).unwrap();
        assert!(
            g.train.rows.len() >= 9 && g.holdout.rows.len() >= 6,
            "{}: {} / {} rows, skipped {:?}",
            kind.name(),
            g.train.rows.len(),
            g.holdout.rows.len(),
            g.train.skipped
        );
    }
}
