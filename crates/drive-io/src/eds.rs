//! CiA 306 electronic data sheets (EDS) and device configuration files (DCF): the INI text
//! format a drive vendor ships to describe the drive's object dictionary.
//!
//! [`Eds::parse`] reads the object sections (`[1017]`, `[1600sub1]`, ...) with their
//! `ParameterName`, `ObjectType`, `DataType`, `AccessType`, `DefaultValue`, `PDOMapping`,
//! `LowLimit`, `HighLimit` (and a DCF's `ParameterValue`); numbers are decimal, `0x` hex or
//! `0` octal (CiA 306 §4.6.3), and may be `$NODEID+...` expressions (evaluated per node with
//! [`OdEntry::default_for`]). Every error names the line. [`Eds::write_dcf`] writes the DCF of
//! a commissioned node: the EDS text with `ParameterValue=` on every configured entry and a
//! `[DeviceComissioning]` section (CiA 306 §5; the spelling is the standard's).
//!
//! The simulated winch's EDS is `config/eds/crs-winch.eds` ([`Eds::builtin_winch`]).

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The simulated winch drive's EDS, compiled in: the default when drives.toml names none.
pub const BUILTIN_WINCH_EDS: &str = include_str!("../../../config/eds/crs-winch.eds");
/// Name reported for the built-in EDS.
pub const BUILTIN_WINCH_EDS_NAME: &str = "config/eds/crs-winch.eds (built in)";

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}: {reason}")]
pub struct EdsError {
    pub file: String,
    /// 1-based line (0 = the file as a whole).
    pub line: usize,
    pub reason: String,
}

/// CiA 301 basic data types (table 44) that fit an expedited SDO transfer; strings/domains are
/// kept as [`DataType::Other`] (listed, never configured).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    Boolean,
    Integer8,
    Integer16,
    Integer32,
    Unsigned8,
    Unsigned16,
    Unsigned32,
    Real32,
    Other(u16),
}

impl DataType {
    pub fn from_code(c: u16) -> Self {
        match c {
            0x0001 => Self::Boolean,
            0x0002 => Self::Integer8,
            0x0003 => Self::Integer16,
            0x0004 => Self::Integer32,
            0x0005 => Self::Unsigned8,
            0x0006 => Self::Unsigned16,
            0x0007 => Self::Unsigned32,
            0x0008 => Self::Real32,
            c => Self::Other(c),
        }
    }
    pub fn code(self) -> u16 {
        match self {
            Self::Boolean => 1,
            Self::Integer8 => 2,
            Self::Integer16 => 3,
            Self::Integer32 => 4,
            Self::Unsigned8 => 5,
            Self::Unsigned16 => 6,
            Self::Unsigned32 => 7,
            Self::Real32 => 8,
            Self::Other(c) => c,
        }
    }
    /// Size in bytes for the expedited types (None for strings, domains, 64-bit).
    pub fn size(self) -> Option<u8> {
        match self {
            Self::Boolean | Self::Integer8 | Self::Unsigned8 => Some(1),
            Self::Integer16 | Self::Unsigned16 => Some(2),
            Self::Integer32 | Self::Unsigned32 | Self::Real32 => Some(4),
            Self::Other(_) => None,
        }
    }
    pub fn is_signed(self) -> bool {
        matches!(self, Self::Integer8 | Self::Integer16 | Self::Integer32)
    }
    /// The value range of the integer types.
    pub fn range(self) -> Option<(i64, i64)> {
        Some(match self {
            Self::Boolean => (0, 1),
            Self::Integer8 => (i8::MIN.into(), i8::MAX.into()),
            Self::Integer16 => (i16::MIN.into(), i16::MAX.into()),
            Self::Integer32 => (i32::MIN.into(), i32::MAX.into()),
            Self::Unsigned8 => (0, u8::MAX.into()),
            Self::Unsigned16 => (0, u16::MAX.into()),
            Self::Unsigned32 | Self::Real32 => (0, u32::MAX.into()),
            Self::Other(_) => return None,
        })
    }
    /// Sign-extends the raw little-endian bits of a value of this type.
    pub fn to_i64(self, raw: u32) -> i64 {
        match self {
            Self::Integer8 => i64::from(raw as u8 as i8),
            Self::Integer16 => i64::from(raw as u16 as i16),
            Self::Integer32 => i64::from(raw as i32),
            _ => i64::from(raw),
        }
    }
}

