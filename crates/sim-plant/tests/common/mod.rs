#![allow(dead_code)]

use cdpr_model::Pose;
use sim_plant::config::parse_plant;
use sim_plant::{Plant, PlantConfig, load_plant};
use std::path::PathBuf;

pub fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

pub fn ideal() -> PlantConfig {
    load_plant(config_dir().join("plant/crs-ideal.toml")).expect("crs-ideal.toml")
}

pub fn crs_like() -> PlantConfig {
    load_plant(config_dir().join("plant/crs-like.toml")).expect("crs-like.toml")
}

/// A plant config from TOML text placed in config/plant/ (so `../crs-nominal.toml` resolves).
pub fn plant_from(text: &str) -> Result<PlantConfig, cdpr_model::config::ConfigError> {
    parse_plant(text, "test.toml", &config_dir().join("plant"))
}

/// crs-like with every effect off except the named ones.
pub fn only(names: &[&str]) -> PlantConfig {
    let full = crs_like();
    let mut c = ideal();
    let fx = &full.effects;
    for n in names {
        match *n {
            "geometry" => c.effects.geometry = fx.geometry.clone(),
            "pulleys" => c.effects.pulleys = fx.pulleys.clone(),
            "powertrain" => c.effects.powertrain = fx.powertrain.clone(),
            "stiffness" => c.effects.stiffness = fx.stiffness,
            "hysteresis" => c.effects.hysteresis = fx.hysteresis,
            "sag" => c.effects.sag = fx.sag,
            "winch" => c.effects.winch = fx.winch.clone(),
            "load" => c.effects.load = fx.load,
            "tracker" => c.effects.tracker = fx.tracker,
            "force_sensors" => c.effects.force_sensors = fx.force_sensors.clone(),
            other => panic!("unknown effect {other}"),
        }
    }
    c
}

/// Commands that put the ideal (nominal) model at `pose` with the nominal f_ini propagated.
pub fn home_command(plant: &mut Plant) -> Vec<f64> {
    let p = plant.config().platform.clone();
    plant
        .setup_tension(&p.home, p.f_ini.as_ref().unwrap())
        .unwrap()
        .q_cmd
}

pub fn pose(x: f64, y: f64, z: f64, a: f64, b: f64, c: f64) -> Pose {
    Pose::from_array([x, y, z, a.to_radians(), b.to_radians(), c.to_radians()])
}

pub fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

pub fn pose_bits(p: &Pose) -> Vec<u64> {
    bits(&p.to_array())
}
