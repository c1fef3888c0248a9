//! Vendor drives in virtual time: drive-io's master against drives built from a vendor-like
//! EDS (`config/eds/vendor-csp-drive.eds`: minimal event-driven PDOs, stray PDOs enabled,
//! CompactSubObj arrays, a segmented device name, no force object) with the cable forces from
//! separate CiA 404 load cells (`config/eds/crs-load-cell.eds`). Frames are passed directly.

use can_transport::{CanFrame, RxFrame};
use cia402_drive::force_node::ForceNode;
use cia402_drive::slave::{DriveSlave, MotionDemand, SlaveEvent, WinchAxis};
use crs_ipc::{BusState, FaultCode, JointSetpoint};
use drive_bus::canopen::{self, BusFrames, Ds402State, FrameBuf, Message};
use drive_bus::eds::Eds;
use drive_bus::mapping::{Direction, Transmission};
use drive_io::Master;
use drives_config::DrivesConfig;

const VENDOR_EDS: &str = include_str!("../../../config/eds/vendor-csp-drive.eds");

fn vendor_eds() -> Eds {
    Eds::parse(VENDOR_EDS, "config/eds/vendor-csp-drive.eds").unwrap()
}

/// Two vendor drives (nodes 1, 2), their load cells (nodes 33, 34); `extra` is appended to
/// the first [[winch]] table.
fn config(extra_winch1: &str) -> DrivesConfig {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/eds");
    let mut t = format!(
        "[bus]\ntransport = \"udpbus:239.255.0.1:1\"\nheartbeat_producer_ms = 20\n\
         heartbeat_timeout_ms = 300\nboot_timeout_ms = 20000\nsdo_timeout_ms = 500\n\
         drive_heartbeat_consumer_ms = 600\neds = \"{dir}/vendor-csp-drive.eds\"\n"
    );
    for n in 1..=2u8 {
        t.push_str(&format!(
            "[[winch]]\nnode_id = {n}\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = {}\noffset_counts = {}\n\
             identity = {{ device_type = 0x00020192, vendor_id = 0x0000ACE1, \
             product_code = 0x00002000, device_name = \"ACME CSP-2000 servo drive\" }}\n",
            if n == 1 { 1 } else { -1 },
            if n == 1 { 0 } else { 200_000_000 }
        ));
        if n == 1 {
            t.push_str(extra_winch1);
            t.push('\n');
        }
    }
    for (n, cable) in [(33u8, 1), (34, 2)] {
        t.push_str(&format!(
            "[[force_sensor]]\nnode_id = {n}\ncable = {cable}\nn_per_unit = 0.1\n\
             physical_unit = 0x00210000\ndecimal_digits = 1\n\
             identity = {{ device_type = 0x00020194, product_code = 0x0043524C }}\n"
        ));
    }
    DrivesConfig::parse(&t).unwrap()
}

struct Rig {
    cfg: DrivesConfig,
    master: Master,
    drives: Vec<DriveSlave>,
    cells: Vec<ForceNode>,
    axes: Vec<WinchAxis>,
    now: u64,
    log: Vec<Message>,
    /// Every frame on the bus (both directions), for counting.
    frames: Vec<CanFrame>,
    force_n: Vec<f64>,
}

impl Rig {
    fn new(cfg: DrivesConfig, drive_eds: &[Eds]) -> Self {
        let master = Master::new(&cfg).unwrap();
        let drives = cfg
            .winches
            .iter()
            .zip(drive_eds)
            .map(|(w, e)| DriveSlave::with_eds(w.node_id, e, 0))
            .collect();
        let cells = cfg
            .force_sensors
            .iter()
            .map(|s| ForceNode::load_cell(s.node_id, 0))
            .collect();
        let axes = (0..cfg.winches.len())
            .map(|i| WinchAxis::new(4.0 + i as f64, 5.0, 14.0))
            .collect();
        let mut r = Self {
            cfg,
            master,
            drives,
            cells,
            axes,
            now: 1_000_000_000,
            log: Vec::new(),
            frames: Vec::new(),
            force_n: vec![3000.0, 4500.5],
        };
        let mut out = FrameBuf::default();
        for (i, d) in r.drives.iter_mut().enumerate() {
            let c = r.cfg.winches[i]
                .length_to_counts(r.axes[i].length_m)
                .unwrap();
            d.set_actual(c, 0, 0);
            d.start(r.now, &mut out);
        }
        for c in &mut r.cells {
            c.start(r.now, &mut out);
        }
        r.deliver(&out);
        r
    }

