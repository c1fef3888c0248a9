//! What drive-io checks and writes in each node at start-up, derived from the node's EDS and
//! drives.toml ([`plan_drive`], [`plan_force_sensor`]): first the identity (0x1000, 0x1018,
//! 0x1008 as configured — nothing is written into a wrong or swapped device), then the PDO
//! communication and mapping (CiA 301 §7.5.2.35-38, the "disable PDO, clear mapping, write
//! entries, set count, enable" order of §7.2.2.3.4) or, for a fixed mapping, its check by
//! upload; stray PDOs disabled; SYNC, heartbeats, the CiA 402 option codes, the quick stop
//! deceleration, the interpolation period, the limits the drive supports, vendor parameters
//! and the mode. Every written value is read back afterwards ([`SdoOp::Verify`]). Nothing here
//! does I/O.
//!
//! Objects are *required* (start-up stops if the EDS lacks them) or *optional* (written only
//! if the EDS lists them: the limits, the communication cycle period, the interpolation period).

use drive_bus::canopen::*;
use drive_bus::eds::{DataType, DcfValue, Eds, OdEntry};
use drive_bus::force_sensor::{ForceSensorConfig, OD_AI_DECIMAL_DIGITS, OD_AI_PHYSICAL_UNIT};
use drive_bus::identity::{Identity, OD_DEVICE_NAME};
use drive_bus::mapping::*;
use drives_config::{BusConfig, DrivesConfig, ParameterValue, WinchConfig, winch_mapping_mode};
use std::sync::Arc;

/// One SDO transfer of the start-up script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoOp {
    /// Download of `len` (1, 2 or 4) bytes.
    Write {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
    /// Upload; the value (masked to `len` bytes) must equal `value` (what drive-io wrote).
    Verify {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
    /// Upload before anything is written; must equal `value` as drives.toml says (identity,
    /// a force sensor's unit and decimal digits): a mismatch is a wrong or swapped device.
    Check {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
    /// Download of the plan's bytes `at..at + len` (segmented beyond 4 bytes).
    WriteBytes {
        index: u16,
        sub: u8,
        at: u16,
        len: u16,
    },
    /// Upload compared with the plan's bytes `at..at + len`; `check` = like [`SdoOp::Check`]
    /// (the device name), else like [`SdoOp::Verify`].
    VerifyBytes {
        index: u16,
        sub: u8,
        at: u16,
        len: u16,
        check: bool,
    },
    /// Upload, logged (device name and versions where nothing is expected).
    Read { index: u16, sub: u8 },
}

impl SdoOp {
    pub fn index_sub(&self) -> (u16, u8) {
        match *self {
            Self::Write { index, sub, .. }
            | Self::Verify { index, sub, .. }
            | Self::Check { index, sub, .. }
            | Self::WriteBytes { index, sub, .. }
            | Self::VerifyBytes { index, sub, .. }
            | Self::Read { index, sub } => (index, sub),
        }
    }
    /// A download (the others are uploads).
    pub fn is_write(&self) -> bool {
        matches!(self, Self::Write { .. } | Self::WriteBytes { .. })
    }
}

/// What a node is to drive-io.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// The CiA 402 drive of cable `cable` (0-based).
    Drive { cable: usize },
    /// The force sensor of cable `cable` (0-based).
    ForceSensor { cable: usize },
}

impl std::fmt::Display for NodeKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Drive { .. } => "drive",
            Self::ForceSensor { .. } => "force sensor",
        })
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    #[error("{kind} node {node}: EDS {eds} lacks required object {object}{hint}")]
    Missing {
        kind: NodeKind,
        node: u8,
        eds: String,
        object: String,
        hint: String,
    },
    #[error("{kind} node {node}: EDS {eds}: {object} {reason}")]
    Unsuitable {
        kind: NodeKind,
        node: u8,
        eds: String,
        object: String,
        reason: String,
    },
    /// The PDO mapping cannot be built as drives.toml asks (`key` names the TOML key).
    #[error("{kind} node {node} ({key}): {reason} [EDS {eds}]")]
    Mapping {
        kind: NodeKind,
        node: u8,
        key: String,
        eds: String,
        reason: String,
    },
}

