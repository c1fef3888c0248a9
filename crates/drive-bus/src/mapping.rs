//! PDO mappings: which objects travel in which PDO of a node, how drive-io encodes its RPDOs
//! and decodes the TPDOs from that mapping (never from fixed offsets, COB-IDs or lengths), and
//! the frames each node puts on the bus ([`PdoFrame`], for the bus budget).
//!
//! The mapping of a node comes from drives.toml and its EDS (`drive_commissioning::commissioning`):
//! `mapping = "default"` (drive-io writes its CSP mapping, [`default_drive_layout`]),
//! `"fixed"` (adopted as the EDS defaults say, checked by SDO upload) or `"custom"` (the
//! `[[winch.rpdo]]` / `[[winch.tpdo]]` lists, written by drive-io). The types here hold the
//! result; nothing here does I/O or allocates per frame.

use crate::canopen::*;
use crate::eds::DataType;
use can_transport::CanFrame;
use serde::Deserialize;

/// An object (index and sub-index) named in drives.toml: an integer (`0x6041`, sub-index 0)
/// or a string in the EDS spelling (`"0x2110sub0"`, `"9130sub1"`) or `"0x9130:1"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(try_from = "ObjectRefText")]
pub struct ObjectRef {
    pub index: u16,
    pub sub: u8,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ObjectRefText {
    Index(i64),
    Text(String),
}

impl TryFrom<ObjectRefText> for ObjectRef {
    type Error = String;
    fn try_from(t: ObjectRefText) -> Result<Self, String> {
        match t {
            ObjectRefText::Index(i) => u16::try_from(i)
                .map(|index| ObjectRef { index, sub: 0 })
                .map_err(|_| format!("object index {i} is not 0..=0xFFFF")),
            ObjectRefText::Text(s) => s.parse(),
        }
    }
}

impl std::str::FromStr for ObjectRef {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad =
            || format!("`{s}`: expected an object like 0x6041, \"0x2110sub0\" or \"0x9130:1\"");
        let t = s.trim().to_ascii_lowercase();
        let t = t.strip_prefix("0x").unwrap_or(&t);
        let (i, sub) = match t.split_once("sub").or_else(|| t.split_once(':')) {
            Some((i, s)) => (i, Some(s.strip_prefix("0x").unwrap_or(s))),
            None => (t, None),
        };
        let index = u16::from_str_radix(i, 16).map_err(|_| bad())?;
        let sub = match sub {
            Some(s) => u8::from_str_radix(s, 16).map_err(|_| bad())?,
            None => 0,
        };
        Ok(Self { index, sub })
    }
}

impl std::fmt::Display for ObjectRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "0x{:04X}sub{}", self.index, self.sub)
    }
}

/// How a node's PDOs are set up (`mapping` in `[[winch]]` / `[[force_sensor]]`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MappingMode {
    /// drive-io writes its own mapping (the drive must allow it: mapping objects writable).
    #[default]
    Default,
    /// The drive's mapping as its EDS defaults say (drives with fixed mappings), checked by
    /// SDO upload; drive-io only sets transmission types where the drive lets it.
    Fixed,
    /// drive-io writes the `[[winch.rpdo]]` / `[[winch.tpdo]]` lists.
    Custom,
}

/// One PDO of a custom mapping (`[[winch.rpdo]]`, `[[winch.tpdo]]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PdoSpec {
    /// PDO number, 1-based: RPDO n is 0x1400/0x1600 + n − 1, TPDO n is 0x1800/0x1A00 + n − 1.
    pub number: u16,
    /// The mapped objects in frame order.
    pub objects: Vec<ObjectRef>,
    /// COB-ID (11 bit). Default: the predefined connection set for PDOs 1-4.
    #[serde(default)]
    pub cob_id: Option<u16>,
    /// CiA 301 transmission type: 1-240 = every n-th SYNC (RPDO: acted on at the next SYNC),
    /// 254/255 = event-driven (TPDOs only). Default 1.
    #[serde(default)]
    pub transmission_type: Option<u8>,
    /// Event-driven TPDO: shortest time between two frames, µs (a multiple of 100, 0x18xx sub 3).
    #[serde(default)]
    pub inhibit_time_us: Option<u32>,
    /// Event-driven TPDO: sent at least this often, ms (0x18xx sub 5; 0 = off).
    #[serde(default)]
    pub event_timer_ms: Option<u16>,
}

/// What drive-io does with a mapped object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Controlword,
    TargetPosition,
    Statusword,
    PositionActual,
    VelocityActual,
    /// The cable force (the drive's force object or a force sensor's measured value).
    Force,
    /// Mapped but not used by drive-io (skipped when decoding).
    Other,
}

/// One mapped object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mapped {
    pub index: u16,
    pub sub: u8,
    pub bits: u8,
    pub data_type: DataType,
    pub role: Role,
}

