//! The monitor's independent implementation agrees with motion-core's (which is a dev-dependency
//! ONLY: the monitor itself never links motion-core code).
//! * the platform identity computed from the monitor's own parse equals `Platform::identity()`
//!   (model, workspace box, limits) and its model part `Model::identity()` bit for
//!   bit on the project's platform files (a mismatch would trip the monitor at start);
//! * φ*(x) equals motion-core's standard inverse kinematics to 1e-9 m over the workspace.

use cdpr_model::config::{load_platform as mc_load, parse_platform as mc_parse};
use proptest::prelude::*;
use safety_monitor::identity::{model_identity, platform_identity};
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::platform::{load_platform, parse_platform};
use std::path::PathBuf;

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

/// Every platform file shipped in config/ (every TOML there with a `[geometry]` table, so a new
/// platform is covered without editing this list).
fn platform_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(config(""))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| {
            std::fs::read_to_string(p)
                .unwrap()
                .lines()
                .any(|l| l.trim() == "[geometry]")
        })
        .collect();
    files.sort();
    files
}

#[test]
fn identity_agrees_with_motion_core_on_the_platform_files() {
    let files = platform_files();
    for known in [
        "icosahedron.toml",
        "helicopter.toml",
        "icosahedron-pulleys.toml",
        "crs-nominal.toml",
    ] {
        assert!(
            files.iter().any(|f| f.ends_with(known)),
            "{known} not found among {files:?}"
        );
    }
    for p in &files {
        let f = p.display();
        let mine = load_platform(p).unwrap();
        let theirs = mc_load(p).unwrap();
        assert_eq!(
            model_identity(&mine),
            theirs.model.identity(),
            "{f}: model identity differs"
        );
        assert_eq!(
            platform_identity(&mine),
            theirs.identity(),
            "{f}: identity differs"
        );
    }
    // Different platforms have different identities.
    let a = platform_identity(&load_platform(&config("icosahedron.toml")).unwrap());
    let b = platform_identity(&load_platform(&config("helicopter.toml")).unwrap());
    assert_ne!(a, b);
}

/// Non-unit pulley axes and per-cable arrays exercise the normalisation and the array forms.
#[test]
fn identity_agrees_with_non_unit_pulley_axes_and_per_cable_values() {
    let text = std::fs::read_to_string(config("icosahedron.toml")).unwrap();
    let text = text.replace(
        "k_f_n = 2.0e6",
        "k_f_n = [2.0e6, 2.1e6, 1.9e6, 2.0e6, 2.05e6, 1.95e6, 2.0e6, 2000000]",
    ) + "\n[pulleys]\nradius_m = [0.161, 0.15, 0.161, 0.17, 0.161, 0.1, 0.161, 0.2]\n\
         swivel_axes = [[0.3, 0.4, 1.2], [0, 0, 3], [0.1, -0.2, 0.7], [1e-3, 0, 1], \
         [0, 0, 1], [-0.5, 0.25, 2], [0.2, 0.2, 0.2], [0, 0.6, 0.8]]\n";
    let ours = platform_identity(&parse_platform(&text, "mem").unwrap());
    let theirs = mc_parse(&text, "mem").unwrap().identity();
    assert_eq!(ours, theirs);
}

/// The identity covers the workspace box and the motion limits, not only the model:
/// changing any one of them changes both implementations' identity identically.
#[test]
fn identity_covers_workspace_box_and_limits() {
    let text = std::fs::read_to_string(config("icosahedron.toml")).unwrap();
    let base = platform_identity(&parse_platform(&text, "mem").unwrap());
    let mut edits = 0;
    for key in [
        "position_max_m",
        "rotation_min_deg",
        "linear_velocity_max_m_per_s",
        "angular_acceleration_max_deg_per_s2",
    ] {
        // Scale the first number of the key's line by 0.9 (stays valid: boxes shrink, limits
        // drop).
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key} =")))
            .unwrap_or_else(|| panic!("{key} not in icosahedron.toml"));
        let edited_line = {
            let (k, v) = line.split_once('=').unwrap();
            let v = v.trim();
            let scaled = if let Some(inner) = v.strip_prefix('[') {
                let inner = inner.split(']').next().unwrap();
                let nums: Vec<f64> = inner
                    .split(',')
                    .map(|x| x.trim().parse().unwrap())
                    .collect();
                let s: Vec<String> = nums.iter().map(|x| format!("{:?}", x * 0.9)).collect();
                format!("[{}]", s.join(", "))
            } else {
                let x: f64 = v.split_whitespace().next().unwrap().parse().unwrap();
                format!("{:?}", x * 0.9)
            };
            format!("{k}= {scaled}")
        };
        let edited = text.replace(line, &edited_line);
        let ours = platform_identity(&parse_platform(&edited, "mem").unwrap());
        let theirs = mc_parse(&edited, "mem").unwrap();
        assert_ne!(ours, base, "{key} is not covered");
        assert_eq!(ours, theirs.identity(), "{key}: implementations differ");
        // The model part alone does not see it.
        assert_eq!(
            model_identity(&parse_platform(&edited, "mem").unwrap()),
            theirs.model.identity()
        );
        edits += 1;
    }
    assert_eq!(edits, 4);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn kinematics_agree_with_motion_core(
        x in -1.5f64..1.5, y in -1.5f64..1.5, z in 1.25f64..2.75,
        ax in -0.2f64..0.2, ay in -0.2f64..0.2, az in -3.2f64..3.2,
        heli in any::<bool>(),
    ) {
        let f = config(if heli { "helicopter.toml" } else { "icosahedron.toml" });
        let kin = StandardKinematics::new(&load_platform(&f).unwrap());
        let platform = mc_load(&f).unwrap();
        let model = platform.model;
        let mut data = cdpr_model::Data::new(&model);
        let pose = [x, y, z, ax, ay, az];
        let mut q_mc = vec![0.0; model.m()];
        cdpr_model::kinematics::lengths(&model, &mut data, &cdpr_model::Pose::from_array(pose), &mut q_mc).unwrap();
        let mut q = [0.0; crs_ipc::MAX_CABLES];
        kin.lengths(&pose, &mut q);
        for i in 0..model.m() {
            prop_assert!((q[i] - q_mc[i]).abs() < 1e-9, "cable {i}: {} vs {}", q[i], q_mc[i]);
        }
    }
}
