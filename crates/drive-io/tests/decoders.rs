//! Property tests: CANopen frame decoding, SDO parsing and the drives TOML never panic, and
//! invalid TOML is rejected with an error naming the field.

use can_transport::CanFrame;
use cia402_drive::slave::DriveSlave;
use drive_bus::canopen::{self, FrameBuf, parse_sdo_request, parse_sdo_response};
use drives_config::DrivesConfig;
use proptest::prelude::*;

const GOOD: &str = r#"
[bus]
transport = "udpbus:239.255.70.1:20000"
[[winch]]
node_id = 1
drum_diameter_m = 0.305
gear_ratio = 10.0
counts_per_rev = 1048576
sign = 1
"#;

proptest! {
    #[test]
    fn canopen_decode_and_slave_never_panic(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let f = CanFrame::new(id, &data).unwrap();
        let _ = canopen::decode(&f);
        let mut s = DriveSlave::new(5, 10);
        let mut out = FrameBuf::default();
        s.start(0, &mut out);
        s.handle_frame(&canopen::nmt(canopen::NMT_START, 0), 0, &mut out);
        s.handle_frame(&f, 1, &mut out);
        s.poll(u64::MAX / 2, &mut out);
    }

    #[test]
    fn sdo_parsers_never_panic(d in any::<[u8; 8]>()) {
        let _ = parse_sdo_request(&d);
        let _ = parse_sdo_response(&d);
    }

    #[test]
    fn toml_never_panics(s in "\\PC{0,200}") {
        let _ = DrivesConfig::parse(&s);
    }

    #[test]
    fn toml_mutations_never_panic(pos in 0usize..200, ch in any::<char>()) {
        let mut s: Vec<char> = GOOD.chars().collect();
        let p = pos.min(s.len() - 1);
        s[p] = ch;
        let s: String = s.into_iter().collect();
        let _ = DrivesConfig::parse(&s);
    }

    #[test]
    fn length_counts_round_trip(l in 0.0f64..30.0, sign in prop_oneof![Just(1i8), Just(-1i8)], off in -1_000_000i64..1_000_000) {
        let cfg = DrivesConfig::parse(&GOOD.replace("sign = 1", &format!("sign = {sign}\noffset_counts = {off}"))).unwrap();
        let w = &cfg.winches[0];
        let c = w.length_to_counts(l).unwrap();
        prop_assert!((w.counts_to_length(c) - l).abs() <= 0.5 / w.counts_per_m() + 1e-12);
    }
}

#[test]
fn good_config_and_scaling() {
    let cfg = DrivesConfig::parse(GOOD).unwrap();
    let w = &cfg.winches[0];
    // One drum revolution = pi * 0.305 m = gear * cpr counts.
    let rev = std::f64::consts::PI * 0.305;
    assert_eq!(w.length_to_counts(rev), Some(10 * 1048576));
    assert_eq!(cfg.bus.sync_period_us, 1000);
    // The SYNC is the bus clock by default; one interface named can0 at 1 Mbit/s, 70 % budget.
    assert_eq!(cfg.bus.sync_source, drives_config::SyncSource::Isochronous);
    assert_eq!(
        (cfg.bus.setpoint_wait_us, cfg.bus.rpdo_guard_us),
        (250, 400)
    );
    let itf = cfg.interfaces();
    assert_eq!(itf.len(), 1);
    assert_eq!(
        (
            itf[0].name.as_str(),
            itf[0].bitrate_bit_per_s,
            itf[0].budget_percent
        ),
        ("can0", 1_000_000, 70.0)
    );
    assert!(w.length_to_counts(-0.1).is_none() && w.length_to_counts(f64::NAN).is_none());
}

