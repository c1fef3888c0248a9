//! Bad plant/campaign TOML gets a clear error (file, key, line); campaigns bookkeep
//! unreachable poses with the reason, run tension tests and are reproducible.

#![allow(clippy::needless_range_loop)] // per-cable index loops read like the equations

mod common;
use common::*;
use crs_dataset::Phase;
use sim_plant::campaign::parse_campaign;
use sim_plant::{
    CampaignConfig, ControlKind, Plant, PoseSet, SkipReason, load_campaign, run_campaign,
};

const MINI: &str = "[plant]\nname = \"t\"\nplatform = \"../crs-nominal.toml\"\n";

#[test]
fn plant_toml_errors_name_file_key_and_line() {
    // unknown key
    let e = plant_from(&format!(
        "{MINI}[sag]\nenabled = true\nmass_per_length_kg_per_m = 0.8\ncolour = 1\n"
    ))
    .unwrap_err();
    assert_eq!(e.file, "test.toml");
    assert_eq!(e.line, Some(7), "{e}");
    assert!(e.message.contains("colour"), "{e}");
    // unknown effect block
    let e = plant_from(&format!("{MINI}[magic]\nenabled = true\n")).unwrap_err();
    assert!(e.message.contains("magic"), "{e}");
    // value out of range, with key and line
    let e = plant_from(&format!(
        "{MINI}[hysteresis]\nenabled = true\nhalf_width_n = -5.0\nstiffness_ratio = 1.0\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "hysteresis.half_width_n");
    assert_eq!(e.line, Some(6));
    // per-cable list of the wrong length
    let e = plant_from(&format!(
        "{MINI}[powertrain]\nenabled = true\nextra_length_m = [1.0, 2.0]\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "powertrain.extra_length_m");
    assert!(e.message.contains("8 cables"));
    // missing required key
    let e = plant_from(&format!(
        "{MINI}[tracker]\nenabled = true\nposition_noise_m = 0.002\n"
    ))
    .unwrap_err();
    assert!(e.message.contains("rotation_noise_deg"), "{e}");
    // enabled is mandatory: a block is never on by accident
    let e = plant_from(&format!("{MINI}[sag]\nmass_per_length_kg_per_m = 0.8\n")).unwrap_err();
    assert!(e.message.contains("enabled"), "{e}");
    // platform that does not exist
    let e = plant_from("[plant]\nname = \"t\"\nplatform = \"nope.toml\"\n").unwrap_err();
    assert_eq!(e.key, "plant.platform");
    assert_eq!(e.line, Some(3));
    // stiffness exponent must be < 1
    let e = plant_from(&format!(
        "{MINI}[stiffness]\nenabled = true\nexponent = 1.0\nforce_offset_n = 100.0\nreference_force_n = 5000.0\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "stiffness.exponent");
    // a valid minimal plant
    assert!(plant_from(MINI).unwrap().effects.enabled_names().is_empty());
}

/// A row of the wrong length is refused at that row (serde's [f64; 3] under toml read the first
/// three values of a row typed with a fourth and dropped it silently).
#[test]
fn rows_of_the_wrong_length_are_refused_at_the_row() {
    let row = |i: usize| {
        if i == 2 {
            "  [0.01, 0.0, 0.0, 9.0],\n".to_string()
        } else {
            "  [0.0, 0.0, 0.0],\n".to_string()
        }
    };
    let rows: String = (0..8).map(row).collect();
    let e = plant_from(&format!(
        "{MINI}[geometry_deviation]\nenabled = true\nframe_anchor_offsets_m = [\n{rows}]\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "geometry_deviation.frame_anchor_offsets_m[2]", "{e}");
    assert_eq!(e.line, Some(9), "{e}");
    assert!(e.message.contains("has 4 values, expected 3"), "{e}");
    let e = plant_from(&format!(
        "{MINI}[load]\nenabled = true\nmass_kg = 500.0\ncenter_of_gravity_m = [0.0, 0.0, 0.1]\nextra_wrench_n_nm = [1.0, 2.0, 3.0, 4.0, 5.0]\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "load.extra_wrench_n_nm", "{e}");
    assert!(e.message.contains("has 5 values, expected 6"), "{e}");
    let e = plant_from(&format!(
        "{MINI}[load]\nenabled = true\nmass_kg = 500.0\ncenter_of_gravity_m = [0.0, nan, 0.1]\n"
    ))
    .unwrap_err();
    assert_eq!(e.key, "load.center_of_gravity_m", "{e}");
    assert!(e.message.contains("finite"), "{e}");
}

#[test]
fn campaign_toml_errors_and_defaults() {
    let dir = config_dir().join("plant");
    let e = parse_campaign(
        "[campaign]\nname = \"c\"\ncontrol_model = \"magic\"\n",
        "c.toml",
        &dir,
    )
    .unwrap_err();
    assert_eq!(e.key, "campaign.control_model");
    assert_eq!(e.line, Some(3));
    let e = parse_campaign(
        "[campaign]\nname = \"c\"\n[poses]\nkind = \"grid\"\npoints = [0, 2, 2]\n",
        "c.toml",
        &dir,
    )
    .unwrap_err();
    assert_eq!(e.key, "poses.points");
    let e = parse_campaign("[campaign]\nname = \"c\"\nspeed = 3\n", "c.toml", &dir).unwrap_err();
    assert!(e.message.contains("speed"));
    let c = parse_campaign("[campaign]\nname = \"c\"\n", "c.toml", &dir).unwrap();
    assert_eq!(c.control, ControlKind::Kinematic);
    assert_eq!(c.poses, CampaignConfig::default().poses);
    let c = load_campaign(config_dir().join("plant/campaign-91.toml")).unwrap();
    assert_eq!(c.poses.poses().len(), 91);
    assert_eq!(c.tension_test, Some(0.03));
    let d = load_campaign(config_dir().join("plant/campaign-default.toml")).unwrap();
    let poses = d.poses.poses();
    assert_eq!(poses.len(), 100);
    // inside the experiments' box (sec. 6.1)
    assert!(
        poses
            .iter()
            .all(|p| p.r.x.abs() <= 1.5 && p.r.y.abs() <= 1.5 && p.r.z >= 1.25 && p.r.z <= 2.0)
    );
}

fn small_campaign(tension: Option<f64>) -> CampaignConfig {
    CampaignConfig {
        poses: PoseSet::Grid {
            min: nalgebra::Vector3::new(-1.5, -1.5, 1.25),
            max: nalgebra::Vector3::new(1.5, 1.5, 2.0),
            points: [3, 3, 2],
            rotations: vec![nalgebra::Vector3::zeros()],
        },
        tension_test: tension,
        ..CampaignConfig::default()
    }
}

#[test]
fn unreachable_poses_are_bookkept_with_reason_and_not_sampled() {
    let cfg = crs_like();
    let control = cfg.platform.clone();
    let mut plant = Plant::new(cfg).unwrap();
    let res = run_campaign(&mut plant, &control, &CampaignConfig::default(), "nominal").unwrap();
    assert!(!res.unreachable.is_empty());
    let p = control.model.params();
    for u in &res.unreachable {
        assert!(
            matches!(
                u.reason,
                SkipReason::BelowLimit { .. }
                    | SkipReason::AboveLimit { .. }
                    | SkipReason::Plant(_)
            ),
            "{}",
            u.reason
        );
        assert!(
            !res.dataset
                .samples
                .iter()
                .any(|s| s.pose_index == u.pose_index as u64)
        );
    }
    // the rejected ones really violate the limits on the plant: re-check one from scratch
    let (cable, force_n, limit_n) = res
        .unreachable
        .iter()
        .find_map(|u| match u.reason {
            SkipReason::BelowLimit {
                cable,
                force_n,
                limit_n,
            } => {
                assert!(force_n < limit_n);
                Some((cable, force_n, limit_n))
            }
            SkipReason::AboveLimit {
                cable,
                force_n,
                limit_n,
            } => {
                assert!(force_n > limit_n);
                Some((cable, force_n, limit_n))
            }
            _ => None,
        })
        .unwrap();
    assert!(limit_n == p.f_min || limit_n == p.f_max);
    assert!(
        (1..=control.model.m()).contains(&cable),
        "cable {cable}, {force_n} N"
    );
    let text = res
        .unreachable
        .iter()
        .find(|u| {
            matches!(
                u.reason,
                SkipReason::BelowLimit { .. } | SkipReason::AboveLimit { .. }
            )
        })
        .unwrap()
        .reason
        .to_string();
    assert!(text.starts_with("force limits: cable "), "{text}");
    // every unreachable pose is listed in the file's metadata too
    let listed = res
        .dataset
        .metadata
        .iter()
        .filter(|(k, _)| k == "unreachable")
        .count();
    assert_eq!(listed, res.unreachable.len());
    // metadata never carries the plant's effect settings
    for (k, v) in &res.dataset.metadata {
        for word in [
            "hysteresis",
            "sag",
            "powertrain",
            "geometry_deviation",
            "tracker",
        ] {
            assert!(!k.contains(word) && !v.contains(word), "{k}: {v}");
        }
    }
}

#[test]
fn tension_tests_raise_forces_and_show_hysteresis_on_return() {
    for (cfg, hyst) in [(crs_like(), true), (ideal(), false)] {
        let control = cfg.platform.clone();
        let mut c = cfg.clone();
        c.effects.tracker = None;
        c.effects.force_sensors = None;
        let mut plant = Plant::new(c).unwrap();
        let res =
            run_campaign(&mut plant, &control, &small_campaign(Some(0.03)), "nominal").unwrap();
        let s = &res.dataset.samples;
        let mut checked = 0;
        for w in s.windows(3) {
            if w[0].phase == Phase::Pose
                && w[1].phase == Phase::Tensioned
                && w[2].phase == Phase::Returned
            {
                let f = |k: usize| w[k].forces.as_ref().unwrap().iter().sum::<f64>();
                assert!(
                    f(1) > f(0) + 8.0 * 1000.0,
                    "tension test must raise the forces"
                );
                assert_eq!(w[0].q_cmd, w[2].q_cmd);
                let d = (f(2) - f(0)).abs();
                if hyst {
                    assert!(
                        d > 100.0,
                        "same command, different force after the tension test: {d}"
                    );
                } else {
                    assert!(d < 1e-4, "no hysteresis: {d}");
                }
                checked += 1;
            }
        }
        assert!(checked >= 3, "{checked} complete tension tests");
    }
}

#[test]
fn campaigns_are_reproducible_and_seed_dependent() {
    let run = |seed: Option<u64>| {
        let cfg = crs_like();
        let control = cfg.platform.clone();
        let mut plant = Plant::new(cfg).unwrap();
        let c = CampaignConfig {
            seed,
            ..small_campaign(None)
        };
        run_campaign(&mut plant, &control, &c, "nominal")
            .unwrap()
            .dataset
    };
    let a = run(Some(5));
    assert_eq!(a, run(Some(5)));
    assert_ne!(a.samples, run(Some(6)).samples);
    assert_eq!(a.meta("seed"), Some("5"));
}

#[test]
fn elastostatic_control_of_the_ideal_plant_has_no_pose_error() {
    let cfg = ideal();
    let control = cfg.platform.clone();
    let mut plant = Plant::new(cfg).unwrap();
    let c = CampaignConfig {
        control: ControlKind::Elastostatic,
        ..small_campaign(None)
    };
    let res = run_campaign(&mut plant, &control, &c, "nominal").unwrap();
    let e = sim_plant::campaign::pose_errors(&res.dataset).unwrap();
    let (mean, max, n) = (e.mean_position, e.max_position, e.samples);
    assert!(n >= 10);
    assert!(max < 1e-9, "mean {mean} max {max}");
}

#[test]
fn recorded_campaign_survives_a_file_round_trip() {
    let cfg = crs_like();
    let control = cfg.platform.clone();
    let mut plant = Plant::new(cfg).unwrap();
    let res = run_campaign(&mut plant, &control, &small_campaign(Some(0.03)), "nominal").unwrap();
    let path = std::env::temp_dir().join(format!("sim-plant-roundtrip-{}.csv", std::process::id()));
    crs_dataset::save_dataset(&path, &res.dataset).unwrap();
    let back = crs_dataset::load_dataset(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    assert_eq!(back, res.dataset);
    assert!(back.has_forces && back.has_reference && back.m == 8);
    assert_eq!(back.meta("control_model"), Some("kinematic"));
}