/// CiA 306 `AccessType`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    Ro,
    Wo,
    Rw,
    /// rw, read by the master from a TPDO
    Rwr,
    /// rw, written by the master in an RPDO
    Rww,
    Const,
}

impl Access {
    fn parse(s: &str) -> Option<Self> {
        Some(match s.to_ascii_lowercase().as_str() {
            "ro" => Self::Ro,
            "wo" => Self::Wo,
            "rw" => Self::Rw,
            "rwr" => Self::Rwr,
            "rww" => Self::Rww,
            "const" => Self::Const,
            _ => return None,
        })
    }
    pub fn readable(self) -> bool {
        self != Self::Wo
    }
    pub fn writable(self) -> bool {
        matches!(self, Self::Wo | Self::Rw | Self::Rwr | Self::Rww)
    }
}

/// A number as written in the EDS, possibly relative to the node id (`$NODEID+0x180`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdsValue {
    pub value: i64,
    pub plus_node_id: bool,
}

impl EdsValue {
    pub fn eval(self, node_id: u8) -> i64 {
        self.value
            + if self.plus_node_id {
                i64::from(node_id)
            } else {
                0
            }
    }
}

/// One sub-entry of the object dictionary (a VAR is sub-index 0 of its own index).
#[derive(Debug, Clone, PartialEq)]
pub struct OdEntry {
    pub index: u16,
    pub sub: u8,
    pub name: String,
    pub data_type: DataType,
    pub access: Access,
    pub default: Option<EdsValue>,
    /// A DCF's configured value.
    pub parameter_value: Option<EdsValue>,
    pub pdo_mappable: bool,
    pub low: Option<i64>,
    pub high: Option<i64>,
    /// Line of the section header (for messages).
    pub line: usize,
}

impl OdEntry {
    /// The default value for node `node_id` (0 if the EDS gives none).
    pub fn default_for(&self, node_id: u8) -> i64 {
        self.default.map_or(0, |v| v.eval(node_id))
    }
    /// Checks `value` against the data type and the EDS limits; the reason if out of range.
    pub fn check_range(&self, value: i64) -> Result<(), RangeError> {
        if let Some((lo, hi)) = self.data_type.range()
            && !(lo..=hi).contains(&value)
        {
            return Err(RangeError::DataType {
                value,
                data_type: self.data_type,
            });
        }
        if let Some(low) = self.low
            && value < low
        {
            return Err(RangeError::BelowLowLimit { value, low });
        }
        if let Some(high) = self.high
            && value > high
        {
            return Err(RangeError::AboveHighLimit { value, high });
        }
        Ok(())
    }
}

/// Why a value does not fit an object-dictionary entry ([`OdEntry::check_range`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RangeError {
    /// Outside the range of the entry's CiA 301 data type.
    #[error("{value} does not fit {data_type:?}")]
    DataType { value: i64, data_type: DataType },
    /// Below the EDS `LowLimit`.
    #[error("{value} below the EDS LowLimit {low}")]
    BelowLowLimit { value: i64, low: i64 },
    /// Above the EDS `HighLimit`.
    #[error("{value} above the EDS HighLimit {high}")]
    AboveHighLimit { value: i64, high: i64 },
}

/// An object (index) with its name and object type (7 VAR, 8 ARRAY, 9 RECORD).
#[derive(Debug, Clone, PartialEq)]
pub struct OdObject {
    pub name: String,
    pub object_type: u8,
}

#[derive(Debug, Clone)]
struct Section {
    name: String,
    line: usize,
    lines: Vec<String>,
}

/// A parsed EDS or DCF.
#[derive(Debug, Clone)]
pub struct Eds {
    pub file: String,
    objects: BTreeMap<u16, OdObject>,
    entries: BTreeMap<(u16, u8), OdEntry>,
    sections: Vec<Section>,
}

