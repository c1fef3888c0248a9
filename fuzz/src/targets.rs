//! The fuzz targets: every decoder and loader of the stack, with the seed inputs a mutator starts
//! from (the shipped configs, files the stack writes, valid frames) and the property checked
//! beyond "does not panic".

use can_transport::CanFrame;
use can_transport::safety_frame::{self, SafetyHeartbeat, SafetyState};
use drive_bus::safety_watch::{SafetyWatch, SafetyWatchConfig};
use nalgebra::Vector3;
use rand::Rng;
use rand::rngs::SmallRng;
use std::path::{Path, PathBuf};

/// What one case did.
#[derive(Debug)]
pub enum Verdict {
    Accepted,
    /// Rejected with this message.
    Rejected(String),
    /// A property beyond "no panic" failed (the message says which).
    Violation(String),
}

/// How a text loader's rejection must point at the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Locate {
    /// Binary decoder: an error value is enough.
    No,
    /// Text file: the message names a line (`file:12`, `line 12`) or a key (`` `key` ``, `field`).
    LineOrKey,
}

/// One target.
pub struct Target {
    pub name: &'static str,
    pub what: &'static str,
    pub locate: Locate,
    pub seeds: fn(&Path) -> Vec<Vec<u8>>,
    /// Runs one case; `scratch` is a per-run directory for loaders that take a path.
    pub run: fn(&[u8], &Scratch) -> Verdict,
}

/// Paths a case may use.
pub struct Scratch {
    pub config_dir: PathBuf,
    pub dir: PathBuf,
}

impl Scratch {
    fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir.join(name);
        std::fs::write(&p, bytes).expect("scratch directory is writable");
        p
    }
}

fn text(b: &[u8]) -> Option<&str> {
    std::str::from_utf8(b).ok()
}

fn verdict<T, E: std::fmt::Display>(r: Result<T, E>) -> Verdict {
    match r {
        Ok(_) => Verdict::Accepted,
        Err(e) => Verdict::Rejected(e.to_string()),
    }
}

fn read(dir: &Path, names: &[&str]) -> Vec<Vec<u8>> {
    names
        .iter()
        .map(|n| std::fs::read(dir.join(n)).unwrap_or_else(|e| panic!("seed {n}: {e}")))
        .collect()
}

const PLATFORMS: &[&str] = &[
    "icosahedron.toml",
    "icosahedron-pulleys.toml",
    "helicopter.toml",
    "crs-nominal.toml",
];

/// A frame as bytes: id (2, LE), length (1), data (up to 8).
fn frame_bytes(f: &CanFrame) -> Vec<u8> {
    let mut v = (f.id() as u16).to_le_bytes().to_vec();
    v.push(f.data().len() as u8);
    v.extend_from_slice(f.data());
    v
}

fn frames_from(b: &[u8]) -> Vec<CanFrame> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 3 <= b.len() {
        let id = u16::from_le_bytes([b[i], b[i + 1]]) & 0x7FF;
        let len = (b[i + 2] as usize).min(8).min(b.len() - i - 3);
        out.push(CanFrame::new_std_lossy(id, &b[i + 3..i + 3 + len]));
        i += 3 + len;
    }
    out
}

fn frame_seeds(_: &Path) -> Vec<Vec<u8>> {
    use drive_bus::canopen as co;
    let hb = SafetyHeartbeat {
        state: SafetyState::Run,
        cause: 0,
        counter: 7,
        epoch: 1,
    };
    let mut v: Vec<CanFrame> = vec![
        co::nmt(1, 0),
        co::sync(),
        co::rpdo1(3, 0x000F, 123_456),
        co::tpdo1(3, 0x0637, -42),
        co::tpdo2(5, 1000, 4_200_000),
        co::emcy(2, 0x8611, 0x81),
        co::sdo_download(4, 0x6060, 0, 8, 1),
        co::sdo_upload(4, 0x6041, 0),
        co::sdo_download_ok(4, 0x6060, 0),
        co::sdo_upload_ok(4, 0x6064, 0, 99, 4),
        co::sdo_abort(4, 0x1234, 1, 0x0602_0000),
    ];
    v.extend(safety_frame::encode(&hb, safety_frame::DEFAULT_COB_ID));
    v.extend(signature().encode(safety_frame::DEFAULT_COB_ID));
    let mut seeds: Vec<Vec<u8>> = v.iter().map(frame_bytes).collect();
    seeds.push(v.iter().flat_map(frame_bytes).collect());
    seeds
}