/// Planning the nodes (and so building drive-io's master) failed: an EDS cannot be read or does
/// not suit the configuration, or two nodes' TPDOs share a COB-ID on one interface.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error("EDS: {0}")]
    Eds(#[from] drive_bus::eds::EdsError),
    #[error(transparent)]
    Plan(#[from] PlanError),
    #[error("TPDO COB-ID 0x{cob_id:03X} is configured for node {a} and node {b} on one interface")]
    CobCollision { cob_id: u16, a: u8, b: u8 },
}

/// CiA 402 0x6007 abort connection option codes.
pub const ABORT_CONNECTION_NO_ACTION: i16 = 0;
pub const ABORT_CONNECTION_FAULT: i16 = 1;
pub const ABORT_CONNECTION_DISABLE_VOLTAGE: i16 = 2;
pub const ABORT_CONNECTION_QUICK_STOP: i16 = 3;
/// CiA 402 0x605A quick stop option code 6: slow down on the quick stop ramp and stay in
/// Quick Stop Active (the drive holds under control; the master decides what follows).
pub const QUICK_STOP_STAY: i16 = 6;
/// CiA 402 quick stop deceleration (counts/s²), the ramp of 0x605A = 6.
pub const OD_QUICK_STOP_DECELERATION: u16 = 0x6085;
/// CiA 402 interpolation time period: sub 1 value, sub 2 index (value · 10^index s).
pub const OD_INTERPOLATION_PERIOD: u16 = 0x60C2;
/// The simulated winch's force object (i32, mN).
pub const DEFAULT_FORCE_OBJECT: ObjectRef = ObjectRef {
    index: OD_PULLEY_FORCE_MN,
    sub: 0,
};
/// Default newtons per unit of the drive's force object (mN).
pub const DEFAULT_FORCE_N_PER_UNIT: f64 = 1e-3;
/// Default: velocity actual every 10th SYNC when it travels alone.
pub const DEFAULT_FEEDBACK_EVERY: u8 = 10;

/// The start-up script and PDO layout of one node.
#[derive(Debug, Clone)]
pub struct Plan {
    pub node: u8,
    pub kind: NodeKind,
    /// The TOML table it comes from, for messages (`winch[2]`, `force_sensor[0]`).
    pub key: String,
    pub eds: Arc<Eds>,
    /// Checks and writes in order, then the read-back of everything written.
    pub ops: Vec<SdoOp>,
    /// Byte strings of [`SdoOp::WriteBytes`] / [`SdoOp::VerifyBytes`].
    pub bytes: Vec<u8>,
    pub mapping: NodeMapping,
    frames: Vec<PdoFrame>,
}

impl Plan {
    /// The PDO frames this node's configuration produces (COB-ID, DLC, direction, every n-th
    /// SYNC or event-driven with its inhibit time; unused ones drive-io could not disable too).
    pub fn pdo_frames(&self) -> &[PdoFrame] {
        &self.frames
    }
    /// The bytes of a [`SdoOp::WriteBytes`] / [`SdoOp::VerifyBytes`].
    pub fn bytes(&self, at: u16, len: u16) -> &[u8] {
        let a = usize::from(at);
        self.bytes.get(a..a + usize::from(len)).unwrap_or(&[])
    }
    /// `(index, sub, value)` the node holds after the script (what its DCF records).
    pub fn configured_values(&self) -> Vec<(u16, u8, DcfValue)> {
        self.ops
            .iter()
            .filter_map(|op| match *op {
                SdoOp::Verify {
                    index, sub, value, ..
                } if index != OD_MODES_DISPLAY => Some((index, sub, DcfValue::Raw(value))),
                SdoOp::VerifyBytes {
                    index,
                    sub,
                    at,
                    len,
                    check: false,
                } => Some((index, sub, DcfValue::Bytes(self.bytes(at, len).to_vec()))),
                _ => None,
            })
            .collect()
    }
    /// The TOML key of a [`SdoOp::Check`] on `(index, sub)`.
    pub fn check_key(&self, index: u16, sub: u8) -> String {
        let k = match index {
            OD_AI_PHYSICAL_UNIT => "physical_unit",
            OD_AI_DECIMAL_DIGITS => "decimal_digits",
            _ => return format!("{}.identity.{}", self.key, Identity::key_of(index, sub)),
        };
        format!("{}.{k}", self.key)
    }
}

/// One PDO drive-io writes (default or custom mapping).
struct LayoutEntry {
    direction: Direction,
    number: u16,
    cob_id: u16,
    objects: Vec<ObjectRef>,
    transmission_type: u8,
    inhibit_us: Option<u32>,
    event_ms: Option<u16>,
}

struct Builder<'a> {
    eds: &'a Eds,
    node: u8,
    kind: NodeKind,
    key: String,
    ops: Vec<SdoOp>,
    verify: Vec<SdoOp>,
    bytes: Vec<u8>,
}

