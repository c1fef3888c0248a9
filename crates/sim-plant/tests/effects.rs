//! Every effect shows its signature when on and is exactly absent when off.

#![allow(clippy::needless_range_loop)] // per-cable index loops read like the equations

mod common;
use cdpr_model::elastostatics::CableLaw;
use cdpr_model::{Data, Pose, kinematics, statics};
use common::*;
use sim_plant::cable_law::PlantLaw;
use sim_plant::{Equilibrium, Plant, PlantConfig};

/// Commands: the ideal home command, then a move to a second pose and back.
fn run(cfg: PlantConfig) -> Vec<Equilibrium> {
    let q_home = {
        let mut p = Plant::new(ideal()).unwrap();
        home_command(&mut p)
    };
    let mut plant = Plant::new(cfg).unwrap();
    let moved: Vec<f64> = q_home
        .iter()
        .enumerate()
        .map(|(i, q)| q + 0.02 * ((i % 3) as f64 - 1.0))
        .collect();
    vec![
        plant.step(&q_home).unwrap(),
        plant.step(&moved).unwrap(),
        plant.step(&q_home).unwrap(),
    ]
}

fn same(a: &[Equilibrium], b: &[Equilibrium]) -> bool {
    a.iter().zip(b).all(|(x, y)| {
        pose_bits(&x.pose) == pose_bits(&y.pose) && bits(&x.forces) == bits(&y.forces)
    })
}

fn dist(a: &Pose, b: &Pose) -> f64 {
    a.error_to(b).0
}

#[test]
fn each_effect_switched_off_in_toml_is_exactly_absent() {
    let base = std::fs::read_to_string(config_dir().join("plant/crs-like.toml")).unwrap();
    let off = base.replace("enabled = true", "enabled = false");
    let cfg = plant_from(&off).unwrap();
    assert!(cfg.effects.enabled_names().is_empty());
    assert!(same(&run(cfg), &run(ideal())));
}

#[test]
fn each_single_effect_changes_the_equilibrium_or_readings() {
    let reference = run(ideal());
    for name in [
        "geometry",
        "pulleys",
        "powertrain",
        "stiffness",
        "hysteresis",
        "sag",
        "winch",
        "load",
    ] {
        let r = run(only(&[name]));
        let dp = dist(&r[1].pose, &reference[1].pose);
        let df = r[1]
            .forces
            .iter()
            .zip(&reference[1].forces)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(dp > 1e-5 || df > 1.0, "{name}: Δpose {dp:e} m, Δf {df:e} N");
    }
}

#[test]
fn geometry_deviation_moves_the_platform_by_centimetres() {
    let a = run(ideal());
    let b = run(only(&["geometry"]));
    let d = dist(&a[0].pose, &b[0].pose);
    assert!(d > 5e-3 && d < 0.5, "{d}");
}

#[test]
fn pulleys_change_lengths_as_the_pulley_model() {
    let cfg = only(&["pulleys"]);
    let plant = Plant::new(cfg).unwrap();
    assert!(plant.physical_model().has_pulleys());
    let pl = plant.physical_model().params().pulleys.clone().unwrap();
    assert!(pl.radius.iter().all(|r| *r == 0.161));
    let ideal_plant = Plant::new(ideal()).unwrap();
    assert!(!ideal_plant.physical_model().has_pulleys());
    let a = run(ideal());
    let b = run(only(&["pulleys"]));
    assert!(dist(&a[0].pose, &b[0].pose) > 1e-3);
}

#[test]
fn winch_errors_are_a_length_map_of_the_command() {
    let cfg = only(&["winch"]);
    let w = cfg.effects.winch.clone().unwrap();
    let mut p1 = Plant::new(cfg).unwrap();
    let mut p0 = Plant::new(ideal()).unwrap();
    let q = home_command(&mut p0);
    let mut p0 = Plant::new(ideal()).unwrap();
    let mapped: Vec<f64> = (0..8)
        .map(|i| w.length_scale[i] * q[i] + w.encoder_offset[i])
        .collect();
    let a = p1.step(&q).unwrap();
    let b = p0.step(&mapped).unwrap();
    assert_eq!(pose_bits(&a.pose), pose_bits(&b.pose));
    assert_eq!(bits(&a.q_theta), bits(&mapped));
}

