//! The ride control socket between an operator's tools (`crs ride`, the console) and
//! motion-core (`motion-core --control PATH`, a Unix stream socket): one request per
//! connection — a command line, `start NAME`, `abort`, `home` or `status`, and for `start` the
//! ride file's text after it; the client then shuts its side down and reads one reply line,
//! `ok …` or `refused …`.
//!
//! The file's text travels, not its path: the daemon (user `crs`) need not be able to read
//! the operator's files, and the refusal names the file as the operator gave it.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::time::Duration;

/// How long the client waits for the daemon's reply (a `start` is answered after the daemon
/// verified the whole ride with the loop's own checks).
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

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
    /// The request's bytes on the socket.
    pub fn encode(&self) -> String {
        match self {
            Request::Start { name, text } => format!("start {name}\n{text}"),
            Request::Abort => "abort\n".into(),
            Request::Home => "home\n".into(),
            Request::Status => "status\n".into(),
        }
    }

    /// A request from its bytes on the socket.
    pub fn decode(bytes: &[u8]) -> Result<Self, RequestError> {
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
    #[error(
        "motion-core did not answer in time (is it stalled? `systemctl status crs-motion-core`)"
    )]
    Timeout,
}

/// Sends one request to the daemon at `path`; `Ok` holds the daemon's message. Waits at most
/// [`REPLY_TIMEOUT`] for each of sending and the reply.
pub fn request(path: &Path, req: &Request) -> Result<String, ClientError> {
    request_within(path, req, REPLY_TIMEOUT)
}

/// [`request`] with its own time limit.
pub fn request_within(
    path: &Path,
    req: &Request,
    timeout: Duration,
) -> Result<String, ClientError> {
    let mut s = UnixStream::connect(path).map_err(|source| ClientError::Connect {
        path: path.to_path_buf(),
        source,
    })?;
    s.set_write_timeout(Some(timeout))?;
    s.set_read_timeout(Some(timeout))?;
    let timed_out = |e: std::io::Error| match e.kind() {
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => ClientError::Timeout,
        _ => ClientError::Io(e),
    };
    s.write_all(req.encode().as_bytes()).map_err(timed_out)?;
    s.shutdown(std::net::Shutdown::Write)?;
    let mut reply = String::new();
    s.read_to_string(&mut reply).map_err(timed_out)?;
    let reply = reply.trim_end();
    if let Some(m) = reply.strip_prefix("ok ") {
        Ok(m.to_string())
    } else if let Some(m) = reply.strip_prefix("refused ") {
        Err(ClientError::Refused(m.to_string()))
    } else {
        Err(ClientError::Garbled(reply.chars().take(200).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::net::UnixListener;

    #[test]
    fn requests_round_trip_and_unknown_commands_are_named() {
        for r in [
            Request::Start {
                name: "a.csv".into(),
                text: "t,x\n0,1\n".into(),
            },
            Request::Abort,
            Request::Home,
            Request::Status,
        ] {
            assert_eq!(Request::decode(r.encode().as_bytes()).unwrap(), r);
        }
        let e = Request::decode(b"launch\n").unwrap_err().to_string();
        assert!(e.contains("`launch`"), "{e}");
    }

    /// A daemon that accepts and never answers: the client gives up with `Timeout`, it does
    /// not hang (the operator's terminal, the console's poller).
    #[test]
    fn a_silent_daemon_times_out() {
        let path =
            std::env::temp_dir().join(format!("crs-ride-silent-{}.sock", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let l = UnixListener::bind(&path).unwrap();
        let held = std::thread::spawn(move || l.accept().map(|(c, _)| c));
        let r = request_within(&path, &Request::Status, Duration::from_millis(200));
        assert!(matches!(r, Err(ClientError::Timeout)), "{r:?}");
        drop(held.join());
        let _ = std::fs::remove_file(&path);
    }
}
