//! drive-io against drives that are not this project's code (python `canopen` LocalNodes,
//! `tools/canopen_interop.py drive`), over python-can's udp_multicast bus. One scenario per
//! run; prints `INTEROP PASS|FAIL <scenario>: ...`; exit status 0 iff it passed.
//! Driven by tools/canopen-interop.sh (which starts the python drives first).

use clap::Parser;
use drive_rig::interop;
use std::process::ExitCode;

#[derive(Parser)]
struct Args {
    /// python-can bus, e.g. pycan-udp:239.74.163.2:43113
    #[arg(long)]
    transport: String,
    /// run | emcy | heartbeat | reboot | refused | swapped
    #[arg(long)]
    scenario: String,
    /// Number of drives (node ids 1..=N).
    #[arg(long, default_value_t = 2)]
    drives: u8,
    /// The drives' EDS.
    #[arg(long, default_value = "config/eds/crs-winch.eds")]
    eds: String,
    #[arg(long)]
    dcf_dir: Option<String>,
    #[arg(long)]
    candump_log: Option<String>,
    /// The node the python side faults (emcy, heartbeat, reboot).
    #[arg(long, default_value_t = 2)]
    node: u8,
    /// The EMCY code the python side sends (emcy), e.g. 0x2310.
    #[arg(long, default_value = "0x2310", value_parser = parse_u16)]
    code: u16,
    /// Force sensors: one CiA 404 load cell per drive (node ids 33..), EDS
    /// config/eds/crs-load-cell.eds, the cable forces from them.
    #[arg(long)]
    cells: bool,
    /// The vendor drive's identity (config/eds/vendor-csp-drive.eds) checked at boot, and its
    /// string parameter 0x2000 written (segmented).
    #[arg(long)]
    vendor_identity: bool,
}

fn parse_u16(s: &str) -> Result<u16, String> {
    match s.strip_prefix("0x") {
        Some(h) => u16::from_str_radix(h, 16),
        None => s.parse(),
    }
    .map_err(|e| format!("{s}: {e}"))
}

fn config(a: &Args) -> Result<drives_config::DrivesConfig, String> {
    let abs = |p: &str| {
        std::path::absolute(p)
            .map(|p| p.display().to_string())
            .map_err(|e| e.to_string())
    };
    // A 2 ms SYNC: the interop checks the protocol, not timing; two drives with three PDOs
    // each (and their load cells) need 78-83 % of one 1 Mbit/s bus at 1 ms, above the 70 %
    // budget drive-io enforces at start (docs/can-protocol.md "Bus budget").
    let mut text = format!(
        "[bus]\ntransport = \"{}\"\nsync_period_us = 2000\nstale_setpoint_cycles = 50\n\
         heartbeat_producer_ms = 20\nheartbeat_timeout_ms = 300\nboot_timeout_ms = 20000\n\
         sdo_timeout_ms = 500\ndrive_heartbeat_consumer_ms = 600\neds = \"{}\"\n",
        a.transport,
        abs(&a.eds)?
    );
    if let Some(d) = &a.dcf_dir {
        text.push_str(&format!("dcf_dir = \"{}\"\n", abs(d)?));
    }
    if let Some(d) = &a.candump_log {
        text.push_str(&format!("candump_log = \"{}\"\n", abs(d)?));
    }
    for n in 1..=a.drives {
        let sign = if n % 2 == 1 { 1 } else { -1 };
        let offset = if sign > 0 { 0 } else { 200_000_000 };
        text.push_str(&format!(
            "[[winch]]\nnode_id = {n}\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = {sign}\noffset_counts = {offset}\n"
        ));
        if a.vendor_identity {
            text.push_str(&format!(
                "identity = {{ device_type = 0x00020192, vendor_id = 0x0000ACE1, \
                 product_code = 0x00002000, revision = 0x00040002, \
                 device_name = \"ACME CSP-2000 servo drive\" }}\n\
                 parameters = [{{ object = \"0x2000\", value = \"CRS winch {n} (cable {n})\" }}]\n"
            ));
        }
    }
    if a.cells {
        let cell_eds = abs("config/eds/crs-load-cell.eds")?;
        for n in 1..=a.drives {
            text.push_str(&format!(
                "[[force_sensor]]\nnode_id = {}\ncable = {n}\neds = \"{cell_eds}\"\n\
                 n_per_unit = 0.1\nphysical_unit = 0x00210000\ndecimal_digits = 1\n\
                 identity = {{ device_type = 0x00020194, product_code = 0x0043524C, \
                 device_name = \"CRS pulley load cell\" }}\n",
                32 + u16::from(n)
            ));
        }
    }
    drives_config::DrivesConfig::parse(&text).map_err(|e| e.to_string())
}

fn main() -> ExitCode {
    crs_log::init("drive-io-interop");
    let a = Args::parse();
    let prefix = format!("interop/{}/", std::process::id());
    let r = config(&a).and_then(|cfg| match a.scenario.as_str() {
        "run" => interop::scenario_run(cfg, &prefix),
        "emcy" => interop::scenario_emcy(cfg, &prefix, a.node, a.code),
        "heartbeat" => {
            interop::scenario_fault(cfg, &prefix, a.node, crs_ipc::FaultCode::HeartbeatLost)
        }
        "reboot" => {
            interop::scenario_fault(cfg, &prefix, a.node, crs_ipc::FaultCode::UnexpectedState)
        }
        "refused" => interop::scenario_refused(
            cfg,
            &prefix,
            &[
                "drive node 1",
                "0x6065",
                "0x06020000",
                "object does not exist",
            ],
        ),
        // The python side answers as another product on node 2 (a swapped drive).
        "swapped" => interop::scenario_refused(
            cfg,
            &prefix,
            &[
                "drive node 2",
                "0x1018sub2",
                "is 0x00003000",
                "expects 0x00002000",
                "winch[1].identity.product_code",
                "before anything was written",
            ],
        ),
        s => Err(format!("unknown scenario {s}")),
    });
    match r {
        Ok(msg) => {
            println!("INTEROP PASS {}: {msg}", a.scenario);
            ExitCode::SUCCESS
        }
        Err(msg) => {
            println!("INTEROP FAIL {}: {msg}", a.scenario);
            ExitCode::FAILURE
        }
    }
}
