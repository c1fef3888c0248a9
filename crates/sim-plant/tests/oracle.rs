//! The plant against its independent oracle: the model library's
//! elastostatic equilibrium (what plant and controller share) and `plant-oracle`'s minimum of
//! the potential energy agree to round-off on every shipped plant's conservative twin and under
//! random commands; a robot the oracle is told differently (1 mm anchor, no pulley) disagrees
//! by far more than the tolerance, so the check can fail.

use sim_plant::oracle_check::{
    self, FORCE_TOLERANCE_N, POSITION_TOLERANCE_M, ROTATION_TOLERANCE_RAD,
};
use sim_plant::{Plant, load_plant};
use std::path::PathBuf;

fn plant_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/plant")
}

/// Every shipped plant TOML (the campaign files in the same folder are not plants).
fn shipped_plants() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(plant_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension().is_some_and(|e| e == "toml")
                && !p
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with("campaign")
        })
        .collect();
    v.sort();
    v
}

#[test]
fn every_shipped_plant_agrees_with_the_oracle() {
    let plants = shipped_plants();
    assert!(plants.len() >= 5, "{plants:?}");
    for path in plants {
        let cfg = load_plant(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let a = oracle_check::check_against_oracle(&cfg)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        println!("{}: {a}", path.display());
        assert!(a.poses >= 3, "{}: {a}", path.display());
        assert!(a.within_tolerance(), "{}: {a}", path.display());
    }
}

/// Commands around the set-up ones, ±10 mm per cable (uniform, fixed seed): the plant steps
/// from one equilibrium to the next (its warm start, its continuation), the oracle starts
/// afresh each time.
#[test]
fn random_commands_agree_on_the_helicopter_twin() {
    let cfg = load_plant(plant_dir().join("helicopter.toml")).unwrap();
    let (twin, _) = oracle_check::conservative_twin(&cfg);
    let mut plant = Plant::new(twin).unwrap();
    let robot = oracle_check::oracle_robot(&plant).unwrap();
    let home = plant.config().platform.home;
    let f_ini = oracle_check::set_up_forces(&plant);
    let q0 = plant.setup_tension(&home, &f_ini).unwrap().q_cmd;
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut uniform = || {
        // xorshift64*: a fixed, dependency-free sequence.
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut max_p, mut max_r, mut max_f) = (0.0_f64, 0.0_f64, 0.0_f64);
    for _ in 0..20 {
        let q: Vec<f64> = q0.iter().map(|q| q + 0.02 * (uniform() - 0.5)).collect();
        let (dp, dr, df) = oracle_check::compare(&mut plant, &robot, &q).unwrap();
        max_p = max_p.max(dp);
        max_r = max_r.max(dr);
        max_f = max_f.max(df);
    }
    println!(
        "20 random commands: position {max_p:.1e} m, rotation {max_r:.1e} rad, force {max_f:.1e} N"
    );
    assert!(max_p < POSITION_TOLERANCE_M, "{max_p}");
    assert!(max_r < ROTATION_TOLERANCE_RAD, "{max_r}");
    assert!(max_f < FORCE_TOLERANCE_N, "{max_f}");
}

/// The check is not vacuous: an oracle told of a 1 mm different anchor, or of no pulleys on a
/// plant with pulleys, disagrees by orders of magnitude more than the tolerance.
#[test]
fn a_different_robot_is_seen() {
    let cfg = load_plant(plant_dir().join("crs-like.toml")).unwrap();
    let (twin, _) = oracle_check::conservative_twin(&cfg);
    assert!(twin.effects.pulleys.is_some(), "crs-like has pulleys");
    let mut plant = Plant::new(twin).unwrap();
    let home = plant.config().platform.home;
    let f_ini = oracle_check::set_up_forces(&plant);
    let q = plant.setup_tension(&home, &f_ini).unwrap().q_cmd;
    let right = oracle_check::oracle_robot(&plant).unwrap();
    let (dp, _, _) = oracle_check::compare(&mut plant, &right, &q).unwrap();
    assert!(dp < POSITION_TOLERANCE_M, "{dp}");

    let mut cables = right.cables().to_vec();
    cables[2].anchor.x += 0.001;
    let moved = plant_oracle::Robot::new(cables, *right.load(), 0.0).unwrap();
    let (dp, dr, df) = oracle_check::compare(&mut plant, &moved, &q).unwrap();
    println!("1 mm anchor: {dp:.1e} m, {dr:.1e} rad, {df:.1e} N");
    assert!(
        dp > 100.0 * POSITION_TOLERANCE_M || dr > 100.0 * ROTATION_TOLERANCE_RAD,
        "{dp} {dr}"
    );

    let mut cables = right.cables().to_vec();
    for c in &mut cables {
        c.pulley = None;
    }
    let no_pulleys = plant_oracle::Robot::new(cables, *right.load(), 0.0).unwrap();
    let (dp, dr, df) = oracle_check::compare(&mut plant, &no_pulleys, &q).unwrap();
    println!("no pulleys: {dp:.1e} m, {dr:.1e} rad, {df:.1e} N");
    assert!(df > 100.0 * FORCE_TOLERANCE_N || dp > 1000.0 * POSITION_TOLERANCE_M);
}
