//! The monitor's reset socket (`[reset] socket`): a unix stream socket on which
//! `safety-monitor reset` asks for a reset. The kernel tells the monitor who is asking
//! (SO_PEERCRED: pid, uid, gid; SO_PEERGROUPS: the supplementary groups, both as of the
//! `connect`), and only a member of the operator group gets an
//! [`OperatorReset`](crate::operator::OperatorReset); every other peer is answered "denied" and
//! logged with its pid, uid, gid and executable.
//!
//! Protocol: the client sends one line `reset`; the monitor answers one line
//! (`accepted`, `not-tripped`, `not-ready`, `refused <cause>`, `exhausted`, `denied <why>`)
//! and closes. Polled once per monitor cycle, never blocking: a connection that has not sent
//! its line within [`REQUEST_TIMEOUT_NS`] is closed; at most [`MAX_PENDING`] connections wait.

use crate::operator::{OperatorReset, ResetChannel};
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};

/// Connections waiting for their request line.
pub const MAX_PENDING: usize = 4;
/// A connection that has not sent its request within this is closed (ns).
pub const REQUEST_TIMEOUT_NS: u64 = 1_000_000_000;

/// Who is on the other end of a connection, as the kernel reported it at `connect`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Peer {
    pub pid: i32,
    pub uid: u32,
    pub gid: u32,
    /// The operator group is the peer's primary or one of its supplementary groups.
    pub operator: bool,
}

impl Peer {
    /// The peer's executable (`/proc/<pid>/exe`) for the log, if it can be read.
    pub fn executable(&self) -> String {
        std::fs::read_link(format!("/proc/{}/exe", self.pid))
            .map(|p| p.display().to_string())
            .unwrap_or_else(|_| "?".into())
    }
}

/// The credentials of `s`'s peer; `operator` = member of `gid`.
fn peer_of(s: &UnixStream, gid: u32) -> std::io::Result<Peer> {
    let fd = s.as_raw_fd();
    let mut cred = libc::ucred {
        pid: 0,
        uid: 0,
        gid: 0,
    };
    let mut len = std::mem::size_of::<libc::ucred>() as libc::socklen_t;
    // SAFETY: `cred` and `len` are valid for the call; the kernel writes at most `len` bytes.
    let rc = unsafe {
        libc::getsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_PEERCRED,
            (&mut cred as *mut libc::ucred).cast(),
            &mut len,
        )
    };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    let mut groups = [0 as libc::gid_t; 64];
    let mut glen = std::mem::size_of_val(&groups) as libc::socklen_t;
    // SAFETY: as above; SO_PEERGROUPS writes at most `glen` bytes of gids.
    let rc = unsafe {
        libc::getsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_PEERGROUPS,
            groups.as_mut_ptr().cast(),
            &mut glen,
        )
    };
    // A peer with more groups than fit (ERANGE) or a kernel without SO_PEERGROUPS: only the
    // primary group counts (fails closed for the supplementary ones).
    let n = if rc == 0 {
        glen as usize / std::mem::size_of::<libc::gid_t>()
    } else {
        0
    };
    Ok(Peer {
        pid: cred.pid,
        uid: cred.uid,
        gid: cred.gid,
        operator: cred.gid == gid || groups[..n.min(groups.len())].contains(&gid),
    })
}

struct Pending {
    stream: UnixStream,
    peer: Peer,
    since_ns: u64,
    buf: [u8; 32],
    len: usize,
}

