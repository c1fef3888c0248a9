//! Where the monitor finds what it supervises on the bus, read from the drives file with its
//! own parser (docs/can-protocol.md: drive-io configures the same layout): per drive the RPDO
//! that carries its controlword and target position (the quick stop is sent in the same
//! layout), per cable the frame that carries its force — the drive's own object in a TPDO, or a
//! separate load cell's TPDO (CiA 404). Layouts the monitor cannot decode without the drives'
//! EDS (`mapping = "fixed"`) are refused at load, naming the key: a layout the monitor cannot
//! read would switch its RPDO and force checks off.

use can_transport::CanFrame;

/// The value type of a mapped object, as the monitor decodes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value {
    U16,
    I16,
    I32,
    F32,
}

impl Value {
    pub fn bytes(self) -> usize {
        match self {
            Value::U16 | Value::I16 => 2,
            Value::I32 | Value::F32 => 4,
        }
    }
    /// The value at `at` in `d` (little endian); None if the frame is too short.
    fn read(self, d: &[u8], at: usize) -> Option<f64> {
        let b = d.get(at..at + self.bytes())?;
        Some(match self {
            Value::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Value::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Value::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Value::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        })
    }
}

/// The RPDO that carries a drive's controlword and target position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RpdoLayout {
    pub interface: usize,
    pub cob_id: u16,
    /// Bytes of the RPDO (its mapping's length).
    pub len: usize,
    pub controlword_at: usize,
    pub target_at: usize,
}

impl RpdoLayout {
    /// drive-io's default CSP mapping: RPDO1 = controlword + target on 0x200 + node id.
    pub fn default_for(interface: usize, node: u8) -> Self {
        Self {
            interface,
            cob_id: 0x200 + u16::from(node & 0x7F),
            len: 6,
            controlword_at: 0,
            target_at: 2,
        }
    }

    /// (controlword, target counts) of a frame in this layout.
    pub fn decode(&self, f: &CanFrame) -> Option<(u16, i32)> {
        let d = f.data();
        if d.len() != self.len {
            return None;
        }
        let cw = d.get(self.controlword_at..self.controlword_at + 2)?;
        let t = d.get(self.target_at..self.target_at + 4)?;
        Some((
            u16::from_le_bytes([cw[0], cw[1]]),
            i32::from_le_bytes([t[0], t[1], t[2], t[3]]),
        ))
    }

    /// A frame in this layout (the monitor's quick stop); other mapped bytes are 0.
    pub fn encode(&self, controlword: u16, target_counts: i32) -> CanFrame {
        let mut d = [0u8; 8];
        d[self.controlword_at..self.controlword_at + 2].copy_from_slice(&controlword.to_le_bytes());
        d[self.target_at..self.target_at + 4].copy_from_slice(&target_counts.to_le_bytes());
        CanFrame::new_std_lossy(self.cob_id, &d[..self.len.min(8)])
    }
}

/// The frame that carries a cable's force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLayout {
    pub interface: usize,
    pub cob_id: u16,
    /// Exact length of the frame.
    pub len: usize,
    pub at: usize,
    pub value: Value,
    pub n_per_unit: f64,
    /// The node that sends it (the drive, or the load cell).
    pub node: u8,
}

impl ForceLayout {
    /// The force in a frame of this layout, N (NaN for a NaN REAL32: the monitor trips on it).
    pub fn decode(&self, f: &CanFrame) -> Option<f64> {
        let d = f.data();
        if d.len() != self.len {
            return None;
        }
        Some(self.value.read(d, self.at)? * self.n_per_unit)
    }
}

/// Every cable's RPDO and force frame (cable order), and the safety I/O node's TPDO1.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BusLayout {
    pub rpdo: Vec<RpdoLayout>,
    pub force: Vec<ForceLayout>,
    /// The safety I/O node's TPDO1 (interface index, COB-ID 0x180 + node id): [inputs,
    /// outputs] (drives file `[safety_io]`).
    pub safety_io: Option<(usize, u16)>,
}

