//! Logs one line the way a daemon's trip does, through [`crs_log::init`]: used by the tests and
//! to check the journal by hand (`systemd-run --unit crs-log-demo crs-log-demo; journalctl -u crs-log-demo`).
fn main() {
    let sink = crs_log::init("crs-log-demo");
    tracing::error!(?sink, cause = "test", "SAFETY TRIP: demo line");
}