/// Parses a CiA 306 number: decimal, `0x` hex, leading-0 octal, optionally with a `$NODEID`
/// term (`$NODEID+0x180`, `0x180+$NODEID`). None if not a number.
pub fn parse_number(s: &str) -> Option<EdsValue> {
    let t: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    let upper = t.to_ascii_uppercase();
    let (rest, plus_node_id) = if let Some(r) = upper.strip_prefix("$NODEID+") {
        (r.to_string(), true)
    } else if let Some(r) = upper.strip_suffix("+$NODEID") {
        (r.to_string(), true)
    } else if upper == "$NODEID" {
        ("0".to_string(), true)
    } else {
        (upper, false)
    };
    let (neg, digits) = match rest.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, rest.as_str()),
    };
    let v = if let Some(h) = digits.strip_prefix("0X") {
        i64::from_str_radix(h, 16).ok()?
    } else if digits.len() > 1 && digits.starts_with('0') {
        i64::from_str_radix(&digits[1..], 8).ok()?
    } else {
        digits.parse::<i64>().ok()?
    };
    Some(EdsValue {
        value: if neg { -v } else { v },
        plus_node_id,
    })
}

/// Object section names: `1017` or `1600sub2` (hex, case-insensitive).
fn object_section(name: &str) -> Option<(u16, Option<u8>)> {
    let lower = name.to_ascii_lowercase();
    let (idx, sub) = match lower.split_once("sub") {
        Some((i, s)) => (i, Some(s)),
        None => (lower.as_str(), None),
    };
    if idx.len() != 4 || !idx.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    let index = u16::from_str_radix(idx, 16).ok()?;
    let sub = match sub {
        Some(s) => Some(u8::from_str_radix(s, 16).ok()?),
        None => None,
    };
    Some((index, sub))
}