impl Mapped {
    /// The CiA 301 mapping entry (index << 16 | sub << 8 | bits).
    pub fn entry(&self) -> u32 {
        (u32::from(self.index) << 16) | (u32::from(self.sub) << 8) | u32::from(self.bits)
    }
}

/// Direction of a PDO, seen from drive-io.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// RPDO of the node: drive-io sends it.
    ToNode,
    /// TPDO of the node: drive-io receives it.
    FromNode,
}

/// When a PDO is on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmission {
    /// Once every `every` SYNCs (TPDO transmission type 1-240; drive-io's RPDOs: every cycle).
    Sync { every: u8 },
    /// On change (transmission type 254/255), at most once per inhibit time (µs), at least
    /// once per event timer (ms, 0 = off).
    Event {
        inhibit_us: u32,
        event_timer_ms: u16,
    },
}

impl Transmission {
    /// From a CiA 301 transmission type (0 = acyclic synchronous: at most once per SYNC).
    pub fn from_type(t: u8, inhibit_us: u32, event_timer_ms: u16) -> Option<Self> {
        match t {
            0 => Some(Self::Sync { every: 1 }),
            1..=240 => Some(Self::Sync { every: t }),
            254 | 255 => Some(Self::Event {
                inhibit_us,
                event_timer_ms,
            }),
            _ => None,
        }
    }
}

/// Largest number of objects in one PDO (8 bytes of 8-bit objects).
pub const MAX_MAPPED: usize = 8;

/// A PDO of a node as configured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pdo {
    pub direction: Direction,
    /// 1-based PDO number.
    pub number: u16,
    pub cob_id: u16,
    pub transmission: Transmission,
    pub count: usize,
    pub entries: [Mapped; MAX_MAPPED],
    /// drive-io sends or reads it (false: a PDO the node keeps producing that drive-io could not
    /// disable; it still loads the bus).
    pub used: bool,
}

impl Pdo {
    pub fn new(direction: Direction, number: u16, cob_id: u16, transmission: Transmission) -> Self {
        Self {
            direction,
            number,
            cob_id,
            transmission,
            count: 0,
            entries: [Mapped {
                index: 0,
                sub: 0,
                bits: 0,
                data_type: DataType::Unsigned8,
                role: Role::Other,
            }; MAX_MAPPED],
            used: true,
        }
    }
    pub fn mapped(&self) -> &[Mapped] {
        &self.entries[..self.count]
    }
    /// Frame length (bytes).
    pub fn dlc(&self) -> u8 {
        let bits: u32 = self.mapped().iter().map(|m| u32::from(m.bits)).sum();
        bits.div_ceil(8) as u8
    }
    /// The communication parameter object (0x1400/0x1800 + n − 1).
    pub fn comm_index(&self) -> u16 {
        match self.direction {
            Direction::ToNode => 0x1400 + self.number - 1,
            Direction::FromNode => 0x1800 + self.number - 1,
        }
    }
    /// The mapping parameter object (0x1600/0x1A00 + n − 1).
    pub fn map_index(&self) -> u16 {
        self.comm_index() + 0x200
    }
    pub fn has(&self, role: Role) -> bool {
        self.mapped().iter().any(|m| m.role == role)
    }
    /// The RPDO carrying `controlword` and `target_counts` where they are mapped (other
    /// entries are refused when the mapping is built, so none is left unset).
    pub fn encode(&self, controlword: u16, target_counts: i32) -> CanFrame {
        let mut d = [0u8; 8];
        let mut at = 0usize;
        for m in self.mapped() {
            let n = usize::from(m.bits / 8);
            match m.role {
                Role::Controlword => d[at..at + 2].copy_from_slice(&controlword.to_le_bytes()),
                Role::TargetPosition => d[at..at + 4].copy_from_slice(&target_counts.to_le_bytes()),
                _ => {}
            }
            at += n;
        }
        CanFrame::new_std_lossy(self.cob_id, &d[..usize::from(self.dlc())])
    }
    /// Decodes a received TPDO into `out`; false (nothing taken) if it is shorter than the
    /// mapping (CiA 301: such a PDO is not processed).
    pub fn decode(&self, data: &[u8], out: &mut Decoded) -> bool {
        if data.len() < usize::from(self.dlc()) {
            return false;
        }
        let mut at = 0usize;
        for m in self.mapped() {
            let n = usize::from(m.bits / 8);
            let mut b = [0u8; 4];
            let k = n.min(4);
            b[..k].copy_from_slice(&data[at..at + k]);
            let raw = u32::from_le_bytes(b);
            match m.role {
                Role::Statusword => out.statusword = Some(raw as u16),
                Role::PositionActual => out.position = Some(raw as i32),
                Role::VelocityActual => out.velocity = Some(raw as i32),
                Role::Force => out.force = value_f64(m.data_type, raw),
                _ => {}
            }
            at += n;
        }
        true
    }
}

