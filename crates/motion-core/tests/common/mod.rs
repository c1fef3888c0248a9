//! Fixtures of the daemon's tests: the shipped configs. (The model's fixtures — poses, finite
//! differences — moved with the model tests to crates/cdpr-model/tests/common.)
#![allow(dead_code)]
use cdpr_model::config::{Platform, load_platform};

pub fn config_path(name: &str) -> String {
    format!("{}/../../config/{name}", env!("CARGO_MANIFEST_DIR"))
}

pub fn platform(name: &str) -> Platform {
    load_platform(config_path(name)).unwrap_or_else(|e| panic!("{e}"))
}