#[test]
fn powertrain_stiffness_includes_drive_train_rope_and_series_compliance() {
    // eq. 6.18: c = (q + l_extra)/EA + c_s instead of q/k_F (eq. 2.33)
    let cfg = only(&["powertrain"]);
    let pt = cfg.effects.powertrain.clone().unwrap();
    let law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    for (i, q) in [(0usize, 6.0), (3, 9.0), (7, 12.0)] {
        let want = 1.0 / ((q + pt.extra_length[i]) / pt.k_f[i] + pt.series_compliance[i]);
        let qt = law.controlled_length(i, q, 5000.0);
        let c = law.force(i, q, qt);
        assert!((c.f - 5000.0).abs() < 1e-6);
        assert!(
            (-c.df_dqt / want - 1.0).abs() < 1e-12,
            "{} vs {want}",
            -c.df_dqt
        );
        // elongation at 5000 N is the rope stored in the drive train stretching too
        assert!(((q - qt) - 5000.0 / want).abs() < 1e-12);
    }
    // the stiffness changes less with the free length than k_F/q: 12 m vs 6 m
    let k = |q: f64| 1.0 / ((q + pt.extra_length[0]) / pt.k_f[0] + pt.series_compliance[0]);
    assert!(k(6.0) / k(12.0) < 1.5);
}

#[test]
fn tension_dependent_stiffness_follows_the_power_law() {
    let cfg = only(&["stiffness"]);
    let t = cfg.effects.stiffness.unwrap();
    let law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    let lin = PlantLaw::new(&cfg.platform.model.params().k_f, &ideal().effects);
    let q = 9.0;
    let k_at = |law: &PlantLaw, f: f64| {
        let qt = law.controlled_length(0, q, f);
        -law.force(0, q, qt).df_dqt
    };
    let k_lin = k_at(&lin, 5000.0);
    // k(f_ref) = linear stiffness, k(f) ∝ ((f + f0)/(f_ref + f0))^n
    assert!((k_at(&law, t.reference_force) / k_lin - 1.0).abs() < 1e-9);
    let want = ((1000.0 + t.force_offset) / (t.reference_force + t.force_offset)).powf(t.exponent);
    assert!(
        (k_at(&law, 1000.0) / k_lin - want).abs() < 1e-9,
        "{}",
        k_at(&law, 1000.0) / k_lin
    );
    assert!(k_at(&law, 9000.0) > k_lin * 1.05);
    // linear law is flat
    assert!((k_at(&lin, 1000.0) - k_lin).abs() < 1e-6 * k_lin);
}

#[test]
fn hysteresis_same_command_different_force_by_direction() {
    let cfg = only(&["hysteresis"]);
    let h = cfg.effects.hysteresis.unwrap().half_width;
    let mut plant = Plant::new(cfg).unwrap();
    let q = home_command(&mut plant);
    let longer: Vec<f64> = q.iter().map(|v| v + 0.01).collect();
    let shorter: Vec<f64> = q.iter().map(|v| v - 0.01).collect();
    plant.step(&longer).unwrap();
    let loading = plant.step(&q).unwrap(); // approached while tightening
    plant.step(&shorter).unwrap();
    let unloading = plant.step(&q).unwrap(); // approached while releasing
    // loading path above, unloading below: about the loop width 2H (redistributed by the
    // slightly different pose)
    let d: Vec<f64> = (0..8)
        .map(|i| loading.forces[i] - unloading.forces[i])
        .collect();
    assert!(d.iter().all(|d| *d > 0.0), "{d:?}");
    let mean = d.iter().sum::<f64>() / 8.0;
    assert!(mean > 0.5 * h && mean < 2.5 * h, "{d:?}");
    assert!(dist(&loading.pose, &unloading.pose) > 1e-7);
    // and without hysteresis the direction does not matter (to the solver's round-off; the
    // warm starts differ)
    let mut p = Plant::new(ideal()).unwrap();
    let q = home_command(&mut p);
    p.step(&longer).unwrap();
    let a = p.step(&q).unwrap();
    p.step(&shorter).unwrap();
    let b = p.step(&q).unwrap();
    for i in 0..8 {
        assert!(
            (a.forces[i] - b.forces[i]).abs() < 1e-6,
            "{} vs {}",
            a.forces[i],
            b.forces[i]
        );
    }
}

