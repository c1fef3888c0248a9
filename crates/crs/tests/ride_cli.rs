//! `crs ride` against the real motion-core daemon with `--control`: it comes up idle (its
//! configured demo does not run), a bad ride file is refused naming file, line, axis and bound
//! (exit 1) and the loop stays idle, the demo ride starts, aborts, and the platform returns
//! home. motion-core runs alone on its own iceoryx2 prefix (no drives: the loop and its
//! control socket are what is under test).
mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};
use std::time::{Duration, Instant};

struct Daemon(Child);
impl Drop for Daemon {
    fn drop(&mut self) {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let _ = self.0.wait();
    }
}

fn crs_ride(crs: &Path, sock: &Path, args: &[&str]) -> Output {
    Command::new(crs)
        .current_dir(common::root())
        .arg("ride")
        .args(args)
        .env("CRS_CONTROL_SOCKET", sock)
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Asks `crs ride status` until `want` is in the answer (motion-core's loop runs on its own
/// clock; this waits on the answer, not on a time).
fn wait_status(crs: &Path, sock: &Path, want: &str, secs: f64) -> String {
    let t0 = Instant::now();
    loop {
        let o = crs_ride(crs, sock, &["status"]);
        let t = text(&o);
        if o.status.success() && t.contains(want) {
            return t;
        }
        assert!(
            t0.elapsed().as_secs_f64() < secs,
            "no `{want}` after {secs} s: {t}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// x of the status line's `pose [x, y, z] m`.
fn pose_x(status: &str) -> f64 {
    let after = status.split("pose [").nth(1).expect("a pose in the status");
    after.split(',').next().unwrap().trim().parse().unwrap()
}

#[test]
fn crs_ride_starts_aborts_and_homes_and_refuses_a_bad_file_on_the_daemon() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    let bins = crs.parent().unwrap().to_path_buf();
    assert!(
        bins.join("motion-core").is_file(),
        "motion-core not built next to crs: `cargo build -p motion-core` first"
    );
    let dir = std::env::temp_dir().join(format!("crs-ride-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let sock = dir.join("control.sock");
    let log = std::fs::File::create(dir.join("motion-core.log")).unwrap();
    let _daemon = Daemon(
        Command::new(bins.join("motion-core"))
            .current_dir(common::root())
            .args(["--config", "config/motion-core.toml", "--control"])
            .arg(&sock)
            .env(
                "CRS_IPC_PREFIX",
                format!("crs-ride-cli-{}/", std::process::id()),
            )
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    let idle = wait_status(&crs, &sock, "idle, holding", 30.0);
    assert!(idle.contains("pose [0.000, 0.000, 2.000] m"), "{idle}");
    assert!(idle.contains("rides started: 0"), "{idle}");

    let bad = dir.join("bad.csv");
    std::fs::write(
        &bad,
        "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n0,0.2,0,2,0,0,0\n2,0,4.0,2,0,0,0\n",
    )
    .unwrap();
    let o = crs_ride(&crs, &sock, &["start", bad.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains(&format!("{}:3:", bad.display())) && t.contains("y_m = 4.000 m"),
        "{t}"
    );
    assert!(t.contains("[-1.500, 1.500] m"), "{t}");
    let still = wait_status(&crs, &sock, "idle", 5.0);
    assert!(still.contains("rides started: 0"), "{still}");

    let o = crs_ride(&crs, &sock, &["start", "config/demo-waypoints.csv"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("ride config/demo-waypoints.csv started"));
    // Under way (x grows towards the first waypoint's 0.4 m), then abort.
    let t0 = Instant::now();
    loop {
        let s = wait_status(&crs, &sock, "riding", 10.0);
        if pose_x(&s) > 0.05 {
            break;
        }
        assert!(t0.elapsed().as_secs() < 20, "the ride does not move: {s}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = crs_ride(&crs, &sock, &["abort"]);
    assert!(o.status.success(), "{}", text(&o));
    let stopped = wait_status(&crs, &sock, "idle, holding", 30.0);
    assert!(
        !stopped.contains("pose [0.000, 0.000, 2.000] m"),
        "{stopped}"
    );
    let o = crs_ride(&crs, &sock, &["start", "config/demo-waypoints.csv"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o).contains("run `crs ride home` first"),
        "{}",
        text(&o)
    );
    let o = crs_ride(&crs, &sock, &["home"]);
    assert!(o.status.success(), "{}", text(&o));
    let home = wait_status(&crs, &sock, "rides started: 2", 10.0);
    let home = if home.contains("idle") {
        home
    } else {
        wait_status(&crs, &sock, "idle, holding", 60.0)
    };
    assert!(home.contains("pose [0.000, 0.000, 2.000] m"), "{home}");
}