impl Eds {
    /// The simulated winch's EDS (`config/eds/crs-winch.eds`, compiled in).
    pub fn builtin_winch() -> &'static Eds {
        static EDS: std::sync::OnceLock<Eds> = std::sync::OnceLock::new();
        EDS.get_or_init(|| {
            Eds::parse(BUILTIN_WINCH_EDS, BUILTIN_WINCH_EDS_NAME)
                .expect("the built-in EDS is checked by the eds unit tests")
        })
    }

    pub fn load(path: &std::path::Path) -> Result<Self, EdsError> {
        let text = std::fs::read_to_string(path).map_err(|e| EdsError {
            file: path.display().to_string(),
            line: 0,
            reason: e.to_string(),
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses EDS/DCF text; `file` is used in error messages.
    pub fn parse(text: &str, file: &str) -> Result<Self, EdsError> {
        let err = |line: usize, reason: String| EdsError {
            file: file.to_string(),
            line,
            reason,
        };
        let mut sections: Vec<Section> = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with(';') {
                if let Some(s) = sections.last_mut() {
                    s.lines.push(raw.to_string());
                }
                continue;
            }
            if let Some(h) = line.strip_prefix('[') {
                let Some(name) = h.strip_suffix(']') else {
                    return Err(err(n + 1, format!("section header without `]`: {line}")));
                };
                let name = name.trim().to_string();
                if sections.iter().any(|s| s.name.eq_ignore_ascii_case(&name)) {
                    return Err(err(n + 1, format!("section [{name}] appears twice")));
                }
                sections.push(Section {
                    name,
                    line: n + 1,
                    lines: Vec::new(),
                });
                continue;
            }
            let Some(s) = sections.last_mut() else {
                return Err(err(n + 1, "key before the first [section]".into()));
            };
            if !line.contains('=') {
                return Err(err(n + 1, format!("expected key=value, got `{line}`")));
            }
            s.lines.push(raw.to_string());
        }
        let mut objects = BTreeMap::new();
        let mut entries = BTreeMap::new();
        for s in &sections {
            let Some((index, sub)) = object_section(&s.name) else {
                continue;
            };
            let mut keys: BTreeMap<String, (String, usize)> = BTreeMap::new();
            for (k, l) in s.lines.iter().enumerate() {
                let t = l.trim();
                if t.is_empty() || t.starts_with(';') {
                    continue;
                }
                let (key, value) = t.split_once('=').unwrap_or((t, ""));
                keys.insert(
                    key.trim().to_ascii_lowercase(),
                    (value.trim().to_string(), s.line + 1 + k),
                );
            }
            let num = |key: &str| -> Result<Option<EdsValue>, EdsError> {
                match keys.get(key) {
                    None => Ok(None),
                    Some((v, _)) if v.is_empty() => Ok(None),
                    Some((v, l)) => parse_number(v)
                        .map(Some)
                        .ok_or_else(|| err(*l, format!("[{}] {key}: not a number: `{v}`", s.name))),
                }
            };
            let name = keys
                .get("parametername")
                .map(|(v, _)| v.clone())
                .ok_or_else(|| err(s.line, format!("[{}] has no ParameterName", s.name)))?;
            if num("compactsubobj")?.is_some_and(|v| v.value != 0) {
                return Err(err(
                    s.line,
                    format!(
                        "[{}] uses CompactSubObj, which this parser does not expand: list the \
                         sub-indices as [{}subN] sections",
                        s.name, s.name
                    ),
                ));
            }
            let object_type = num("objecttype")?.map_or(7, |v| v.value);
            if !(0..=9).contains(&object_type) {
                return Err(err(
                    s.line,
                    format!("[{}] ObjectType {object_type}", s.name),
                ));
            }
            if sub.is_none() {
                objects.insert(
                    index,
                    OdObject {
                        name: name.clone(),
                        object_type: object_type as u8,
                    },
                );
                if object_type == 8 || object_type == 9 {
                    continue; // ARRAY/RECORD: the data are in the [XXXXsubN] sections
                }
            }
            let data_type = num("datatype")?
                .ok_or_else(|| err(s.line, format!("[{}] has no DataType", s.name)))?;
            let access = keys
                .get("accesstype")
                .ok_or_else(|| err(s.line, format!("[{}] has no AccessType", s.name)))?;
            let access = Access::parse(&access.0).ok_or_else(|| {
                err(
                    access.1,
                    format!(
                        "[{}] AccessType `{}` is not ro/wo/rw/rwr/rww/const",
                        s.name, access.0
                    ),
                )
            })?;
            let pdo = num("pdomapping")?.is_some_and(|v| v.value != 0);
            let entry = OdEntry {
                index,
                sub: sub.unwrap_or(0),
                name,
                data_type: DataType::from_code(data_type.value as u16),
                access,
                default: num("defaultvalue").unwrap_or(None),
                parameter_value: num("parametervalue").unwrap_or(None),
                pdo_mappable: pdo,
                low: num("lowlimit")?.map(|v| v.value),
                high: num("highlimit")?.map(|v| v.value),
                line: s.line,
            };
            if let Some(d) = entry.default
                && !d.plus_node_id
                && entry.data_type.size().is_some()
            {
                let v = d.value;
                // Unsigned32 defaults like 0x80000000 are bit patterns; signed types may be
                // written as their two's complement hex.
                let fits = entry.check_range(v).is_ok()
                    || (entry.data_type.is_signed()
                        && entry.data_type.range().is_some_and(|(lo, _)| {
                            v >= 0 && v < (-lo) * 2 && entry.check_range(v + 2 * lo).is_ok()
                        }));
                if !fits {
                    return Err(err(
                        s.line,
                        format!("[{}] DefaultValue {v} out of range", s.name),
                    ));
                }
            }
            entries.insert((index, entry.sub), entry);
        }
        for ((index, sub), e) in &entries {
            if *sub != 0 && !objects.contains_key(index) {
                return Err(err(
                    e.line,
                    format!("[{index:04X}sub{sub:X}] without its object section [{index:04X}]"),
                ));
            }
        }
        Ok(Self {
            file: file.to_string(),
            objects,
            entries,
            sections,
        })
    }

    pub fn entry(&self, index: u16, sub: u8) -> Option<&OdEntry> {
        self.entries.get(&(index, sub))
    }
    pub fn object(&self, index: u16) -> Option<&OdObject> {
        self.objects.get(&index)
    }
    pub fn entries(&self) -> impl Iterator<Item = &OdEntry> {
        self.entries.values()
    }
    /// Human name of an object entry for messages: `0x1600sub1 (RPDO1 mapping / mapped object 1)`.
    pub fn describe(&self, index: u16, sub: u8) -> String {
        let obj = self.objects.get(&index).map(|o| o.name.as_str());
        let ent = self.entries.get(&(index, sub)).map(|e| e.name.as_str());
        let name = match (obj, ent) {
            (Some(o), Some(e)) if o != e => format!("{o} / {e}"),
            (Some(o), _) => o.to_string(),
            (None, Some(e)) => e.to_string(),
            (None, None) => "not in the EDS".to_string(),
        };
        format!("0x{index:04X}sub{sub} ({name})")
    }

    /// The DCF of node `node_id`: this EDS with `ParameterValue=` for every `(index, sub,
    /// value)` configured and a `[DeviceComissioning]` section (CiA 306 §5).
    pub fn write_dcf(
        &self,
        node_id: u8,
        node_name: &str,
        baudrate_kbit: u32,
        configured: &[(u16, u8, u32)],
    ) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "; DCF written by drive-io from {} for node {node_id}",
            self.file
        );
        for s in &self.sections {
            if s.name.eq_ignore_ascii_case("DeviceComissioning") {
                continue;
            }
            let _ = writeln!(out, "[{}]", s.name);
            let key = object_section(&s.name);
            let value = key.and_then(|(index, sub)| {
                let sub = sub.unwrap_or(0);
                configured
                    .iter()
                    .rev()
                    .find(|(i, s2, _)| *i == index && *s2 == sub)
                    .map(|&(_, _, v)| v)
            });
            for l in &s.lines {
                let k = l
                    .split_once('=')
                    .map(|(k, _)| k.trim().to_ascii_lowercase());
                if value.is_some() && k.as_deref() == Some("parametervalue") {
                    continue;
                }
                if l.trim().is_empty() {
                    continue;
                }
                let _ = writeln!(out, "{l}");
            }
            if let Some(v) = value {
                let _ = writeln!(out, "ParameterValue=0x{v:X}");
            }
            let _ = writeln!(out);
        }
        let _ = writeln!(out, "[DeviceComissioning]");
        let _ = writeln!(out, "NodeID=0x{node_id:02X}");
        let _ = writeln!(out, "NodeName={node_name}");
        let _ = writeln!(out, "Baudrate={baudrate_kbit}");
        let _ = writeln!(out, "NetNumber=0");
        let _ = writeln!(out, "NetworkName=crs drive bus");
        let _ = writeln!(out, "CANopenManager=0");
        let _ = writeln!(out, "LSS_SerialNumber=0");
        out
    }
}

