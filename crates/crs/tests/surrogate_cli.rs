//! `crs surrogate` end to end as an operator runs it: fit on the CRS nominal platform with a
//! plant evaluation, check the file like the daemon does, refuse a foreign platform, a corrupted
//! file and an over-range fit (nothing written).
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn crs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_crs"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run crs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("crs-sg-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn fit_evaluate_check_and_refusals() {
    let dir = tmp("fit");
    let file = dir.join("sg.json");
    let report = dir.join("report");
    let o = crs(&[
        "surrogate",
        "fit",
        "--platform",
        "config/crs-nominal.toml",
        "--validation-samples",
        "500",
        "--out",
        file.to_str().unwrap(),
        "--plant",
        "config/plant/crs-ideal.toml",
        "--grid",
        "2",
        "--report-dir",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(file.exists());
    for f in ["report.md", "report.json", "tracking.svg"] {
        assert!(report.join(f).exists(), "{f} missing");
    }
    // On the ideal plant the surrogate controller reaches f_ref within tens of N, far better
    // than the kinematic controller (whose forces follow its set-up tension).
    let ev: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("report.json")).unwrap())
            .unwrap();
    let max = |ctl: &str, key: &str| {
        ev[ctl][key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap_or(f64::NAN))
            .fold(0.0f64, f64::max)
    };
    assert_eq!(ev["poses"].as_u64(), Some(2 * 2 * 2 * 27));
    assert!(max("surrogate", "force_error_n") < 100.0);
    assert!(max("surrogate", "position_error_mm") < 1.0);
    assert!(max("kinematic", "force_error_n") > 1000.0);
    let svg = std::fs::read_to_string(report.join("tracking.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("kinematics + surrogate"));

    // The daemon's loader accepts it for its own platform ...
    let o = crs(&["surrogate", "check", "--file", file.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    // ... and refuses it for another platform, naming the mismatch.
    let o = crs(&[
        "surrogate",
        "check",
        "--file",
        file.to_str().unwrap(),
        "--platform",
        "config/icosahedron.toml",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).to_lowercase().contains("platform"), "{}", text(&o));

    // One changed coefficient digit: checksum mismatch.
    let s = std::fs::read_to_string(&file).unwrap();
    let k = s.find("\"coefficients_m\"").unwrap();
    let digit = k + s[k..].find(|c: char| c.is_ascii_digit()).unwrap();
    let mut bad = s.clone().into_bytes();
    bad[digit] = if bad[digit] == b'7' { b'3' } else { b'7' };
    let bad_file = dir.join("bad.json");
    std::fs::write(&bad_file, bad).unwrap();
    let o = crs(&["surrogate", "check", "--file", bad_file.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(text(&o).to_lowercase().contains("checksum"), "{}", text(&o));

    // Over-range: with a 95 mm margin the bound is 5 mm, the CRS offset is ~34 mm → refused,
    // saying where, and nothing is written.
    let refused = dir.join("refused.json");
    let o = crs(&[
        "surrogate",
        "fit",
        "--validation-samples",
        "200",
        "--margin-mm",
        "95",
        "--out",
        refused.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(!refused.exists());
    let t = text(&o);
    assert!(t.contains("cable") && t.contains("mm"), "{t}");
    let _ = std::fs::remove_dir_all(&dir);
}
