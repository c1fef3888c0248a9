//! `crs commission` on the running simulated stack, and `crs load track`.
//! The commissioning's identified payload is checked against the PLANT's truth (the
//! plant is the oracle, the estimator sees only force readings), and a cabin with an extra
//! 60 kg rider whose weight sits 0.25 m above the floor of the configured load must be refused
//! (exit non-zero, "REFUSED", commission.toml says not ready), with its COG height found from
//! the tilted poses.
mod common;
use common::{root, stack_bin_dir};
use std::path::{Path, PathBuf};
use std::process::Command;

fn crs() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_crs"))
}

fn commission(out: &Path, plant: Option<&Path>) -> (bool, String) {
    let mut c = Command::new(crs());
    c.current_dir(root()).args([
        "commission",
        "--platform",
        "helicopter",
        "--timing",
        "relaxed",
        "--transport",
        "wire",
        "--dwell-s",
        "1.0",
    ]);
    c.arg("--out").arg(out);
    if let Some(p) = plant {
        c.arg("--plant").arg(p);
    }
    let o = c.output().expect("run crs commission");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.success(), text)
}

fn value(toml: &toml::Table, section: &str, key: &str) -> f64 {
    toml[section][key]
        .as_float()
        .unwrap_or_else(|| panic!("{section}.{key}"))
}

#[test]
fn commissioning_finds_the_plants_payload_and_refuses_an_unexpected_rider() {
    let _one = common::one_stack();
    stack_bin_dir(&crs());
    let base = std::env::temp_dir().join(format!("crs-commission-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);

    // 1. The shipped helicopter plant: its load is the configured one.
    let (ok, text) = commission(&base.join("ok"), None);
    assert!(ok, "commissioning of the shipped cabin failed:\n{text}");
    assert!(text.contains("PRE-RIDE CHECK: READY"), "{text}");
    let t: toml::Table = std::fs::read_to_string(base.join("ok/commission.toml"))
        .unwrap()
        .parse()
        .expect("commission.toml parses");
    let truth = value(&t, "payload", "plant_truth_mass_kg");
    let mass = value(&t, "payload", "mass_kg");
    assert!(
        (mass - truth).abs() < 5.0,
        "mass {mass} kg vs plant {truth} kg"
    );
    assert_eq!(t["verdict"]["ready"].as_bool(), Some(true));
    // The forces are averaged over each rest window: c_z resolves to centimetres.
    let cz = t["payload"]["cog_m"][2].as_float().expect("c_z observable");
    let cz_std = t["payload"]["cog_std_m"][2].as_float().unwrap();
    assert!(
        cz.abs() < 0.04 && cz_std < 0.02,
        "COG height {cz} ± {cz_std} m vs 0"
    );
    // eq. 6.24: offsets are negative elongations of a few centimetres at ~5 kN.
    for q in t["setup"]["q_off_m"].as_array().unwrap() {
        let q = q.as_float().unwrap();
        assert!((-0.05..-0.005).contains(&q), "q_off {q} m");
    }
    assert!(
        t["initial_tension"]["f_ini_n"].as_array().is_some(),
        "{t:?}"
    );

    // 2. An extra rider: the plant carries 60 kg more, with the COG raised.
    let plant_text = std::fs::read_to_string(root().join("config/plant/helicopter.toml")).unwrap();
    let platform = root().join("config/helicopter.toml");
    let heavy = plant_text.replace(
        "platform = \"../helicopter.toml\"",
        &format!("platform = {:?}", platform.display().to_string()),
    ) + "\n[load]\nenabled = true\nmass_kg = 824.5\ncenter_of_gravity_m = [-0.074, 0.0, 0.25]\n";
    std::fs::create_dir_all(&base).unwrap();
    let heavy_path = base.join("heavy-plant.toml");
    std::fs::write(&heavy_path, heavy).unwrap();
    let (ok, text) = commission(&base.join("heavy"), Some(&heavy_path));
    assert!(!ok, "an unexpected 60 kg must be refused:\n{text}");
    assert!(text.contains("PRE-RIDE CHECK: REFUSED"), "{text}");
    assert!(text.contains("payload mass"), "{text}");
    let t: toml::Table = std::fs::read_to_string(base.join("heavy/commission.toml"))
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(t["verdict"]["ready"].as_bool(), Some(false));
    let mass = value(&t, "payload", "mass_kg");
    assert!((mass - 824.5).abs() < 5.0, "mass {mass} kg vs 824.5 kg");
    let cz = t["payload"]["cog_m"][2]
        .as_float()
        .expect("c_z observable with tilts");
    assert!((cz - 0.25).abs() < 0.04, "COG height {cz} m vs 0.25 m");
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn load_track_follows_the_walking_subject_within_the_seeds_accuracy() {
    let _one = common::one_stack();
    let out = std::env::temp_dir().join(format!("crs-load-track-{}", std::process::id()));
    let o = Command::new(crs())
        .current_dir(root())
        .args(["load", "track", "--laps", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.join("walk.svg").is_file());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("walk.json")).unwrap()).unwrap();
    let mean = r["error_mean_m"].as_f64().unwrap();
    assert!(mean < 0.097, "mean tracking error {mean} m");
    assert_eq!(r["failed"].as_u64(), Some(0));
    let bad = Command::new(crs())
        .args(["load", "track", "--subject-kg=-3"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--subject-kg"));
    let _ = std::fs::remove_dir_all(&out);
}
