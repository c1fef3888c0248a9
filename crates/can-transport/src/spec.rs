//! Transport selection string (from the drives TOML or the command line).

use std::fmt;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::PathBuf;
use std::str::FromStr;

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TransportSpec {
    /// `socketcan:<iface>`
    SocketCan { iface: String },
    /// `udpbus:<multicast group>:<port>`: shared loopback bus, all members see each other.
    UdpMulticast { group: Ipv4Addr, port: u16 },
    /// `pycan-udp:<group>:<port>`: python-can's `udp_multicast` bus (msgpack framing), shared
    /// with python-can / python `canopen` processes (interoperability tests).
    PyCanUdp { group: Ipv4Addr, port: u16 },
    /// `udp:<local>-><remote>`: point-to-point cannelloni link (bridge to a real bus).
    UdpPeer {
        local: SocketAddrV4,
        remote: SocketAddrV4,
    },
    /// `wire:<socket path>`: one node of a bus the `can-wire` hub runs in its bus model (bit
    /// time, arbitration, transmit queues).
    Wire { path: PathBuf },
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid transport {input:?}: {reason}. Expected \"socketcan:<iface>\", \
         \"udpbus:<239.x.y.z>:<port>\", \"pycan-udp:<239.x.y.z>:<port>\", \"udp:<ip:port>-><ip:port>\" \
         or \"wire:<socket path>\""
)]
pub struct SpecError {
    pub input: String,
    pub reason: String,
}

impl FromStr for TransportSpec {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<Self, SpecError> {
        let err = |reason: &str| SpecError {
            input: s.to_string(),
            reason: reason.to_string(),
        };
        let (kind, rest) = s
            .split_once(':')
            .ok_or_else(|| err("missing ':' after the kind"))?;
        match kind {
            "socketcan" => {
                // Linux IFNAMSIZ is 16 including the NUL.
                if rest.is_empty() || rest.len() > 15 {
                    return Err(err("interface name must be 1..=15 bytes"));
                }
                if !rest
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-' || b == b'.')
                {
                    return Err(err(
                        "interface name has characters other than [A-Za-z0-9_.-]",
                    ));
                }
                Ok(Self::SocketCan {
                    iface: rest.to_string(),
                })
            }
            "udpbus" | "pycan-udp" => {
                let a: SocketAddrV4 = rest
                    .parse()
                    .map_err(|_| err("expected <ipv4 multicast group>:<port>"))?;
                if !a.ip().is_multicast() {
                    return Err(err("group must be an IPv4 multicast address (224.0.0.0/4)"));
                }
                if a.port() == 0 {
                    return Err(err("port must not be 0"));
                }
                let (group, port) = (*a.ip(), a.port());
                Ok(if kind == "udpbus" {
                    Self::UdpMulticast { group, port }
                } else {
                    Self::PyCanUdp { group, port }
                })
            }
            "udp" => {
                let (l, r) = rest
                    .split_once("->")
                    .ok_or_else(|| err("expected <local>-><remote>"))?;
                let local = l.parse().map_err(|_| err("local is not <ipv4>:<port>"))?;
                let remote = r.parse().map_err(|_| err("remote is not <ipv4>:<port>"))?;
                Ok(Self::UdpPeer { local, remote })
            }
            "wire" => {
                // sun_path holds 108 bytes including the terminating NUL.
                if rest.is_empty() || rest.len() > 107 {
                    return Err(err("socket path must be 1..=107 bytes"));
                }
                if rest.contains('\0') {
                    return Err(err("socket path contains a NUL byte"));
                }
                Ok(Self::Wire {
                    path: PathBuf::from(rest),
                })
            }
            _ => Err(err("unknown kind")),
        }
    }
}

impl fmt::Display for TransportSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SocketCan { iface } => write!(f, "socketcan:{iface}"),
            Self::UdpMulticast { group, port } => write!(f, "udpbus:{group}:{port}"),
            Self::UdpPeer { local, remote } => write!(f, "udp:{local}->{remote}"),
            Self::PyCanUdp { group, port } => write!(f, "pycan-udp:{group}:{port}"),
            Self::Wire { path } => write!(f, "wire:{}", path.display()),
        }
    }
}
