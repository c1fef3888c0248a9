//! Which CAN transport a run of the stack uses.

/// `--transport` names no transport `can_transport` knows.
#[derive(Debug, thiserror::Error)]
#[error("--transport: {0}")]
pub struct BadTransport(String);

/// `arg` as given, or for `auto`: vcan0 when the kernel can open it, else a UDP multicast bus
/// with a port derived from the pid and `run_no` (runs in one process do not share a bus).
pub fn choose_transport(arg: &str, run_no: u32) -> Result<String, BadTransport> {
    if arg != "auto" {
        arg.parse::<can_transport::TransportSpec>()
            .map_err(|e| BadTransport(e.to_string()))?;
        return Ok(arg.to_string());
    }
    let vcan = can_transport::TransportSpec::SocketCan {
        iface: "vcan0".into(),
    };
    match can_transport::open(&vcan) {
        Ok(_) => Ok("socketcan:vcan0".into()),
        Err(e) => {
            let port = 20000 + ((std::process::id() + 97 * run_no) % 20000) as u16;
            println!("  vcan0 not available ({e}); using the CAN-over-UDP loopback bus");
            Ok(format!("udpbus:239.255.70.9:{port}"))
        }
    }
}
