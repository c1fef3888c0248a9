//! The plant on the drive bus (`sim_plant::bus`), on the host without CAN:
//! * in virtual time against drive-io's real CiA 402 master ([`drive_io::Master`]), frames
//!   handed over directly (deterministic);
//! * with raw CANopen frames (state machine corner cases, bad input);
//! * the process loop [`bus::run`] against drive-io's real runner over the UDP multicast bus.

// Per-cable checks index several parallel arrays (feedback, truth, φ) by the cable number.
#![allow(clippy::needless_range_loop)]

use can_transport::{CanBus, CanError, CanFrame, RxFrame};
use cdpr_model::config::Platform;
use cdpr_model::{Data, Pose, kinematics};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, IpcNode, JointSetpoint, PlantTruth, ProcessId, StateEvent,
};
use drive_bus::canopen::{self, Ds402State, NmtState};
use drive_io::Master;
use drives_config::DrivesConfig;
use sim_plant::bus::{self, BusOptions, BusPlantError, PlantBus};
use sim_plant::{Plant, PlantConfig, load_plant};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

fn plant_cfg(name: &str) -> PlantConfig {
    load_plant(config_dir().join("plant").join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The simulated winches (force object in their TPDO2) on one interface: the plant on the bus
/// in virtual time, its drives' own force and fault objects (tests/fixtures/drives-one-bus.toml).
fn fixture_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/drives-one-bus.toml")
}

fn drives() -> DrivesConfig {
    let mut d = DrivesConfig::load(&fixture_path()).expect("tests/fixtures/drives-one-bus.toml");
    assert!(
        d.safety_heartbeat.is_some(),
        "the drives config validates the safety monitor's heartbeat"
    );
    // These tests exercise the plant without a safety monitor on the bus; the drives' safety
    // watch has its own tests (drives_with_a_safety_heartbeat_watch_* below, crates/drive-io),
    // the safety I/O node's STO its own (drives_without_a_heartbeat_watch_*), both on the
    // shipped config/drives.toml.
    d.safety_heartbeat = None;
    assert!(d.safety_io.is_none() && d.force_sensors.is_empty());
    d
}

/// The shipped configuration (vendor drives, load cells, four drive interfaces, the safety I/O
/// node on a fifth).
fn shipped() -> DrivesConfig {
    DrivesConfig::load(&config_dir().join("drives.toml")).expect("config/drives.toml")
}

/// The shipped layout (four drive buses of two drives and their load cells) on one
/// interface: the virtual-time rig and the raw-frame tests speak to interface 0. The budget
/// is not checked here (Master::new does not; the runner and `crs sim` do).
fn one_interface(mut d: DrivesConfig) -> DrivesConfig {
    let transport = d.interfaces()[0].transport.clone();
    d.bus.transport = None;
    d.bus.interfaces = vec![drives_config::InterfaceConfig {
        name: "can0".into(),
        transport,
        bitrate_bit_per_s: 1_000_000,
        budget_percent: 70.0,
    }];
    for w in &mut d.winches {
        w.interface = Some("can0".into());
    }
    for s in &mut d.force_sensors {
        s.interface = Some("can0".into());
    }
    d
}

fn plant_bus(cfg: PlantConfig) -> PlantBus {
    let d = drives();
    let control = cfg.platform.clone();
    let opts = BusOptions::new(&d, &control);
    PlantBus::new(cfg, &control, &d, opts).expect("plant on the bus")
}

/// Collects the frames the plant sends.
#[derive(Default)]
struct VecBus(Vec<CanFrame>);

impl CanBus for VecBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        self.0.push(*frame);
        Ok(())
    }
    fn recv_timeout(&mut self, _: Duration) -> Result<Option<RxFrame>, CanError> {
        Ok(None)
    }
    fn interface(&self) -> &str {
        "vec"
    }
}

/// φ(x) of the control model: what motion-core commands (standard IK, no surrogate).
fn phi(control: &Platform, x: &Pose) -> Vec<f64> {
    let mut data = Data::new(&control.model);
    kinematics::inverse(&control.model, &mut data, x).expect("IK");
    data.q.clone()
}

/// drive-io's master and the plant, frames handed over directly in virtual time (1 ms SYNC).
struct Rig {
    master: Master,
    plant: PlantBus,
    control: Platform,
    now: u64,
    seq: u64,
    wire: VecBus,
    /// Plant commands of every cycle that solved the equilibrium, in order.
    solved: Vec<Vec<f64>>,
    reports: Vec<bus::CycleReport>,
}

impl Rig {
    fn new(cfg: PlantConfig) -> Self {
        let control = cfg.platform.clone();
        let plant = plant_bus(cfg);
        Self::with_plant(control, plant)
    }

    fn with_plant(control: Platform, plant: PlantBus) -> Self {
        Self::with_drives(control, plant, &drives())
    }

    fn with_drives(control: Platform, mut plant: PlantBus, d: &DrivesConfig) -> Self {
        let master = Master::new(d).unwrap();
        let now = 1_000_000_000;
        plant.start(now);
        let mut r = Self {
            master,
            plant,
            control,
            now,
            seq: 0,
            wire: VecBus::default(),
            solved: Vec::new(),
            reports: Vec::new(),
        };
        r.deliver_to_master();
        r
    }

    fn deliver_to_master(&mut self) {
        self.plant
            .flush(std::slice::from_mut(&mut self.wire))
            .unwrap();
        for f in self.wire.0.drain(..) {
            self.master.on_frame(
                0,
                &RxFrame {
                    frame: f,
                    rx_monotonic_ns: self.now,
                    kernel_rx_realtime_ns: None,
                    own: false,
                },
            );
        }
    }

    /// One SYNC period: master cycle -> drives -> plant cycle + TPDOs -> master.
    fn step(&mut self, sp: Option<&JointSetpoint>) {
        self.now += 1_000_000;
        let mut out = canopen::BusFrames::new(1);
        self.master.cycle(self.now, sp, &mut out);
        self.master.mark_written(self.now);
        // One interface: its frames, then the SYNC the cycle asks for (as the runner sends).
        let mut frames: Vec<CanFrame> = out.on(0).to_vec();
        if out.sync_requested() {
            frames.push(canopen::sync());
        }
        for f in &frames {
            if self.plant.handle_frame(0, f, self.now) {
                let rep = self.plant.cycle(self.now, 1e-3);
                if rep.solved {
                    self.solved.push(self.plant.plant_lengths().to_vec());
                }
                self.reports.push(rep);
                self.plant.transmit_pdos();
            }
        }
        self.plant.poll(self.now);
        self.deliver_to_master();
    }

    fn boot(&mut self) {
        for _ in 0..500 {
            self.step(None);
            if self.master.state() == BusState::Ready {
                return;
            }
        }
        panic!(
            "drives not Ready after 500 cycles: {:?}",
            self.master.state()
        );
    }

    /// Setpoint of the control model's φ(x) (what motion-core publishes at x).
    fn setpoint(&mut self, x: &Pose) -> JointSetpoint {
        self.seq += 1;
        let q = phi(&self.control, x);
        let mut sp = JointSetpoint {
            cable_count: q.len() as u32,
            sequence: self.seq,
            timestamp_ns: self.now + 1_000_000,
            pose: x.to_array(),
            ..Default::default()
        };
        sp.cable_length_m[..q.len()].copy_from_slice(&q);
        sp
    }

    /// Follows a raised-cosine path home -> home + delta over `n` cycles, then holds `hold`.
    fn move_by(&mut self, delta: [f64; 6], n: usize, hold: usize) -> Pose {
        let x0 = self.plant.home().to_array();
        let at = |s: f64| {
            let mut x = x0;
            for k in 0..6 {
                x[k] += s * delta[k];
            }
            Pose::from_array(x)
        };
        for k in 1..=n {
            let s = 0.5 - 0.5 * (std::f64::consts::PI * k as f64 / n as f64).cos();
            let sp = self.setpoint(&at(s));
            self.step(Some(&sp));
        }
        for _ in 0..hold {
            let sp = self.setpoint(&at(1.0));
            self.step(Some(&sp));
        }
        at(1.0)
    }