    fn deliver(&mut self, out: &FrameBuf) {
        for f in out.as_slice() {
            self.frames.push(*f);
            self.log.push(canopen::decode(f));
            self.master.on_frame(
                0,
                &RxFrame {
                    frame: *f,
                    rx_monotonic_ns: self.now,
                    kernel_rx_realtime_ns: None,
                    own: false,
                },
            );
        }
    }

    /// One 1 ms cycle: master -> nodes -> physics -> nodes -> master.
    fn step(&mut self, sp: Option<&JointSetpoint>) {
        self.now += 1_000_000;
        let mut out = BusFrames::new(1);
        self.master.cycle(self.now, sp, &mut out);
        self.master.mark_written(self.now);
        // One interface: its frames, then the SYNC the cycle asks for (as the runner sends).
        let mut m_out: Vec<CanFrame> = out.on(0).to_vec();
        if out.sync_requested() {
            m_out.push(canopen::sync());
        }
        let mut s_out = FrameBuf::default();
        for f in &m_out {
            self.frames.push(*f);
            self.log.push(canopen::decode(f));
            for i in 0..self.drives.len() {
                if self.drives[i].handle_frame(f, self.now, &mut s_out) == SlaveEvent::Sync {
                    let w = self.cfg.winches[i].clone();
                    match self.drives[i].demand() {
                        MotionDemand::Follow { target_counts } => {
                            self.axes[i].step(Some(w.counts_to_length(target_counts)), 1e-3)
                        }
                        MotionDemand::QuickStop => self.axes[i].step(None, 1e-3),
                        MotionDemand::Hold => self.axes[i].hold(),
                    }
                    let c = w.length_to_counts(self.axes[i].length_m).unwrap();
                    let v = w.m_per_s_to_counts_per_s(self.axes[i].velocity_m_per_s);
                    self.drives[i].set_actual(c, v, 0);
                    self.drives[i].transmit_pdos(&mut s_out);
                }
            }
            for (j, c) in self.cells.iter_mut().enumerate() {
                if c.handle_frame(f, self.now, &mut s_out) {
                    c.set_force_n(self.force_n[j]);
                    c.transmit_pdos(&mut s_out);
                }
            }
        }
        for d in &mut self.drives {
            d.poll(self.now, &mut s_out);
        }
        for c in &mut self.cells {
            c.poll(self.now, &mut s_out);
        }
        self.deliver(&s_out);
    }

    fn boot(&mut self) {
        for _ in 0..400 {
            self.step(None);
            if self.master.state() == BusState::Ready {
                return;
            }
        }
        panic!(
            "not Ready after 400 cycles: {:?} {:?}",
            self.master.state(),
            self.master.describe_commissioning_fault()
        );
    }

    fn setpoint(&self, seq: u64, lengths: &[f64]) -> JointSetpoint {
        let mut sp = JointSetpoint {
            sequence: seq,
            cable_count: lengths.len() as u32,
            timestamp_ns: self.now,
            ..Default::default()
        };
        sp.cable_length_m[..lengths.len()].copy_from_slice(lengths);
        sp
    }

    /// SDO requests drive-io sent to `node`.
    fn sdo_requests(&self, node: u8) -> Vec<[u8; 8]> {
        self.log
            .iter()
            .filter_map(|m| match m {
                Message::SdoRequest { node: n, data } if *n == node => Some(*data),
                _ => None,
            })
            .collect()
    }
}