impl BusLayout {
    /// The cable whose RPDO `f` (received on `iface`) is, with its controlword and target.
    pub fn rpdo_of(&self, iface: usize, f: &CanFrame) -> Option<(usize, u16, i32)> {
        let id = f.id() as u16;
        let (cable, l) = self
            .rpdo
            .iter()
            .enumerate()
            .find(|(_, l)| l.interface == iface && l.cob_id == id)?;
        let (cw, t) = l.decode(f)?;
        Some((cable, cw, t))
    }

    /// The cable whose force `f` (received on `iface`) carries, with the force in N.
    pub fn force_of(&self, iface: usize, f: &CanFrame) -> Option<(usize, f64)> {
        let id = f.id() as u16;
        let (cable, l) = self
            .force
            .iter()
            .enumerate()
            .find(|(_, l)| l.interface == iface && l.cob_id == id)?;
        Some((cable, l.decode(f)?))
    }
}

/// The size and type of an object the monitor decodes (the CiA 402 and CiA 404 objects of
/// drive-io's mappings); None for any other.
pub fn object_value(index: u16, sub: u8) -> Option<Value> {
    Some(match (index, sub) {
        (0x6040, 0) | (0x6041, 0) => Value::U16,
        (0x607A, 0) | (0x6064, 0) | (0x606C, 0) | (0x2110, 0) => Value::I32,
        (0x9130, 1..=0xFE) => Value::I32,
        (0x7130, 1..=0xFE) => Value::I16,
        (0x6130, 1..=0xFE) => Value::F32,
        _ => return None,
    })
}

/// `"0x6040"`, `"0x607Asub0"`, `"0x9130sub1"` → (index, sub); None if malformed.
pub fn parse_object(text: &str) -> Option<(u16, u8)> {
    let t = text.trim();
    let t = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X"))?;
    let (i, s) = match t.to_ascii_lowercase().split_once("sub") {
        Some((i, s)) => (i.to_string(), Some(s.to_string())),
        None => (t.to_string(), None),
    };
    let index = u16::from_str_radix(&i, 16).ok()?;
    let sub = match s {
        None => 0,
        Some(s) => s
            .strip_prefix("0x")
            .map_or_else(|| s.parse().ok(), |h| u8::from_str_radix(h, 16).ok())?,
    };
    Some((index, sub))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_decode_and_encode_what_drive_io_configures() {
        let r = RpdoLayout::default_for(1, 5);
        let f = r.encode(0x0002, -7);
        assert_eq!((f.id(), f.data().len()), (0x205, 6));
        assert_eq!(r.decode(&f), Some((2, -7)));
        let l = BusLayout {
            rpdo: vec![RpdoLayout::default_for(0, 5), r],
            force: vec![ForceLayout {
                interface: 1,
                cob_id: 0x1A1,
                len: 2,
                at: 0,
                value: Value::I16,
                n_per_unit: 1.0,
                node: 33,
            }],
            safety_io: None,
        };
        // The same node id on another interface is another drive.
        assert_eq!(l.rpdo_of(1, &f), Some((1, 2, -7)));
        assert_eq!(l.rpdo_of(0, &f), Some((0, 2, -7)));
        assert_eq!(l.rpdo_of(2, &f), None);
        let cell = CanFrame::new(0x1A1, &(-1234i16).to_le_bytes()).unwrap();
        assert_eq!(l.force_of(1, &cell), Some((0, -1234.0)));
        assert_eq!(l.force_of(0, &cell), None, "other interface");
        let short = CanFrame::new(0x1A1, &[1]).unwrap();
        assert_eq!(
            l.force_of(1, &short),
            None,
            "a frame of another length is not the force"
        );
        assert_eq!(parse_object("0x9130sub1"), Some((0x9130, 1)));
        assert_eq!(parse_object("0x6040"), Some((0x6040, 0)));
        assert_eq!(parse_object("0x2110sub0x0"), Some((0x2110, 0)));
        assert_eq!(parse_object("6040"), None);
        assert_eq!(object_value(0x7130, 1), Some(Value::I16));
        assert_eq!(object_value(0x2000, 0), None);
    }
}