#[test]
fn hysteresis_state_survives_snapshot_restore_and_failed_steps() {
    let mut plant = Plant::new(crs_like()).unwrap();
    let q = home_command(&mut plant);
    plant.step(&q).unwrap();
    let st = plant.state();
    assert!(plant.step(&[1.0; 3]).is_err());
    assert!(plant.step(&[f64::NAN; 8]).is_err());
    assert_eq!(plant.state(), st);
    let shorter: Vec<f64> = q.iter().map(|v| v - 0.01).collect();
    plant.step(&shorter).unwrap();
    assert_ne!(plant.state(), st);
    plant.restore(&st);
    assert_eq!(plant.state(), st);
}

#[test]
fn sag_keeps_tension_in_a_cable_longer_than_its_chord() {
    let cfg = only(&["sag"]);
    let mut law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    let lin = PlantLaw::new(&cfg.platform.model.params().k_f, &ideal().effects);
    // a nearly horizontal lower cable is set through the plant; here: the law directly with a
    // horizontal chord (cos² α = 1) of 9 m
    let mut plant = Plant::new(cfg.clone()).unwrap();
    let q_home = home_command(&mut plant);
    let eq = plant.step(&q_home).unwrap();
    assert!(eq.forces.iter().all(|f| *f > 0.0));
    // the platform carries half of every free span's weight: Σ ½ μ g q_f,i more load
    let m = plant.physical_model();
    let mut data = Data::new(m);
    kinematics::inverse(m, &mut data, &eq.pose).unwrap();
    let half_weight: f64 = data.q_free.iter().map(|q| 0.5 * 0.8 * 9.81 * q).sum();
    let nominal = cfg.platform.model.params().w_e;
    assert!(
        (eq.wrench[2] - (nominal[2] - half_weight)).abs() < 1e-9,
        "{} {}",
        eq.wrench[2],
        half_weight
    );
    assert!(half_weight > 200.0 && half_weight < 400.0);
    // and the equilibrium holds with it (A^T f + w = 0)
    assert!(statics::residual_wrench(&data, &eq.forces, &eq.wrench).amax() < 1e-6);
    set_horizontal(&mut law);
    let q = 9.0;
    // unstretched rope 1 cm longer than the chord: the linear law is slack, the catenary holds
    let f_lin = lin.force(0, q, q + 0.01).f;
    let f_sag = law.force(0, q, q + 0.01).f;
    assert!(f_lin < 0.0 && f_sag > 10.0, "{f_lin} {f_sag}");
    // parabolic catenary: rope length = chord + (w q)^2 q / (24 f^2) (Irvine), w = μ g
    let w = 0.8 * 9.81;
    let c = q / cfg.platform.model.params().k_f[0];
    let sag = w * w * q * q * q / (24.0 * f_sag * f_sag);
    assert!((q + sag - (q + 0.01 + c * f_sag)).abs() < 1e-9);
    // under high tension the sag vanishes: force ≈ linear law (relative change < 0.1 %)
    let f_hi_lin = lin.force(0, q, q - 0.04).f;
    let f_hi_sag = law.force(0, q, q - 0.04).f;
    assert!(f_hi_lin > 8000.0 && (f_hi_sag / f_hi_lin - 1.0).abs() < 1e-3 && f_hi_sag > f_hi_lin);
    // Ernst's equivalent modulus: the tangent compliance grows by (w l)^2 q / (12 f^3)
    let d = law.force(0, q, q - 0.005);
    let ernst = 1.0 / (c + w * w * q * q * q / (12.0 * d.f * d.f * d.f));
    assert!(
        (-d.df_dqt / ernst - 1.0).abs() < 1e-9,
        "{} vs {ernst}",
        -d.df_dqt
    );
}