#[test]
fn vendor_drives_with_load_cells_boot_follow_and_report_the_cells_forces() {
    // A vendor string parameter (13 bytes: segmented download, read back segmented).
    let cfg = config("parameters = [{ object = \"0x2000\", value = \"CRS cable one\" }]");
    let mut r = Rig::new(cfg, &[vendor_eds(), vendor_eds()]);
    r.boot();
    assert_eq!(r.drives[0].od_bytes(0x2000, 0), Some(&b"CRS cable one"[..]));
    assert_eq!(r.drives[1].od_bytes(0x2000, 0), Some(&b"axis"[..]));
    assert!(r.sdo_requests(1).iter().any(|d| d[0] == 0x21 && d[4] == 13));
    // Identity first: the first requests to drive 1 upload 0x1000, 0x1018 sub 1/2, then the
    // device name (segmented: the answer is 0x41 and segments follow).
    let req = r.sdo_requests(1);
    let first: Vec<(u16, u8, u8)> = req[..4]
        .iter()
        .map(|d| (u16::from_le_bytes([d[1], d[2]]), d[3], d[0]))
        .collect();
    assert_eq!(
        first,
        vec![
            (0x1000, 0, 0x40),
            (0x1018, 1, 0x40),
            (0x1018, 2, 0x40),
            (0x1008, 0, 0x40)
        ]
    );
    let segments = req.iter().filter(|d| d[0] & 0xEF == 0x60).count();
    assert!(
        segments >= 4,
        "0x1008's 25 bytes take 4 segments: {segments}"
    );
    assert!(r.log.iter().any(
        |m| matches!(m, Message::SdoResponse { node: 1, data } if data[0] == 0x41 && data[1..4] == [0x08, 0x10, 0])
    ));
    // Stray PDOs of the vendor defaults are disabled; drive-io's mapping is in place.
    for d in &r.drives {
        let cob = |i| d.od_value(i, 1).unwrap();
        assert_ne!(
            cob(0x1401) & 0x8000_0000,
            0,
            "RPDO2 (controlword + mode) disabled"
        );
        assert_ne!(cob(0x1802) & 0x8000_0000, 0, "TPDO3 disabled");
        assert_eq!(cob(0x1800) & 0x8000_0000, 0);
        assert_eq!(d.od_value(0x1800, 2), Some(1), "TPDO1 every SYNC");
        assert_eq!(d.od_value(0x1801, 2), Some(10), "velocity every 10th SYNC");
        assert_eq!(
            d.od_value(0x1A01, 0),
            Some(1),
            "velocity alone: no force object"
        );
        assert_eq!(d.od_value(0x60C2, 1), Some(1));
        assert_eq!(d.od_value(0x60C2, 2), Some(0xFD), "-3 as INTEGER8");
        assert_eq!(d.ds402_state(), Ds402State::OperationEnabled);
    }
    // The frames the bus budget sees: 6 + 6 B every SYNC, 4 B every 10th; a cell: 4 B.
    let plans = r.master.plans();
    let frames: Vec<_> = plans[0]
        .pdo_frames()
        .iter()
        .map(|f| (f.cob_id, f.dlc, f.direction, f.transmission))
        .collect();
    assert_eq!(
        frames,
        vec![
            (0x201, 6, Direction::ToNode, Transmission::Sync { every: 1 }),
            (
                0x181,
                6,
                Direction::FromNode,
                Transmission::Sync { every: 1 }
            ),
            (
                0x281,
                4,
                Direction::FromNode,
                Transmission::Sync { every: 10 }
            ),
        ]
    );
    assert_eq!(
        plans[2].pdo_frames()[0].cob_id,
        0x180 + 33,
        "load cell TPDO1"
    );
    // Follow 20 mm; the forces are the cells' (0.1 N resolution).
    let l0: Vec<f64> = r.master.feedback().cable_length_m[..2].to_vec();
    r.frames.clear();
    for k in 1..=200u64 {
        // Rest to rest (3t² − 2t³): a step out of a hold is acceleration-checked.
        let t = k as f64 / 200.0;
        let l: Vec<f64> = l0
            .iter()
            .map(|x| x + 0.02 * t * t * (3.0 - 2.0 * t))
            .collect();
        let sp = r.setpoint(k, &l);
        r.step(Some(&sp));
    }
    for _ in 0..50 {
        let sp = r.setpoint(201 + r.now / 1_000_000, &[l0[0] + 0.02, l0[1] + 0.02]);
        r.step(Some(&sp));
    }
    let f = *r.master.feedback();
    assert_eq!(BusState::from_u32(f.bus_state), Some(BusState::Running));
    for (i, l) in l0.iter().enumerate() {
        assert!((f.cable_length_m[i] - (l + 0.02)).abs() < 1e-6, "{i}");
    }
    assert_eq!(f.cable_force_n[0], 3000.0);
    assert!((f.cable_force_n[1] - 4500.5).abs() < 1e-9);
    // 250 cycles: velocity TPDOs every 10th SYNC, statusword/position TPDOs every SYNC.
    let count = |id: u32| r.frames.iter().filter(|f| f.id() == id).count();
    assert_eq!(count(0x181), 250);
    assert_eq!(count(0x281), 25);
    assert_eq!(count(0x180 + 33), 250);
}

