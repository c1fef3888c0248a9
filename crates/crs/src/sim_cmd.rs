//! `crs sim`: the whole simulated stack as separate processes, as a user runs it.
//!
//! sim-plant (the winches + platform physics on the bus), safety-monitor (when built),
//! drive-io (CiA 402 master) and motion-core (the 1 ms loop) start in that order on the default
//! icosahedron configuration, over vcan0 when the kernel has it and over the CAN-over-UDP
//! loopback bus otherwise (the launcher says which). motion-core runs the demo trajectory; the
//! launcher listens on iceoryx2 (its own service prefix per run) and prints the tracked-pose
//! error against the reference, the cable forces against the limits, the loop statistics and the
//! monitor state. Ctrl-C stops all children cleanly; a child that dies stops the rest.

use crs_ipc::{
    DriveFeedback, EventKind, Heartbeat, IpcNode, JointSetpoint, LoopStatsSample, PlantTruth,
    ProcessId, StateEvent,
};
use motion_core::Pose;
use motion_core::config::load_platform;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// motion-core daemon TOML (platform, surrogate, realtime, trajectory).
    #[arg(long, default_value = "config/motion-core.toml")]
    config: PathBuf,
    /// Drive bus TOML.
    #[arg(long, default_value = "config/drives.toml")]
    drives: PathBuf,
    /// Plant TOML (must be the platform of the daemon TOML).
    #[arg(long, default_value = "config/plant/icosahedron.toml")]
    plant: PathBuf,
    /// `auto` (vcan0 if present, else the UDP loopback bus), or a transport such as
    /// `socketcan:vcan0` / `udpbus:239.255.70.9:20900`.
    #[arg(long, default_value = "auto")]
    transport: String,
    /// Waypoint CSV for the demo trajectory (default: the daemon TOML's).
    #[arg(long)]
    waypoints: Option<PathBuf>,
    /// Seconds to hold after the trajectory before stopping (static error is taken here).
    #[arg(long, default_value_t = 1.0)]
    hold_s: f64,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 120.0)]
    timeout_s: f64,
    /// Directory with the stack's binaries (default: next to this `crs`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// Directory for the children's logs and the JSON summary.
    #[arg(long, default_value = "out/sim")]
    out: PathBuf,
    /// Run without the safety monitor even if it is built.
    #[arg(long)]
    no_monitor: bool,
    /// Fail (exit 1) unless the run meets the expectations: trajectory completed, no e-stop,
    /// every plant step converged, forces within [f_min, f_max], static error below
    /// --max-static-error-mm. For tests and CI.
    #[arg(long)]
    check: bool,
    /// Static (at rest) position error bound for --check, mm.
    #[arg(long, default_value_t = 20.0)]
    max_static_error_mm: f64,
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::Relaxed);
}

struct Proc {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

/// The children, stopped (SIGTERM, then SIGKILL after 3 s) in reverse start order on drop.
struct Stack {
    procs: Vec<Proc>,
}

impl Stack {
    fn spawn(
        &mut self,
        name: &'static str,
        exe: &Path,
        args: &[String],
        prefix: &str,
        out: &Path,
    ) -> Result<(), String> {
        let log = out.join(format!("{name}.log"));
        let f = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
        let f2 = f.try_clone().map_err(|e| e.to_string())?;
        let child = Command::new(exe)
            .args(args)
            .env("CRS_IPC_PREFIX", prefix)
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()),
            )
            .stdin(Stdio::null())
            .stdout(f)
            .stderr(f2)
            .spawn()
            .map_err(|e| format!("starting {}: {e}", exe.display()))?;
        println!(
            "  started {name:<15} pid {:>6}  log {}",
            child.id(),
            log.display()
        );
        self.procs.push(Proc { name, child, log });
        Ok(())
    }

    /// The first child that has exited, with its status.
    fn exited(&mut self) -> Option<(&'static str, std::process::ExitStatus, PathBuf)> {
        for p in &mut self.procs {
            if let Ok(Some(st)) = p.child.try_wait() {
                return Some((p.name, st, p.log.clone()));
            }
        }
        None
    }

    fn stop_all(&mut self) {
        for p in self.procs.iter_mut().rev() {
            if let Ok(None) = p.child.try_wait() {
                // SAFETY: kill(2) on our own child's pid.
                unsafe { libc::kill(p.child.id() as libc::pid_t, libc::SIGTERM) };
            }
        }
        let t0 = Instant::now();
        for p in self.procs.iter_mut().rev() {
            loop {
                match p.child.try_wait() {
                    Ok(Some(_)) | Err(_) => break,
                    Ok(None) if t0.elapsed() > Duration::from_secs(3) => {
                        let _ = p.child.kill();
                        let _ = p.child.wait();
                        break;
                    }
                    Ok(None) => std::thread::sleep(Duration::from_millis(10)),
                }
            }
        }
        self.procs.clear();
    }
}