/// A value of an integer or REAL32 object as f64 (None for other types).
pub fn value_f64(t: DataType, raw: u32) -> Option<f64> {
    match t {
        DataType::Real32 => Some(f64::from(f32::from_bits(raw))),
        t if t.size().is_some() => Some(t.to_i64(raw) as f64),
        _ => None,
    }
}

/// What one TPDO carried.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Decoded {
    pub statusword: Option<u16>,
    pub position: Option<i32>,
    pub velocity: Option<i32>,
    /// In the object's own unit (scaled by [`NodeMapping::force_n_per_unit`]).
    pub force: Option<f64>,
}

/// A frame a node's configuration puts on the bus (for the bus budget).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoFrame {
    pub node: u8,
    pub cob_id: u16,
    pub dlc: u8,
    pub direction: Direction,
    pub transmission: Transmission,
    /// false: a PDO drive-io does not use but could not disable (it still loads the bus).
    pub used: bool,
}

/// All PDOs of one node.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeMapping {
    pub node: u8,
    pub pdos: Vec<Pdo>,
    /// Newtons per unit of the [`Role::Force`] object.
    pub force_n_per_unit: f64,
}

impl NodeMapping {
    pub fn rpdos(&self) -> impl Iterator<Item = &Pdo> {
        self.pdos
            .iter()
            .filter(|p| p.used && p.direction == Direction::ToNode)
    }
    /// The used TPDO with this COB-ID.
    pub fn tpdo(&self, cob_id: u16) -> Option<&Pdo> {
        self.pdos
            .iter()
            .find(|p| p.used && p.direction == Direction::FromNode && p.cob_id == cob_id)
    }
    /// The frames of this node's PDOs.
    pub fn frames(&self) -> Vec<PdoFrame> {
        self.pdos
            .iter()
            .map(|p| PdoFrame {
                node: self.node,
                cob_id: p.cob_id,
                dlc: p.dlc(),
                direction: p.direction,
                transmission: p.transmission,
                used: p.used,
            })
            .collect()
    }
    /// The PDO and entry that carry `role`.
    pub fn find(&self, role: Role) -> Option<(&Pdo, &Mapped)> {
        self.pdos
            .iter()
            .filter(|p| p.used)
            .find_map(|p| p.mapped().iter().find(|m| m.role == role).map(|m| (p, m)))
    }
}

/// The role of `object` in a drive's PDOs (`force` = the configured force object, if the
/// drive measures the force itself).
pub fn drive_role(object: ObjectRef, force: Option<ObjectRef>) -> Role {
    if Some(object) == force {
        return Role::Force;
    }
    match (object.index, object.sub) {
        (OD_CONTROLWORD, 0) => Role::Controlword,
        (OD_TARGET_POSITION, 0) => Role::TargetPosition,
        (OD_STATUSWORD, 0) => Role::Statusword,
        (OD_POSITION_ACTUAL, 0) => Role::PositionActual,
        (OD_VELOCITY_ACTUAL, 0) => Role::VelocityActual,
        _ => Role::Other,
    }
}

/// A PDO of drive-io's default CSP layout: number, COB-ID base (+ node id), objects.
pub struct LayoutPdo {
    pub direction: Direction,
    pub number: u16,
    pub cob_base: u16,
    pub objects: Vec<ObjectRef>,
    pub transmission_type: u8,
}

/// drive-io's default CSP mapping (docs/can-protocol.md), sized for the bus budget:
/// RPDO1 = controlword + target position (6 B, every SYNC); TPDO1 = statusword + position
/// actual (6 B, every SYNC); TPDO2 = velocity actual (+ the drive's force object where the
/// drive measures the cable force, then 8 B) every `feedback_every_n_syncs`-th SYNC.
pub fn default_drive_layout(force: Option<ObjectRef>, feedback_every: u8) -> Vec<LayoutPdo> {
    let obj = |index| ObjectRef { index, sub: 0 };
    let mut tpdo2 = vec![obj(OD_VELOCITY_ACTUAL)];
    tpdo2.extend(force);
    vec![
        LayoutPdo {
            direction: Direction::ToNode,
            number: 1,
            cob_base: COB_RPDO1_BASE,
            objects: vec![obj(OD_CONTROLWORD), obj(OD_TARGET_POSITION)],
            transmission_type: 1,
        },
        LayoutPdo {
            direction: Direction::FromNode,
            number: 1,
            cob_base: COB_TPDO1_BASE,
            objects: vec![obj(OD_STATUSWORD), obj(OD_POSITION_ACTUAL)],
            transmission_type: 1,
        },
        LayoutPdo {
            direction: Direction::FromNode,
            number: 2,
            cob_base: COB_TPDO2_BASE,
            objects: tpdo2,
            transmission_type: feedback_every,
        },
    ]
}