impl Builder<'_> {
    fn missing(&self, index: u16, sub: u8, hint: &str) -> PlanError {
        PlanError::Missing {
            kind: self.kind,
            node: self.node,
            eds: self.eds.file.clone(),
            object: format!("0x{index:04X}sub{sub}"),
            hint: hint.to_string(),
        }
    }
    fn unsuitable(&self, index: u16, sub: u8, reason: impl Into<String>) -> PlanError {
        PlanError::Unsuitable {
            kind: self.kind,
            node: self.node,
            eds: self.eds.file.clone(),
            object: self.eds.describe(index, sub),
            reason: reason.into(),
        }
    }
    fn mapping_error(&self, key: &str, reason: impl Into<String>) -> PlanError {
        PlanError::Mapping {
            kind: self.kind,
            node: self.node,
            key: format!("{}{key}", self.key),
            eds: self.eds.file.clone(),
            reason: reason.into(),
        }
    }
    fn entry(&self, index: u16, sub: u8) -> Result<&OdEntry, PlanError> {
        self.eds
            .entry(index, sub)
            .ok_or_else(|| self.missing(index, sub, ""))
    }
    fn verify_later(&mut self, op: SdoOp) {
        let is = op.index_sub();
        self.verify.retain(|v| v.index_sub() != is);
        self.verify.push(op);
    }
    /// Writes `value` (range-checked against the EDS); `verify` = read back afterwards.
    fn write(&mut self, index: u16, sub: u8, value: i64, verify: bool) -> Result<(), PlanError> {
        let e = self.entry(index, sub)?;
        if !e.access.writable() {
            return Err(self.unsuitable(index, sub, format!("is {:?}, not writable", e.access)));
        }
        let Some(len) = e.data_type.size() else {
            return Err(self.unsuitable(index, sub, "has no integer data type"));
        };
        // Unsigned32 COB-IDs / mapping entries are bit patterns; signed values are checked.
        if let Err(r) = e.check_range(value) {
            return Err(self.unsuitable(index, sub, format!("cannot take {r}")));
        }
        let value = value as u32;
        self.ops.push(SdoOp::Write {
            index,
            sub,
            value,
            len,
        });
        if verify {
            self.verify_later(SdoOp::Verify {
                index,
                sub,
                value,
                len,
            });
        }
        Ok(())
    }
    fn write_optional(&mut self, index: u16, sub: u8, value: i64) -> Result<bool, PlanError> {
        if self.eds.entry(index, sub).is_none() {
            return Ok(false);
        }
        self.write(index, sub, value, true)?;
        Ok(true)
    }
    /// Read-back only (a value the EDS fixes, checked to be there).
    fn verify_default(&mut self, index: u16, sub: u8) -> Result<u32, PlanError> {
        let e = self.entry(index, sub)?;
        let Some(len) = e.data_type.size() else {
            return Err(self.unsuitable(index, sub, "has no integer data type"));
        };
        if !e.access.readable() {
            return Err(self.unsuitable(index, sub, "is write-only"));
        }
        let value = e.default_for(self.node) as u32;
        self.verify_later(SdoOp::Verify {
            index,
            sub,
            value,
            len,
        });
        Ok(value)
    }
    fn add_bytes(&mut self, b: &[u8]) -> (u16, u16) {
        let at = self.bytes.len() as u16;
        self.bytes.extend_from_slice(b);
        (at, b.len() as u16)
    }

    /// Identity first: nothing is written before these pass.
    fn identity(&mut self, id: &Identity) -> Result<(), PlanError> {
        for c in id.checks() {
            let e = self.eds.entry(c.index, c.sub).ok_or_else(|| {
                self.missing(
                    c.index,
                    c.sub,
                    &format!(" (drives.toml {}.identity.{} checks it)", self.key, c.key),
                )
            })?;
            let len = e.data_type.size().unwrap_or(4);
            self.ops.push(SdoOp::Check {
                index: c.index,
                sub: c.sub,
                value: c.expected,
                len,
            });
        }
        match &id.device_name {
            Some(name) => {
                self.entry(OD_DEVICE_NAME, 0)?;
                let (at, len) = self.add_bytes(name.as_bytes());
                self.ops.push(SdoOp::VerifyBytes {
                    index: OD_DEVICE_NAME,
                    sub: 0,
                    at,
                    len,
                    check: true,
                });
            }
            None => {
                if self
                    .eds
                    .entry(OD_DEVICE_NAME, 0)
                    .is_some_and(|e| e.access.readable())
                {
                    self.ops.push(SdoOp::Read {
                        index: OD_DEVICE_NAME,
                        sub: 0,
                    });
                }
            }
        }
        // Hardware / software versions, for the log.
        for index in [0x1009, 0x100A] {
            if self
                .eds
                .entry(index, 0)
                .is_some_and(|e| e.access.readable())
            {
                self.ops.push(SdoOp::Read { index, sub: 0 });
            }
        }
        Ok(())
    }

    /// A mapped object as the EDS describes it (byte-sized, mappable in this direction).
    fn mappable(
        &self,
        o: ObjectRef,
        dir: Direction,
        role: Role,
        key: &str,
    ) -> Result<Mapped, PlanError> {
        let e = self
            .eds
            .entry(o.index, o.sub)
            .ok_or_else(|| self.missing(o.index, o.sub, ""))?;
        if !e.pdo_mappable {
            return Err(self.unsuitable(o.index, o.sub, "is not PDO-mappable (PDOMapping=0)"));
        }
        let Some(bytes) = e.data_type.size() else {
            return Err(self.unsuitable(o.index, o.sub, "has no integer data type"));
        };
        let bits = bytes * 8;
        let ok_dir = match dir {
            Direction::FromNode => e.access.readable(),
            Direction::ToNode => e.access.writable(),
        };
        if !ok_dir {
            return Err(self.unsuitable(
                o.index,
                o.sub,
                format!("access {:?} cannot be mapped", e.access),
            ));
        }
        let want_bits = match role {
            Role::Controlword | Role::Statusword => Some(16),
            Role::TargetPosition | Role::PositionActual | Role::VelocityActual => Some(32),
            _ => None,
        };
        if want_bits.is_some_and(|b| b != bits) {
            return Err(self.unsuitable(
                o.index,
                o.sub,
                format!("is not {} bits wide", want_bits.unwrap_or(0)),
            ));
        }
        if role == Role::Force && value_f64(e.data_type, 0).is_none() {
            return Err(self.unsuitable(o.index, o.sub, "is no number"));
        }
        if dir == Direction::ToNode && !matches!(role, Role::Controlword | Role::TargetPosition) {
            return Err(self.mapping_error(
                key,
                format!(
                    "RPDO object {o} is not one drive-io sends (controlword 0x6040, target \
                     position 0x607A)"
                ),
            ));
        }
        Ok(Mapped {
            index: o.index,
            sub: o.sub,
            bits,
            data_type: e.data_type,
            role,
        })
    }

    /// Writes one PDO: disable, clear the mapping, map, set the count, transmission type
    /// (inhibit time, event timer), enable.
    fn write_pdo(
        &mut self,
        p: &Pdo,
        inhibit_us: Option<u32>,
        event_ms: Option<u16>,
        tt: u8,
    ) -> Result<(), PlanError> {
        let (comm, map) = (p.comm_index(), p.map_index());
        let valid = i64::from(p.cob_id);
        self.write(comm, 1, valid | 0x8000_0000, false)?;
        self.write(map, 0, 0, false)?;
        for (k, m) in p.mapped().iter().enumerate() {
            self.write(map, k as u8 + 1, i64::from(m.entry()), true)?;
        }
        self.write(map, 0, p.count as i64, true)?;
        self.write(comm, 2, i64::from(tt), true)?;
        if let Some(us) = inhibit_us {
            self.write(comm, 3, i64::from(us / 100), true)?;
        }
        if let Some(ms) = event_ms {
            self.write(comm, 5, i64::from(ms), true)?;
        }
        self.write(comm, 1, valid, true)?;
        Ok(())
    }

    /// Every PDO of the EDS that is not in `used`: disabled where the COB-ID is writable;
    /// one that stays valid is listed as an unused frame (it loads the bus).
    fn disable_others(
        &mut self,
        used: &[(Direction, u16)],
        out: &mut Vec<Pdo>,
    ) -> Result<(), PlanError> {
        for (dir, base) in [
            (Direction::ToNode, 0x1400u16),
            (Direction::FromNode, 0x1800),
        ] {
            for n in 1..=512u16 {
                let comm = base + n - 1;
                let Some(e) = self.eds.entry(comm, 1) else {
                    continue;
                };
                if used.contains(&(dir, n)) {
                    continue;
                }
                let cob = e.default_for(self.node);
                if e.access.writable() {
                    self.write(comm, 1, (cob & 0x7FF) | 0x8000_0000, true)?;
                } else if cob & 0x8000_0000 == 0 && dir == Direction::FromNode {
                    let mut p = self.eds_pdo(dir, n)?;
                    p.used = false;
                    if let Transmission::Event { inhibit_us: 0, .. } = p.transmission {
                        return Err(self.unsuitable(
                            comm,
                            1,
                            "is a valid event-driven TPDO without inhibit time that drive-io \
                             cannot disable: its bus load is unbounded",
                        ));
                    }
                    out.push(p);
                }
            }
        }
        Ok(())
    }

    /// PDO `n` as the EDS defaults describe it (roles not yet assigned).
    fn eds_pdo(&self, dir: Direction, n: u16) -> Result<Pdo, PlanError> {
        let base = match dir {
            Direction::ToNode => 0x1400,
            Direction::FromNode => 0x1800,
        };
        let comm = base + n - 1;
        let map = comm + 0x200;
        let cob = self.entry(comm, 1)?.default_for(self.node);
        let default_of = |sub: u8, d: i64| {
            self.eds
                .entry(comm, sub)
                .map_or(d, |e| e.default_for(self.node))
        };
        let tt = default_of(2, 255) as u8;
        let inhibit_us = default_of(3, 0) as u32 * 100;
        let event_ms = default_of(5, 0) as u16;
        let transmission = Transmission::from_type(tt, inhibit_us, event_ms).ok_or_else(|| {
            self.unsuitable(comm, 2, format!("transmission type {tt} is reserved"))
        })?;
        let mut p = Pdo::new(dir, n, (cob & 0x7FF) as u16, transmission);
        let count = self
            .eds
            .entry(map, 0)
            .map_or(0, |e| e.default_for(self.node)) as usize;
        if count > MAX_MAPPED {
            return Err(self.unsuitable(
                map,
                0,
                format!("maps {count} objects (at most {MAX_MAPPED})"),
            ));
        }
        for k in 0..count {
            let raw = self.entry(map, k as u8 + 1)?.default_for(self.node) as u32;
            let (index, sub, bits) = ((raw >> 16) as u16, (raw >> 8) as u8, raw as u8);
            if bits % 8 != 0 {
                return Err(self.unsuitable(
                    map,
                    k as u8 + 1,
                    format!("maps {bits} bits of 0x{index:04X}sub{sub}: drive-io decodes whole bytes only"),
                ));
            }
            let data_type = self
                .eds
                .entry(index, sub)
                .map_or(DataType::Other(0), |e| e.data_type);
            p.entries[k] = Mapped {
                index,
                sub,
                bits,
                data_type,
                role: Role::Other,
            };
        }
        p.count = count;
        if cob & 0x8000_0000 != 0 {
            p.used = false;
        }
        Ok(p)
    }

    /// A fixed mapping: the EDS's PDOs carrying `roles`, checked by upload; COB-IDs enabled and
    /// transmission types set where the drive lets drive-io write them (`tt_of` per PDO).
    fn fixed(
        &mut self,
        assign: &dyn Fn(ObjectRef) -> Role,
        tt_of: &dyn Fn(&Pdo) -> u8,
    ) -> Result<Vec<Pdo>, PlanError> {
        let mut pdos = Vec::new();
        let mut covered: Vec<Role> = Vec::new();
        for (dir, base) in [
            (Direction::ToNode, 0x1400u16),
            (Direction::FromNode, 0x1800),
        ] {
            for n in 1..=512u16 {
                let comm = base + n - 1;
                let Some(cob_entry) = self.eds.entry(comm, 1) else {
                    continue;
                };
                let cob_writable = cob_entry.access.writable();
                let mut p = self.eds_pdo(dir, n)?;
                for m in &mut p.entries[..p.count] {
                    m.role = assign(ObjectRef {
                        index: m.index,
                        sub: m.sub,
                    });
                }
                let new_roles = p
                    .mapped()
                    .iter()
                    .any(|m| m.role != Role::Other && !covered.contains(&m.role));
                let enabled = cob_entry.default_for(self.node) & 0x8000_0000 == 0;
                if !new_roles || (!enabled && !cob_writable) {
                    continue;
                }
                let key = match dir {
                    Direction::ToNode => ".rpdo",
                    Direction::FromNode => ".tpdo",
                };
                for m in p.mapped() {
                    let o = ObjectRef {
                        index: m.index,
                        sub: m.sub,
                    };
                    if dir == Direction::ToNode && m.role == Role::Other {
                        return Err(self.mapping_error(
                            key,
                            format!(
                                "the fixed RPDO{n} also maps {o}, which drive-io does not send: \
                                 use mapping = \"default\" or \"custom\""
                            ),
                        ));
                    }
                    if m.role != Role::Other {
                        // Role objects must suit their use (width, direction).
                        self.mappable(o, dir, m.role, key)?;
                    }
                    if covered.contains(&m.role) && m.role != Role::Other {
                        return Err(self.mapping_error(
                            key,
                            format!("{o} is mapped twice in the fixed mapping"),
                        ));
                    }
                }
                covered.extend(
                    p.mapped()
                        .iter()
                        .map(|m| m.role)
                        .filter(|r| *r != Role::Other),
                );
                // The mapping as the drive holds it, checked by upload.
                let map = p.map_index();
                self.verify_default(map, 0)?;
                for k in 0..p.count {
                    self.verify_default(map, k as u8 + 1)?;
                }
                let tt = tt_of(&p);
                let tt_entry = self.eds.entry(comm, 2).map(|e| e.access.writable());
                if tt_entry == Some(true) {
                    self.write(comm, 2, i64::from(tt), true)?;
                    p.transmission = Transmission::from_type(tt, 0, 0).unwrap_or(p.transmission);
                } else if tt_entry == Some(false) {
                    self.verify_default(comm, 2)?;
                }
                if dir == Direction::ToNode && !matches!(p.transmission, Transmission::Sync { .. })
                {
                    return Err(self.unsuitable(
                        comm,
                        2,
                        "is not synchronous: a CSP set-point must act at the SYNC",
                    ));
                }
                if let Transmission::Event { inhibit_us: 0, .. } = p.transmission {
                    return Err(self.unsuitable(
                        comm,
                        2,
                        "is event-driven without inhibit time: its bus load is unbounded",
                    ));
                }
                if enabled {
                    self.verify_default(comm, 1)?;
                } else {
                    self.write(comm, 1, i64::from(p.cob_id), true)?;
                }
                p.used = true;
                pdos.push(p);
            }
        }
        Ok(pdos)
    }

    /// A written mapping (default or custom): builds and writes every PDO of `layout`.
    fn written(
        &mut self,
        layout: &[LayoutEntry],
        assign: &dyn Fn(ObjectRef) -> Role,
    ) -> Result<Vec<Pdo>, PlanError> {
        let mut pdos = Vec::new();
        for (k, e) in layout.iter().enumerate() {
            let (dir, n, cob, objects, tt, inhibit, event) = (
                &e.direction,
                &e.number,
                &e.cob_id,
                &e.objects,
                &e.transmission_type,
                &e.inhibit_us,
                &e.event_ms,
            );
            let key = match dir {
                Direction::ToNode => format!(".rpdo[{k}]"),
                Direction::FromNode => format!(".tpdo[{k}]"),
            };
            let transmission =
                Transmission::from_type(*tt, inhibit.unwrap_or(0), event.unwrap_or(0)).ok_or_else(
                    || self.mapping_error(&key, format!("transmission type {tt} is reserved")),
                )?;
            if *dir == Direction::ToNode && !matches!(transmission, Transmission::Sync { .. }) {
                return Err(self.mapping_error(
                    &key,
                    "an RPDO's transmission type must be 1..=240 (acted on at the SYNC)",
                ));
            }
            if let Transmission::Event { inhibit_us: 0, .. } = transmission {
                return Err(self.mapping_error(
                    &key,
                    "an event-driven TPDO needs inhibit_time_us > 0 (else its bus load is unbounded)",
                ));
            }
            if objects.len() > MAX_MAPPED {
                return Err(self.mapping_error(&key, format!("more than {MAX_MAPPED} objects")));
            }
            let mut p = Pdo::new(*dir, *n, *cob, transmission);
            for (j, o) in objects.iter().enumerate() {
                p.entries[j] = self.mappable(*o, *dir, assign(*o), &key)?;
            }
            p.count = objects.len();
            if p.dlc() > 8 {
                return Err(
                    self.mapping_error(&key, format!("{} bytes do not fit a CAN frame", p.dlc()))
                );
            }
            self.write_pdo(&p, *inhibit, *event, *tt)?;
            pdos.push(p);
        }
        Ok(pdos)
    }

    fn finish(self, mapping: NodeMapping) -> Plan {
        let mut ops = self.ops;
        ops.extend(self.verify);
        let frames = mapping.frames();
        Plan {
            node: self.node,
            kind: self.kind,
            key: self.key,
            eds: Arc::new(self.eds.clone()),
            ops,
            bytes: self.bytes,
            mapping,
            frames,
        }
    }
}

