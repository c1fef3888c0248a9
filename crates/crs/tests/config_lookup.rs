//! The stack's one configuration lookup rule (crates/crs-service/src/paths.rs, docs/install.md) as an
//! installed binary meets it outside the repository: `config/…` defaults resolve to
//! $CRS_CONFIG_DIR, else ./config, else /etc/crs/config — for `crs sim` and the daemons.
//! Nothing starts in these runs: `crs sim` stops at its ride check, the daemons at their config.
mod common;

use std::path::PathBuf;
use std::process::Command;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("crs-config-lookup-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn crs_sim_outside_the_repository_reads_the_config_dir_of_the_rule() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    let bins = common::stack_bin_dir(&crs);
    let here = scratch("sim");
    // A ride outside the region: refused before anything starts, which proves that the
    // platform's daemon, plant, monitor and drives configs were all found.
    std::fs::write(
        here.join("far.csv"),
        "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n0,0,0,9,0,0,0\n",
    )
    .unwrap();
    let o = Command::new(&crs)
        .current_dir(&here)
        .args(["sim", "--waypoints", "far.csv", "--bin-dir"])
        .arg(&bins)
        .env("CRS_CONFIG_DIR", common::root().join("config"))
        .output()
        .unwrap();
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(
        t.contains("ride refused, nothing started: far.csv:2:"),
        "{t}"
    );
    assert!(t.contains("z_m = 9.000 m"), "{t}");

    // Without the override and without ./config: the installed directory, named.
    let o = Command::new(&crs)
        .current_dir(&here)
        .args(["sim", "--bin-dir"])
        .arg(&bins)
        .env_remove("CRS_CONFIG_DIR")
        .output()
        .unwrap();
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(t.contains("/etc/crs/config/"), "{t}");
    let _ = std::fs::remove_dir_all(&here);
}

#[test]
fn every_daemon_outside_the_repository_looks_in_etc_crs() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    let bins = common::stack_bin_dir(&crs);
    let here = scratch("daemons");
    for (bin, file) in [
        ("motion-core", "/etc/crs/config/motion-core.toml"),
        ("drive-io", "/etc/crs/config/drives.toml"),
        ("safety-monitor", "/etc/crs/config/safety-monitor.toml"),
        ("sim-plant", "/etc/crs/config/plant/icosahedron.toml"),
    ] {
        if std::path::Path::new(file).exists() {
            panic!("{file} exists on this machine: the test needs a machine without the package");
        }
        let o = Command::new(bins.join(bin))
            .current_dir(&here)
            .env_remove("CRS_CONFIG_DIR")
            .output()
            .unwrap();
        let t = text(&o);
        assert!(!o.status.success(), "{bin}: {t}");
        assert!(t.contains(file), "{bin} did not look for {file}: {t}");
    }
    let _ = std::fs::remove_dir_all(&here);
}