    fn feedback(&self) -> &DriveFeedback {
        self.master.feedback()
    }
}

/// A fresh plant set up like the bus plant, then stepped through `commands` in order.
fn direct(cfg: PlantConfig, commands: &[Vec<f64>]) -> sim_plant::Equilibrium {
    let control = cfg.platform.clone();
    let m = control.model.m();
    let p = control.model.params();
    let mut plant = Plant::new(cfg).unwrap();
    let s = plant
        .setup_tension(&control.home, &vec![0.5 * (p.f_min + p.f_max); m])
        .unwrap();
    let mut eq = plant.step(&s.q_cmd).unwrap();
    for q in commands {
        eq = plant.step(q).unwrap();
    }
    eq
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn starts_at_home_with_the_setup_tension_and_homed_encoders() {
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let pb = plant_bus(cfg.clone());
    let m = pb.m();
    assert_eq!(m, 8);
    // The plant settled at the home pose with the set-up forces (ideal plant: exactly).
    let t = pb.truth();
    let (dp, dr) = Pose::from_array(t.pose).error_to(&control.home);
    assert!(
        dp < 1e-9 && dr < 1e-9,
        "start pose off home by {dp} m / {dr} rad"
    );
    assert!(max_abs_diff(&t.force_n[..m], &pb.setup().forces) < 1e-6);
    let p = control.model.params();
    assert!(
        t.force_n[..m]
            .iter()
            .all(|f| *f >= p.f_min && *f <= p.f_max),
        "set-up forces {:?} outside [f_min, f_max]",
        &t.force_n[..m]
    );
    assert_eq!(t.converged, 1);
    assert_eq!(t.braked, 1, "drives not enabled yet: brakes hold");
    // Encoders homed: the drives read φ(home); the plant holds φ(home) + q_off = set-up command.
    let phi_home = phi(&control, &control.home);
    for i in 0..m {
        assert!((pb.drive_length_m(i).unwrap() - phi_home[i]).abs() < 1e-12);
        assert!((pb.q_off()[i] - (pb.setup().q_cmd[i] - phi_home[i])).abs() < 1e-12);
        assert!((t.cable_length_m[i] - pb.setup().q_cmd[i]).abs() < 1e-12);
        // Cables are stretched under tension: the controlled length is shorter than φ.
        assert!(pb.q_off()[i] < 0.0, "q_off[{i}] = {}", pb.q_off()[i]);
    }
}

/// Commissioning with a surrogate controller: the drives are homed to the controller's full
/// command at home, q_θ(home) = φ(home) + δ (δ = the surrogate offset there, tens of mm), so
/// the first setpoint equals the drives' positions (no jump, no fault), the plant holds the
/// set-up state at home, and the offset stream φ(x) + δ drives the plant exactly like the plain
/// stream φ(x) with the default homing.
#[test]
fn home_lengths_option_homes_the_drives_to_the_controllers_full_command() {
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let d = drives();
    let phi_home = phi(&control, &control.home);
    let delta: Vec<f64> = (0..8).map(|i| -0.020 - 0.002 * i as f64).collect();
    let q_home: Vec<f64> = phi_home.iter().zip(&delta).map(|(p, e)| p + e).collect();
    let mut opts = BusOptions::new(&d, &control);
    opts.home_lengths_m = Some(q_home.clone());
    let plant = PlantBus::new(cfg.clone(), &control, &d, opts).expect("plant with home lengths");
    let default = plant_bus(cfg.clone());
    for i in 0..8 {
        assert!((plant.drive_length_m(i).unwrap() - q_home[i]).abs() < 1e-12);
        assert!((plant.home_drive_lengths()[i] - q_home[i]).abs() < 1e-12);
        // Same set-up (plant commands), the offset absorbs δ.
        assert!((plant.setup().q_cmd[i] - default.setup().q_cmd[i]).abs() < 1e-12);
        assert!((plant.q_off()[i] - (default.q_off()[i] - delta[i])).abs() < 1e-12);
    }
    let mut rig = Rig::with_plant(control.clone(), plant);
    rig.boot();
    let count_m = 1.0 / d.winches[0].counts_per_m();
    for i in 0..8 {
        let e = (rig.feedback().cable_length_m[i] - q_home[i]).abs();
        assert!(e <= count_m, "cable {i}: drive-io reads {e} m off q_home");
    }
    // The controller's stream: φ(x) + δ (a constant offset stands in for φ_sg).
    let offset_setpoint = |rig: &mut Rig, x: &Pose| {
        let mut sp = rig.setpoint(x);
        for i in 0..8 {
            sp.cable_length_m[i] += delta[i];
        }
        sp
    };
    let home = control.home;
    for _ in 0..50 {
        let sp = offset_setpoint(&mut rig, &home);
        rig.step(Some(&sp));
    }
    assert_eq!(
        rig.master.state(),
        BusState::Running,
        "first setpoint accepted"
    );
    assert_eq!(rig.feedback().fault(), Ok(crs_ipc::FaultCode::None));
    let (dp, dr) = Pose::from_array(rig.plant.truth().pose).error_to(&home);
    assert!(dp < 1e-6 && dr < 1e-6, "plant left home: {dp} m, {dr} rad");
    // Move away and hold: the plant holds φ(x) + δ + q_off = φ(x) + q_off(default homing).
    let x = Pose::from_array([0.2, -0.1, 2.1, 1f64.to_radians(), 0.0, -1f64.to_radians()]);
    for k in 1..=800 {
        let s = 0.5 - 0.5 * (std::f64::consts::PI * (k.min(600) as f64) / 600.0).cos();
        let xs = Pose::from_array(std::array::from_fn(|j| {
            home.to_array()[j] + s * (x.to_array()[j] - home.to_array()[j])
        }));
        let sp = offset_setpoint(&mut rig, &xs);
        rig.step(Some(&sp));
    }
    assert_eq!(rig.master.state(), BusState::Running);
    let phi_x = phi(&control, &x);
    for i in 0..8 {
        let expect = phi_x[i] + default.q_off()[i];
        let e = (rig.plant.truth().cable_length_m[i] - expect).abs();
        assert!(
            e <= 0.5 * count_m + 1e-9,
            "cable {i}: plant holds {e} m off φ(x) + q_off"
        );
    }
    // A wrong number of home lengths is refused, naming the option.
    let mut bad = BusOptions::new(&d, &control);
    bad.home_lengths_m = Some(vec![8.0; 7]);
    match PlantBus::new(cfg, &control, &d, bad) {
        Err(BusPlantError::Option { name, .. }) => assert_eq!(name, "home_lengths_m"),
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("7 home lengths for 8 cables accepted"),
    }
}

#[test]
fn boot_then_csp_targets_move_the_plant_and_match_a_direct_plant_step() {
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let mut rig = Rig::new(cfg.clone());
    let d = drives();
    let start_lengths = rig.plant.plant_lengths().to_vec();
    rig.boot();
    // Boot went through NMT, SDO and the CiA 402 state machine; nothing moved meanwhile.
    for i in 0..8 {
        let sw = rig.feedback().statusword[i];
        assert_eq!(
            Ds402State::from_statusword(sw),
            Ds402State::OperationEnabled
        );
        assert_eq!(rig.plant.drives().slave(i).unwrap().mode_of_operation(), 8);
    }
    assert!(
        rig.reports.iter().any(|r| r.braked),
        "brakes held during boot"
    );
    // Enabling latches target = position actual: the winches only settle onto the encoder
    // count (≤ half a count ≈ 0.05 µm), below the re-solve threshold.
    let count_m = 1.0 / d.winches[0].counts_per_m();
    assert!(max_abs_diff(rig.plant.plant_lengths(), &start_lengths) <= 0.5 * count_m + 1e-12);
    assert!(
        rig.reports.iter().all(|r| !r.solved),
        "nothing to solve during boot"
    );
    // drive-io reads φ(home) (one count ≈ 0.09 µm of quantisation).
    let phi_home = phi(&rig.control, &rig.control.home);
    for i in 0..8 {
        let e = (rig.feedback().cable_length_m[i] - phi_home[i]).abs();
        assert!(e <= count_m, "cable {i}: feedback off φ(home) by {e} m");
    }

    let delta = [
        0.10,
        -0.05,
        0.08,
        1f64.to_radians(),
        -1f64.to_radians(),
        2f64.to_radians(),
    ];
    let n_solved_before = rig.solved.len();
    let x_end = rig.move_by(delta, 600, 150);
    assert_eq!(rig.master.state(), BusState::Running);
    assert!(
        rig.solved.len() > n_solved_before + 500,
        "equilibrium re-solved while moving"
    );
    let last = rig.reports.last().unwrap();
    assert!(last.converged && !last.braked);

    // The winches hold the commanded φ(x_end): drive-io reads it back within a count.
    let q_end = phi(&rig.control, &x_end);
    for i in 0..8 {
        let e = (rig.feedback().cable_length_m[i] - q_end[i]).abs();
        assert!(e <= count_m, "cable {i}: feedback off φ(x_end) by {e} m");
        let e = (rig.plant.truth().cable_length_m[i] - (q_end[i] + rig.plant.q_off()[i])).abs();
        // (the target went over the bus as counts: half a count of quantisation)
        assert!(
            e <= 0.5 * count_m + 1e-12,
            "cable {i}: plant holds φ + q_off up to {e} m"
        );
    }
    // The plant moved with the command, up to the force-propagation drift of a kinematic
    // command (eq. 3.24, a few mm on this geometry).
    let truth = *rig.plant.truth();
    let pose = Pose::from_array(truth.pose);
    let (dp, dr) = pose.error_to(&x_end);
    assert!(
        dp < 0.01 && dr < 0.5f64.to_radians(),
        "pose error {dp} m, {dr} rad"
    );
    let (moved, _) = pose.error_to(&rig.control.home);
    assert!(moved > 0.12, "platform moved only {moved} m");

    // Truth == a direct Plant::step on the same lengths (ideal plant: path independent).
    let eq = direct(cfg.clone(), &[truth.cable_length_m[..8].to_vec()]);
    let (dp, dr) = eq.pose.error_to(&pose);
    assert!(
        dp < 1e-6 && dr < 1e-6,
        "truth vs direct step: {dp} m, {dr} rad"
    );
    assert!(max_abs_diff(&eq.forces, &truth.force_n[..8]) < 1e-2);
    // And the TPDO force (mN) is that force (no sensor noise on the ideal plant).
    assert!(max_abs_diff(&rig.feedback().cable_force_n[..8], &truth.force_n[..8]) <= 0.5e-3);
    assert!(truth.force_n[..8].iter().all(|f| *f > 0.0));
}

#[test]
fn mild_plant_on_the_bus_replays_exactly_and_reports_noisy_sensors() {
    let cfg = plant_cfg("icosahedron.toml");
    assert!(cfg.effects.hysteresis.is_some() && cfg.effects.force_sensors.is_some());
    let mut rig = Rig::new(cfg.clone());
    rig.boot();
    let delta = [-0.08, 0.06, -0.10, 0.0, 2f64.to_radians(), 0.0];
    rig.move_by(delta, 500, 100);
    let truth = *rig.plant.truth();
    assert_eq!(truth.converged, 1);
    // Path-dependent plant (hysteresis): replaying the same solved commands in the same order
    // on a fresh plant gives the same equilibrium, bit for bit up to rounding.
    let eq = direct(cfg, &rig.solved);
    let (dp, dr) = eq.pose.error_to(&Pose::from_array(truth.pose));
    assert!(
        dp < 1e-12 && dr < 1e-12,
        "replay differs by {dp} m, {dr} rad"
    );
    assert!(max_abs_diff(&eq.forces, &truth.force_n[..8]) < 1e-9);
    // TPDO forces are sensor readings: true force + N(0, 10 N).
    let fb = rig.feedback().cable_force_n;
    let diffs: Vec<f64> = (0..8).map(|i| fb[i] - truth.force_n[i]).collect();
    assert!(
        diffs.iter().all(|d| d.abs() < 60.0),
        "sensor error {diffs:?}"
    );
    assert!(
        diffs.iter().any(|d| d.abs() > 1e-3),
        "no sensor noise: {diffs:?}"
    );
    // The tracker pose is the true pose with noise (0.5 mm): close, not equal.
    let tr = rig.plant.tracker();
    assert_eq!(tr.valid, 1);
    let (dp, _) = Pose::from_array(tr.pose).error_to(&Pose::from_array(truth.pose));
    assert!(dp > 0.0 && dp < 0.005, "tracker off truth by {dp} m");
}

#[test]
fn estop_quick_stop_decelerates_then_brakes_hold() {
    let mut rig = Rig::new(plant_cfg("icosahedron-ideal.toml"));
    rig.boot();
    // Move and stop in the middle of the motion (cables at speed).
    let x0 = rig.plant.home().to_array();
    let mut dx = 0.0;
    for k in 1..=300 {
        let mut x = x0;
        // Up to 0.3 m/s along x over 100 ms (3 m/s²: drive-io refuses a setpoint that
        // accelerates a cable beyond bus.max_cable_acceleration_m_per_s2).
        dx += 0.3 * (k as f64 / 100.0).min(1.0) / 1000.0;
        x[0] += dx;
        let sp = rig.setpoint(&Pose::from_array(x));
        rig.step(Some(&sp));
    }
    let speed: f64 = (0..8)
        .map(|i| rig.feedback().cable_velocity_m_per_s[i].abs())
        .fold(0.0, f64::max);
    assert!(
        speed > 0.05,
        "cables should be moving, max speed {speed} m/s"
    );
    assert_eq!(rig.plant.truth().braked, 0);
    let ev = StateEvent::new(ProcessId::Test, EventKind::EStop, 1);
    rig.master.on_event(&ev, rig.now);
    // Setpoints keep coming (and keep moving): the drives must ignore them.
    let mut braked_at = None;
    for k in 301..=500 {
        let mut x = x0;
        x[0] += 0.3 * (k as f64 / 1000.0);
        let sp = rig.setpoint(&Pose::from_array(x));
        rig.step(Some(&sp));
        if braked_at.is_none() && rig.plant.truth().braked == 1 {
            braked_at = Some(k);
        }
    }
    assert_eq!(rig.master.state(), BusState::EStop);
    let braked_at = braked_at.expect("brakes never engaged after quick stop");
    // Deceleration at 14 m/s² from < 0.5 m/s takes < 40 ms (+ 2 cycles of bus latency).
    assert!(
        braked_at - 300 <= 45,
        "braked only after {} cycles",
        braked_at - 300
    );
    for i in 0..8 {
        assert_eq!(
            Ds402State::from_statusword(rig.feedback().statusword[i]),
            Ds402State::QuickStopActive
        );
    }
    // Held: nothing moves and nothing is re-solved any more.
    let held = rig.plant.plant_lengths().to_vec();
    let pose = rig.plant.truth().pose;
    let n = rig.reports.len();
    for k in 501..=600 {
        let mut x = x0;
        x[0] += 0.3 * (k as f64 / 1000.0);
        let sp = rig.setpoint(&Pose::from_array(x));
        rig.step(Some(&sp));
    }
    assert_eq!(max_abs_diff(rig.plant.plant_lengths(), &held), 0.0);
    assert_eq!(rig.plant.truth().pose, pose);
    assert_eq!(rig.plant.truth().braked, 1);
    assert!(rig.reports[n..].iter().all(|r| !r.solved && r.braked));
}

/// Raw CANopen frames from a hand-driven master.
struct Raw {
    plant: PlantBus,
    now: u64,
    wire: VecBus,
}

impl Raw {
    fn new(cfg: PlantConfig) -> Self {
        Self::with(cfg, |_| {})
    }
    fn with(cfg: PlantConfig, tweak: impl FnOnce(&mut BusOptions)) -> Self {
        let d = drives();
        let control = cfg.platform.clone();
        let mut opts = BusOptions::new(&d, &control);
        tweak(&mut opts);
        let mut plant = PlantBus::new(cfg, &control, &d, opts).expect("plant on the bus");
        plant.start(0);
        Self {
            plant,
            now: 0,
            wire: VecBus::default(),
        }
    }
    fn send(&mut self, f: CanFrame) -> Option<bus::CycleReport> {
        let r = self.plant.handle_frame(0, &f, self.now).then(|| {
            let r = self.plant.cycle(self.now, 1e-3);
            self.plant.transmit_pdos();
            r
        });
        self.plant
            .flush(std::slice::from_mut(&mut self.wire))
            .unwrap();
        r
    }
    fn sync(&mut self) -> bus::CycleReport {
        self.now += 1_000_000;
        self.send(canopen::sync()).expect("SYNC acted on")
    }
    fn counts(&self, i: usize, length_m: f64) -> i32 {
        drives().winches[i].length_to_counts(length_m).unwrap()
    }
    fn rpdo_all(&mut self, cw: u16, target: impl Fn(usize) -> i32) {
        for i in 0..8 {
            self.send(canopen::rpdo1(i as u8 + 1, cw, target(i)));
        }
    }
    /// NMT start, CSP mode by SDO, shutdown / switch on / enable with target = actual.
    fn enable(&mut self) {
        self.send(canopen::nmt(canopen::NMT_START, 0));
        for n in 1..=8u8 {
            self.send(canopen::sdo_download(n, 0x6060, 0, 8, 1));
        }
        let home: Vec<i32> = (0..8)
            .map(|i| self.counts(i, self.plant.drive_length_m(i).unwrap()))
            .collect();
        for cw in [0x06, 0x07, 0x0F] {
            self.rpdo_all(cw, |i| home[i]);
            self.sync();
        }
        for i in 0..8 {
            let s = self.plant.drives().slave(i).unwrap();
            assert_eq!(s.ds402_state(), Ds402State::OperationEnabled);
        }
    }
}

#[test]
fn drives_not_enabled_or_nmt_stopped_hold_the_cables() {
    let mut raw = Raw::new(plant_cfg("icosahedron-ideal.toml"));
    let start = raw.plant.plant_lengths().to_vec();
    // Operational but Switch On Disabled: enable-operation controlword and far targets do
    // nothing (the state machine needs shutdown -> switch on first).
    raw.send(canopen::nmt(canopen::NMT_START, 0));
    // What drive-io configures at start-up (docs/can-protocol.md): 0x6007 = 2, NMT stop =>
    // disable voltage (the brake holds). The EDS default 0 would keep following.
    for node in 1..=8 {
        raw.send(canopen::sdo_download(
            node,
            canopen::OD_ABORT_CONNECTION,
            0,
            2,
            2,
        ));
    }
    for _ in 0..50 {
        raw.rpdo_all(0x0F, |_| 0);
        let r = raw.sync();
        assert!(r.braked && !r.solved);
    }
    assert_eq!(max_abs_diff(raw.plant.plant_lengths(), &start), 0.0);
    assert_eq!(raw.plant.truth().braked, 1);

    // Enabled: the cables follow a 20 mm longer target for cable 1.
    raw.enable();
    let l0 = raw.plant.drive_length_m(0).unwrap();
    let target0 = raw.counts(0, l0 + 0.02);
    let hold: Vec<i32> = (0..8)
        .map(|i| raw.counts(i, raw.plant.drive_length_m(i).unwrap()))
        .collect();
    for _ in 0..20 {
        raw.rpdo_all(0x0F, |i| if i == 0 { target0 } else { hold[i] });
        let r = raw.sync();
        assert!(!r.braked);
    }
    let moving = raw.plant.drive_length_m(0).unwrap();
    assert!(moving > l0 + 1e-4, "cable 1 did not move: {l0} -> {moving}");
    // NMT stop of all drives mid-motion: brakes engage at once, nothing moves, no PDOs.
    raw.send(canopen::nmt(canopen::NMT_STOP, 0));
    raw.wire.0.clear();
    let held = raw.plant.plant_lengths().to_vec();
    for _ in 0..30 {
        raw.rpdo_all(0x0F, |i| if i == 0 { target0 } else { hold[i] });
        raw.now += 1_000_000;
        // SYNC is not acted on in NMT stopped: the plant runs a free cycle (as `run` does).
        assert!(raw.send(canopen::sync()).is_none());
        let r = raw.plant.cycle(raw.now, 1e-3);
        assert!(r.braked && !r.solved);
    }
    assert_eq!(max_abs_diff(raw.plant.plant_lengths(), &held), 0.0);
    assert_eq!(raw.plant.truth().braked, 1);
    let pdos = raw.wire.0.iter().filter(|f| {
        matches!(
            canopen::decode(f),
            canopen::Message::Tpdo1 { .. } | canopen::Message::Tpdo2 { .. }
        )
    });
    assert_eq!(pdos.count(), 0, "no PDOs in NMT stopped");
    for i in 0..8 {
        assert_eq!(
            raw.plant.drives().slave(i).unwrap().nmt_state(),
            NmtState::Stopped
        );
    }
}

#[test]
fn no_equilibrium_is_reported_not_fatal_and_recovers() {
    // Winches far beyond the real limits, so a cable jumps by up to 1 m per cycle: faster than
    // the platform can follow quasi-statically, which the plant solver cannot track.
    let mut raw = Raw::with(plant_cfg("icosahedron-ideal.toml"), |o| {
        o.max_cable_speed_m_per_s = 1000.0;
        o.max_cable_accel_m_per_s2 = 1e6;
    });
    raw.enable();
    let home: Vec<i32> = (0..8)
        .map(|i| raw.counts(i, raw.plant.drive_length_m(i).unwrap()))
        .collect();
    let good = *raw.plant.truth();
    // Pay out 3 m on the four upper cables (anchors at z ≈ 6.5 m) at once: the platform loses
    // its support and the solver finds no equilibrium (all cables slack).
    let far: Vec<i32> = (0..8)
        .map(|i| {
            let l = raw.plant.drive_length_m(i).unwrap();
            raw.counts(i, if i % 2 == 0 { l + 3.0 } else { l })
        })
        .collect();
    let mut failed = false;
    for _ in 0..20 {
        raw.rpdo_all(0x0F, |i| far[i]);
        let r = raw.sync();
        if !r.converged {
            failed = true;
            break;
        }
    }
    assert!(failed, "expected a plant without equilibrium");
    let t = *raw.plant.truth();
    assert_eq!(t.converged, 0);
    assert_eq!(raw.plant.tracker().valid, 0);
    assert!(raw.plant.last_error().is_some());
    assert!(raw.plant.stats().failed_solves >= 1);
    // TPDOs keep flowing (the drives do not know about the plant's solver).
    raw.wire.0.clear();
    raw.rpdo_all(0x0F, |i| far[i]);
    raw.sync();
    assert_eq!(raw.wire.0.len(), 16, "TPDO1 + TPDO2 of 8 drives");
    // Winding back to the home lengths finds the equilibrium again.
    let mut recovered = false;
    for _ in 0..20 {
        raw.rpdo_all(0x0F, |i| home[i]);
        if raw.sync().converged {
            recovered = true;
        }
    }
    assert!(recovered, "no equilibrium after returning home");
    let t = raw.plant.truth();
    assert_eq!(t.converged, 1);
    let (dp, _) = Pose::from_array(t.pose).error_to(&Pose::from_array(good.pose));
    assert!(dp < 1e-3, "back home within 1 mm, got {dp} m");
}

#[test]
fn bus_input_never_panics_and_targets_are_clamped() {
    use proptest::prelude::*;
    let mut raw = Raw::new(plant_cfg("icosahedron-ideal.toml"));
    raw.enable();
    // Extreme targets: clamped to [0, max_cable_length_m] of the drive, never NaN.
    for target in [i32::MIN, i32::MAX, 0, -1] {
        for _ in 0..3 {
            raw.rpdo_all(0x0F, |_| target);
            raw.sync();
        }
        for i in 0..8 {
            let l = raw.plant.drive_length_m(i).unwrap();
            assert!(
                l.is_finite() && (0.0..=20.0 + 1.0).contains(&l),
                "cable {i}: {l}"
            );
        }
        assert!(raw.plant.truth().pose.iter().all(|v| v.is_finite()));
    }
    // Arbitrary frames and cycle lengths.
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases: 64,
        ..ProptestConfig::default()
    });
    let frames = proptest::collection::vec(
        (
            0u32..0x800,
            proptest::collection::vec(any::<u8>(), 0..=8),
            any::<f64>(),
        ),
        1..40,
    );
    runner
        .run(&frames, |fs| {
            let mut r = Raw::new(plant_cfg("icosahedron-ideal.toml"));
            for (id, data, dt) in fs {
                let f = CanFrame::new(id as u16, &data).unwrap();
                if r.plant.handle_frame(0, &f, r.now) {
                    r.plant.cycle(r.now, dt);
                    r.plant.transmit_pdos();
                }
                r.now += 1_000_000;
                r.plant.cycle(r.now, dt);
                r.plant.poll(r.now);
                r.plant.flush(std::slice::from_mut(&mut r.wire)).unwrap();
            }
            let t = r.plant.truth();
            prop_assert!(t.pose.iter().all(|v| v.is_finite()));
            Ok(())
        })
        .unwrap();
}

