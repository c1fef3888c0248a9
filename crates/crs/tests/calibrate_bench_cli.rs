//! `crs calibrate bench-diagnosis`, reduced to one seed of a few scenarios per generator (the
//! full benchmark is a command whose figures are in docs/calibration.md): baselines must add
//! nothing, a drum radius error of ≥ 0.25 mm on the simulated plant and a large command-switched
//! hysteresis on the independent plant must be named, no step's FK may fail, no parameter may
//! leave its physical range; `crs calibrate generate` writes a scenario that `crs calibrate run`
//! reads.
use std::path::Path;
use std::process::Command;

fn crs(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_crs"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
        .args(args)
        .output()
        .expect("run crs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn bench_diagnosis_smoke_sim_plant() {
    let (ok, out, err) = crs(&[
        "calibrate",
        "bench-diagnosis",
        "--generator",
        "sim-plant",
        "--seeds",
        "1",
        "--poses",
        "10",
        "--baseline-seeds",
        "1",
        "--scenarios",
        "baseline,drum",
    ]);
    assert!(ok, "{out}{err}");
    assert!(out.contains("generator `sim-plant`"), "{out}");
    assert!(out.contains("| baseline | 1 (0) | 1 (0) |"), "{out}{err}");
    assert!(
        out.contains("| runs with an FK failure in any step | 0/2 |"),
        "{out}"
    );
    assert!(
        out.contains("| runs with a non-physical final parameter | 0/2 |"),
        "{out}"
    );
    let drum = err
        .lines()
        .find(|l| l.starts_with("sim-plant") && l.contains(" drum ") && l.contains("seed 0"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(drum.contains("chosen [drum"), "{drum}");
}

#[test]
fn bench_diagnosis_smoke_independent() {
    // Run 2 of the command-switched hysteresis draws 0.90 of its range (2.0 mm).
    let (ok, out, err) = crs(&[
        "calibrate",
        "bench-diagnosis",
        "--generator",
        "independent",
        "--kinds",
        "baseline,hysteresis-command",
        "--first-seed",
        "2",
        "--seeds",
        "1",
        "--baseline-seeds",
        "1",
    ]);
    assert!(ok, "{out}{err}");
    assert!(out.contains("generator `independent`"), "{out}");
    assert!(out.contains("| baseline | 1 (0) | 1 (0) |"), "{out}{err}");
    assert!(
        out.contains("| runs with an FK failure in any step | 0/2 |"),
        "{out}"
    );
    assert!(
        out.contains("| single-effect runs where the effect matters: effect named | 1/1 (100 %) |"),
        "{out}{err}"
    );
}

#[test]
fn generate_writes_a_scenario_that_run_reads() {
    let dir = std::env::temp_dir().join(format!("crs-generate-{}", std::process::id()));
    let d = dir.display().to_string();
    let (ok, out, err) = crs(&[
        "calibrate",
        "generate",
        "--scenario",
        "drum-setup,hysteresis-command",
        "--magnitude",
        "0.9",
        "--seed",
        "3",
        "--poses",
        "12",
        "--out",
        &d,
    ]);
    assert!(ok, "{out}{err}");
    let truth = std::fs::read_to_string(dir.join("truth.json")).unwrap();
    assert!(
        truth.contains("\"drum-setup\"") && truth.contains("\"hysteresis-command\""),
        "{truth}"
    );
    let ident = std::fs::read_to_string(dir.join("identification.csv")).unwrap();
    assert!(ident.starts_with("# format: crs-dataset 1"), "{ident}");
    // The data set says what recorded it, never the truth.
    assert!(
        !ident.contains("drum-setup") && !ident.contains("hysteresis"),
        "{ident}"
    );
    let out_dir = dir.join("run").display().to_string();
    let (ok, out, err) = crs(&[
        "calibrate",
        "run",
        "--platform",
        "config/crs-nominal.toml",
        "--data",
        &format!("{d}/identification.csv"),
        "--validate",
        &format!("{d}/validation.csv"),
        "--out",
        &out_dir,
    ]);
    assert!(ok, "{out}{err}");
    assert!(dir.join("run/report.md").exists());
    // Bad input is refused naming the flag's value.
    let (ok, _, err) = crs(&["calibrate", "generate", "--scenario", "drum-sideways"]);
    assert!(!ok && err.contains("drum-sideways"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