/// The predefined connection set's COB-ID base of PDO `number` (1-4), CiA 301 §7.3.5.
pub fn predefined_cob_base(direction: Direction, number: u16) -> Option<u16> {
    if !(1..=4).contains(&number) {
        return None;
    }
    let base = match direction {
        Direction::FromNode => 0x180,
        Direction::ToNode => 0x200,
    };
    Some(base + 0x100 * (number - 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_refs_parse_every_spelling() {
        let r = |s: &str| s.parse::<ObjectRef>().map(|o| (o.index, o.sub));
        assert_eq!(r("0x6041"), Ok((0x6041, 0)));
        assert_eq!(r("2110sub0"), Ok((0x2110, 0)));
        assert_eq!(r("0x9130sub1"), Ok((0x9130, 1)));
        assert_eq!(r("0x9130:0x1"), Ok((0x9130, 1)));
        assert_eq!(r("0x1A00subA"), Ok((0x1A00, 10)));
        assert!(r("0x16000").is_err());
        assert!(r("force").is_err());
        #[derive(Deserialize)]
        struct T {
            o: Vec<ObjectRef>,
        }
        let t: T = toml::from_str("o = [0x6041, \"0x2110sub0\"]").unwrap();
        assert_eq!(
            t.o[0],
            ObjectRef {
                index: 0x6041,
                sub: 0
            }
        );
        assert_eq!(t.o[1].to_string(), "0x2110sub0");
        assert!(toml::from_str::<T>("o = [70000]").is_err());
    }

    fn pdo(direction: Direction, objs: &[(u16, u8, DataType, Role)]) -> Pdo {
        let mut p = Pdo::new(direction, 1, 0x181, Transmission::Sync { every: 1 });
        for (k, &(index, bits, data_type, role)) in objs.iter().enumerate() {
            p.entries[k] = Mapped {
                index,
                sub: 0,
                bits,
                data_type,
                role,
            };
        }
        p.count = objs.len();
        p
    }

    #[test]
    fn encode_and_decode_follow_the_mapping_not_fixed_offsets() {
        use DataType::*;
        // Position before statusword, an unused 8-bit object between them.
        let t = pdo(
            Direction::FromNode,
            &[
                (OD_POSITION_ACTUAL, 32, Integer32, Role::PositionActual),
                (0x1001, 8, Unsigned8, Role::Other),
                (OD_STATUSWORD, 16, Unsigned16, Role::Statusword),
            ],
        );
        assert_eq!(t.dlc(), 7);
        let mut d = Decoded::default();
        assert!(t.decode(&[0xFE, 0xFF, 0xFF, 0xFF, 0x55, 0x37, 0x12], &mut d));
        assert_eq!((d.position, d.statusword), (Some(-2), Some(0x1237)));
        assert!(!t.decode(&[0; 6], &mut Decoded::default()), "too short");
        // A REAL32 and an INTEGER16 force.
        let f = pdo(Direction::FromNode, &[(0x6130, 32, Real32, Role::Force)]);
        let mut d = Decoded::default();
        f.decode(&1234.5f32.to_bits().to_le_bytes(), &mut d);
        assert_eq!(d.force, Some(1234.5));
        let f = pdo(Direction::FromNode, &[(0x7130, 16, Integer16, Role::Force)]);
        f.decode(&(-300i16).to_le_bytes(), &mut d);
        assert_eq!(d.force, Some(-300.0));
        // Target before controlword.
        let r = pdo(
            Direction::ToNode,
            &[
                (OD_TARGET_POSITION, 32, Integer32, Role::TargetPosition),
                (OD_CONTROLWORD, 16, Unsigned16, Role::Controlword),
            ],
        );
        let frame = r.encode(0x000F, -5);
        assert_eq!(frame.id(), 0x181);
        assert_eq!(frame.data(), &[0xFB, 0xFF, 0xFF, 0xFF, 0x0F, 0x00]);
    }

    #[test]
    fn default_layout_fits_the_budget() {
        let l = default_drive_layout(None, 10);
        assert_eq!(l.len(), 3);
        assert_eq!(l[2].objects.len(), 1);
        assert_eq!(l[2].transmission_type, 10);
        let l = default_drive_layout(
            Some(ObjectRef {
                index: 0x2110,
                sub: 0,
            }),
            1,
        );
        assert_eq!(l[2].objects.len(), 2);
        assert_eq!(predefined_cob_base(Direction::FromNode, 3), Some(0x380));
        assert_eq!(predefined_cob_base(Direction::ToNode, 2), Some(0x300));
        assert_eq!(predefined_cob_base(Direction::ToNode, 5), None);
    }
}