/// 0x60C2 for a period in µs: (value, index) with value · 10^index s, the coarsest exact one.
pub fn interpolation_period(period_us: u32) -> Option<(u8, i8)> {
    (-6i8..=0).rev().find_map(|idx| {
        let div = 10u64.pow((6 + i32::from(idx)) as u32);
        let v = u64::from(period_us);
        (v % div == 0 && (1..=255).contains(&(v / div))).then_some(((v / div) as u8, idx))
    })
}

/// The start-up script of drive `i` of `cfg` from its EDS: identity checks, PDOs, settings,
/// then the read-back of every value written and of 0x6061 == CSP. The error names drive, EDS
/// and object (or TOML key).
pub fn plan_drive(cfg: &DrivesConfig, i: usize, eds: &Eds) -> Result<Plan, PlanError> {
    let w = &cfg.winches[i];
    let n = w.node_id;
    let mut b = Builder {
        eds,
        node: n,
        kind: NodeKind::Drive { cable: i },
        key: format!("winch[{i}]"),
        ops: Vec::new(),
        verify: Vec::new(),
        bytes: Vec::new(),
    };
    b.identity(&w.identity)?;
    let own_force = cfg.force_sensor_of(i).is_none();
    let force_obj = own_force.then(|| w.force_object.unwrap_or(DEFAULT_FORCE_OBJECT));
    if let Some(o) = force_obj
        && eds.entry(o.index, o.sub).is_none()
    {
        return Err(b.missing(
            o.index,
            o.sub,
            &format!(
                " (the cable force, force = \"drive\"): configure a [[force_sensor]] for cable \
                 {} or the drive's force object (winch[{i}].force_object)",
                i + 1
            ),
        ));
    }
    let feedback_every =
        w.feedback_every_n_syncs
            .unwrap_or(if own_force { 1 } else { DEFAULT_FEEDBACK_EVERY });
    let mut pdos = drive_pdos(&mut b, w, force_obj, feedback_every)?;
    let used: Vec<(Direction, u16)> = pdos.iter().map(|p| (p.direction, p.number)).collect();
    check_roles(&b, &pdos, winch_mapping_mode(w), force_obj)?;
    b.disable_others(&used, &mut pdos)?;
    write_drive_settings(&mut b, &cfg.bus, w, eds)?;
    write_parameters(&mut b, w)?;
    b.write(OD_MODES_OF_OPERATION, 0, i64::from(MODE_CSP), true)?;
    b.entry(OD_MODES_DISPLAY, 0)?;
    b.verify.push(SdoOp::Verify {
        index: OD_MODES_DISPLAY,
        sub: 0,
        value: u32::from(MODE_CSP as u8),
        len: 1,
    });
    let n_per_unit = w.force_n_per_unit.unwrap_or(DEFAULT_FORCE_N_PER_UNIT);
    Ok(b.finish(NodeMapping {
        node: n,
        pdos,
        force_n_per_unit: n_per_unit,
    }))
}