#[test]
fn a_swapped_drive_is_refused_before_anything_is_written() {
    // Node 2 answers as another product (a drive swapped in from another machine).
    let cfg = config("");
    let other = VENDOR_EDS.replace(
        "ParameterName=Product code\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x00002000",
        "ParameterName=Product code\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x00003000",
    );
    assert_ne!(other, VENDOR_EDS);
    let other = Eds::parse(&other, "other.eds").unwrap();
    let mut r = Rig::new(cfg, &[vendor_eds(), other]);
    for _ in 0..200 {
        r.step(None);
    }
    assert_eq!(r.master.state(), BusState::Fault);
    assert_eq!(r.master.feedback().fault_node, 2);
    let msg = r.master.describe_commissioning_fault().unwrap();
    for want in [
        "drive node 2",
        "0x1018sub2 (Identity object / Product code)",
        "0x00003000",
        "expects 0x00002000",
        "winch[1].identity.product_code",
        "swapped",
    ] {
        assert!(msg.contains(want), "`{want}` missing in: {msg}");
    }
    // Not one SDO download reached the swapped drive.
    let writes = r.sdo_requests(2).iter().filter(|d| d[0] >> 5 == 1).count();
    assert_eq!(writes, 0);
    assert!(!r.log.iter().any(|m| matches!(
        m,
        Message::Nmt {
            command: canopen::NMT_START,
            ..
        }
    )));
}

#[test]
fn a_wrong_device_name_or_load_cell_unit_is_refused() {
    let mut cfg = config("");
    cfg.winches[0].identity.device_name = Some("ACME CSP-1000 servo drive".into());
    let mut r = Rig::new(cfg, &[vendor_eds(), vendor_eds()]);
    for _ in 0..200 {
        r.step(None);
    }
    let msg = r.master.describe_commissioning_fault().unwrap();
    assert!(
        msg.contains("\"ACME CSP-2000 servo drive\"")
            && msg.contains("expects \"ACME CSP-1000 servo drive\"")
            && msg.contains("winch[0].identity.device_name"),
        "{msg}"
    );
    // A load cell configured for mN (CiA 303-2 prefix milli) reports N: refused.
    let mut cfg = config("");
    cfg.force_sensors[1].physical_unit = Some(0xFD21_0000);
    let mut r = Rig::new(cfg, &[vendor_eds(), vendor_eds()]);
    for _ in 0..200 {
        r.step(None);
    }
    let msg = r.master.describe_commissioning_fault().unwrap();
    assert!(
        msg.contains("force sensor node 34")
            && msg.contains("0x6131sub1")
            && msg.contains("force_sensor[1].physical_unit"),
        "{msg}"
    );
}

#[test]
fn statusword_bit_13_or_a_cell_beyond_the_force_limit_stops_every_drive() {
    let mut r = Rig::new(config(""), &[vendor_eds(), vendor_eds()]);
    r.boot();
    // Drive 2 reports a following error (CSP statusword bit 13) in its TPDO1.
    let pos = r.drives[1].od_value(0x6064, 0).unwrap().to_le_bytes();
    let sw = (0x1237u16 | canopen::SW_FOLLOWING_ERROR).to_le_bytes();
    let tpdo = CanFrame::new(0x182, &[sw[0], sw[1], pos[0], pos[1], pos[2], pos[3]]).unwrap();
    let mut out = FrameBuf::default();
    out.push(tpdo);
    r.deliver(&out);
    r.step(None);
    let f = *r.master.feedback();
    assert_eq!(BusState::from_u32(f.bus_state), Some(BusState::Fault));
    assert_eq!(
        (f.fault().unwrap(), f.fault_node),
        (FaultCode::DriveFaultBit, 2)
    );

    // A load cell reading beyond bus.force_hard_limit_n (14 kN): fault naming the cell.
    let mut r = Rig::new(config(""), &[vendor_eds(), vendor_eds()]);
    r.boot();
    r.force_n[1] = 15_000.0;
    r.step(None);
    r.step(None);
    let f = *r.master.feedback();
    assert_eq!(
        (f.fault().unwrap(), f.fault_node),
        (FaultCode::ForceLimit, 34)
    );

    // A cell that falls silent: its TPDO times out (300 ms).
    let mut r = Rig::new(config(""), &[vendor_eds(), vendor_eds()]);
    r.boot();
    r.cells.truncate(1);
    for _ in 0..320 {
        r.step(None);
    }
    let f = *r.master.feedback();
    assert_eq!(f.fault_node, 34, "code {}", f.fault_code);
    assert!(matches!(
        f.fault().unwrap(),
        FaultCode::PdoTimeout | FaultCode::HeartbeatLost
    ));
}