pub fn all() -> Vec<Target> {
    vec![
        Target {
            name: "platform-toml",
            what: "operator platform TOML (cdpr_model::config::parse_platform)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, PLATFORMS),
            run: |b, _| match text(b) {
                Some(t) => verdict(cdpr_model::config::parse_platform(t, "fuzz.toml")),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "monitor-platform-toml",
            what: "the safety monitor's own platform parser (safety_monitor::platform)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, PLATFORMS),
            run: |b, _| match text(b) {
                Some(t) => verdict(safety_monitor::platform::parse_platform(t, "fuzz.toml")),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "monitor-toml",
            what: "safety-monitor.toml (safety_monitor::config::load)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["safety-monitor.toml"]),
            run: |b, s| {
                // The monitor resolves its platform and drives files relative to its own file.
                let p = s.file("safety-monitor.toml", b);
                verdict(safety_monitor::config::load(&p))
            },
        },
        Target {
            name: "monitor-drives-toml",
            what: "drives.toml as the monitor reads it (safety_monitor::config::load_drives)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["drives.toml"]),
            run: |b, s| {
                verdict(safety_monitor::config::load_drives(
                    &s.file("drives.toml", b),
                ))
            },
        },
        Target {
            name: "drives-toml",
            what: "drives.toml (drives_config::DrivesConfig::parse)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["drives.toml"]),
            run: |b, _| match text(b) {
                Some(t) => verdict(drives_config::DrivesConfig::parse(t)),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "motion-core-toml",
            what: "motion-core.toml (motion_core::daemon::config::parse)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["motion-core.toml"]),
            run: |b, s| match text(b) {
                Some(t) => verdict(motion_core::daemon::config::parse(
                    t,
                    "motion-core.toml",
                    &s.config_dir,
                )),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "plant-toml",
            what: "plant TOML (sim_plant::parse_plant)",
            locate: Locate::LineOrKey,
            seeds: |d| {
                read(
                    &d.join("plant"),
                    &[
                        "crs-like.toml",
                        "icosahedron.toml",
                        "icosahedron-assembly.toml",
                    ],
                )
            },
            run: |b, s| match text(b) {
                Some(t) => verdict(sim_plant::parse_plant(
                    t,
                    "plant.toml",
                    &s.config_dir.join("plant"),
                )),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "campaign-toml",
            what: "campaign TOML (sim_plant::parse_campaign)",
            locate: Locate::LineOrKey,
            seeds: |d| {
                read(
                    &d.join("plant"),
                    &["campaign-91.toml", "campaign-default.toml"],
                )
            },
            run: |b, s| match text(b) {
                Some(t) => verdict(sim_plant::parse_campaign(
                    t,
                    "campaign.toml",
                    &s.config_dir.join("plant"),
                )),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "waypoints-csv",
            what: "waypoint CSV (motion_core::daemon::trajectory::parse_waypoints)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["demo-waypoints.csv", "calibration-campaign.csv"]),
            run: |b, _| match text(b) {
                Some(t) => verdict(motion_core::daemon::trajectory::parse_waypoints(
                    t,
                    "waypoints.csv",
                )),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "dataset-csv",
            what: "measurement data set (crs_dataset::read_dataset)",
            locate: Locate::LineOrKey,
            seeds: |_| vec![dataset_seed(true), dataset_seed(false)],
            run: |b, _| verdict(crs_dataset::read_dataset(b, "data.csv")),
        },
        Target {
            name: "surrogate-json",
            what: "surrogate file (surrogate::Surrogate::load)",
            locate: Locate::No,
            seeds: |_| vec![surrogate_seed()],
            run: |b, s| {
                let p = s.file("surrogate.json", b);
                verdict(surrogate::Surrogate::load(&p, SURROGATE_PLATFORM))
            },
        },
        Target {
            name: "candump-line",
            what: "candump log line (can_transport::candump::parse_line)",
            locate: Locate::No,
            seeds: |_| {
                vec![
                    b"(1700000000.000123) vcan0 181#3706C4FFFFFF".to_vec(),
                    b"(0.000001) can0 701#05".to_vec(),
                    b"(12.5) udpbus 101#0100070000000FF01".to_vec(),
                ]
            },
            run: |b, _| match text(b) {
                Some(t) => verdict(can_transport::candump::parse_line(t)),
                None => Verdict::Rejected("not UTF-8".into()),
            },
        },
        Target {
            name: "eds",
            what: "CiA 306 EDS/DCF (drive_bus::eds::Eds::parse)",
            locate: Locate::LineOrKey,
            seeds: |d| read(d, &["eds/crs-winch.eds"]),
            run: |b, _| match text(b) {
                Some(t) => verdict(drive_bus::eds::Eds::parse(t, "fuzz.eds")),
                None => Verdict::Rejected("not UTF-8 (line 1)".into()),
            },
        },
        Target {
            name: "pycan-udp",
            what: "python-can udp_multicast datagram (can_transport::pycan_udp::decode)",
            locate: Locate::No,
            seeds: |d| {
                frame_seeds(d)
                    .iter()
                    .flat_map(|b| frames_from(b))
                    .map(|f| {
                        let mut out = Vec::new();
                        can_transport::pycan_udp::encode(&f, 1.5, &mut out);
                        out
                    })
                    .collect()
            },
            run: |b, _| {
                // A decoded frame re-encodes to a datagram that decodes to the same frame.
                match can_transport::pycan_udp::decode(b) {
                    Ok(m) if !m.is_error_frame && !m.is_fd => {
                        let mut out = Vec::new();
                        can_transport::pycan_udp::encode(&m.frame, m.timestamp_s, &mut out);
                        match can_transport::pycan_udp::decode(&out) {
                            Ok(m2) if m2.frame == m.frame => Verdict::Accepted,
                            r => Verdict::Violation(format!("round trip: {r:?} != {m:?}")),
                        }
                    }
                    r => verdict(r),
                }
            },
        },
        Target {
            name: "cannelloni",
            what: "CAN-over-UDP datagram (can_transport::cannelloni::decode)",
            locate: Locate::No,
            seeds: |d| {
                frame_seeds(d)
                    .iter()
                    .map(|b| {
                        let fs = frames_from(b);
                        let mut out = vec![0u8; 1500];
                        let n = can_transport::cannelloni::encode(3, &fs, &mut out)
                            .expect("seed frames fit one datagram");
                        out.truncate(n);
                        out
                    })
                    .collect()
            },
            run: |b, _| {
                let mut n = 0usize;
                verdict(can_transport::cannelloni::decode(b, |_| n += 1))
            },
        },
        Target {
            name: "transport-spec",
            what: "transport spec string (can_transport::TransportSpec)",
            locate: Locate::No,
            seeds: |_| {
                vec![
                    b"udpbus".to_vec(),
                    b"socketcan:vcan0".to_vec(),
                    b"udpbus:239.255.70.9:21182".to_vec(),
                ]
            },
            run: |b, _| match text(b) {
                Some(t) => verdict(t.parse::<can_transport::TransportSpec>()),
                None => Verdict::Rejected("not UTF-8".into()),
            },
        },
        Target {
            name: "canopen-frame",
            what: "CANopen decoding: NMT/SYNC/PDO/EMCY/SDO (drive_bus::canopen), the monitor's bus observer",
            locate: Locate::No,
            seeds: frame_seeds,
            run: |b, _| {
                for f in frames_from(b) {
                    let _ = drive_bus::canopen::decode(&f);
                    for iface in 0..2 {
                        let _ = safety_monitor::bus_frames::observe(monitor_layout(), iface, &f);
                    }
                    let mut d = [0u8; 8];
                    let n = f.data().len();
                    d[..n].copy_from_slice(f.data());
                    let _ = drive_bus::canopen::parse_sdo_request(&d);
                    let _ = drive_bus::canopen::parse_sdo_response(&d);
                }
                Verdict::Accepted
            },
        },
        Target {
            name: "safety-pair",
            what: "doubled safety frame (can_transport::safety_frame::decode_pair)",
            locate: Locate::No,
            seeds: frame_seeds,
            run: |b, _| {
                let fs = frames_from(b);
                let mut any = Verdict::Accepted;
                for w in fs.windows(2) {
                    match safety_frame::decode_pair(&w[0], &w[1], safety_frame::DEFAULT_COB_ID) {
                        Ok(hb) => {
                            // A pair is valid only as exact inverses on the two ids.
                            let inv_ok =
                                w[0].data().iter().zip(w[1].data()).all(|(a, c)| *a == !*c)
                                    && w[0].data().len() == 8
                                    && w[1].data().len() == 8;
                            if !inv_ok {
                                return Verdict::Violation(format!(
                                    "decode_pair accepted a pair that is not an exact inverse: {hb:?}"
                                ));
                            }
                        }
                        Err(e) => any = Verdict::Rejected(format!("{e:?}")),
                    }
                }
                any
            },
        },
        Target {
            name: "config-signature",
            what: "the monitor's doubled configuration signature (safety_frame::ConfigSignature, issue 16)",
            locate: Locate::No,
            seeds: frame_seeds,
            run: |b, _| {
                let id = safety_frame::config_cob_id(safety_frame::DEFAULT_COB_ID);
                let mut rx = safety_frame::PairReceiver::new(id, 10_000_000);
                let mut any = Verdict::Accepted;
                let mut last_normal: Option<[u8; 8]> = None;
                for (k, f) in frames_from(b).iter().enumerate() {
                    if f.id() == u32::from(id) && f.data().len() == 8 {
                        let mut d = [0u8; 8];
                        d.copy_from_slice(f.data());
                        last_normal = Some(d);
                    }
                    match rx.on_frame_raw(f, k as u64 * 1000) {
                        None => {}
                        Some(Err(e)) => any = Verdict::Rejected(format!("{e:?}")),
                        Some(Ok(d)) => {
                            let inv_ok = f.data().len() == 8
                                && last_normal.is_some_and(|n| {
                                    n == d && n.iter().zip(f.data()).all(|(a, c)| *a == !*c)
                                });
                            if !inv_ok {
                                return Verdict::Violation(
                                    "a signature pair was accepted that is not an exact inverse"
                                        .into(),
                                );
                            }
                            match safety_frame::ConfigSignature::from_bytes(&d) {
                                Ok(sig) if sig.to_bytes() != d => {
                                    return Verdict::Violation(format!(
                                        "signature {sig:?} does not round-trip"
                                    ));
                                }
                                Ok(_) => {}
                                Err(e) => any = Verdict::Rejected(format!("{e:?}")),
                            }
                        }
                    }
                }
                any
            },
        },
        Target {
            name: "safety-watch",
            what: "SafetyWatch state machine (drive_bus::safety_watch) under arbitrary frame sequences and times",
            locate: Locate::No,
            seeds: |_| vec![watch_seed()],
            run: run_watch,
        },
        Target {
            name: "monitor-latch",
            what: "the safety monitor core (safety_monitor::Monitor) under arbitrary interleavings of setpoints, feedback, forces, RPDOs, drive reports, safety I/O inputs (the reset key), e-stops and cycles: no motion permitted after a trip without a reset it accepted",
            locate: Locate::No,
            seeds: |_| vec![monitor_seed()],
            run: run_monitor,
        },
    ]
}

/// Frame sequences for the watch: per event 1 byte time step (ms), then a frame as in
/// [`frames_from`]. The seed is a valid RUN heartbeat every 15 ms.
fn watch_seed() -> Vec<u8> {
    let mut v = Vec::new();
    for c in 0..40u32 {
        let hb = SafetyHeartbeat {
            state: SafetyState::Run,
            cause: 0,
            counter: c as u16,
            epoch: 1,
        };
        let [s1, s2] = signature().encode(safety_frame::DEFAULT_COB_ID);
        let [n, i] = safety_frame::encode(&hb, safety_frame::DEFAULT_COB_ID);
        v.push(15);
        v.extend(frame_bytes(&s1));
        v.push(0);
        v.extend(frame_bytes(&s2));
        v.push(0);
        v.extend(frame_bytes(&n));
        v.push(0);
        v.extend(frame_bytes(&i));
    }
    v
}

/// The monitor's configuration signature for the default SRDO configuration.
fn signature() -> safety_frame::ConfigSignature {
    safety_frame::ConfigSignature {
        srdo_crc: SafetyWatchConfig::default().srdo_crc(),
        safety_params_crc: 0x1234_5678,
    }
}

/// Properties: no panic; never PERMIT when no frame at all arrived on the safety ids within the
/// validation time; never PERMIT right after the monitor said STOP in a valid pair; never
/// PERMIT without a signature frame within twice the validation time; after a trip (PERMIT →
/// INHIBIT) never PERMIT again on an epoch that is not a reset the watch has not acted on
/// (`crs_limits::reset_epoch::releases` of the epoch it permitted on before the trip): no
/// self-release, no release on a restarted monitor's start epoch or a replay.
fn run_watch(b: &[u8], _: &Scratch) -> Verdict {
    let cfg = SafetyWatchConfig::default();
    let validation_ns = u64::from(cfg.validation_time_ms) * 1_000_000;
    let mut w = SafetyWatch::new(cfg);
    let mut now: u64 = 1_000_000_000;
    let mut last_safety_frame: Option<u64> = None;
    let mut last_signature_frame: Option<u64> = None;
    let mut i = 0;
    let mut pending_normal: Option<CanFrame> = None;
    // The epoch of the last valid RUN pair, the one the watch permitted on, and the one in
    // force at its last trip.
    let mut last_run_epoch: Option<u32> = None;
    let mut permitted_on: Option<u32> = None;
    let mut in_force: Option<u32> = None;
    let mut was_permitting = false;
    while i + 4 <= b.len() {
        now += u64::from(b[i]) * 1_000_000;
        let fs = frames_from(&b[i + 1..]);
        let Some(f) = fs.first().copied() else { break };
        i += 1 + 3 + f.data().len();
        w.on_frame(&f, now);
        let id = f.id() as u16;
        let safety_id = id == cfg.cob_id || id == cfg.cob_id + 1;
        if safety_id {
            last_safety_frame = Some(now);
        }
        if id == cfg.cob_id + 2 || id == cfg.cob_id + 3 {
            last_signature_frame = Some(now);
        }
        let mut stop_said = false;
        let mut n_pair = None;
        if id == cfg.cob_id {
            pending_normal = Some(f);
        } else if id == cfg.cob_id + 1
            && let Some(n) = pending_normal.take()
            && let Ok(hb) = safety_frame::decode_pair(&n, &f, cfg.cob_id)
        {
            stop_said = hb.state == SafetyState::Stop;
            n_pair = Some(hb);
        }
        if let Some(hb) = n_pair
            && hb.state == SafetyState::Run
        {
            last_run_epoch = Some(hb.epoch);
        }
        let permits = w.permits(now);
        if was_permitting && !permits {
            in_force = permitted_on;
        }
        if permits {
            if let (Some(f), Some(e)) = (in_force, last_run_epoch)
                && !crs_limits::reset_epoch::releases(e, f)
            {
                return Verdict::Violation(format!(
                    "SafetyWatch permits at t = {now} ns on epoch {e:#x} after a trip under \
                     epoch {f:#x} without a reset of the current monitor"
                ));
            }
            permitted_on = last_run_epoch;
        }
        was_permitting = permits;
        let silent = last_safety_frame.is_none_or(|t| now.saturating_sub(t) > validation_ns);
        if permits && silent {
            return Verdict::Violation(format!(
                "SafetyWatch permits at t = {now} ns with no frame on the safety ids for more than the validation time"
            ));
        }
        if permits && last_signature_frame.is_none_or(|t| now.saturating_sub(t) > 2 * validation_ns)
        {
            return Verdict::Violation(format!(
                "SafetyWatch permits at t = {now} ns without a configuration signature"
            ));
        }
        if permits && stop_said {
            return Verdict::Violation(
                "SafetyWatch permits right after a valid STOP pair".to_string(),
            );
        }
    }
    Verdict::Accepted
}

/// The monitor for [`run_monitor`]: the shipped configuration, started ready.
fn fuzz_monitor() -> safety_monitor::Monitor {
    use safety_monitor::config;
    static C: std::sync::OnceLock<config::MonitorConfig> = std::sync::OnceLock::new();
    let c = C.get_or_init(|| {
        let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/safety-monitor.toml");
        config::load(&p).expect("the shipped monitor config loads")
    });
    let lim = safety_monitor::monitor::Limits::from(c);
    let id = safety_monitor::identity::platform_identity(&c.platform);
    let mut m = safety_monitor::Monitor::new(
        lim,
        safety_monitor::kinematics::StandardKinematics::new(&c.platform),
        id,
    );
    m.on_identity(&crs_ipc::PlatformIdentity::new(id, 8));
    m
}

/// Operations for the monitor, 3 bytes each: opcode, two argument bytes. The seed: drives
/// reporting with forces, holding setpoints and feedback, cycles; a NaN setpoint (a trip);
/// the key turned and released; clean cycles.
fn monitor_seed() -> Vec<u8> {
    let mut v = Vec::new();
    // One cycle: every drive reporting operational with an in-band force, a holding setpoint,
    // feedback, the safety I/O node's inputs (bit 0 e-stop circuit closed, bit 1 the key).
    let cycle = |v: &mut Vec<u8>, inputs: u8| {
        for k in 0..8u8 {
            v.extend([6, k, 1]);
            v.extend([4, k, 40]);
        }
        v.extend([0, 0, 0, 3, 0, 0, 7, inputs, 0x01, 9, 0, 0]);
    };
    for _ in 0..30 {
        cycle(&mut v, 0x01);
    }
    v.extend([2, 0, 0, 9, 0, 0]);
    for _ in 0..30 {
        cycle(&mut v, 0x01);
    }
    // The key turned for two cycles, then released.
    cycle(&mut v, 0x03);
    cycle(&mut v, 0x03);
    for _ in 0..30 {
        cycle(&mut v, 0x01);
    }
    v
}

/// Property: once tripped, the monitor leaves the latch only in a cycle in which it accepted
/// an operator reset (from the key: the only channel that exists in the core), and its epoch
/// changes only with an accepted reset. No panic on any input.
fn run_monitor(b: &[u8], _: &Scratch) -> Verdict {
    monitor_walk(b).0
}

/// What [`run_monitor`] saw: its verdict, the trips (Armed → Tripped at a cycle's end) and the
/// accepted resets.
fn monitor_walk(b: &[u8]) -> (Verdict, u32, u32) {
    use safety_monitor::operator::{KeyEvent, KeyWatch};
    use safety_monitor::{ResetDecision, StateCode};
    static HOME_Q: std::sync::OnceLock<[f64; crs_ipc::MAX_CABLES]> = std::sync::OnceLock::new();
    let mut m = fuzz_monitor();
    let q = *HOME_Q.get_or_init(|| {
        // The monitor's own φ*(home) is what a holding stream sends.
        let mut q = [0.0; crs_ipc::MAX_CABLES];
        let c = safety_monitor::config::load(
            &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/safety-monitor.toml"),
        )
        .expect("shipped config");
        safety_monitor::kinematics::StandardKinematics::new(&c.platform)
            .lengths(&[0.0, 0.0, 2.0, 0.0, 0.0, 0.0], &mut q);
        q
    });
    let mut key = KeyWatch::new();
    let mut now: u64 = 1_000_000_000;
    let mut seq = 0u64;
    let mut fb_cycle = 0u64;
    let mut accepted_since_check = false;
    let mut was_tripped = false;
    let mut epoch = m.reset_epoch();
    let (mut trips, mut accepted) = (0u32, 0u32);
    m.begin_cycle(now);
    for op in b.chunks_exact(3) {
        let (a, x) = (op[1], op[2]);
        let k = usize::from(a % 8);
        match op[0] % 10 {
            0..=2 => {
                seq += 1;
                let mut s = crs_ipc::JointSetpoint {
                    cable_count: 8,
                    sequence: seq,
                    // Published within this cycle, on the monitor's clock.
                    timestamp_ns: now + u64::from(x) * 10_000,
                    pose: [0.0, 0.0, 2.0, 0.0, 0.0, 0.0],
                    cable_length_m: q,
                    ..crs_ipc::JointSetpoint::default()
                };
                if op[0] % 10 == 1 {
                    s.cable_length_m[k] += f64::from(x) * 1e-3;
                    s.pose[0] += f64::from(a) * 1e-4;
                } else if op[0] % 10 == 2 {
                    s.pose[3] = f64::NAN;
                }
                m.on_setpoint(&s);
            }
            3 => {
                fb_cycle += 1;
                let mut fb = crs_ipc::DriveFeedback {
                    cycle: fb_cycle,
                    timestamp_ns: now,
                    applied_setpoint_sequence: seq,
                    bus_state: crs_ipc::BusState::Running as u32,
                    ..crs_ipc::DriveFeedback::default()
                };
                fb.cable_length_m = q;
                fb.cable_count = 8;
                m.on_feedback(&fb);
            }
            4 => m.on_force(k, f64::from(x) * 100.0, now),
            5 => m.on_rpdo(k, q[k] + (f64::from(x) - 128.0) * 1e-3, now),
            6 => m.on_drive_report(k, x & 1 == 1, now),
            7 => {
                m.on_safety_io(a, x, now);
                if let KeyEvent::Reset(r) = key.on_inputs(a, now)
                    && let ResetDecision::Accepted { epoch: e } = m.request_reset(r)
                {
                    accepted_since_check = true;
                    accepted += 1;
                    epoch = e;
                }
            }
            8 => m.on_estop_event(u32::from(a)),
            _ => {
                now += 15_000_000;
                let _ = m.end_cycle(now);
                let tripped = m.state_code() == StateCode::Tripped;
                if was_tripped && !tripped && !accepted_since_check {
                    return (
                        Verdict::Violation(
                            "the monitor left its latch without an accepted operator reset".into(),
                        ),
                        trips,
                        accepted,
                    );
                }
                if m.reset_epoch() != epoch {
                    return (
                        Verdict::Violation(format!(
                            "the reset epoch moved ({epoch:#x} -> {:#x}) without an accepted reset",
                            m.reset_epoch()
                        )),
                        trips,
                        accepted,
                    );
                }
                trips += u32::from(tripped && !was_tripped);
                was_tripped = tripped;
                accepted_since_check = false;
                m.begin_cycle(now);
            }
        }
    }
    (Verdict::Accepted, trips, accepted)
}

const SURROGATE_PLATFORM: &str = "fuzz-platform";

fn surrogate_seed() -> Vec<u8> {
    let region = surrogate::Region {
        lower: [-1.0, -1.0, 1.0, -0.1, -0.1, -0.1],
        upper: [1.0, 1.0, 2.0, 0.1, 0.1, 0.1],
    };
    let opts = surrogate::FitOptions {
        degree: 2,
        validation_samples: 200,
        ..surrogate::FitOptions::default()
    };
    let (s, _) = surrogate::fit(&region, &opts, 8, SURROGATE_PLATFORM, |x: &[f64; 6]| {
        Ok::<_, String>(std::array::from_fn::<f64, 8, _>(|j| {
            0.01 * (x[0] + 0.1 * j as f64).sin() + 0.002 * x[3]
        }))
    })
    .expect("seed surrogate fits");
    let p = std::env::temp_dir().join(format!("crs-fuzz-seed-{}.json", std::process::id()));
    s.save(&p).expect("seed surrogate saves");
    let bytes = std::fs::read(&p).expect("seed surrogate reads back");
    let _ = std::fs::remove_file(&p);
    bytes
}

fn dataset_seed(forces: bool) -> Vec<u8> {
    let mut ds = crs_dataset::Dataset::new(8, forces, true);
    ds.metadata.push(("platform".into(), "fuzz".into()));
    let mut rng: SmallRng = rand::SeedableRng::seed_from_u64(1);
    for k in 0..6 {
        let pose = cdpr_model::Pose::new(
            Vector3::new(rng.random_range(-1.0..1.0), 0.2, 1.8),
            Vector3::new(0.01, -0.02, 0.03),
        );
        ds.samples.push(crs_dataset::Sample {
            sample: k,
            pose_index: k / 2,
            phase: crs_dataset::Phase::Pose,
            q_cmd: (0..8).map(|_| rng.random_range(7.0..10.0)).collect(),
            pose,
            forces: forces.then(|| (0..8).map(|_| rng.random_range(1000.0..9000.0)).collect()),
            pose_ref: Some(pose),
        });
    }
    let mut out = Vec::new();
    crs_dataset::write_dataset(&mut out, &ds).expect("seed data set writes");
    out
}

/// A layout like the shipped one for the monitor's observer: default RPDOs of drives 1-8 on
/// interface 0, 16-bit load cells 33-36 and drive-measured forces of 5-8 (TPDO2, offset 4).
fn monitor_layout() -> &'static safety_monitor::bus_layout::BusLayout {
    use safety_monitor::bus_layout::{BusLayout, ForceLayout, RpdoLayout, Value};
    static L: std::sync::OnceLock<BusLayout> = std::sync::OnceLock::new();
    L.get_or_init(|| BusLayout {
        rpdo: (1..=8).map(|n| RpdoLayout::default_for(0, n)).collect(),
        force: (0..8u8)
            .map(|k| {
                if k < 4 {
                    ForceLayout {
                        interface: 0,
                        cob_id: 0x1A1 + u16::from(k),
                        len: 2,
                        at: 0,
                        value: Value::I16,
                        n_per_unit: 1.0,
                        node: 33 + k,
                    }
                } else {
                    ForceLayout {
                        interface: 0,
                        cob_id: 0x281 + u16::from(k),
                        len: 8,
                        at: 4,
                        value: Value::I32,
                        n_per_unit: 0.001,
                        node: 1 + k,
                    }
                }
            })
            .collect(),
        safety_io: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The monitor target's seed is not vacuous: it trips the monitor and the key resets it;
    /// without the key the latch holds through the same clean cycles.
    #[test]
    fn the_monitor_seed_trips_and_only_the_key_resets() {
        let seed = monitor_seed();
        let (v, trips, accepted) = monitor_walk(&seed);
        assert!(matches!(v, Verdict::Accepted), "{v:?}");
        assert!(
            trips >= 1 && accepted >= 1,
            "trips {trips}, accepted {accepted}"
        );
        // The key's two operations (turned: inputs 0x03) replaced by clean inputs.
        let mut no_key = seed.clone();
        for op in no_key.chunks_exact_mut(3) {
            if op[0] == 7 && op[1] == 0x03 {
                op[1] = 0x01;
            }
        }
        let (v, trips, accepted) = monitor_walk(&no_key);
        assert!(matches!(v, Verdict::Accepted), "{v:?}");
        assert_eq!((trips, accepted), (1, 0));
    }
}