#[test]
fn config_mismatches_are_clear_errors() {
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let full = drives();
    let mut four = full.clone();
    four.winches.truncate(4);
    let mut opts = BusOptions::new(&full, &control);
    opts.files.plant = "config/plant/x.toml".into();
    opts.files.drives = "config/drives.toml".into();
    let e = PlantBus::new(cfg.clone(), &control, &four, opts.clone())
        .err()
        .unwrap();
    assert!(matches!(
        e,
        BusPlantError::CableCount {
            plant_m: 8,
            drives_m: 4,
            ..
        }
    ));
    let msg = e.to_string();
    assert!(
        msg.contains("config/plant/x.toml") && msg.contains("config/drives.toml"),
        "{msg}"
    );

    let mut drum = full.clone();
    drum.winches[3].drum_diameter_m = 0.3;
    let e = PlantBus::new(cfg.clone(), &control, &drum, opts.clone())
        .err()
        .unwrap();
    assert!(e.to_string().contains("winch[3].drum_diameter_m"), "{e}");

    let mut short = full.clone();
    short.winches[5].max_cable_length_m = 5.0;
    let e = PlantBus::new(cfg.clone(), &control, &short, opts.clone())
        .err()
        .unwrap();
    assert!(e.to_string().contains("winch[5].max_cable_length_m"), "{e}");

    let mut bad = opts.clone();
    bad.f_ini_n = Some(vec![5000.0; 7]);
    let e = PlantBus::new(cfg.clone(), &control, &full, bad)
        .err()
        .unwrap();
    assert!(e.to_string().contains("f_ini_n"), "{e}");
    let mut bad = opts.clone();
    bad.sync_period_s = f64::NAN;
    assert!(PlantBus::new(cfg.clone(), &control, &full, bad).is_err());
    // An initial tension that cannot be realised (a cable would push) names the cause.
    let mut bad = opts;
    bad.f_ini_n = Some(vec![1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
    let e = PlantBus::new(cfg, &control, &full, bad).err().unwrap();
    assert!(matches!(e, BusPlantError::Setup { .. }), "{e}");
}

#[test]
fn binary_rejects_bad_files_naming_them() {
    let exe = env!("CARGO_BIN_EXE_sim-plant");
    let dir = std::env::temp_dir().join(format!("sim-plant-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |args: &[&str]| {
        let out = std::process::Command::new(exe)
            .args(args)
            .current_dir(config_dir().join(".."))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?} should fail");
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    // A plant TOML with a bad value: file:line:column and key.
    let bad_plant = dir.join("bad-plant.toml");
    std::fs::write(
        &bad_plant,
        format!(
            "[plant]\nname = \"x\"\nplatform = \"{}\"\n\n[tracker]\nenabled = true\nposition_noise_m = -1.0\nrotation_noise_deg = 0.0\n",
            config_dir().join("icosahedron.toml").display()
        ),
    )
    .unwrap();
    let err = run(&["--plant", bad_plant.to_str().unwrap()]);
    assert!(
        err.contains("bad-plant.toml:7:") && err.contains("tracker.position_noise_m"),
        "{err}"
    );
    // Drives config with 4 winches for an 8-cable plant: both files named.
    let text = std::fs::read_to_string(config_dir().join("drives.toml")).unwrap();
    let cut = text.match_indices("[[winch]]").nth(4).unwrap().0;
    let four = dir.join("four-drives.toml");
    std::fs::write(&four, &text[..cut]).unwrap();
    let err = run(&["--drives", four.to_str().unwrap()]);
    assert!(
        err.contains("four-drives.toml")
            && err.contains("icosahedron.toml")
            && err.contains("8 cables"),
        "{err}"
    );
    let err = run(&["--plant", "config/plant/nope.toml"]);
    assert!(err.contains("config/plant/nope.toml"), "{err}");
    let err = run(&["--transport", "bogus:1"]);
    assert!(err.contains("bogus:1"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The process loop end to end on the host: drive-io's real runner and [`bus::run`] as threads
/// on the UDP multicast bus, setpoints over iceoryx2 as motion-core would publish them.
#[test]
fn run_loop_with_drive_io_over_udp_follows_setpoints() {
    // The shipped layout (vendor drives and load cells on four interfaces), each interface a
    // UDP multicast bus of its own (groups 3..6 on one reserved port); no monitor on the bus
    // (its watch has its own tests).
    let port = crs_test_support::ports::reserve_udp_port();
    let prefix = format!("simplant/{}/", std::process::id());
    let mut d = shipped();
    d.safety_heartbeat = None;
    d.safety_io = None;
    d.bus.interfaces.retain(|i| i.name != "safety");
    for (k, i) in d.bus.interfaces.iter_mut().enumerate() {
        i.transport = port.udpbus(3 + k as u8);
    }
    // Lenient timing: the host is shared and not real time (behaviour is asserted, not timing).
    d.bus.heartbeat_timeout_ms = 500;
    d.bus.stale_setpoint_cycles = 200;
    d.bus.boot_timeout_ms = 20_000;
    d.bus.sdo_timeout_ms = 500;
    d.validate().unwrap();
    assert_eq!(d.interfaces().len(), 4);
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let open = |d: &DrivesConfig| -> Vec<_> {
        d.transports()
            .unwrap()
            .iter()
            .map(|t| can_transport::open(t).unwrap())
            .collect()
    };
    let mut plant_buses = open(&d);
    let dio_buses = open(&d);
    let mut plant = PlantBus::new(cfg, &control, &d, BusOptions::new(&d, &control)).unwrap();
    let truth = Arc::new(Mutex::new(PlantTruth::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let (t2, s2) = (truth.clone(), stop.clone());
    let plant_thread = std::thread::spawn(move || {
        bus::run(
            &mut plant_buses,
            &mut plant,
            Duration::from_millis(1),
            &s2,
            |t, _| *t2.lock().unwrap() = *t,
        )
    });
    let (d2, s3, p2) = (d.clone(), stop.clone(), prefix.clone());
    let dio_thread = std::thread::spawn(move || {
        let ipc = IpcNode::with_prefix("drive-io", &p2).map_err(|e| e.to_string())?;
        drive_io::runner::run(&d2, dio_buses, &ipc, &s3).map_err(|e| e.to_string())
    });
    let node = IpcNode::with_prefix("bus-test", &prefix).unwrap();
    let setpoints = node.publisher::<JointSetpoint>().unwrap();
    let feedback = node.subscriber::<DriveFeedback>().unwrap();
    let result = (|| -> Result<(), String> {
        let t0 = Instant::now();
        let mut fb = DriveFeedback::default();
        while fb.bus().ok() != Some(BusState::Ready) {
            if let Some(f) = feedback.latest().map_err(|e| e.to_string())? {
                fb = f;
            }
            if t0.elapsed() > Duration::from_secs(30) {
                return Err(format!("not Ready: {:?}", fb.bus().ok()));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        // All drives enabled: the brakes release with the next plant cycle (the deadline only
        // stops a hang; a loaded host may take a while to run that cycle).
        let t_rel = Instant::now();
        while truth.lock().unwrap().braked != 0 {
            if t_rel.elapsed() > Duration::from_secs(30) {
                return Err("brakes still engaged with all drives enabled".into());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let phi_home = phi(&control, &control.home);
        for i in 0..8 {
            let e = (fb.cable_length_m[i] - phi_home[i]).abs();
            if e > 1e-6 {
                return Err(format!("cable {i}: drive-io reads {e} m off φ(home)"));
            }
        }
        // Stream setpoints: 50 mm up in z over 0.5 s (raised cosine), stamped as published.
        let x0 = control.home.to_array();
        // The trajectory by setpoint (1 ms each, as motion-core's loop computes it), not by
        // the host's clock: a host stall must not turn into a step in the stream.
        let mut seq = 0;
        let mut x_end = control.home;
        while seq < 900 {
            let s = ((seq + 1) as f64 * 1e-3 / 0.5).min(1.0);
            let mut x = x0;
            x[2] += 0.05 * (0.5 - 0.5 * (std::f64::consts::PI * s).cos());
            x_end = Pose::from_array(x);
            let q = phi(&control, &x_end);
            seq += 1;
            let mut sp = JointSetpoint {
                cable_count: 8,
                sequence: seq,
                timestamp_ns: crs_ipc::monotonic_ns(),
                pose: x,
                ..Default::default()
            };
            sp.cable_length_m[..8].copy_from_slice(&q);
            setpoints.publish(&sp).map_err(|e| e.to_string())?;
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(50));
        if let Some(f) = feedback.latest().map_err(|e| e.to_string())? {
            fb = f;
        }
        if fb.bus().ok() != Some(BusState::Running) {
            return Err(format!(
                "drive-io state {:?} (fault {} node {})",
                fb.bus().ok(),
                fb.fault_code,
                fb.fault_node
            ));
        }
        let t = *truth.lock().unwrap();
        let q_end = phi(&control, &x_end);
        let mut err = 0.0f64;
        for i in 0..8 {
            err = err.max((fb.cable_length_m[i] - q_end[i]).abs());
        }
        if err > 1e-6 {
            return Err(format!("drive feedback off the final setpoint by {err} m"));
        }
        let (dp, _) = Pose::from_array(t.pose).error_to(&x_end);
        let (moved, _) = Pose::from_array(t.pose).error_to(&control.home);
        if t.converged != 1 || t.braked != 0 || dp > 0.005 || moved < 0.045 {
            return Err(format!(
                "truth: converged {} braked {} pose error {dp} m, moved {moved} m",
                t.converged, t.braked
            ));
        }
        // The load cells' 16-bit newtons (every 5th SYNC; the platform is at rest).
        for i in 0..8 {
            if (fb.cable_force_n[i] - t.force_n[i]).abs() > 1.0 {
                return Err(format!(
                    "cable {i}: load cell force {} N vs truth {} N",
                    fb.cable_force_n[i], t.force_n[i]
                ));
            }
        }
        Ok(())
    })();
    stop.store(true, Ordering::Release);
    let summary = plant_thread.join().unwrap().expect("plant loop");
    let dio = dio_thread.join().unwrap();
    if let Err(e) = result {
        panic!("{e}; plant loop {summary:?}; drive-io {dio:?}");
    }
    assert!(
        summary.syncs > 500 && summary.sync_settles > 300,
        "{summary:?}"
    );
    assert!(dio.is_ok(), "{dio:?}");
}

#[test]
fn csp_winch_follows_a_moving_target_without_lag_and_stops_at_a_far_one() {
    use sim_plant::bus::CspWinch;
    let dt = 1e-3;
    // A target stream accelerating at 10 m/s² to 1.5 m/s (beyond the stack's cable speeds),
    // within the winch limits: the winch is exactly where the target is, every period.
    let mut w = CspWinch::new(5.0, 5.0, 14.0);
    let mut t = 5.0;
    let mut v: f64 = 0.0;
    let mut worst: f64 = 0.0;
    for k in 0..600 {
        v = (v + 10.0 * dt).min(1.5);
        t += v * dt;
        w.follow(t, dt);
        if k > 5 {
            worst = worst.max((w.length_m - t).abs());
        }
    }
    assert!(worst < 1e-9, "following error {worst} m");
    assert!((w.velocity_m_per_s - 1.5).abs() < 1e-9);
    // A jump of the target by 2 m: limited speed and acceleration, no overshoot beyond 10 µm,
    // at rest on the target in the end.
    let mut w = CspWinch::new(5.0, 5.0, 14.0);
    let (mut v_prev, mut peak, mut over) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..3000 {
        w.follow(7.0, dt);
        assert!(w.velocity_m_per_s.abs() <= 5.0 + 1e-12);
        assert!((w.velocity_m_per_s - v_prev).abs() <= 14.0 * dt + 1e-12);
        v_prev = w.velocity_m_per_s;
        peak = peak.max(w.velocity_m_per_s);
        over = over.max(w.length_m - 7.0);
    }
    eprintln!("2 m jump: peak {peak} m/s, overshoot {over} m");
    assert!(peak > 3.0, "peak speed {peak}");
    assert!(over < 1e-5, "overshoot {over} m");
    assert!((w.length_m - 7.0).abs() < 1e-9 && w.velocity_m_per_s.abs() < 1e-9);
    // Quick stop from 2 m/s at 14 m/s²: 143 ms, 0.143 m.
    let mut w = CspWinch::new(5.0, 5.0, 14.0);
    w.velocity_m_per_s = 2.0;
    let mut n = 0;
    while w.velocity_m_per_s != 0.0 {
        w.quick_stop(dt);
        n += 1;
        assert!(n < 1000);
    }
    assert!((142..=144).contains(&n), "{n} periods");
    assert!(
        (w.length_m - 5.0 - 2.0 * 2.0 / 28.0).abs() < 2e-3,
        "{}",
        w.length_m
    );
}

#[test]
fn drives_with_a_safety_heartbeat_watch_stay_braked_without_the_monitor() {
    // The stack's drives config as it is: it validates the monitor's heartbeat.
    // Drives with their own watch of the monitor's frames (no safety I/O node), on one bus.
    let mut d = shipped();
    d.safety_io = None;
    let d = one_interface(d);
    assert!(d.safety_heartbeat.is_some());
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let mut plant = PlantBus::new(cfg, &control, &d, BusOptions::new(&d, &control)).unwrap();
    let mut wire = VecBus::default();
    let start = plant.plant_lengths().to_vec();
    let mut now = 0;
    plant.start(now);
    plant.handle_frame(0, &canopen::nmt(canopen::NMT_START, 0), now);
    for n in 1..=8u8 {
        plant.handle_frame(0, &canopen::sdo_download(n, 0x6060, 0, 8, 1), now);
    }
    for cw in [0x06, 0x07, 0x0F, 0x0F, 0x0F] {
        for i in 0..8 {
            plant.handle_frame(0, &canopen::rpdo1(i as u8 + 1, cw, 0), now);
        }
        now += 1_000_000;
        assert!(plant.handle_frame(0, &canopen::sync(), now));
        let r = plant.cycle(now, 1e-3);
        assert!(r.braked && !r.solved);
        plant.flush(std::slice::from_mut(&mut wire)).unwrap();
    }
    for i in 0..8 {
        let s = plant.drives().slave(i).unwrap();
        assert_ne!(
            s.ds402_state(),
            Ds402State::OperationEnabled,
            "drive {i} enabled"
        );
    }
    assert_eq!(max_abs_diff(plant.plant_lengths(), &start), 0.0);
}

/// sim-plant's winches check the monitor's SRDO configuration CRC. With valid RUN
/// heartbeats whose configuration signature carries another CRC (a monitor configured with
/// another validation time) no drive can be enabled; with the signature of the drives' own
/// configuration the same sequence enables all eight.
#[test]
fn winches_refuse_a_monitor_with_another_srdo_configuration() {
    use can_transport::safety_frame::{self, ConfigSignature, SafetyHeartbeat, SafetyState};
    // Drives with their own watch of the monitor's frames (no safety I/O node), on one bus.
    let mut d = shipped();
    d.safety_io = None;
    let d = one_interface(d);
    let own = d.safety_heartbeat.unwrap();
    let other = drive_bus::safety_watch::SafetyWatchConfig {
        validation_time_ms: own.validation_time_ms + 100,
        ..own
    };
    let enabled_with = |srdo_crc: u16| -> usize {
        let cfg = plant_cfg("icosahedron-ideal.toml");
        let control = cfg.platform.clone();
        let mut plant = PlantBus::new(cfg, &control, &d, BusOptions::new(&d, &control)).unwrap();
        let mut wire = VecBus::default();
        let mut now = 0;
        plant.start(now);
        plant.handle_frame(0, &canopen::nmt(canopen::NMT_START, 0), now);
        for n in 1..=8u8 {
            plant.handle_frame(0, &canopen::sdo_download(n, 0x6060, 0, 8, 1), now);
        }
        for k in 0..40u16 {
            now += 15_000_000;
            let sig = ConfigSignature {
                srdo_crc,
                safety_params_crc: 0,
            };
            let hb = SafetyHeartbeat {
                state: SafetyState::Run,
                cause: 0,
                counter: k,
                epoch: 7,
            };
            for f in sig
                .encode(own.cob_id)
                .into_iter()
                .chain(safety_frame::encode(&hb, own.cob_id))
            {
                plant.handle_frame(0, &f, now);
            }
            let cw = [0x06, 0x07, 0x0F][usize::from(k.min(2))];
            for i in 0..8 {
                plant.handle_frame(0, &canopen::rpdo1(i as u8 + 1, cw, 0), now);
            }
            assert!(plant.handle_frame(0, &canopen::sync(), now));
            plant.cycle(now, 1e-3);
            plant.flush(std::slice::from_mut(&mut wire)).unwrap();
        }
        (0..8)
            .filter(|&i| {
                plant.drives().slave(i).unwrap().ds402_state() == Ds402State::OperationEnabled
            })
            .count()
    };
    assert_ne!(own.srdo_crc(), other.srdo_crc());
    assert_eq!(
        enabled_with(other.srdo_crc()),
        0,
        "enabled despite the CRC mismatch"
    );
    assert_eq!(
        enabled_with(own.srdo_crc()),
        8,
        "the matching signature must release"
    );
}

/// Ramps an offset on one cable's command (0.1 mm per SYNC, as the fault matrix's 0.1 m/s)
/// from home until `target_m`, then holds 200 cycles; returns (offset at the first drive
/// fault, the cable's largest and smallest measured force before it).
fn ramp_offset(rig: &mut Rig, cable: usize, target_m: f64) -> (Option<f64>, f64, f64) {
    let home = rig.control.home;
    let (mut fmax, mut fmin) = (f64::NEG_INFINITY, f64::INFINITY);
    let n = (target_m.abs() / 1e-4).round() as usize;
    // 0.1 mm per setpoint (0.1 m/s), reached over 20 setpoints (5 m/s²: drive-io refuses a
    // setpoint that accelerates a cable beyond bus.max_cable_acceleration_m_per_s2).
    let step = 1e-4f64.copysign(target_m);
    let mut off = 0.0f64;
    for k in 1..=n + 210 {
        off += step * (k as f64 / 20.0).min(1.0);
        if off.abs() > target_m.abs() {
            off = target_m;
        }
        let mut sp = rig.setpoint(&home);
        sp.cable_length_m[cable] += off;
        rig.step(Some(&sp));
        if rig.master.state() == BusState::Fault {
            rig.step(None); // drive-io assembles its feedback in the next cycle
            return (Some(off), fmax, fmin);
        }
        let f = rig.feedback().cable_force_n[cable];
        fmax = fmax.max(f);
        fmin = fmin.min(f);
    }
    (None, fmax, fmin)
}

#[test]
fn slack_and_overload_raise_drive_faults_that_drive_io_sees() {
    // Lengthening one cable slackens its antagonists: the first drive whose measured force
    // drops below slack_fault_n faults (EMCY 0xFF10), drive-io stops all drives.
    let mut rig = Rig::new(plant_cfg("icosahedron-ideal.toml"));
    rig.boot();
    let (at, _, _) = ramp_offset(&mut rig, 5, 0.3);
    let at = at.expect("a 300 mm longer cable makes a slack cable");
    let fb = *rig.feedback();
    assert_eq!(rig.master.state(), BusState::Fault);
    assert_eq!(
        (fb.fault(), fb.last_emcy_code),
        (
            Ok(crs_ipc::FaultCode::Emcy),
            u32::from(sim_plant::bus::EMCY_CABLE_SLACK)
        )
    );
    let node = fb.fault_node as usize;
    // The TPDO2 of that cycle carries the slack reading that made the drive fault.
    assert!(
        fb.cable_force_n[node - 1] < rig.plant.options().slack_fault_n,
        "node {node}: {:?}",
        &fb.cable_force_n[..8]
    );
    assert_eq!(rig.plant.stats().slack_faults, 1);
    eprintln!(
        "+{:.1} mm on cable 6: slack drive fault on cable {node}, forces {:?} N",
        at * 1e3,
        fb.cable_force_n[..8]
            .iter()
            .map(|f| f.round())
            .collect::<Vec<_>>()
    );
    // Shortening one cable overloads it beyond the 14 kN rating (EMCY 0xFF11).
    let mut rig = Rig::new(plant_cfg("icosahedron-ideal.toml"));
    rig.boot();
    let (at, _, _) = ramp_offset(&mut rig, 5, -0.3);
    let at = at.expect("a 300 mm shorter cable overloads");
    let fb = *rig.feedback();
    assert_eq!(
        fb.last_emcy_code,
        u32::from(sim_plant::bus::EMCY_CABLE_OVERLOAD)
    );
    let node = fb.fault_node as usize;
    assert!(fb.cable_force_n[node - 1] > rig.plant.options().overload_fault_n);
    assert_eq!(rig.plant.stats().overload_faults, 1);
    eprintln!(
        "{:.1} mm on cable 6: overload drive fault on cable {node}, forces {:?} N",
        at * 1e3,
        fb.cable_force_n[..8]
            .iter()
            .map(|f| f.round())
            .collect::<Vec<_>>()
    );
}

/// The pulleys' load cells on the bus (`[[force_sensor]]`, CiA 404): the plant plays them next
/// to the drives and drive-io's feedback forces are theirs — the plant's sensor readings to the
/// load cell's 0.1 N resolution — while the winches' own force object is not used.
#[test]
fn force_sensors_on_the_bus_report_the_plants_forces() {
    let mut text = std::fs::read_to_string(fixture_path()).unwrap();
    for cable in 1..=8 {
        text.push_str(&format!(
            "\n[[force_sensor]]\nnode_id = {}\ncable = {cable}\nn_per_unit = 0.1\n\
             identity = {{ device_type = 0x00020194 }}\n",
            32 + cable
        ));
    }
    let mut d = DrivesConfig::parse(&text).unwrap();
    d.safety_heartbeat = None;
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    let plant = PlantBus::new(cfg, &control, &d, BusOptions::new(&d, &control)).unwrap();
    let mut rig = Rig::with_drives(control, plant, &d);
    rig.boot();
    // The drives' TPDO2 carries the velocity only: no force object mapped (the default
    // mapping, forces from the cells), velocity every 10th SYNC.
    let drive = rig.plant.drives().slave(0).unwrap();
    assert_eq!(drive.od_value(0x1A01, 0), Some(1));
    assert_eq!(drive.od_value(0x1801, 2), Some(10));
    rig.move_by([0.0, 0.0, 0.03, 0.0, 0.0, 0.0], 200, 50);
    let f = *rig.feedback();
    assert_eq!(f.bus().ok(), Some(BusState::Running));
    let measured = rig.plant.measured_forces().to_vec();
    for (i, m) in measured.iter().enumerate() {
        assert!(
            (f.cable_force_n[i] - m).abs() <= 0.05 + 1e-9,
            "cable {}: feedback {} N, load cell measured {m} N",
            i + 1,
            f.cable_force_n[i]
        );
    }
    assert!(measured.iter().all(|m| *m > 100.0), "{measured:?}");
}

/// Drives that ignore the monitor's frames (real CiA 402 drives) behind a safety I/O node: the
/// node on its own interface validates the monitor's doubled heartbeat and drives their STO
/// inputs. RUN pairs on the safety interface let the drives be enabled; the same RUN pairs on
/// the drives' own interface do nothing; when the pairs stop, torque is removed within the
/// validation time (Switch On Disabled, brakes closed) and no controlword enables again.
#[test]
fn drives_without_a_heartbeat_watch_are_stopped_by_the_safety_io_nodes_sto() {
    use can_transport::safety_frame::{self, ConfigSignature, SafetyHeartbeat, SafetyState};
    let mut d = one_interface(shipped());
    let own = d.safety_heartbeat.unwrap();
    d.bus.interfaces.push(drives_config::InterfaceConfig {
        name: "safety".into(),
        transport: "udpbus:239.255.70.1:20999".into(),
        bitrate_bit_per_s: 1_000_000,
        budget_percent: 70.0,
    });
    d.safety_io = Some(drives_config::SafetyIoConfig {
        interface: "safety".into(),
        node_id: 0x30,
        inputs_period_ms: 10,
        heartbeat_ms: 10,
    });
    d.validate().unwrap();
    let run = |pairs_on: usize, cycles: u16, plant: &mut PlantBus, now: &mut u64, k0: u16| {
        let mut wire = vec![VecBus::default(), VecBus::default()];
        for k in k0..k0 + cycles {
            *now += 15_000_000;
            let sig = ConfigSignature {
                srdo_crc: own.srdo_crc(),
                safety_params_crc: 0,
            };
            let hb = SafetyHeartbeat {
                state: SafetyState::Run,
                cause: 0,
                counter: k,
                epoch: 7,
            };
            for f in sig
                .encode(own.cob_id)
                .into_iter()
                .chain(safety_frame::encode(&hb, own.cob_id))
            {
                plant.handle_frame(pairs_on, &f, *now);
            }
            // As drive-io does: the controlword follows each drive's statusword.
            for i in 0..8 {
                let s = plant.drives().slave(i).unwrap();
                let cw = canopen::enable_step(s.ds402_state(), k % 2 == 0);
                // Holding the actual position, as drive-io does while enabling.
                let hold = s.od_value(0x6064, 0).unwrap_or(0) as i32;
                plant.handle_frame(0, &canopen::rpdo1(i as u8 + 1, cw, hold), *now);
            }
            assert!(plant.handle_frame(0, &canopen::sync(), *now));
            plant.cycle(*now, 1e-3);
            plant.poll(*now);
            plant.flush(&mut wire).unwrap();
        }
        (0..8)
            .filter(|&i| {
                plant.drives().slave(i).unwrap().ds402_state() == Ds402State::OperationEnabled
            })
            .count()
    };
    let start = |plant: &mut PlantBus, now: u64| {
        plant.start(now);
        for iface in 0..2 {
            plant.handle_frame(iface, &canopen::nmt(canopen::NMT_START, 0), now);
        }
        for n in 1..=8u8 {
            plant.handle_frame(0, &canopen::sdo_download(n, 0x6060, 0, 8, 1), now);
        }
    };
    let cfg = plant_cfg("icosahedron-ideal.toml");
    let control = cfg.platform.clone();
    // The monitor's frames on the drives' interface: the drives do not read them, the node
    // does not see them.
    let mut plant =
        PlantBus::new(cfg.clone(), &control, &d, BusOptions::new(&d, &control)).unwrap();
    let mut now = 0;
    start(&mut plant, now);
    assert_eq!(
        run(0, 20, &mut plant, &mut now, 0),
        0,
        "STO held without the node's RUN"
    );
    assert!(plant.drives().slave(0).unwrap().sto_active());
    // On the safety interface: the node releases STO, the drives enable.
    let mut plant = PlantBus::new(cfg, &control, &d, BusOptions::new(&d, &control)).unwrap();
    let mut now = 0;
    start(&mut plant, now);
    assert_eq!(run(1, 20, &mut plant, &mut now, 0), 8);
    assert!(plant.safety_io().unwrap().sto_released());
    // The monitor falls silent: within the validation time (50 ms) every drive loses torque.
    let mut wire = vec![VecBus::default(), VecBus::default()];
    let mut silent = 0;
    while plant.safety_io().unwrap().sto_released() {
        now += 1_000_000;
        silent += 1;
        assert!(plant.handle_frame(0, &canopen::sync(), now));
        plant.cycle(now, 1e-3);
        plant.poll(now);
        plant.flush(&mut wire).unwrap();
        assert!(
            silent <= own.validation_time_ms + 1,
            "STO not applied after {silent} ms"
        );
    }
    for i in 0..8 {
        let s = plant.drives().slave(i).unwrap();
        assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled, "drive {i}");
        assert!(matches!(
            s.demand(),
            cia402_drive::slave::MotionDemand::Hold
        ));
    }
    // Enable operation is refused while STO holds.
    for i in 0..8 {
        plant.handle_frame(0, &canopen::rpdo1(i as u8 + 1, 0x06, 0), now);
        plant.handle_frame(0, &canopen::rpdo1(i as u8 + 1, 0x0F, 0), now);
    }
    assert!(
        (0..8).all(|i| plant.drives().slave(i).unwrap().ds402_state() != Ds402State::OperationEnabled)
    );
}
