//! The daemon's ride control socket (a Unix stream socket, `motion-core --control PATH`) and
//! its client (`crs ride`). One request per connection: a command line — `start NAME`,
//! `abort`, `home` or `status` — and for `start` the ride file's text after it; the client
//! then shuts its side down and reads one reply line, `ok …` or `refused …`.
//!
//! The file's text travels, not its path: the daemon (user `crs`) need not be able to read
//! the operator's files, and the refusal names the file as the operator gave it.

use super::lifecycle::VerifiedPlan;
use super::ride::{RideCommandError, RideControl, RideSlot};
use super::trajectory::{self, PlanningFailed};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;

/// Largest request accepted (a ride file of ~20 000 waypoints).
pub const MAX_REQUEST_BYTES: u64 = 1 << 20;

/// The default socket of the installed stack (`RuntimeDirectory=crs/motion-core` of the unit).
pub const DEFAULT_SOCKET: &str = "/run/crs/motion-core/control.sock";

/// An operator's command.
#[derive(Clone, Debug, PartialEq)]
pub enum Request {
    Start { name: String, text: String },
    Abort,
    Home,
    Status,
}

/// A request that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    #[error("request is not UTF-8 text")]
    NotText,
    #[error("request larger than {MAX_REQUEST_BYTES} bytes")]
    TooLarge,
    #[error("unknown command `{0}` (start NAME | abort | home | status)")]
    Unknown(String),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

impl Request {
    fn encode(&self) -> String {
        match self {
            Request::Start { name, text } => format!("start {name}\n{text}"),
            Request::Abort => "abort\n".into(),
            Request::Home => "home\n".into(),
            Request::Status => "status\n".into(),
        }
    }

    fn decode(bytes: &[u8]) -> Result<Self, RequestError> {
        let text = std::str::from_utf8(bytes).map_err(|_| RequestError::NotText)?;
        let (first, rest) = text.split_once('\n').unwrap_or((text, ""));
        let first = first.trim();
        match first.split_once(' ') {
            Some(("start", name)) => Ok(Request::Start {
                name: name.trim().to_string(),
                text: rest.to_string(),
            }),
            _ => match first {
                "abort" => Ok(Request::Abort),
                "home" => Ok(Request::Home),
                "status" => Ok(Request::Status),
                other => Err(RequestError::Unknown(other.chars().take(40).collect())),
            },
        }
    }
}

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

/// What the client got back.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("{}: cannot connect to motion-core's control socket: {source} (is the stack running? `systemctl status crs-stack.target`)", path.display())]
    Connect {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("motion-core's control socket: {0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Refused(String),
    #[error("unexpected reply from motion-core: {0}")]
    Garbled(String),
}

/// Sends one request to the daemon at `path`; `Ok` holds the daemon's message.
pub fn request(path: &Path, req: &Request) -> Result<String, ClientError> {
    let mut s = UnixStream::connect(path).map_err(|source| ClientError::Connect {
        path: path.to_path_buf(),
        source,
    })?;
    s.write_all(req.encode().as_bytes())?;
    s.shutdown(std::net::Shutdown::Write)?;
    let mut reply = String::new();
    s.read_to_string(&mut reply)?;
    let reply = reply.trim_end();
    if let Some(m) = reply.strip_prefix("ok ") {
        Ok(m.to_string())
    } else if let Some(m) = reply.strip_prefix("refused ") {
        Err(ClientError::Refused(m.to_string()))
    } else {
        Err(ClientError::Garbled(reply.chars().take(200).collect()))
    }
}