impl Drop for Stack {
    fn drop(&mut self) {
        self.stop_all();
    }
}

fn tail(path: &Path, n: usize) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// vcan0 when the kernel can open it, else a UDP multicast bus with a per-run port.
fn choose_transport(arg: &str) -> Result<String, String> {
    if arg != "auto" {
        arg.parse::<can_transport::TransportSpec>()
            .map_err(|e| format!("--transport: {e}"))?;
        return Ok(arg.to_string());
    }
    let vcan = can_transport::TransportSpec::SocketCan {
        iface: "vcan0".into(),
    };
    match can_transport::open(&vcan) {
        Ok(_) => Ok("socketcan:vcan0".into()),
        Err(e) => {
            let port = 20000 + (std::process::id() % 20000) as u16;
            println!("  vcan0 not available ({e}); using the CAN-over-UDP loopback bus");
            Ok(format!("udpbus:239.255.70.9:{port}"))
        }
    }
}

#[derive(Default, serde::Serialize)]
struct Summary {
    transport: String,
    monitor: bool,
    plant_samples: u64,
    setpoints: u64,
    tracking_position_mean_mm: f64,
    tracking_position_max_mm: f64,
    tracking_rotation_mean_deg: f64,
    tracking_rotation_max_deg: f64,
    static_position_mm: f64,
    static_rotation_deg: f64,
    force_min_n: f64,
    force_max_n: f64,
    f_min_n: f64,
    f_max_n: f64,
    non_converged_plant_steps: u64,
    loop_cycles: u64,
    loop_overruns: u64,
    loop_rejected: u64,
    loop_lateness_p99_us: f64,
    loop_lateness_max_us: f64,
    loop_compute_p99_us: f64,
    estops: u64,
    monitor_heartbeats: u64,
    drive_faults: u64,
}