/// The PDOs of drive `w` as its mapping mode asks: drive-io's default layout, the
/// custom `[[winch.rpdo]]` / `[[winch.tpdo]]` lists (both written), or the EDS's fixed mapping.
fn drive_pdos(
    b: &mut Builder<'_>,
    w: &WinchConfig,
    force_obj: Option<ObjectRef>,
    feedback_every: u8,
) -> Result<Vec<Pdo>, PlanError> {
    let n = w.node_id;
    let assign = |o: ObjectRef| drive_role(o, force_obj);
    let pdos = match winch_mapping_mode(w) {
        MappingMode::Default => {
            let layout: Vec<_> = default_drive_layout(force_obj, feedback_every)
                .into_iter()
                .map(|p| LayoutEntry {
                    direction: p.direction,
                    number: p.number,
                    cob_id: p.cob_base + u16::from(n),
                    objects: p.objects,
                    transmission_type: p.transmission_type,
                    inhibit_us: None,
                    event_ms: None,
                })
                .collect();
            b.written(&layout, &assign)?
        }
        MappingMode::Custom => {
            let mut layout = Vec::new();
            for (dir, list) in [(Direction::ToNode, &w.rpdo), (Direction::FromNode, &w.tpdo)] {
                for p in list {
                    let cob = p
                        .cob_id
                        .or_else(|| predefined_cob_base(dir, p.number).map(|c| c + u16::from(n)))
                        .unwrap_or(0);
                    layout.push(LayoutEntry {
                        direction: dir,
                        number: p.number,
                        cob_id: cob,
                        objects: p.objects.clone(),
                        transmission_type: p.transmission_type.unwrap_or(1),
                        inhibit_us: p.inhibit_time_us,
                        event_ms: p.event_timer_ms,
                    });
                }
            }
            b.written(&layout, &assign)?
        }
        MappingMode::Fixed => {
            let tt_of = |p: &Pdo| -> u8 {
                let only_velocity = p.has(Role::VelocityActual)
                    && !p.has(Role::Statusword)
                    && !p.has(Role::PositionActual)
                    && !p.has(Role::Force);
                if only_velocity { feedback_every } else { 1 }
            };
            b.fixed(&assign, &tt_of)?
        }
    };
    Ok(pdos)
}

