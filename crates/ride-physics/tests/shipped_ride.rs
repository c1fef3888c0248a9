//! The shipped helicopter ride (config/ride-helicopter.toml on config/helicopter.toml): its
//! settings and their refusals, and the hover dynamics on it (hover holds, full collective
//! climbs at its authority, pitch and roll fly the commanded way).

use cdpr_model::Pose;
use nalgebra::Vector3;
use ride_physics::PilotInput;
use ride_physics::hover::{HoverModel, HoverState, step, thrust};
use ride_physics::settings::HoverSettings;
use std::path::Path;

fn config(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

fn helicopter_model() -> HoverModel {
    let pf = cdpr_model::config::load_platform(config("helicopter.toml")).unwrap();
    HoverSettings::load(&config("ride-helicopter.toml"))
        .unwrap()
        .model(&pf, "ride-helicopter.toml")
        .unwrap()
}

fn run(model: &HoverModel, u: PilotInput, seconds: f64) -> HoverState {
    let mut s = HoverState::at_rest(&Pose::new(Vector3::new(0.0, 0.0, 1.5), Vector3::zeros()));
    for _ in 0..(seconds * 1000.0) as usize {
        step(model, &mut s, &u, 1e-3);
    }
    s
}

#[test]
fn hover_collective_holds_still_and_full_collective_climbs_at_its_authority() {
    let m = helicopter_model();
    let s = run(&m, PilotInput::HOVER, 5.0);
    assert!(
        (s.r - Vector3::new(0.0, 0.0, 1.5)).norm() < 1e-12 && s.v.norm() < 1e-12,
        "{s:?}"
    );
    // One step of full collective: a = authority · g upwards (nothing else acts yet).
    let mut s = HoverState::at_rest(&Pose::new(Vector3::new(0.0, 0.0, 1.5), Vector3::zeros()));
    step(
        &m,
        &mut s,
        &PilotInput {
            collective: 1.0,
            ..PilotInput::HOVER
        },
        1e-3,
    );
    assert!(
        (s.acc.z - m.collective_authority * m.gravity_m_per_s2).abs() < 1e-9,
        "{}",
        s.acc
    );
}

#[test]
fn pitch_flies_towards_plus_x_roll_towards_minus_y_with_the_commanded_attitude() {
    let mut m = helicopter_model();
    // Without walls, to see the free response.
    m.walls.min = Vector3::repeat(-1e3);
    m.walls.max = Vector3::repeat(1e3);
    let s = run(
        &m,
        PilotInput {
            pitch: 0.5,
            ..PilotInput::HOVER
        },
        6.0,
    );
    assert!(s.v.x > 0.05 && s.v.y.abs() < 1e-6, "{:?}", s.v);
    assert!(
        (s.phi.y - 0.5 * m.attitude_command_max.y).abs() < 0.05 * m.attitude_command_max.y,
        "{}",
        s.phi
    );
    let s = run(
        &m,
        PilotInput {
            roll: 0.5,
            ..PilotInput::HOVER
        },
        6.0,
    );
    assert!(s.v.y < -0.05 && s.v.x.abs() < 1e-6, "{:?}", s.v);
    // The damped horizontal speed: T sin φ / D_lin.
    let t = thrust(&m, 0.5);
    let v_term = t * (0.5 * m.attitude_command_max.x).sin() / m.damping_linear.y;
    let s = run(
        &m,
        PilotInput {
            roll: 0.5,
            ..PilotInput::HOVER
        },
        30.0,
    );
    assert!(
        (s.v.y.abs() - v_term).abs() < 0.02 * v_term,
        "{} vs {v_term}",
        s.v.y
    );
}

#[test]
fn the_shipped_ride_config_makes_walls_inside_the_region() {
    let m = helicopter_model();
    assert!((m.mass_kg - 764.5).abs() < 1e-9);
    assert_eq!(m.walls.min, Vector3::new(-1.3, -1.3, 1.35));
}

#[test]
fn bad_settings_name_the_key() {
    let text = std::fs::read_to_string(config("ride-helicopter.toml")).unwrap();
    let bad = text.replace("collective_authority = 0.1", "collective_authority = 1.5");
    let e = HoverSettings::parse(&bad, "r.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("r.toml: `controls.collective_authority`: must lie in (0, 1)"),
        "{e}"
    );
    let bad = text.replace("[damping]", "[damping]\nfoo = 1");
    let e = HoverSettings::parse(&bad, "r.toml").unwrap_err();
    assert!(e.line.is_some() && e.message.contains("foo"), "{e}");
    let pf = cdpr_model::config::load_platform(config("helicopter.toml")).unwrap();
    let s = HoverSettings::parse(
        &text.replace("margin_m = [0.2, 0.2, 0.1]", "margin_m = [0.2, 0.2, 0.3]"),
        "r.toml",
    )
    .unwrap();
    let e = s.model(&pf, "r.toml").unwrap_err().to_string();
    assert!(
        e.contains("walls.margin_m[2]") && e.contains("no room"),
        "{e}"
    );
    let mut bare = pf.clone();
    bare.dynamics = None;
    let e = HoverSettings::parse(&text, "r.toml")
        .unwrap()
        .model(&bare, "r.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no [dynamics]"), "{e}");
}
