//! `crs calibrate bench-diagnosis`, reduced to one seed of two scenarios (the full benchmark is
//! a command whose figures are in docs/calibration.md): a baseline must add nothing, a drum
//! radius error of ≥ 0.25 mm must be named, no step's FK may fail, no parameter may leave its
//! physical range.
use std::path::Path;
use std::process::Command;

#[test]
fn bench_diagnosis_smoke() {
    let o = Command::new(env!("CARGO_BIN_EXE_crs"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
        .args([
            "calibrate",
            "bench-diagnosis",
            "--seeds",
            "1",
            "--poses",
            "10",
            "--baseline-seeds",
            "1",
            "--scenarios",
            "baseline,drum",
        ])
        .output()
        .expect("run crs");
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{out}{err}");
    assert!(out.contains("| baseline | 1 (0) |"), "{out}{err}");
    assert!(
        out.contains("| runs with an FK failure in any step | 0/2 |"),
        "{out}"
    );
    assert!(
        out.contains("| runs with a non-physical final parameter | 0/2 |"),
        "{out}"
    );
    assert!(
        err.contains("drum          seed 0") && err.contains("chosen [drum"),
        "{err}"
    );
}