/// Every role drive-io needs, exactly once, among the used PDOs.
fn check_roles(
    b: &Builder<'_>,
    pdos: &[Pdo],
    mode: MappingMode,
    force_obj: Option<ObjectRef>,
) -> Result<(), PlanError> {
    let needed: &[(Role, &str)] = &[
        (Role::Controlword, "controlword 0x6040 in an RPDO"),
        (Role::TargetPosition, "target position 0x607A in an RPDO"),
        (Role::Statusword, "statusword 0x6041 in a TPDO"),
        (Role::PositionActual, "position actual 0x6064 in a TPDO"),
        (Role::VelocityActual, "velocity actual 0x606C in a TPDO"),
    ];
    let mut needed: Vec<(Role, String)> = needed.iter().map(|(r, s)| (*r, s.to_string())).collect();
    if let Some(o) = force_obj {
        needed.push((Role::Force, format!("the cable force {o} in a TPDO")));
    }
    for (role, what) in &needed {
        let count: usize = pdos
            .iter()
            .filter(|p| p.used)
            .map(|p| p.mapped().iter().filter(|m| m.role == *role).count())
            .sum();
        if count != 1 {
            let key = match mode {
                MappingMode::Fixed => ".mapping",
                _ => ".tpdo",
            };
            return Err(b.mapping_error(
                key,
                format!("the {mode:?} mapping must carry {what} exactly once (found {count})")
                    .to_lowercase(),
            ));
        }
    }
    Ok(())
}

/// SYNC consumer, heartbeats, the CiA 402 option codes, the quick stop deceleration, the
/// interpolation period and the limits the drive supports (in its units).
fn write_drive_settings(
    b: &mut Builder<'_>,
    bus: &BusConfig,
    w: &WinchConfig,
    eds: &Eds,
) -> Result<(), PlanError> {
    // SYNC consumer (bit 30 clear: the drive does not produce SYNC).
    b.write_optional(0x1005, 0, i64::from(COB_SYNC))?;
    b.write_optional(0x1006, 0, i64::from(bus.sync_period_us))?;
    if bus.drive_consumer_ms() > 0 {
        // The drive watches drive-io's heartbeat: lost => 0x6007 action (CiA 301 §7.2.8.3.2.2).
        let v = (u32::from(bus.master_node_id) << 16) | u32::from(bus.drive_consumer_ms());
        b.write(0x1016, 1, i64::from(v), true)?;
    }
    b.write(
        OD_PRODUCER_HEARTBEAT_MS,
        0,
        i64::from(bus.heartbeat_producer_ms),
        true,
    )?;
    b.write(
        OD_ABORT_CONNECTION,
        0,
        i64::from(bus.abort_connection_option),
        true,
    )?;
    b.write(OD_QUICK_STOP_OPTION, 0, i64::from(QUICK_STOP_STAY), true)?;
    // 0x605A = 6 ramps down on 0x6085: the configured cable deceleration in counts/s².
    let decel = (bus.quick_stop_deceleration_m_per_s2 * w.counts_per_m()).round();
    if !(decel.is_finite() && decel >= 1.0 && decel <= f64::from(u32::MAX)) {
        return Err(b.unsuitable(
            OD_QUICK_STOP_DECELERATION,
            0,
            format!("cannot take bus.quick_stop_deceleration_m_per_s2 as {decel} counts/s²"),
        ));
    }
    b.write(OD_QUICK_STOP_DECELERATION, 0, decel as i64, true)?;
    // CSP interpolates between SYNCs over this period: the SYNC period (CiA 402 0x60C2).
    if eds.entry(OD_INTERPOLATION_PERIOD, 1).is_some() {
        let Some((value, index)) = interpolation_period(bus.sync_period_us) else {
            return Err(b.unsuitable(
                OD_INTERPOLATION_PERIOD,
                1,
                format!(
                    "cannot express bus.sync_period_us = {} as value · 10^index s",
                    bus.sync_period_us
                ),
            ));
        };
        b.write(OD_INTERPOLATION_PERIOD, 1, i64::from(value), true)?;
        b.write(OD_INTERPOLATION_PERIOD, 2, i64::from(index), true)?;
    }
    // Limits the drive supports, in its units (counts, counts/s).
    let lo = w.length_to_counts(0.0);
    let hi = w.length_to_counts(w.max_cable_length_m);
    if let (Some(a), Some(c)) = (lo, hi)
        && eds.entry(OD_SOFTWARE_POSITION_LIMIT, 1).is_some()
    {
        b.write(OD_SOFTWARE_POSITION_LIMIT, 1, i64::from(a.min(c)), true)?;
        b.write(OD_SOFTWARE_POSITION_LIMIT, 2, i64::from(a.max(c)), true)?;
    }
    let vmax = (bus.max_cable_speed_m_per_s * w.counts_per_m()).round();
    if vmax.is_finite() && vmax <= f64::from(u32::MAX) {
        b.write_optional(OD_MAX_PROFILE_VELOCITY, 0, vmax as i64)?;
    }
    let window = (bus.following_error_window_m * w.counts_per_m()).round();
    if window.is_finite() && window <= f64::from(u32::MAX) {
        b.write_optional(OD_FOLLOWING_ERROR_WINDOW, 0, window as i64)?;
    }
    Ok(())
}