fn set_horizontal(law: &mut PlantLaw) {
    law.set_chord_cos2(&[1.0; 8]);
}

#[test]
fn load_torque_turns_with_the_platform_and_equilibrium_holds_there() {
    let cfg = only(&["load"]);
    let l = cfg.effects.load.unwrap();
    let mut plant = Plant::new(cfg).unwrap();
    let w0 = plant.wrench_at(&pose(0.0, 0.0, 1.5, 0.0, 0.0, 0.0));
    let w1 = plant.wrench_at(&pose(0.0, 0.0, 1.5, 0.0, 0.0, 30.0));
    assert!((w0[2] + l.mass * l.gravity).abs() < 1e-9);
    assert!((w0.fixed_rows::<3>(3) - w1.fixed_rows::<3>(3)).norm() > 10.0);
    let q = home_command(&mut plant);
    let rotated: Vec<f64> = q
        .iter()
        .enumerate()
        .map(|(i, v)| v + if i % 2 == 0 { 0.02 } else { -0.02 })
        .collect();
    let eq = plant.step(&rotated).unwrap();
    // residual wrench with the load evaluated at the settled pose
    let m = plant.physical_model();
    let mut data = Data::new(m);
    kinematics::inverse(m, &mut data, &eq.pose).unwrap();
    let w = plant.wrench_at(&eq.pose);
    let r = statics::residual_wrench(&data, &eq.forces, &w);
    assert!(r.amax() < 1e-6, "{r}");
    // and the ideal plant uses the nominal wrench everywhere
    let p0 = Plant::new(ideal()).unwrap();
    assert_eq!(
        p0.wrench_at(&eq.pose),
        p0.config().platform.model.params().w_e
    );
}

#[test]
fn tracker_noise_is_seeded_gaussian_and_absent_when_off() {
    let read = |cfg: PlantConfig, n: usize| {
        let mut plant = Plant::new(cfg).unwrap();
        let q = home_command(&mut plant);
        let eq = plant.step(&q).unwrap();
        let r: Vec<_> = (0..n).map(|_| plant.measure(&eq)).collect();
        (eq, r)
    };
    let (eq, r) = read(only(&["tracker"]), 2000);
    let t = only(&["tracker"]).effects.tracker.unwrap();
    let (mut s_p, mut s_r) = (0.0, 0.0);
    for s in &r {
        let d = s.pose.to_array();
        let e = eq.pose.to_array();
        s_p += (d[0] - e[0]).powi(2);
        s_r += (d[4] - e[4]).powi(2);
        assert_eq!(bits(&s.forces), bits(&eq.forces));
    }
    let sd_p = (s_p / r.len() as f64).sqrt();
    let sd_r = (s_r / r.len() as f64).sqrt();
    assert!((sd_p / t.position_noise - 1.0).abs() < 0.1, "{sd_p}");
    assert!((sd_r / t.rotation_noise - 1.0).abs() < 0.1, "{sd_r}");
    let (_, r2) = read(only(&["tracker"]), 2000);
    assert_eq!(r, r2, "same seed, same readings");
    let (eq0, r0) = read(ideal(), 3);
    assert!(
        r0.iter()
            .all(|s| s.pose == eq0.pose && s.forces == eq0.forces)
    );
}

#[test]
fn force_sensors_have_offset_gain_and_noise() {
    let cfg = only(&["force_sensors"]);
    let fs = cfg.effects.force_sensors.clone().unwrap();
    let mut plant = Plant::new(cfg).unwrap();
    let q = home_command(&mut plant);
    let eq = plant.step(&q).unwrap();
    let n = 2000;
    let mut mean = [0.0; 8];
    for _ in 0..n {
        let r = plant.measure(&eq);
        assert_eq!(r.pose, eq.pose);
        for i in 0..8 {
            mean[i] += r.forces[i] / n as f64;
        }
    }
    for i in 0..8 {
        let want = fs.gain[i] * eq.forces[i] + fs.offset[i];
        assert!(
            (mean[i] - want).abs() < 4.0 * fs.noise / (n as f64).sqrt(),
            "cable {i}: {} vs {want}",
            mean[i]
        );
    }
}

