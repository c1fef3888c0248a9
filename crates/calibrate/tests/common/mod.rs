#![allow(dead_code)]
//! Test data from the simulated plant (sim-plant): campaigns with chosen effects.

use calibrate::{Observation, from_dataset};
use cdpr_model::config::{Platform, load_platform};
use nalgebra::Vector3;
use sim_plant::config::Effects;
use sim_plant::{CampaignConfig, Plant, PlantConfig, PoseSet, run_campaign};
use std::path::PathBuf;

pub fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

pub fn nominal() -> Platform {
    load_platform(config_dir().join("crs-nominal.toml")).expect("nominal platform")
}

/// Geometry deviation of the CRS-like plant (config/plant/crs-like.toml).
pub fn crs_like_effects() -> Effects {
    sim_plant::load_plant(config_dir().join("plant/crs-like.toml"))
        .expect("crs-like plant")
        .effects
}

/// Runs a random-pose campaign on a plant with `effects` under nominal kinematic control.
pub fn campaign(effects: Effects, poses: usize, seed: u64, tension_test: bool) -> Vec<Observation> {
    let platform = nominal();
    let mut cfg = PlantConfig::ideal(platform.clone(), config_dir().join("crs-nominal.toml"));
    cfg.effects = effects;
    let mut plant = Plant::new(cfg).expect("plant");
    let campaign = CampaignConfig {
        name: "test".into(),
        poses: PoseSet::Random {
            min: Vector3::new(-1.5, -1.5, 1.25),
            max: Vector3::new(1.5, 1.5, 2.0),
            count: poses,
            rotation_max: Vector3::repeat(5f64.to_radians()),
            seed,
        },
        tension_test: tension_test.then_some(0.03),
        ..CampaignConfig::default()
    };
    let res = run_campaign(&mut plant, &platform, &campaign, "test").expect("campaign");
    from_dataset(&res.dataset, platform.model.m()).expect("observations")
}