/// The vendor parameters of `w` (`[[winch]] parameters`): integers written and verified,
/// texts written as bytes (segmented beyond 4) and read back where readable.
fn write_parameters(b: &mut Builder<'_>, w: &WinchConfig) -> Result<(), PlanError> {
    for p in &w.parameters {
        let o = p.object;
        match &p.value {
            ParameterValue::Integer(v) => b.write(o.index, o.sub, *v, true)?,
            ParameterValue::Text(t) => {
                let e = b.entry(o.index, o.sub)?;
                let (access, data_type) = (e.access, e.data_type);
                if !access.writable() {
                    return Err(b.unsuitable(
                        o.index,
                        o.sub,
                        format!("is {access:?}, not writable"),
                    ));
                }
                let bytes = match data_type {
                    t2 if t2.is_string() => t2.text_bytes(t),
                    _ => None,
                }
                .ok_or_else(|| {
                    b.unsuitable(o.index, o.sub, format!("cannot take the text `{t}`"))
                })?;
                let (at, len) = b.add_bytes(&bytes);
                b.ops.push(SdoOp::WriteBytes {
                    index: o.index,
                    sub: o.sub,
                    at,
                    len,
                });
                if access.readable() {
                    b.verify.push(SdoOp::VerifyBytes {
                        index: o.index,
                        sub: o.sub,
                        at,
                        len,
                        check: false,
                    });
                }
            }
        }
    }
    Ok(())
}

/// The start-up script of force sensor `j` of `cfg`: identity (and unit) checks, the TPDO
/// carrying the measured value every n-th SYNC (other TPDOs disabled), SYNC consumer,
/// heartbeat; then the read-back.
pub fn plan_force_sensor(cfg: &DrivesConfig, j: usize, eds: &Eds) -> Result<Plan, PlanError> {
    let s: &ForceSensorConfig = &cfg.force_sensors[j];
    let n = s.node_id;
    let mut b = Builder {
        eds,
        node: n,
        kind: NodeKind::ForceSensor { cable: s.cable - 1 },
        key: format!("force_sensor[{j}]"),
        ops: Vec::new(),
        verify: Vec::new(),
        bytes: Vec::new(),
    };
    b.identity(&s.identity)?;
    let ch = s.object.sub;
    for (index, v, key) in [
        (OD_AI_PHYSICAL_UNIT, s.physical_unit, "physical_unit"),
        (
            OD_AI_DECIMAL_DIGITS,
            s.decimal_digits.map(u32::from),
            "decimal_digits",
        ),
    ] {
        if let Some(v) = v {
            let e = b.eds.entry(index, ch).ok_or_else(|| {
                b.missing(
                    index,
                    ch,
                    &format!(" (drives.toml force_sensor[{j}].{key} checks it)"),
                )
            })?;
            let len = e.data_type.size().unwrap_or(4);
            b.ops.push(SdoOp::Check {
                index,
                sub: ch,
                value: v,
                len,
            });
        }
    }
    let object = s.object;
    let assign = move |o: ObjectRef| {
        if o == object {
            Role::Force
        } else {
            Role::Other
        }
    };
    let pdos = match s.mapping {
        MappingMode::Fixed => b.fixed(&assign, &|_| s.every_n_syncs)?,
        _ => {
            let cob = s
                .cob_id
                .or_else(|| {
                    predefined_cob_base(Direction::FromNode, s.tpdo).map(|c| c + u16::from(n))
                })
                .unwrap_or(0);
            b.written(
                &[LayoutEntry {
                    direction: Direction::FromNode,
                    number: s.tpdo,
                    cob_id: cob,
                    objects: vec![object],
                    transmission_type: s.every_n_syncs,
                    inhibit_us: None,
                    event_ms: None,
                }],
                &assign,
            )?
        }
    };
    let force_pdos = pdos.iter().filter(|p| p.used && p.has(Role::Force)).count();
    if force_pdos != 1 {
        return Err(b.mapping_error(
            ".object",
            format!("{object} must be in exactly one enabled TPDO of the fixed mapping (found {force_pdos})"),
        ));
    }
    let mut pdos: Vec<Pdo> = pdos
        .into_iter()
        .filter(|p| p.direction == Direction::FromNode)
        .collect();
    let used: Vec<(Direction, u16)> = pdos.iter().map(|p| (p.direction, p.number)).collect();
    // Only TPDOs load the bus: the sensor's RPDOs, if any, are left as they are.
    let mut others = Vec::new();
    b.disable_others(&used, &mut others)?;
    pdos.extend(
        others
            .into_iter()
            .filter(|p| p.direction == Direction::FromNode),
    );
    b.write_optional(0x1005, 0, i64::from(COB_SYNC))?;
    b.write(
        OD_PRODUCER_HEARTBEAT_MS,
        0,
        i64::from(cfg.bus.heartbeat_producer_ms),
        true,
    )?;
    Ok(b.finish(NodeMapping {
        node: n,
        pdos,
        force_n_per_unit: s.n_per_unit,
    }))
}

/// The plans of every node of `cfg`: the drives in cable order, then the force sensors. Each
/// EDS is read once per path. `drive_eds` overrides every drive's EDS (tests).
pub fn plan_all(cfg: &DrivesConfig, drive_eds: Option<&Eds>) -> Result<Vec<Plan>, SetupError> {
    let mut cache: Vec<(Option<String>, Eds)> = Vec::new();
    let mut plans = Vec::new();
    for i in 0..cfg.winches.len() {
        let plan = match drive_eds {
            Some(e) => plan_drive(cfg, i, e)?,
            None => {
                let path = cfg.winches[i].eds.clone().or_else(|| cfg.bus.eds.clone());
                let eds = match cache.iter().find(|(p, _)| *p == path) {
                    Some((_, e)) => e,
                    None => {
                        cache.push((path, cfg.load_winch_eds(i)?));
                        &cache[cache.len() - 1].1
                    }
                };
                plan_drive(cfg, i, eds)?
            }
        };
        plans.push(plan);
    }
    for j in 0..cfg.force_sensors.len() {
        let eds = cfg.load_sensor_eds(j)?;
        plans.push(plan_force_sensor(cfg, j, &eds)?);
    }
    Ok(plans)
}

#[cfg(test)]
mod tests {
    use super::*;
    use drives_config::DrivesConfig;

    fn cfg() -> DrivesConfig {
        DrivesConfig::parse(
            "[bus]\ntransport = \"udpbus:239.255.70.1:20000\"\n[[winch]]\nnode_id = 3\n\
             drum_diameter_m = 0.305\ngear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = -1\n\
             max_cable_length_m = 20.0\n",
        )
        .unwrap()
    }

