//! What the hub runs: its buses (`--bus name=…,bitrate=…,socket=…|ports=…`) and its timing.

use std::path::PathBuf;

/// Where a bus's nodes are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// Host: a `SOCK_SEQPACKET` unix socket; every `wire:<path>` client is one node.
    Socket(PathBuf),
    /// Guest: one SocketCAN interface per node (the node writes to its own; the hub forwards).
    Ports(Vec<String>),
}

/// One bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusSpec {
    pub name: String,
    pub bitrate_bps: u32,
    pub endpoint: Endpoint,
    /// Frames a node holds not yet off the wire (`txqueuelen`, default 10).
    pub queue_len: usize,
    /// Nodes the bus can ever have (host; the ports in the guest).
    pub max_nodes: usize,
    /// Identifiers with their own statistics.
    pub max_ids: usize,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--bus {input:?}: {field}: {reason}")]
pub struct BusSpecError {
    pub input: String,
    pub field: String,
    pub reason: String,
}

impl std::str::FromStr for BusSpec {
    type Err = BusSpecError;

    /// `name=can0,bitrate=1000000,socket=/run/crs/can0.sock` or
    /// `name=can0,bitrate=1000000,ports=vcan10+vcan11+vcan12`, optionally `queue=10`,
    /// `nodes=32`, `ids=128`.
    fn from_str(s: &str) -> Result<Self, BusSpecError> {
        let err = |field: &str, reason: String| BusSpecError {
            input: s.to_string(),
            field: field.to_string(),
            reason,
        };
        let mut name = None;
        let mut bitrate = None;
        let mut endpoint = None;
        let mut queue_len = can_bus_model::DEFAULT_QUEUE_LEN;
        let mut max_nodes = None;
        let mut max_ids = 128;
        for part in s.split(',') {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| err(part, "expected key=value".into()))?;
            let num = |lo: u64, hi: u64| -> Result<u64, BusSpecError> {
                let n: u64 = v
                    .parse()
                    .map_err(|_| err(k, format!("{v:?} is not a whole number")))?;
                if !(lo..=hi).contains(&n) {
                    return Err(err(k, format!("{n} is outside {lo}..={hi}")));
                }
                Ok(n)
            };
            match k {
                "name" => {
                    if v.is_empty()
                        || v.len() > 15
                        || !v
                            .bytes()
                            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
                    {
                        return Err(err(k, format!("{v:?} must be 1..=15 of [A-Za-z0-9_-]")));
                    }
                    name = Some(v.to_string());
                }
                "bitrate" => bitrate = Some(num(1_000, 1_000_000)? as u32),
                "socket" => {
                    if endpoint.is_some() {
                        return Err(err(k, "give either socket= or ports=, once".into()));
                    }
                    if v.is_empty() || v.len() > 107 {
                        return Err(err(k, "socket path must be 1..=107 bytes".into()));
                    }
                    endpoint = Some(Endpoint::Socket(PathBuf::from(v)));
                }
                "ports" => {
                    if endpoint.is_some() {
                        return Err(err(k, "give either socket= or ports=, once".into()));
                    }
                    let ports: Vec<String> = v.split('+').map(str::to_string).collect();
                    if ports.len() < 2 {
                        return Err(err(k, "a bus needs at least two ports (a+b)".into()));
                    }
                    for p in &ports {
                        if p.is_empty() || p.len() > 15 {
                            return Err(err(
                                k,
                                format!("interface name {p:?} must be 1..=15 bytes"),
                            ));
                        }
                    }
                    let mut sorted = ports.clone();
                    sorted.sort();
                    sorted.dedup();
                    if sorted.len() != ports.len() {
                        return Err(err(k, "an interface is named twice".into()));
                    }
                    endpoint = Some(Endpoint::Ports(ports));
                }
                "queue" => queue_len = num(1, 4096)? as usize,
                "nodes" => max_nodes = Some(num(2, 256)? as usize),
                "ids" => max_ids = num(1, 4096)? as usize,
                _ => {
                    return Err(err(
                        k,
                        "unknown key (known: name, bitrate, socket, ports, queue, nodes, ids)"
                            .into(),
                    ));
                }
            }
        }
        let name = name.ok_or_else(|| err("name", "missing".into()))?;
        let bitrate_bps = bitrate.ok_or_else(|| err("bitrate", "missing (bit/s)".into()))?;
        let endpoint = endpoint
            .ok_or_else(|| err("socket", "missing: give socket=<path> or ports=a+b".into()))?;
        let max_nodes = match (&endpoint, max_nodes) {
            (Endpoint::Ports(p), Some(n)) if n != p.len() => {
                return Err(err(
                    "nodes",
                    format!("{n}, but {} ports are named", p.len()),
                ));
            }
            (Endpoint::Ports(p), _) => p.len(),
            (Endpoint::Socket(_), n) => n.unwrap_or(32),
        };
        Ok(Self {
            name,
            bitrate_bps,
            endpoint,
            queue_len,
            max_nodes,
            max_ids,
        })
    }
}

