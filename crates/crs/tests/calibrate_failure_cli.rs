//! `crs calibrate run` on a validation set whose commands no model can hold (every cable 4 m
//! slack): the elastostatic steps' FK fails on every held-out sample, so the report must say
//! "failed" with the count (never 0.00), the command must exit non-zero with the reason on
//! stderr, and calibrated.toml may only hold the last validated (kinematic) step.
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

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The data set with `delta` added to every commanded length.
fn shift_commands(src: &Path, dst: &Path, delta: f64) {
    let t = std::fs::read_to_string(src).unwrap();
    let mut cols = Vec::new();
    let mut out = String::new();
    for line in t.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if cols.is_empty() {
            cols = line
                .split(',')
                .map(|c| c.starts_with("q_cmd_"))
                .collect::<Vec<_>>();
            out.push_str(line);
        } else {
            let f: Vec<String> = line
                .split(',')
                .zip(&cols)
                .map(|(v, q)| {
                    if *q {
                        format!("{:?}", v.parse::<f64>().unwrap() + delta)
                    } else {
                        v.to_string()
                    }
                })
                .collect();
            out.push_str(&f.join(","));
        }
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
}

#[test]
fn failed_validation_is_reported_and_exits_non_zero() {
    let dir = std::env::temp_dir().join(format!("crs-calfail-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let camp = dir.join("campaign.toml");
    std::fs::write(
        &camp,
        "[campaign]\nname = \"small\"\ncontrol_model = \"kinematic\"\ntension_test_shortening_m = 0.03\nforce_columns = true\n\n[poses]\nkind = \"random\"\ncount = 14\nposition_min_m = [-1.5, -1.5, 1.25]\nposition_max_m = [1.5, 1.5, 2.0]\nrotation_max_deg = [5.0, 5.0, 5.0]\nseed = 3\n",
    )
    .unwrap();
    let demo = dir.join("demo");
    let o = crs(&[
        "calibrate",
        "demo",
        "--campaign",
        camp.to_str().unwrap(),
        "--no-extension",
        "--out",
        demo.to_str().unwrap(),
    ]);
    assert!(
        o.status.success(),
        "the healthy demo must pass: {}",
        text(&o)
    );
    assert!(demo.join("calibrated.toml").exists());
    let bad = dir.join("validation-slack.csv");
    shift_commands(&demo.join("validation.csv"), &bad, 4.0);
    let out = dir.join("run");
    let o = crs(&[
        "calibrate",
        "run",
        "--platform",
        "config/crs-nominal.toml",
        "--data",
        demo.join("identification.csv").to_str().unwrap(),
        "--validate",
        bad.to_str().unwrap(),
        "--no-extension",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success(),
        "a failed final step must exit non-zero"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("failed"), "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let rows: Vec<&str> = md
        .lines()
        .filter(|l| l.starts_with("| ") && l.contains("elastostatic") && l.contains("FK failed on"))
        .collect();
    assert!(!rows.is_empty(), "{md}");
    for r in rows {
        assert!(r.contains("**failed**"), "{r}");
        assert!(!r.contains("0.00 /"), "{r}");
    }
    // Only the last validated (kinematic) step may be written.
    let toml = std::fs::read_to_string(out.join("calibrated.toml")).unwrap();
    assert!(toml.contains("calibrated"));
    assert!(
        md.contains("Identified platform (step \"optimal kinematic\")"),
        "{md}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
