//! The daemon's side of the ride control socket (`motion-core --control PATH`): the protocol
//! and its client are the process contract `crs_ipc::ride_control`.

use super::lifecycle::VerifiedPlan;
use super::ride::{RideCommandError, RideControl, RideSlot};
use super::trajectory::{self, PlanningFailed};
use crs_ipc::ride_control::{MAX_REQUEST_BYTES, Request, RequestError};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;
use std::time::Duration;

/// How long a connection may take to send its request: a client that connects and never
/// finishes must not hold the control thread (the next operator's STOP-then-home would wait).
const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

/// The daemon's answer to one request.
pub fn answer(
    control: &RideControl,
    slot: &RideSlot,
    req: Request,
    on_error: impl Fn(PlanningFailed) + Send + Clone + 'static,
) -> Result<String, RideCommandError> {
    let planned = |what: &str, p: VerifiedPlan| format!("{what}: plan {:.1} s", p.duration_s);
    match req {
        Request::Start { name, text } => {
            let ride = trajectory::parse_ride(&text, &name)
                .map_err(|e| RideCommandError::Refused(super::lifecycle::RideRefused::File(e)))?;
            let n = ride.waypoints.len();
            control
                .start(slot, &ride, on_error)
                .map(|p| planned(&format!("ride {name} started ({n} waypoints)"), p))
        }
        Request::Home => control
            .home(slot, on_error)
            .map(|p| planned("returning home", p)),
        Request::Abort => control
            .abort(slot)
            .map(|()| "aborting: braking the ride to a stop".into()),
        Request::Status => {
            // Rounded to the printed digits first, so that a rounding error prints as 0.000.
            let tidy = |v: f64, scale: f64| (v * scale).round() / scale + 0.0;
            let p = slot.pose();
            Ok(format!(
                "{}; pose [{:.3}, {:.3}, {:.3}] m [{:.2}, {:.2}, {:.2}]°; rides started: {}",
                slot.phase().name(),
                tidy(p.r.x, 1e3),
                tidy(p.r.y, 1e3),
                tidy(p.r.z, 1e3),
                tidy(p.phi.x.to_degrees(), 1e2),
                tidy(p.phi.y.to_degrees(), 1e2),
                tidy(p.phi.z.to_degrees(), 1e2),
                slot.rides_started()
            ))
        }
    }
}

/// Serves one connection: reads the request, answers one line, returns the line.
pub fn serve_one(
    mut stream: UnixStream,
    control: &RideControl,
    slot: &RideSlot,
    on_error: impl Fn(PlanningFailed) + Send + Clone + 'static,
) -> std::io::Result<String> {
    stream.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let mut buf = Vec::new();
    (&mut stream)
        .take(MAX_REQUEST_BYTES + 1)
        .read_to_end(&mut buf)?;
    let reply = if buf.len() as u64 > MAX_REQUEST_BYTES {
        format!("refused {}", RequestError::TooLarge)
    } else {
        match Request::decode(&buf) {
            Ok(req) => match answer(control, slot, req, on_error) {
                Ok(msg) => format!("ok {msg}"),
                Err(e) => format!("refused {e}"),
            },
            Err(e) => format!("refused {e}"),
        }
    };
    // One line: the refusal's own line breaks (none expected) flattened.
    let reply = reply.replace('\n', " ");
    stream.write_all(format!("{reply}\n").as_bytes())?;
    Ok(reply)
}

/// Binds the control socket at `path` (a stale socket file replaced), group-writable so the
/// operators of the `crs` group can connect.
pub fn bind(path: &Path) -> std::io::Result<UnixListener> {
    use std::os::unix::fs::PermissionsExt;
    if path.exists() {
        std::fs::remove_file(path)?;
    }
    let l = UnixListener::bind(path)?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o660))?;
    Ok(l)
}