/// CiA 301 SDO abort codes (table 22): the standard's text for a code.
pub fn sdo_abort_text(code: u32) -> &'static str {
    match code {
        0x0503_0000 => "toggle bit not alternated",
        0x0504_0000 => "SDO protocol timed out",
        0x0504_0001 => "client/server command specifier not valid or unknown",
        0x0504_0002 => "invalid block size",
        0x0504_0003 => "invalid sequence number",
        0x0504_0004 => "CRC error",
        0x0504_0005 => "out of memory",
        0x0601_0000 => "unsupported access to an object",
        0x0601_0001 => "attempt to read a write only object",
        0x0601_0002 => "attempt to write a read only object",
        0x0602_0000 => "object does not exist in the object dictionary",
        0x0604_0041 => "object cannot be mapped to the PDO",
        0x0604_0042 => "the number and length of the objects to be mapped would exceed PDO length",
        0x0604_0043 => "general parameter incompatibility reason",
        0x0604_0047 => "general internal incompatibility in the device",
        0x0606_0000 => "access failed due to a hardware error",
        0x0607_0010 => "data type does not match, length of service parameter does not match",
        0x0607_0012 => "data type does not match, length of service parameter too high",
        0x0607_0013 => "data type does not match, length of service parameter too low",
        0x0609_0011 => "sub-index does not exist",
        0x0609_0030 => "invalid value for parameter (download only)",
        0x0609_0031 => "value of parameter written too high (download only)",
        0x0609_0032 => "value of parameter written too low (download only)",
        0x0609_0036 => "maximum value is less than minimum value",
        0x060A_0023 => "resource not available: SDO connection",
        0x0800_0000 => "general error",
        0x0800_0020 => "data cannot be transferred or stored to the application",
        0x0800_0021 => {
            "data cannot be transferred or stored to the application because of local control"
        }
        0x0800_0022 => {
            "data cannot be transferred or stored to the application because of the present device state"
        }
        0x0800_0023 => {
            "object dictionary dynamic generation fails or no object dictionary is present"
        }
        0x0800_0024 => "no data available",
        _ => "unknown abort code (not in CiA 301 table 22)",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_per_cia306() {
        let n = |s| parse_number(s).map(|v| (v.value, v.plus_node_id));
        assert_eq!(n("10"), Some((10, false)));
        assert_eq!(n("0x1F"), Some((31, false)));
        assert_eq!(n("017"), Some((15, false)));
        assert_eq!(n("-5"), Some((-5, false)));
        assert_eq!(n("$NODEID+0x180"), Some((0x180, true)));
        assert_eq!(n("0x200 + $NODEID"), Some((0x200, true)));
        assert_eq!(n("$nodeid"), Some((0, true)));
        assert_eq!(n("twelve"), None);
        assert_eq!(n(""), None);
    }

    #[test]
    fn builtin_winch_eds_parses_and_has_the_cia402_objects() {
        let eds = Eds::builtin_winch();
        let e = eds.entry(0x1000, 0).unwrap();
        assert_eq!(e.default_for(1), 0x0002_0192);
        let cob = eds.entry(0x1800, 1).unwrap();
        assert_eq!(cob.default_for(5), 0x185);
        assert_eq!(eds.entry(0x6060, 0).unwrap().data_type, DataType::Integer8);
        assert!(eds.entry(0x6064, 0).unwrap().pdo_mappable);
        assert!(!eds.entry(0x6064, 0).unwrap().access.writable());
        assert_eq!(eds.object(0x1600).unwrap().object_type, 9);
        assert!(eds.describe(0x1600, 1).contains("RPDO1 mapping"));
    }

    #[test]
    fn errors_name_the_line() {
        let e = Eds::parse("[1000]\nParameterName=x\nDataType=0x0007\n", "a.eds").unwrap_err();
        assert_eq!(e.line, 1);
        assert!(e.reason.contains("AccessType"), "{e}");
        let e = Eds::parse(
            "[1000]\nParameterName=x\nDataType=zz\nAccessType=ro\n",
            "a.eds",
        )
        .unwrap_err();
        assert_eq!((e.line, e.file.as_str()), (3, "a.eds"));
        let e = Eds::parse(
            "[1016]\nParameterName=x\nObjectType=0x8\nCompactSubObj=2\n",
            "a.eds",
        )
        .unwrap_err();
        assert!(e.reason.contains("CompactSubObj"), "{e}");
        let e = Eds::parse("x=1\n", "a.eds").unwrap_err();
        assert_eq!(e.line, 1);
        let e = Eds::parse("[1000\n", "a.eds").unwrap_err();
        assert_eq!(e.line, 1);
        let e = Eds::parse(
            "[1000]\nParameterName=x\nDataType=0x0005\nAccessType=ro\nDefaultValue=300\n",
            "a.eds",
        )
        .unwrap_err();
        assert!(e.reason.contains("out of range"), "{e}");
        let e = Eds::parse(
            "[1000sub1]\nParameterName=x\nDataType=0x0005\nAccessType=ro\n",
            "a.eds",
        )
        .unwrap_err();
        assert!(e.reason.contains("without its object"), "{e}");
    }

    #[test]
    fn dcf_round_trips_configured_values() {
        let eds = Eds::builtin_winch();
        let dcf = eds.write_dcf(3, "winch 3", 1000, &[(0x1017, 0, 10), (0x1800, 1, 0x183)]);
        let back = Eds::parse(&dcf, "node3.dcf").unwrap();
        assert_eq!(
            back.entry(0x1017, 0)
                .unwrap()
                .parameter_value
                .unwrap()
                .value,
            10
        );
        assert_eq!(
            back.entry(0x1800, 1)
                .unwrap()
                .parameter_value
                .unwrap()
                .value,
            0x183
        );
        assert!(back.entry(0x6060, 0).unwrap().parameter_value.is_none());
        assert!(dcf.contains("[DeviceComissioning]\nNodeID=0x03"));
    }

    #[test]
    fn abort_codes_have_the_standard_text() {
        assert_eq!(
            sdo_abort_text(0x0602_0000),
            "object does not exist in the object dictionary"
        );
        assert!(sdo_abort_text(0x1234_5678).contains("unknown"));
    }

    proptest::proptest! {
        #[test]
        fn parser_never_panics(text in "(\\[[0-9a-fA-Fsub]{0,8}\\]|[A-Za-z]{0,12}=[0-9xA-F$NODEID+]{0,10}|;.*|)(\n(\\[[0-9a-fA-Fsub]{0,8}\\]|[A-Za-z]{0,12}=[0-9xA-F$NODEID+]{0,10}|;.*|)){0,20}") {
            let _ = Eds::parse(&text, "fuzz.eds");
        }
    }
}