/// What a polled connection asks for.
#[derive(Debug)]
pub enum Request {
    /// A member of the operator group asks for a reset: the authorised request.
    Reset(OperatorReset),
    /// Anyone else (logged by the caller with [`Peer::executable`]), or a malformed request.
    Denied { peer: Peer, why: &'static str },
}

/// The listening socket and the connections waiting for their request.
pub struct ResetSocket {
    listener: UnixListener,
    path: PathBuf,
    gid: u32,
    pending: [Option<Pending>; MAX_PENDING],
    /// The connection whose request was handed out by [`ResetSocket::poll`] last.
    answering: Option<Pending>,
}

#[derive(Debug, thiserror::Error)]
pub enum SocketError {
    #[error("reset socket {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("reset socket {0}: exists and is not a socket (refusing to remove it)")]
    NotASocket(String),
}

impl ResetSocket {
    /// Binds `path` (a stale socket file left by a previous run is removed; any other file is
    /// refused), world-connectable: every peer reaches the credential check, and is logged.
    pub fn bind(path: &Path, operator_gid: u32) -> Result<Self, SocketError> {
        use std::os::unix::fs::{FileTypeExt, PermissionsExt};
        let io = |source| SocketError::Io {
            path: path.display().to_string(),
            source,
        };
        match std::fs::symlink_metadata(path) {
            Ok(md) if md.file_type().is_socket() => std::fs::remove_file(path).map_err(io)?,
            Ok(_) => return Err(SocketError::NotASocket(path.display().to_string())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(e)),
        }
        if let Some(dir) = path.parent()
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let listener = UnixListener::bind(path).map_err(io)?;
        listener.set_nonblocking(true).map_err(io)?;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o666)).map_err(io)?;
        Ok(Self {
            listener,
            path: path.to_path_buf(),
            gid: operator_gid,
            pending: [None, None, None, None],
            answering: None,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Accepts new connections and returns the first complete request (one per call; the
    /// caller answers it with [`ResetSocket::answer`] before the next poll).
    pub fn poll(&mut self, now_ns: u64) -> Option<Request> {
        // New connections (never blocking), a bounded number per cycle (a local flood of
        // connections cannot hold the cycle); beyond MAX_PENDING they are closed unanswered.
        for _ in 0..2 * MAX_PENDING {
            let Ok((stream, _)) = self.listener.accept() else {
                break;
            };
            let _ = stream.set_nonblocking(true);
            let Ok(peer) = peer_of(&stream, self.gid) else {
                continue;
            };
            if let Some(slot) = self.pending.iter_mut().find(|p| p.is_none()) {
                *slot = Some(Pending {
                    stream,
                    peer,
                    since_ns: now_ns,
                    buf: [0; 32],
                    len: 0,
                });
            } else {
                tracing::warn!(
                    pid = peer.pid,
                    uid = peer.uid,
                    "reset socket: too many pending connections, closed"
                );
            }
        }
        for slot in &mut self.pending {
            let Some(p) = slot else { continue };
            let mut done = false;
            loop {
                if p.len == p.buf.len() {
                    done = true;
                    break;
                }
                match p.stream.read(&mut p.buf[p.len..]) {
                    Ok(0) => {
                        done = true;
                        break;
                    }
                    Ok(n) => {
                        p.len += n;
                        if p.buf[..p.len].contains(&b'\n') {
                            done = true;
                            break;
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(_) => {
                        done = true;
                        break;
                    }
                }
            }
            if !done {
                if now_ns.saturating_sub(p.since_ns) > REQUEST_TIMEOUT_NS {
                    *slot = None;
                }
                continue;
            }
            let p = slot.take()?;
            let line = &p.buf[..p.len];
            let is_reset = line.split(|&b| b == b'\n').next().map(<[u8]>::trim_ascii)
                == Some(b"reset".as_slice());
            let peer = p.peer;
            self.answering = Some(p);
            return Some(if !is_reset {
                Request::Denied {
                    peer,
                    why: "malformed request (expected the line `reset`)",
                }
            } else if peer.operator {
                Request::Reset(OperatorReset::new(ResetChannel::Socket {
                    pid: peer.pid,
                    uid: peer.uid,
                    gid: peer.gid,
                }))
            } else {
                Request::Denied {
                    peer,
                    why: "not a member of the operator group",
                }
            });
        }
        None
    }

    /// Answers the request [`ResetSocket::poll`] returned last (one line) and closes it.
    pub fn answer(&mut self, text: &str) {
        if let Some(mut p) = self.answering.take() {
            let _ = p.stream.set_nonblocking(false);
            let _ = p
                .stream
                .set_write_timeout(Some(std::time::Duration::from_millis(5)));
            let _ = p.stream.write_all(text.as_bytes());
            let _ = p.stream.write_all(b"\n");
        }
    }
}

impl Drop for ResetSocket {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Client side (`safety-monitor reset`): sends `reset`, returns the monitor's answer line.
pub fn request(path: &Path, timeout: std::time::Duration) -> std::io::Result<String> {
    let mut s = UnixStream::connect(path)?;
    s.set_read_timeout(Some(timeout))?;
    s.set_write_timeout(Some(timeout))?;
    s.write_all(b"reset\n")?;
    let mut out = String::new();
    s.read_to_string(&mut out)?;
    Ok(out.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel's credentials decide: this process's own gid is an operator, any other gid
    /// is not; a malformed line is denied; the answer reaches the client.
    #[test]
    fn only_members_of_the_operator_group_get_a_reset() {
        let dir = std::env::temp_dir().join(format!("crs-reset-socket-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("reset.sock");
        // SAFETY: getgid has no preconditions.
        let own_gid = unsafe { libc::getgid() };
        for (gid, line, want_reset) in [
            (own_gid, "reset\n", true),
            (own_gid.wrapping_add(4242), "reset\n", false),
            (own_gid, "release everything\n", false),
        ] {
            let mut sock = ResetSocket::bind(&path, gid).unwrap();
            let p = path.clone();
            let line = line.to_string();
            let client = std::thread::spawn(move || {
                let mut s = UnixStream::connect(&p).unwrap();
                s.write_all(line.as_bytes()).unwrap();
                let mut out = String::new();
                s.read_to_string(&mut out).unwrap();
                out
            });
            let mut got = None;
            for k in 0..2000u64 {
                if let Some(r) = sock.poll(k * 1_000_000) {
                    got = Some(r);
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            match got.expect("a request") {
                Request::Reset(r) => {
                    assert!(want_reset);
                    // SAFETY: getuid has no preconditions.
                    let uid = unsafe { libc::getuid() };
                    assert!(matches!(
                        r.channel(),
                        ResetChannel::Socket { pid, uid: u, .. } if pid == std::process::id() as i32 && u == uid
                    ));
                    sock.answer("accepted");
                }
                Request::Denied { peer, why } => {
                    assert!(!want_reset, "{why}");
                    assert_eq!(peer.pid, std::process::id() as i32);
                    sock.answer("denied");
                }
            }
            let answer = client.join().unwrap();
            assert_eq!(
                answer.trim(),
                if want_reset { "accepted" } else { "denied" }
            );
        }
        // A regular file at the socket's path is not removed.
        std::fs::write(&path, b"x").unwrap();
        assert!(matches!(
            ResetSocket::bind(&path, own_gid),
            Err(SocketError::NotASocket(_))
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
