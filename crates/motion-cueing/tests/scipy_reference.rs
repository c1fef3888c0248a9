//! The crate's transfer functions (`lti::Lti`: canonical form, exact zero-order-hold
//! discretisation) against scipy.signal (tf2ss, cont2discrete 'zoh', dlsim): the washout's
//! translational and rotational high-passes, the tilt low-pass, the otolith and the canal
//! models of config/cueing.toml, for a step, a ramp and a 0.33 Hz sine, 20 s at 1 kHz, every
//! 50th sample compared. Regenerate the reference with
//! `python3 tools/cueing-scipy-reference.py > crates/motion-cueing/tests/data/scipy_reference.json`.
use motion_cueing::lti::Lti;
use nalgebra::SVector;

fn input(name: &str, k: usize, dt: f64) -> f64 {
    let t = k as f64 * dt;
    match name {
        "step" => f64::from(u8::from(t >= 1.0)),
        "ramp" => ((t - 1.0) / 0.5).clamp(0.0, 1.0),
        "sine" if t >= 1.0 => (2.0 * std::f64::consts::PI * 0.33 * (t - 1.0)).sin(),
        "sine" => 0.0,
        other => panic!("unknown input {other}"),
    }
}

fn simulate<const N: usize>(num: &[f64], den: &[f64], dt: f64, u: &str, n: usize) -> Vec<f64> {
    let f = Lti::<N>::from_tf(num, den, dt).unwrap();
    let mut z = SVector::<f64, N>::zeros();
    (0..n).map(|k| f.step(&mut z, input(u, k, dt))).collect()
}

#[test]
fn transfer_functions_match_scipy() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scipy_reference.json");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let n = r["samples"].as_u64().unwrap() as usize;
    let cases = r["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 15);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let v = |k: &str| -> Vec<f64> {
            c[k].as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (num, den) = (v("num"), v("den"));
        let dt = c["dt"].as_f64().unwrap();
        let u = c["input"].as_str().unwrap();
        let every = c["every"].as_u64().unwrap() as usize;
        let ours = match den.len() - 1 {
            2 => simulate::<2>(&num, &den, dt, u, n),
            3 => simulate::<3>(&num, &den, dt, u, n),
            d => panic!("{name}: order {d}"),
        };
        let theirs = v("y");
        let scale = theirs.iter().fold(1e-12f64, |m, y| m.max(y.abs()));
        let mut worst = 0.0f64;
        for (i, y) in theirs.iter().enumerate() {
            worst = worst.max((ours[i * every] - y).abs());
        }
        println!("{name}: largest difference {worst:.2e} (peak {scale:.3e})");
        assert!(
            worst <= 1e-9 * scale + 1e-12,
            "{name}: differs from scipy by {worst:e} (peak {scale:e})"
        );
    }
}
