//! The monitor's safety parameter set. Profiles (no switch that turns
//! a check off outside the bench profile), the accepted platform (hash pinned), the SRDO
//! configuration whose CRC goes on the bus, and the CRC of the whole parameter set.

use safety_monitor::config::{self, MonitorConfig};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

/// The shipped monitor config edited line by line (`edit(section, line) -> Some(new line)`),
/// plus `extra` lines appended to `[monitor]`, with the platform and drives copied beside it.
fn load_edited(
    tag: &str,
    edit: impl Fn(&str, &str) -> Option<String>,
    extra_monitor: &[&str],
    platform_bytes: Option<&[u8]>,
) -> Result<MonitorConfig, String> {
    let text = std::fs::read_to_string(root().join("safety-monitor.toml")).unwrap();
    let mut out = Vec::new();
    let mut section = String::new();
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            section = t.trim_matches(|c| c == '[' || c == ']').to_string();
            out.push(line.to_string());
            if section == "monitor" {
                out.extend(extra_monitor.iter().map(|s| s.to_string()));
            }
            continue;
        }
        out.push(edit(&section, t).unwrap_or_else(|| line.to_string()));
    }
    let dir = std::env::temp_dir().join(format!("sm-integrity-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let plat = platform_bytes
        .map(<[u8]>::to_vec)
        .unwrap_or_else(|| std::fs::read(root().join("icosahedron.toml")).unwrap());
    std::fs::write(dir.join("icosahedron.toml"), plat).unwrap();
    std::fs::copy(root().join("drives.toml"), dir.join("drives.toml")).unwrap();
    let p = dir.join("safety-monitor.toml");
    std::fs::write(&p, out.join("\n") + "\n").unwrap();
    let r = config::load(&p).map_err(|e| e.to_string());
    std::fs::remove_dir_all(&dir).ok();
    r
}

fn set(
    sec: &'static str,
    key: &'static str,
    v: &'static str,
) -> impl Fn(&str, &str) -> Option<String> {
    move |s, l| (s == sec && l.starts_with(&format!("{key} ="))).then(|| format!("{key} = {v}"))
}

#[test]
fn switching_a_check_off_needs_the_bench_profile() {
    for (sec, key, off) in [
        ("monitor", "require_ready", "false"),
        ("feedback", "check_following_error", "false"),
        ("feedback", "silence_cycles", "0"),
        ("forces", "check", "false"),
        ("motion", "check", "false"),
        ("can", "check_rpdo", "false"),
    ] {
        let e = load_edited("robot", set(sec, key, off), &[], None).expect_err(&format!(
            "{sec}.{key} = {off} accepted in the robot profile"
        ));
        assert!(
            e.contains(&format!("{sec}.{key}")) && e.contains("bench"),
            "{sec}.{key}: {e}"
        );
        // The same switch in the bench profile loads.
        let bench = |s: &str, l: &str| {
            set(sec, key, off)(s, l).or_else(|| set("monitor", "profile", "\"bench\"")(s, l))
        };
        let c = load_edited("bench", bench, &[], None)
            .unwrap_or_else(|e| panic!("{sec}.{key} in the bench profile: {e}"));
        assert!(c.is_bench());
    }
    let e = load_edited("prof", set("monitor", "profile", "\"lab\""), &[], None).unwrap_err();
    assert!(e.contains("monitor.profile"), "{e}");
}

#[test]
fn only_the_accepted_platform_file_runs() {
    let shipped = load_edited("ok", |_, _| None, &[], None).unwrap();
    assert!(!shipped.is_bench());
    // One byte more (a comment) in the platform file: refused, naming both hashes.
    let mut changed = std::fs::read(root().join("icosahedron.toml")).unwrap();
    changed.extend_from_slice(b"# recalibrated\n");
    let e = load_edited("changed", |_, _| None, &[], Some(&changed)).unwrap_err();
    assert!(
        e.contains("monitor.platform_sha256") && e.contains(&shipped.platform_sha256),
        "{e}"
    );
    // No hash at all: refused in the robot profile, allowed on the bench.
    let drop_hash = |s: &str, l: &str| {
        (s == "monitor" && l.starts_with("platform_sha256")).then(|| "# no hash".to_string())
    };
    let e = load_edited("nohash", drop_hash, &[], None).unwrap_err();
    assert!(e.contains("platform_sha256") && e.contains("accept"), "{e}");
    let bench =
        |s: &str, l: &str| drop_hash(s, l).or_else(|| set("monitor", "profile", "\"bench\"")(s, l));
    assert!(load_edited("nohash-bench", bench, &[], None).is_ok());
}

#[test]
fn srdo_settings_are_bounded() {
    for (key, bad) in [
        ("safety_validation_time_ms", "15"),
        ("safety_validation_time_ms", "201"),
        ("safety_pair_window_ms", "0"),
        ("safety_pair_window_ms", "51"),
        ("safety_cob_id", "0x7FD"),
    ] {
        let e = load_edited("srdo", set("can", key, bad), &[], None).unwrap_err();
        assert!(e.contains(&format!("can.{key}")), "{key} = {bad}: {e}");
    }
    assert!(
        load_edited(
            "srdo-ok",
            set("can", "safety_validation_time_ms", "200"),
            &[],
            None
        )
        .is_ok()
    );
}

/// The shipped monitor announces the SRDO CRC that the shipped drives configuration expects
/// (drive-io's own parser and CRC of `[safety_heartbeat]`, read here from the TOML by hand so
/// this crate does not depend on drive-io): otherwise nothing would ever move.
#[test]
fn shipped_monitor_and_drives_agree_on_the_srdo_crc() {
    let drives: toml::Table =
        toml::from_str(&std::fs::read_to_string(root().join("drives.toml")).unwrap()).unwrap();
    let sh = drives["safety_heartbeat"].as_table().unwrap();
    let n = |k: &str| sh[k].as_integer().unwrap();
    let consumer = can_transport::safety_frame::SrdoParams {
        cob_id: n("cob_id") as u16,
        refresh_time_ms: n("refresh_time_ms") as u32,
        validation_time_ms: n("validation_time_ms") as u32,
        pair_window_ms: n("pair_window_ms") as u32,
    };
    for f in ["safety-monitor.toml", "safety-monitor-helicopter.toml"] {
        let c = config::load(&root().join(f)).unwrap();
        assert_eq!(c.srdo(), consumer, "{f}");
        assert_eq!(c.srdo().crc(), consumer.crc(), "{f}");
    }
}

/// The safety parameter CRC covers the monitor file, the platform and the drives file: any
/// byte changed in any of them changes it.
#[test]
fn safety_parameter_crc_covers_every_file() {
    let base = load_edited("crc0", |_, _| None, &[], None)
        .unwrap()
        .safety_params_crc;
    let again = load_edited("crc1", |_, _| None, &[], None)
        .unwrap()
        .safety_params_crc;
    assert_eq!(base, again);
    let c = load_edited("crc2", set("monitor", "reset_clear_cycles", "4"), &[], None).unwrap();
    assert_ne!(c.safety_params_crc, base);
    // The platform's bytes count too (bench profile without a pinned hash, so that a changed
    // platform loads at all): the same monitor file, one byte more in the platform.
    let bench_no_hash = |s: &str, l: &str| {
        set("monitor", "profile", "\"bench\"")(s, l)
            .or_else(|| (s == "monitor" && l.starts_with("platform_sha256")).then(String::new))
    };
    let b0 = load_edited("crc3", bench_no_hash, &[], None)
        .unwrap()
        .safety_params_crc;
    let mut p = std::fs::read(root().join("icosahedron.toml")).unwrap();
    p.extend_from_slice(b"\n");
    let b1 = load_edited("crc4", bench_no_hash, &[], Some(&p))
        .unwrap()
        .safety_params_crc;
    assert_ne!(b0, b1);
}

/// The accept step: a calibration's new platform file is shown as a diff and changes nothing
/// without --yes; with it the monitor's accepted copy and its hash are written, the config
/// loads the new parameters, and later edits of the candidate file (a calibration writing
/// again) do not reach the monitor.
#[test]
fn a_new_platform_becomes_active_only_through_accept() {
    let dir = std::env::temp_dir().join(format!("sm-accept-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for f in ["safety-monitor.toml", "icosahedron.toml", "drives.toml"] {
        std::fs::copy(root().join(f), dir.join(f)).unwrap();
    }
    let cfg = dir.join("safety-monitor.toml");
    let before = std::fs::read_to_string(&cfg).unwrap();
    let plat = std::fs::read_to_string(dir.join("icosahedron.toml")).unwrap();
    let calibrated = plat.replace("f_max_n = 9000.0", "f_max_n = 9500.0");
    assert_ne!(calibrated, plat);
    let cand = dir.join("calibrated.toml");
    std::fs::write(&cand, &calibrated).unwrap();

    // Shown only.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_safety-monitor"))
        .args([
            "accept",
            cand.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(text.contains("forces.f_max_n: 9000 -> 9500"), "{text}");
    assert!(text.contains("1 parameter(s) differ"), "{text}");
    assert!(text.contains("(accepted)"), "{text}");
    assert_eq!(std::fs::read_to_string(&cfg).unwrap(), before);
    assert_eq!(config::load(&cfg).unwrap().platform.f_max_n, 9000.0);

    // Accepted.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_safety-monitor"))
        .args([
            "accept",
            cand.to_str().unwrap(),
            "--yes",
            "--config",
            cfg.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let c = config::load(&cfg).unwrap();
    assert_eq!(c.platform.f_max_n, 9500.0);
    assert!(
        c.platform_file
            .ends_with("accepted/safety-monitor.platform.toml")
    );
    assert_eq!(
        std::fs::read(&c.platform_file).unwrap(),
        calibrated.as_bytes()
    );
    // Every other line of the config is unchanged.
    let after = std::fs::read_to_string(&cfg).unwrap();
    let strip = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| !l.starts_with("platform"))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(strip(&before), strip(&after));
    // The calibration writes its file again: the monitor still runs its accepted copy.
    std::fs::write(&cand, plat.replace("f_max_n = 9000.0", "f_max_n = 8000.0")).unwrap();
    assert_eq!(config::load(&cfg).unwrap().platform.f_max_n, 9500.0);
    // Editing the accepted copy itself is caught by the pinned hash.
    let copy = c.platform_file.clone();
    std::fs::write(&copy, calibrated.replace("9500.0", "9600.0")).unwrap();
    let e = config::load(&cfg).unwrap_err().to_string();
    assert!(e.contains("platform_sha256"), "{e}");
    // A candidate the monitor's parser refuses is not accepted.
    std::fs::write(&cand, "[platform]\nname = \"x\"\n").unwrap();
    let e = safety_monitor::accept::accept(&cfg, &cand, true).unwrap_err();
    assert!(
        matches!(e, safety_monitor::accept::AcceptError::Candidate(_)),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