impl BusSpec {
    pub fn model_config(&self) -> can_bus_model::BusConfig {
        can_bus_model::BusConfig {
            bitrate_bps: self.bitrate_bps,
            max_nodes: self.max_nodes,
            queue_len: self.queue_len,
            max_ids: self.max_ids,
        }
    }
}

/// The whole hub.
#[derive(Debug, Clone, PartialEq)]
pub struct HubConfig {
    pub buses: Vec<BusSpec>,
    /// Hub time runs this far behind the clock: a submission that reaches the hub within it
    /// still competes in the arbitration at its stamp.
    pub lookahead_ns: u64,
    /// The hub wakes this long after the earliest due event and handles everything due by then
    /// (fewer wake-ups; deliveries up to this late in real time; stamps are unaffected).
    pub coalesce_ns: u64,
    pub stats_path: Option<PathBuf>,
    pub stats_period_ns: u64,
    pub ready_file: Option<PathBuf>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HubConfigError {
    #[error("no --bus given")]
    NoBus,
    #[error("bus name {0:?} is used twice")]
    DuplicateName(String),
    #[error("socket {0:?} is used by two buses")]
    DuplicateSocket(PathBuf),
    #[error("interface {0:?} is a port of two buses")]
    DuplicatePort(String),
}

impl HubConfig {
    pub fn validate(&self) -> Result<(), HubConfigError> {
        if self.buses.is_empty() {
            return Err(HubConfigError::NoBus);
        }
        let mut names = std::collections::BTreeSet::new();
        let mut sockets = std::collections::BTreeSet::new();
        let mut ports = std::collections::BTreeSet::new();
        for b in &self.buses {
            if !names.insert(b.name.clone()) {
                return Err(HubConfigError::DuplicateName(b.name.clone()));
            }
            match &b.endpoint {
                Endpoint::Socket(p) => {
                    if !sockets.insert(p.clone()) {
                        return Err(HubConfigError::DuplicateSocket(p.clone()));
                    }
                }
                Endpoint::Ports(ps) => {
                    for p in ps {
                        if !ports.insert(p.clone()) {
                            return Err(HubConfigError::DuplicatePort(p.clone()));
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_specs_parse_and_errors_name_the_field() {
        let b: BusSpec = "name=can0,bitrate=1000000,socket=/tmp/c.sock"
            .parse()
            .unwrap();
        assert_eq!(b.endpoint, Endpoint::Socket("/tmp/c.sock".into()));
        assert_eq!((b.queue_len, b.max_nodes, b.max_ids), (10, 32, 128));
        let b: BusSpec = "name=can1,bitrate=500000,ports=vcan10+vcan11+vcan12,queue=4"
            .parse()
            .unwrap();
        assert_eq!(b.max_nodes, 3);
        assert_eq!(b.queue_len, 4);
        for (s, field) in [
            ("name=can0,bitrate=fast,socket=x", "bitrate"),
            ("name=can0,bitrate=2000000,socket=x", "bitrate"),
            ("name=can0,socket=x", "bitrate"),
            ("bitrate=1000000,socket=x", "name"),
            ("name=can0,bitrate=1000000", "socket"),
            ("name=can0,bitrate=1000000,ports=vcan10", "ports"),
            ("name=can0,bitrate=1000000,ports=a+a", "ports"),
            ("name=can0,bitrate=1000000,socket=x,ports=a+b", "ports"),
            ("name=can0,bitrate=1000000,socket=x,queue=0", "queue"),
            ("name=can0,bitrate=1000000,socket=x,colour=red", "colour"),
            ("name=can0,bitrate=1000000,ports=a+b,nodes=3", "nodes"),
            ("name=can 0,bitrate=1000000,socket=x", "name"),
            ("name=can0,bitrate", "bitrate"),
        ] {
            let e = s.parse::<BusSpec>().unwrap_err();
            assert_eq!(e.field, field, "{s}: {e}");
            assert!(e.to_string().contains(s), "{e}");
        }
    }

    #[test]
    fn a_hub_refuses_shared_names_sockets_and_ports() {
        let bus = |s: &str| s.parse::<BusSpec>().unwrap();
        let mut c = HubConfig {
            buses: vec![
                bus("name=a,bitrate=1000000,socket=x"),
                bus("name=b,bitrate=1000000,socket=x"),
            ],
            lookahead_ns: 0,
            coalesce_ns: 0,
            stats_path: None,
            stats_period_ns: 1_000_000_000,
            ready_file: None,
        };
        assert!(matches!(
            c.validate(),
            Err(HubConfigError::DuplicateSocket(_))
        ));
        c.buses[1] = bus("name=a,bitrate=1000000,socket=y");
        assert!(matches!(
            c.validate(),
            Err(HubConfigError::DuplicateName(_))
        ));
        c.buses = vec![
            bus("name=a,bitrate=1000000,ports=v1+v2"),
            bus("name=b,bitrate=1000000,ports=v2+v3"),
        ];
        assert!(matches!(
            c.validate(),
            Err(HubConfigError::DuplicatePort(_))
        ));
        c.buses.clear();
        assert_eq!(c.validate(), Err(HubConfigError::NoBus));
    }
}