    fn writes(p: &Plan) -> Vec<(u16, u8, u32)> {
        p.ops
            .iter()
            .filter_map(|o| match *o {
                SdoOp::Write {
                    index, sub, value, ..
                } => Some((index, sub, value)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn plan_maps_pdos_in_the_cia301_order_and_verifies_everything() {
        let c = cfg();
        let plan = plan_drive(&c, 0, Eds::builtin_winch()).unwrap();
        let ops = &plan.ops;
        let writes = writes(&plan);
        // RPDO1: disable, clear, map, count, type, enable.
        assert_eq!(
            &writes[..6],
            &[
                (0x1400, 1, 0x8000_0203),
                (0x1600, 0, 0),
                (0x1600, 1, 0x6040_0010),
                (0x1600, 2, 0x607A_0020),
                (0x1600, 0, 2),
                (0x1400, 2, 1),
            ]
        );
        assert!(writes.contains(&(0x1400, 1, 0x203)));
        // The simulated winch measures the force itself: TPDO2 = velocity + force, every SYNC.
        assert!(writes.contains(&(0x1A01, 2, 0x2110_0020)));
        assert!(writes.contains(&(0x1801, 2, 1)));
        assert!(writes.contains(&(0x1401, 1, 0x8000_0303)));
        assert!(writes.contains(&(0x6007, 0, 2)));
        assert!(writes.contains(&(0x605A, 0, 6)));
        // 14 m/s² in counts/s².
        let decel = (14.0 * c.winches[0].counts_per_m()).round() as u32;
        assert!(writes.contains(&(0x6085, 0, decel)));
        // 1 ms = 1 · 10^-3 s.
        assert!(writes.contains(&(0x60C2, 1, 1)));
        assert!(writes.contains(&(0x60C2, 2, (-3i32) as u32)));
        // Default consumer time: twice heartbeat_timeout_ms (default 100 ms).
        assert!(writes.contains(&(0x1016, 1, (0x7F << 16) | 200)));
        // sign -1: the limits swap; the length range maps to [-max, 0] counts.
        let max = c.winches[0].length_to_counts(20.0).unwrap();
        assert!(writes.contains(&(0x607D, 1, max as u32)));
        assert!(writes.contains(&(0x607D, 2, 0)));
        // Every value that stays is read back; the temporary ones (disabled COB-ID) are not.
        let verified: Vec<(u16, u8)> = ops
            .iter()
            .filter(|o| matches!(o, SdoOp::Verify { .. }))
            .map(SdoOp::index_sub)
            .collect();
        assert!(verified.contains(&(0x1400, 1)));
        assert!(verified.contains(&(0x6061, 0)));
        let v1400: Vec<_> = ops
            .iter()
            .filter(|o| {
                matches!(
                    o,
                    SdoOp::Verify {
                        index: 0x1400,
                        sub: 1,
                        ..
                    }
                )
            })
            .collect();
        assert_eq!(v1400.len(), 1);
        assert!(matches!(v1400[0], SdoOp::Verify { value: 0x203, .. }));
        // The frames for the bus budget: RPDO1 6 B, TPDO1 6 B, TPDO2 8 B, all every SYNC.
        let f: Vec<(u16, u8, Direction, Transmission)> = plan
            .pdo_frames()
            .iter()
            .map(|f| (f.cob_id, f.dlc, f.direction, f.transmission))
            .collect();
        let every = Transmission::Sync { every: 1 };
        assert_eq!(
            f,
            vec![
                (0x203, 6, Direction::ToNode, every),
                (0x183, 6, Direction::FromNode, every),
                (0x283, 8, Direction::FromNode, every),
            ]
        );
        // The built-in EDS's device name is read for the log.
        assert!(ops.contains(&SdoOp::Read {
            index: 0x1008,
            sub: 0
        }));
    }

    #[test]
    fn missing_or_unmappable_objects_name_drive_eds_and_object() {
        let c = cfg();
        let text = drive_bus::eds::BUILTIN_WINCH_EDS.replace("[6007]", "[2FF7]");
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan_drive(&c, 0, &eds).unwrap_err().to_string();
        assert!(
            e.contains("node 3") && e.contains("vendor.eds") && e.contains("0x6007"),
            "{e}"
        );
        // Pulley force not mappable: refused before anything is written.
        let text = drive_bus::eds::BUILTIN_WINCH_EDS.replace(
            "ParameterName=Pulley force (mN)\nObjectType=0x7\nDataType=0x0004\nAccessType=ro\nDefaultValue=0\nPDOMapping=1",
            "ParameterName=Pulley force (mN)\nObjectType=0x7\nDataType=0x0004\nAccessType=ro\nDefaultValue=0\nPDOMapping=0",
        );
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan_drive(&c, 0, &eds).unwrap_err().to_string();
        assert!(
            e.contains("0x2110") && e.contains("not PDO-mappable"),
            "{e}"
        );
        // No force object at all and no force sensor: the message says what to configure.
        let text = drive_bus::eds::BUILTIN_WINCH_EDS.replace("[2110]", "[2111]");
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan_drive(&c, 0, &eds).unwrap_err().to_string();
        assert!(
            e.contains("0x2110sub0") && e.contains("[[force_sensor]]"),
            "{e}"
        );
        // A limit outside the EDS range is refused with the reason.
        let mut c2 = c.clone();
        c2.bus.abort_connection_option = 3;
        let text = drive_bus::eds::BUILTIN_WINCH_EDS
            .replace("LowLimit=0\nHighLimit=3", "LowLimit=0\nHighLimit=1");
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan_drive(&c2, 0, &eds).unwrap_err().to_string();
        assert!(e.contains("0x6007") && e.contains("HighLimit"), "{e}");
    }

    #[test]
    fn interpolation_period_is_the_coarsest_exact_coding() {
        assert_eq!(interpolation_period(1000), Some((1, -3)));
        assert_eq!(interpolation_period(250), Some((25, -5)));
        assert_eq!(interpolation_period(2500), Some((25, -4)));
        assert_eq!(interpolation_period(100_000), Some((1, -1)));
        assert_eq!(interpolation_period(257), None);
    }
}