#[test]
fn all_effects_law_derivatives_match_finite_differences() {
    let cfg = crs_like();
    let mut law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    law.set_chord_cos2(&[0.8; 8]);
    for (q, qt) in [(9.0, 8.98), (8.0, 7.99), (10.0, 9.975)] {
        let c = law.force(2, q, qt);
        let h = 1e-7;
        let dq = (law.force(2, q + h, qt).f - law.force(2, q - h, qt).f) / (2.0 * h);
        let dqt = (law.force(2, q, qt + h).f - law.force(2, q, qt - h).f) / (2.0 * h);
        assert!((c.df_dq / dq - 1.0).abs() < 1e-5, "{} vs {dq}", c.df_dq);
        assert!((c.df_dqt / dqt - 1.0).abs() < 1e-5, "{} vs {dqt}", c.df_dqt);
        // controlled_length inverts force
        let back = law.controlled_length(2, q, c.f);
        assert!((back - qt).abs() < 1e-10, "{back} vs {qt}");
    }
}

#[test]
fn tension_setup_reaches_home_with_the_projected_f_ini() {
    let cfg = crs_like();
    let home = cfg.platform.home;
    let f_ini = cfg.platform.f_ini.clone().unwrap();
    let mut plant = Plant::new(cfg).unwrap();
    let setup = plant.setup_tension(&home, &f_ini).unwrap();
    let eq = plant.step(&setup.q_cmd).unwrap();
    assert!(eq.pose.error_to(&home).0 < 1e-8, "{:?}", eq.pose);
    for i in 0..8 {
        assert!((eq.forces[i] - setup.forces[i]).abs() < 1e-4 * setup.forces[i]);
        // eq. 3.19 keeps f_ini's internal part: the projection moves each force by < 15 %
        assert!(
            (setup.forces[i] / f_ini[i] - 1.0).abs() < 0.15,
            "{} vs {}",
            setup.forces[i],
            f_ini[i]
        );
    }
}

#[test]
fn crs_like_powertrain_linear_fit_errs_by_about_600_n() {
    // sec. 5.1 / Fig. 5.7: a least-squares linear spring fitted to a loading and unloading
    // sweep of one powertrain over 500-12000 N errs by up to ≈ 600 N.
    let cfg = only(&["powertrain", "stiffness", "hysteresis"]);
    let mut law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    let q = 9.0;
    let qt_lo = law.controlled_length(0, q, 500.0);
    law.advance(0, q, qt_lo + 0.01); // start slack-ish, then load
    let qt_hi = qt_lo - 0.06;
    let n = 400;
    let mut pts = Vec::new();
    for k in (0..=n).chain((0..=n).rev()) {
        let qt = qt_lo + (qt_hi - qt_lo) * k as f64 / n as f64;
        let f = law.advance(0, q, qt).f;
        if (500.0..=12000.0).contains(&f) {
            pts.push((q - qt, f));
        }
    }
    let m = pts.len() as f64;
    let (me, mf) = (
        pts.iter().map(|p| p.0).sum::<f64>() / m,
        pts.iter().map(|p| p.1).sum::<f64>() / m,
    );
    let a = pts.iter().map(|p| (p.0 - me) * (p.1 - mf)).sum::<f64>()
        / pts.iter().map(|p| (p.0 - me).powi(2)).sum::<f64>();
    let err = pts
        .iter()
        .map(|p| (a * (p.0 - me) + mf - p.1).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "crs-like powertrain: linear fit error {err:.0} N over {} points",
        pts.len()
    );
    assert!(err > 450.0 && err < 750.0, "linear fit error {err} N");
    // the same sweep without the effects: a linear spring fits exactly
    let lin_cfg = ideal();
    let mut lin = PlantLaw::new(&lin_cfg.platform.model.params().k_f, &lin_cfg.effects);
    let f1 = lin.advance(0, q, qt_lo).f;
    let f2 = lin.advance(0, q, qt_hi).f;
    let f3 = lin.advance(0, q, qt_lo).f;
    assert_eq!(f1, f3);
    assert!(f2 > f1);
}