/// A vendor drive whose mapping is fixed (mapping objects read-only): adopted as its EDS
/// defaults say, checked by upload, with the transmission types drive-io may set.
#[test]
fn a_fixed_mapping_is_adopted_and_checked() {
    let sub = |index: &str, k: u8, name: &str, from: &str, to: &str| {
        let head = format!("[{index}sub{k}]\nParameterName={name}\nObjectType=0x7\nDataType=");
        let at = VENDOR_EDS.find(&head).unwrap();
        let end = at + VENDOR_EDS[at..].find("\n\n").unwrap();
        let section = &VENDOR_EDS[at..end];
        assert!(section.contains(from), "{section}");
        (section.to_string(), section.replace(from, to))
    };
    // RPDO1 = controlword + target, TPDO1 = statusword + position, TPDO3 = velocity alone.
    let mut fixed = VENDOR_EDS.to_string();
    for (a, b) in [
        sub(
            "1600",
            0,
            "Number of mapped objects",
            "DefaultValue=1",
            "DefaultValue=2",
        ),
        sub(
            "1600",
            2,
            "Mapped object 2",
            "DefaultValue=0",
            "DefaultValue=0x607A0020",
        ),
        sub(
            "1A00",
            0,
            "Number of mapped objects",
            "DefaultValue=1",
            "DefaultValue=2",
        ),
        sub(
            "1A00",
            2,
            "Mapped object 2",
            "DefaultValue=0",
            "DefaultValue=0x60640020",
        ),
        sub(
            "1A02",
            0,
            "Number of mapped objects",
            "DefaultValue=2",
            "DefaultValue=1",
        ),
        sub(
            "1A02",
            1,
            "Mapped object 1",
            "DefaultValue=0x60640020",
            "DefaultValue=0x606C0020",
        ),
    ] {
        fixed = fixed.replace(&a, &b);
    }
    let eds_path = std::env::temp_dir().join(format!("fixed-{}.eds", std::process::id()));
    std::fs::write(&eds_path, &fixed).unwrap();
    let fixed_eds = Eds::parse(&fixed, "fixed.eds").unwrap();
    let cfg = config(&format!(
        "mapping = \"fixed\"\neds = \"{}\"",
        eds_path.display()
    ));
    let plan = &drive_commissioning::commissioning::plan_all(&cfg, None).unwrap()[0];
    // The mapping is checked, not written.
    use drive_commissioning::commissioning::SdoOp;
    assert!(
        !plan
            .ops
            .iter()
            .any(|o| matches!(o, SdoOp::Write { index: 0x1600..=0x1603 | 0x1A00..=0x1A03, .. }))
    );
    assert!(plan.ops.contains(&SdoOp::Verify {
        index: 0x1600,
        sub: 2,
        value: 0x607A_0020,
        len: 4
    }));
    let f: Vec<_> = plan
        .pdo_frames()
        .iter()
        .map(|f| (f.cob_id, f.dlc, f.transmission))
        .collect();
    assert_eq!(
        f,
        vec![
            (0x201, 6, Transmission::Sync { every: 1 }),
            (0x181, 6, Transmission::Sync { every: 1 }),
            (0x381, 4, Transmission::Sync { every: 10 }),
        ]
    );
    let mut r = Rig::new(cfg, &[fixed_eds, vendor_eds()]);
    r.boot();
    let l0 = r.master.feedback().cable_length_m;
    let sp = r.setpoint(1, &l0[..2]);
    r.step(Some(&sp));
    assert_eq!(r.master.state(), BusState::Running);
    let _ = std::fs::remove_file(eds_path);
}