pub fn run(a: SimArgs) -> Result<(), Box<dyn std::error::Error>> {
    let bin_dir = match &a.bin_dir {
        Some(d) => d.clone(),
        None => std::env::current_exe()?
            .parent()
            .map(Path::to_path_buf)
            .ok_or("cannot locate the binary directory")?,
    };
    let exe = |name: &str| bin_dir.join(name);
    for need in ["motion-core", "drive-io", "sim-plant"] {
        if !exe(need).is_file() {
            return Err(format!(
                "{} not found: build the stack first (`cargo build --release --workspace --bins`) or pass --bin-dir",
                exe(need).display()
            )
            .into());
        }
    }
    let with_monitor = !a.no_monitor && exe("safety-monitor").is_file();
    // Validate the inputs before anything starts.
    let daemon = motion_core::daemon::config::load(&a.config).map_err(|e| e.to_string())?;
    let platform = load_platform(&daemon.platform)?;
    let p = platform.model.params();
    let (f_min, f_max) = (p.f_min, p.f_max);
    for f in [&a.drives, &a.plant] {
        if !f.is_file() {
            return Err(format!("{}: no such file", f.display()).into());
        }
    }
    if !(a.hold_s.is_finite() && a.hold_s >= 0.0 && a.timeout_s > 0.0) {
        return Err("--hold-s must be ≥ 0 and --timeout-s > 0".into());
    }
    std::fs::create_dir_all(&a.out)?;
    let transport = choose_transport(&a.transport)?;
    let prefix = format!("crs-sim-{}/", std::process::id());
    println!(
        "crs sim: platform `{}`, transport {transport}, iceoryx2 prefix {prefix}, safety monitor {}",
        platform.name,
        if with_monitor {
            "on"
        } else if a.no_monitor {
            "off (--no-monitor)"
        } else {
            "not built (crates/safety-monitor): running without"
        }
    );

    // SAFETY: the handler only stores to an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let node = IpcNode::with_prefix("crs-sim", &prefix)?;
    let truth = node.subscriber::<PlantTruth>()?;
    let setpoints = node.subscriber::<JointSetpoint>()?;
    let loop_stats = node.subscriber::<LoopStatsSample>()?;
    let events = node.subscriber::<StateEvent>()?;
    let heartbeats = node.subscriber::<Heartbeat>()?;
    let feedback = node.subscriber::<DriveFeedback>()?;

    let mut stack = Stack { procs: Vec::new() };
    let s = |p: &Path| p.display().to_string();
    let wait_for = |what: &str, secs: f64, ready: &mut dyn FnMut() -> bool, stack: &mut Stack| {
        let t0 = Instant::now();
        while !ready() {
            if let Some((name, st, log)) = stack.exited() {
                return Err(format!(
                    "{name} exited ({st}) while waiting for {what}:\n{}",
                    tail(&log, 15)
                ));
            }
            if INTERRUPTED.load(Ordering::Relaxed) {
                return Err("interrupted".to_string());
            }
            if t0.elapsed().as_secs_f64() > secs {
                return Err(format!("timed out after {secs} s waiting for {what}"));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(())
    };

    stack.spawn(
        "sim-plant",
        &exe("sim-plant"),
        &[
            "--plant".into(),
            s(&a.plant),
            "--drives".into(),
            s(&a.drives),
            "--transport".into(),
            transport.clone(),
        ],
        &prefix,
        &a.out,
    )?;
    let mut first_truth = None;
    wait_for(
        "the plant's first state",
        20.0,
        &mut || {
            while let Ok(Some(t)) = truth.receive() {
                first_truth = Some(t);
            }
            first_truth.is_some()
        },
        &mut stack,
    )?;
    if with_monitor {
        stack.spawn(
            "safety-monitor",
            &exe("safety-monitor"),
            &["--transport".into(), transport.clone()],
            &prefix,
            &a.out,
        )?;
    }
    stack.spawn(
        "drive-io",
        &exe("drive-io"),
        &[
            "--config".into(),
            s(&a.drives),
            "--transport".into(),
            transport.clone(),
        ],
        &prefix,
        &a.out,
    )?;
    let operational = crs_ipc::BusState::Ready as u32;
    wait_for(
        "the drives to be operational (NMT boot, SDO, CiA 402 enable)",
        30.0,
        &mut || {
            let mut ok = false;
            while let Ok(Some(f)) = feedback.receive() {
                ok |= f.bus_state == operational;
            }
            ok
        },
        &mut stack,
    )?;
    let mut mc_args = vec![
        "--config".into(),
        s(&a.config),
        "--exit-after-plan-s".into(),
        a.hold_s.to_string(),
    ];
    if let Some(w) = &a.waypoints {
        mc_args.push("--waypoints".into());
        mc_args.push(s(w));
    }
    stack.spawn(
        "motion-core",
        &exe("motion-core"),
        &mc_args,
        &prefix,
        &a.out,
    )?;

    // Follow the run.
    let mut sum = Summary {
        transport: transport.clone(),
        monitor: with_monitor,
        force_min_n: f64::INFINITY,
        force_max_n: f64::NEG_INFINITY,
        f_min_n: f_min,
        f_max_n: f_max,
        ..Summary::default()
    };
    let mut refs: std::collections::VecDeque<(u64, [f64; 6])> = Default::default();
    let (mut sum_p, mut sum_r, mut n_track) = (0.0, 0.0, 0u64);
    let mut last_truth = first_truth;
    let mut last_ref = None;
    let t0 = Instant::now();
    let result: Result<(), String> = loop {
        std::thread::sleep(Duration::from_millis(5));
        while let Ok(Some(sp)) = setpoints.receive() {
            sum.setpoints += 1;
            refs.push_back((sp.timestamp_ns, sp.pose));
            last_ref = Some(sp.pose);
            if refs.len() > 4000 {
                refs.pop_front();
            }
        }
        while let Ok(Some(t)) = truth.receive() {
            sum.plant_samples += 1;
            if t.converged == 0 {
                sum.non_converged_plant_steps += 1;
            }
            for f in &t.force_n[..t.cable_count as usize] {
                sum.force_min_n = sum.force_min_n.min(*f);
                sum.force_max_n = sum.force_max_n.max(*f);
            }
            // Tracking error against the newest reference published before this plant state.
            if let Some((_, x_ref)) = refs.iter().rev().find(|(ts, _)| *ts <= t.timestamp_ns) {
                let (dp, dr) = Pose::from_array(t.pose).error_to(&Pose::from_array(*x_ref));
                sum_p += dp;
                sum_r += dr;
                n_track += 1;
                sum.tracking_position_max_mm = sum.tracking_position_max_mm.max(dp * 1e3);
                sum.tracking_rotation_max_deg = sum.tracking_rotation_max_deg.max(dr.to_degrees());
            }
            last_truth = Some(t);
        }
        while let Ok(Some(s)) = loop_stats.receive() {
            sum.loop_cycles = s.cycles;
            sum.loop_overruns = s.overruns;
            sum.loop_rejected = s.rejected;
            sum.loop_lateness_p99_us = s.lateness_p99_ns as f64 * 1e-3;
            sum.loop_lateness_max_us = s.lateness_max_ns as f64 * 1e-3;
            sum.loop_compute_p99_us = s.compute_p99_ns as f64 * 1e-3;
        }
        while let Ok(Some(e)) = events.receive() {
            if e.kind == EventKind::EStop as u32 {
                sum.estops += 1;
                println!("  E-STOP from process {} (detail {})", e.source, e.detail);
            }
        }
        while let Ok(Some(h)) = heartbeats.receive() {
            if h.source == ProcessId::SafetyMonitor as u32 {
                sum.monitor_heartbeats += 1;
            }
        }
        while let Ok(Some(f)) = feedback.receive() {
            if f.fault_code != 0 {
                sum.drive_faults += 1;
            }
        }
        if INTERRUPTED.load(Ordering::Relaxed) {
            break Err("interrupted (Ctrl-C): stopped all processes".into());
        }
        if let Some((name, st, log)) = stack.exited() {
            if name == "motion-core" && st.success() {
                break Ok(());
            }
            break Err(format!(
                "{name} exited ({st}); stopping the stack:\n{}",
                tail(&log, 20)
            ));
        }
        if t0.elapsed().as_secs_f64() > a.timeout_s {
            break Err(format!("timed out after {} s", a.timeout_s));
        }
    };
    // Let the last plant states arrive, then stop everything.
    std::thread::sleep(Duration::from_millis(50));
    while let Ok(Some(t)) = truth.receive() {
        last_truth = Some(t);
    }
    stack.stop_all();
    if n_track > 0 {
        sum.tracking_position_mean_mm = sum_p / n_track as f64 * 1e3;
        sum.tracking_rotation_mean_deg = (sum_r / n_track as f64).to_degrees();
    }
    if let (Some(t), Some(r)) = (last_truth, last_ref) {
        let (dp, dr) = Pose::from_array(t.pose).error_to(&Pose::from_array(r));
        sum.static_position_mm = dp * 1e3;
        sum.static_rotation_deg = dr.to_degrees();
    }
    print_summary(&sum);
    let json = a.out.join("summary.json");
    std::fs::write(&json, serde_json::to_string_pretty(&sum)?)?;
    println!("summary written to {}", json.display());
    result?;
    if sum.plant_samples == 0 || sum.setpoints == 0 {
        return Err("the run produced no plant states or no setpoints".into());
    }
    if a.check {
        let mut fails = Vec::new();
        if sum.estops > 0 {
            fails.push(format!("{} e-stop(s)", sum.estops));
        }
        if sum.non_converged_plant_steps > 0 {
            fails.push(format!(
                "{} plant steps without equilibrium",
                sum.non_converged_plant_steps
            ));
        }
        if !(sum.force_min_n >= f_min && sum.force_max_n <= f_max) {
            fails.push(format!(
                "forces {:.0} … {:.0} N outside [{f_min:.0}, {f_max:.0}] N",
                sum.force_min_n, sum.force_max_n
            ));
        }
        if sum.static_position_mm.is_nan() || sum.static_position_mm > a.max_static_error_mm {
            fails.push(format!(
                "static position error {:.2} mm > {} mm",
                sum.static_position_mm, a.max_static_error_mm
            ));
        }
        if sum.loop_rejected > 0 {
            fails.push(format!(
                "{} references rejected by motion-core",
                sum.loop_rejected
            ));
        }
        if sum.drive_faults > 0 {
            fails.push(format!("{} drive fault reports", sum.drive_faults));
        }
        if !fails.is_empty() {
            println!("SIM-CHECK: FAIL ({})", fails.join("; "));
            return Err(format!("check failed: {}", fails.join("; ")).into());
        }
        println!("SIM-CHECK: PASS");
    }
    Ok(())
}

fn print_summary(s: &Summary) {
    println!("\n== crs sim summary ({})", s.transport);
    println!(
        "  setpoints {}, plant states {} ({} without equilibrium)",
        s.setpoints, s.plant_samples, s.non_converged_plant_steps
    );
    println!(
        "  tracked pose vs reference: position mean {:.2} mm, max {:.2} mm; rotation mean {:.3}°, max {:.3}°",
        s.tracking_position_mean_mm,
        s.tracking_position_max_mm,
        s.tracking_rotation_mean_deg,
        s.tracking_rotation_max_deg
    );
    println!(
        "  at rest after the trajectory: position {:.2} mm, rotation {:.3}°",
        s.static_position_mm, s.static_rotation_deg
    );
    let ok = s.force_min_n >= s.f_min_n && s.force_max_n <= s.f_max_n;
    println!(
        "  cable forces {:.0} … {:.0} N (limits {:.0} … {:.0} N): {}",
        s.force_min_n,
        s.force_max_n,
        s.f_min_n,
        s.f_max_n,
        if ok { "within" } else { "OUTSIDE" }
    );
    println!(
        "  loop: {} cycles, {} overruns, {} rejected; lateness p99 {:.1} µs, max {:.1} µs; compute p99 {:.1} µs",
        s.loop_cycles,
        s.loop_overruns,
        s.loop_rejected,
        s.loop_lateness_p99_us,
        s.loop_lateness_max_us,
        s.loop_compute_p99_us
    );
    println!(
        "  safety monitor: {}; e-stops {}; drive faults reported {}",
        if s.monitor {
            format!("{} heartbeats", s.monitor_heartbeats)
        } else {
            "not running".into()
        },
        s.estops,
        s.drive_faults
    );
}
