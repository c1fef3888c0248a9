//! The monitor's own reading of the drives file: the interfaces, where the safety frames go,
//! each drive's RPDO and each cable's force frame — the shipped CRS layout, a custom mapping,
//! and layouts it cannot decode refused by key.

use safety_monitor::bus_layout::Value;
use safety_monitor::config::{self, load_drives};
use std::path::PathBuf;

fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

#[test]
fn the_shipped_layout_as_the_monitor_reads_it() {
    let d = load_drives(&config_dir().join("drives.toml")).unwrap();
    let names: Vec<&str> = d.interfaces.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["can0", "can1", "can2", "can3", "safety"]);
    assert_eq!(
        d.safety_interfaces,
        vec![4],
        "the safety frames travel on `safety` only"
    );
    assert_eq!(d.safety_io, Some((4, 0x30)));
    // Cable 3 (node 3) is on can1; its RPDO is drive-io's default one.
    let r = d.layout.rpdo[2];
    assert_eq!(
        (r.interface, r.cob_id, r.len, r.controlword_at, r.target_at),
        (1, 0x203, 6, 0, 2)
    );
    // Its force comes from its load cell (node 35): a 16-bit newton value in TPDO1.
    let f = d.layout.force[2];
    assert_eq!((f.interface, f.cob_id, f.len, f.at), (1, 0x1A3, 2, 0));
    assert_eq!((f.value, f.n_per_unit, f.node), (Value::I16, 1.0, 35));
    // The monitor's config on it: every interface observed, the drives file's transports.
    let cfg = config::load(&config_dir().join("safety-monitor.toml")).unwrap();
    assert_eq!(cfg.interfaces.len(), 5);
    assert_eq!(cfg.layout, d.layout);
}

fn with(text: &str) -> Result<config::Drives, config::ConfigError> {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "drives-layout-{}-{}",
        std::process::id(),
        text.len()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("drives.toml");
    std::fs::write(&p, text).unwrap();
    load_drives(&p)
}

const ONE: &str = "[bus]\ntransport = \"udpbus:239.255.70.1:20000\"\n\
[[winch]]\nnode_id = 5\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = 1\n";

#[test]
fn custom_mappings_and_drive_forces_are_decoded_where_drive_io_puts_them() {
    // Default mapping, force measured by the drive: TPDO2 = velocity + force (mN).
    let d = with(ONE).unwrap();
    let f = d.layout.force[0];
    assert_eq!(
        (f.cob_id, f.len, f.at, f.value, f.n_per_unit),
        (0x285, 8, 4, Value::I32, 0.001)
    );
    // A custom RPDO with the target first and the controlword second, on RPDO2's COB-ID.
    let custom = format!(
        "{ONE}mapping = \"custom\"\nforce = \"drive\"\n\
         [[winch.rpdo]]\nnumber = 2\nobjects = [\"0x607A\", \"0x6040\"]\n\
         [[winch.tpdo]]\nnumber = 1\nobjects = [\"0x6041\", \"0x6064\"]\n\
         [[winch.tpdo]]\nnumber = 3\nobjects = [\"0x2110sub0\", \"0x606C\"]\n"
    );
    let d = with(&custom).unwrap();
    let r = d.layout.rpdo[0];
    assert_eq!(
        (r.cob_id, r.len, r.controlword_at, r.target_at),
        (0x305, 6, 4, 0)
    );
    let f = d.layout.force[0];
    assert_eq!((f.cob_id, f.len, f.at), (0x385, 8, 0));
}

#[test]
fn layouts_the_monitor_cannot_decode_are_refused_by_key() {
    for (edit, key) in [
        (format!("{ONE}mapping = \"fixed\"\n"), "winch[0].mapping"),
        (
            format!(
                "{ONE}mapping = \"custom\"\n[[winch.rpdo]]\nnumber = 1\nobjects = [\"0x6040\"]\n"
            ),
            "winch[0].rpdo",
        ),
        (format!("{ONE}force = 40\n"), "winch[0].force"),
        (
            format!(
                "{ONE}[[force_sensor]]\nnode_id = 33\ncable = 1\nn_per_unit = 1.0\nobject = \"0x2000sub1\"\n"
            ),
            "force_sensor[0].object",
        ),
        (
            format!("{ONE}[safety_io]\ninterface = \"safety\"\nnode_id = 48\n"),
            "safety_io.interface",
        ),
    ] {
        let e = with(&edit).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
}