#[test]
fn errors_name_the_field() {
    let cases = [
        (
            GOOD.replace("node_id = 1", "node_id = 0"),
            "winch[0].node_id",
        ),
        (GOOD.replace("sign = 1", "sign = 2"), "winch[0].sign"),
        (
            GOOD.replace("drum_diameter_m = 0.305", "drum_diameter_m = -1.0"),
            "winch[0].drum_diameter_m",
        ),
        (
            GOOD.replace("udpbus:239.255.70.1:20000", "udpbus:10.0.0.1:1"),
            "bus.transport",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nstale_setpoint_cycles = 0"),
            "bus.stale_setpoint_cycles",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nsetpoint_wait_us = 500"),
            "bus.setpoint_wait_us",
        ),
        // Safety-relevant values bounded both ways, refused by key.
        (
            GOOD.replace("[bus]", "[bus]\nstale_setpoint_cycles = 501"),
            "bus.stale_setpoint_cycles",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nabort_connection_option = 0"),
            "bus.abort_connection_option",
        ),
        (
            GOOD.replace("[bus]", "[bus]\ndrive_heartbeat_consumer_ms = 0"),
            "bus.drive_heartbeat_consumer_ms",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nmax_cable_speed_m_per_s = 11.0"),
            "bus.max_cable_speed_m_per_s",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nmax_cable_acceleration_m_per_s2 = 0.0"),
            "bus.max_cable_acceleration_m_per_s2",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nmax_cable_acceleration_m_per_s2 = 201.0"),
            "bus.max_cable_acceleration_m_per_s2",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nforce_hard_limit_n = 20001.0"),
            "bus.force_hard_limit_n",
        ),
        (
            GOOD.replace("[bus]", "[bus]\nsync_source = \"tick\""),
            "sync_source",
        ),
        (
            GOOD.replace("counts_per_rev = 1048576", "counts_per_rev = 1e12"),
            "winch[0].max_cable_length_m",
        ),
        (
            format!(
                "{GOOD}\n[[winch]]\nnode_id = 1\ndrum_diameter_m = 0.3\ngear_ratio = 1.0\ncounts_per_rev = 4096\nsign = 1\n"
            ),
            "winch[1].node_id",
        ),
    ];
    for (text, field) in cases {
        let e = DrivesConfig::parse(&text).unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
    // Unknown keys and syntax errors carry the TOML line.
    let e = DrivesConfig::parse(&GOOD.replace("sign = 1", "sgn = 1"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("sgn") && e.contains("line"), "{e}");
}

/// Several interfaces: winches name theirs, node ids repeat across interfaces, transports
/// are overridden per interface, and every mistake names its key.
const TWO: &str = r#"
[bus]
[[bus.interface]]
name = "can0"
transport = "udpbus:239.255.70.1:20000"
[[bus.interface]]
name = "can1"
transport = "udpbus:239.255.70.1:20001"
bitrate_bit_per_s = 500000
budget_percent = 60
[[winch]]
interface = "can0"
node_id = 1
drum_diameter_m = 0.305
gear_ratio = 10.0
counts_per_rev = 1048576
sign = 1
[[winch]]
interface = "can1"
node_id = 1
drum_diameter_m = 0.305
gear_ratio = 10.0
counts_per_rev = 1048576
sign = -1
"#;

#[test]
fn several_interfaces() {
    let mut cfg = DrivesConfig::parse(TWO).unwrap();
    assert_eq!(cfg.interfaces().len(), 2);
    assert_eq!((cfg.winch_interface(0), cfg.winch_interface(1)), (0, 1));
    assert_eq!(cfg.transports().unwrap().len(), 2);
    // A single-bus tool refuses it, naming why.
    let e = cfg.transport().unwrap_err().to_string();
    assert!(e.contains("bus.interface") && e.contains("2"), "{e}");
    cfg.override_transports(&["can1=udpbus:239.255.70.1:20009".into()])
        .unwrap();
    assert_eq!(cfg.interfaces()[1].transport, "udpbus:239.255.70.1:20009");
    let e = cfg
        .override_transports(&["udpbus:239.255.70.1:20010".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("NAME=SPEC"), "{e}");
    let e = cfg
        .override_transports(&["can7=udpbus:239.255.70.1:20010".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("can7"), "{e}");
    let cases = [
        (
            TWO.replace(
                "interface = \"can1\"\nnode_id",
                "interface = \"can9\"\nnode_id",
            ),
            "winch[1].interface",
        ),
        (
            TWO.replacen("interface = \"can0\"\n", "", 1),
            "winch[0].interface",
        ),
        (
            TWO.replace("name = \"can1\"", "name = \"can0\""),
            "bus.interface[1].name",
        ),
        (TWO.replace("20001", "20000"), "bus.interface[1].transport"),
        (
            TWO.replace("budget_percent = 60", "budget_percent = 80"),
            "bus.interface[1].budget_percent",
        ),
        (
            TWO.replace("bitrate_bit_per_s = 500000", "bitrate_bit_per_s = 2000000"),
            "bus.interface[1].bitrate_bit_per_s",
        ),
        (
            TWO.replace("[bus]", "[bus]\ntransport = \"udpbus:239.255.70.1:20005\""),
            "bus.transport",
        ),
        (
            TWO.replace(
                "interface = \"can1\"\nnode_id",
                "interface = \"can0\"\nnode_id",
            ),
            "winch[1].node_id",
        ),
    ];
    for (text, field) in cases {
        let e = DrivesConfig::parse(&text).unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
}

#[test]
fn repo_config_is_valid() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/drives.toml");
    let cfg = DrivesConfig::load(&path).unwrap();
    assert_eq!(cfg.winches.len(), 8);
    assert!(cfg.winches.iter().all(|w| w.drum_diameter_m == 0.305));
}
