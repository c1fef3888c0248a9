//! CiA 306 electronic data sheets (EDS) and device configuration files (DCF): the INI text
//! format a drive vendor ships to describe the drive's object dictionary.
//!
//! [`Eds::parse`] reads the object sections (`[1017]`, `[1600sub1]`, ...) with their
//! `ParameterName`, `ObjectType`, `DataType`, `AccessType`, `DefaultValue`, `PDOMapping`,
//! `LowLimit`, `HighLimit` (and a DCF's `ParameterValue`); numbers are decimal, `0x` hex or
//! `0` octal (CiA 306 §4.6.3), and may be `$NODEID+...` expressions (evaluated per node with
//! [`OdEntry::default_for`]). Every error names the line. ARRAY objects written compactly
//! (`CompactSubObj=N`, CiA 306 §4.5.2.2, with the optional `[XXXXName]` / `[XXXXValue]`
//! sections) are expanded into their sub-indices 0..=N, as Lely and python canopen read them.
//! String and domain values are kept as text ([`OdEntry::default_text`]).
//! [`Eds::write_dcf`] writes the DCF of a commissioned node: the EDS text with
//! `ParameterValue=` on every configured entry (signed types as signed decimals, compact
//! objects written out as `[XXXXsubN]` sections) and a `[DeviceComissioning]` section (CiA 306
//! §5; the spelling is the standard's).
//!
//! The simulated winch's EDS is `config/eds/crs-winch.eds` ([`Eds::builtin_winch`]).

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The simulated winch drive's EDS, compiled in: the default when drives.toml names none.
pub const BUILTIN_WINCH_EDS: &str = include_str!("../../../config/eds/crs-winch.eds");
/// Name reported for the built-in EDS.
pub const BUILTIN_WINCH_EDS_NAME: &str = "config/eds/crs-winch.eds (built in)";
/// The simulated pulley load cell's EDS (CiA 404), compiled in: the default of a
/// `[[force_sensor]]` that names none.
pub const BUILTIN_LOAD_CELL_EDS: &str = include_str!("../../../config/eds/crs-load-cell.eds");
/// Name reported for the built-in load cell EDS.
pub const BUILTIN_LOAD_CELL_EDS_NAME: &str = "config/eds/crs-load-cell.eds (built in)";

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
    /// VISIBLE_STRING, OCTET_STRING, UNICODE_STRING or DOMAIN: a byte string of any length
    /// (segmented SDO).
    pub fn is_string(self) -> bool {
        matches!(self, Self::Other(0x0009 | 0x000A | 0x000B | 0x000F))
    }
    /// The value's bytes from its EDS text: VISIBLE_STRING as written, OCTET_STRING/DOMAIN as
    /// hex digits (python canopen's and Lely's reading), UNICODE_STRING as UTF-16LE. None if
    /// the text is not valid for the type or the type is no string.
    pub fn text_bytes(self, text: &str) -> Option<Vec<u8>> {
        match self {
            Self::Other(0x0009) => Some(text.as_bytes().to_vec()),
            Self::Other(0x000A | 0x000F) => {
                let t: String = text.chars().filter(|c| !c.is_whitespace()).collect();
                let t = t.strip_prefix("0x").unwrap_or(&t);
                if !t.len().is_multiple_of(2) {
                    return None;
                }
                (0..t.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(t.get(i..i + 2)?, 16).ok())
                    .collect()
            }
            Self::Other(0x000B) => Some(text.encode_utf16().flat_map(u16::to_le_bytes).collect()),
            _ => None,
        }
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
    /// The `DefaultValue` as written (the value of string and domain entries).
    pub default_text: Option<String>,
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
    /// `CompactSubObj=N`: an ARRAY of N equal sub-indices described in its object section.
    pub compact: Option<u8>,
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

/// The keys of one section: lower-case key → (value, 1-based line).
type Keys = BTreeMap<String, (String, usize)>;

/// [`Eds::parse`]'s state while it reads the sections of one file.
struct Parser<'a> {
    file: &'a str,
    /// `[XXXXName]` / `[XXXXValue]`: per-sub names and (DCF) values of compact arrays.
    compact_names: BTreeMap<u16, BTreeMap<u8, String>>,
    compact_values: BTreeMap<u16, BTreeMap<u8, (String, usize)>>,
    objects: BTreeMap<u16, OdObject>,
    entries: BTreeMap<(u16, u8), OdEntry>,
}

impl Parser<'_> {
    fn err(&self, line: usize, reason: String) -> EdsError {
        EdsError {
            file: self.file.to_string(),
            line,
            reason,
        }
    }

    /// The text split into its sections (comments and blank lines kept with their section).
    fn sections(&self, text: &str) -> Result<Vec<Section>, EdsError> {
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
                    return Err(self.err(n + 1, format!("section header without `]`: {line}")));
                };
                let name = name.trim().to_string();
                if sections.iter().any(|s| s.name.eq_ignore_ascii_case(&name)) {
                    return Err(self.err(n + 1, format!("section [{name}] appears twice")));
                }
                sections.push(Section {
                    name,
                    line: n + 1,
                    lines: Vec::new(),
                });
                continue;
            }
            let Some(s) = sections.last_mut() else {
                return Err(self.err(n + 1, "key before the first [section]".into()));
            };
            if !line.contains('=') {
                return Err(self.err(n + 1, format!("expected key=value, got `{line}`")));
            }
            s.lines.push(raw.to_string());
        }
        Ok(sections)
    }

    /// The `[XXXXName]` / `[XXXXValue]` sections of compact arrays.
    fn compact_tables(&mut self, sections: &[Section]) -> Result<(), EdsError> {
        for s in sections {
            let lower = s.name.to_ascii_lowercase();
            let (idx, into_names) = if let Some(i) = lower.strip_suffix("name") {
                (i, true)
            } else if let Some(i) = lower.strip_suffix("value") {
                (i, false)
            } else {
                continue;
            };
            if idx.len() != 4 || !idx.chars().all(|c| c.is_ascii_hexdigit()) {
                continue;
            }
            let index =
                u16::from_str_radix(idx, 16).map_err(|e| self.err(s.line, e.to_string()))?;
            for (k, l) in s.lines.iter().enumerate() {
                let t = l.trim();
                if t.is_empty() || t.starts_with(';') {
                    continue;
                }
                let (key, value) = t.split_once('=').unwrap_or((t, ""));
                let key = key.trim();
                if key.eq_ignore_ascii_case("NrOfEntries") {
                    continue;
                }
                let Some(sub) = key.parse::<u8>().ok().filter(|n| *n > 0) else {
                    return Err(self.err(
                        s.line + 1 + k,
                        format!("[{}]: `{key}` is not a sub-index 1..=255", s.name),
                    ));
                };
                let value = value.trim().to_string();
                if into_names {
                    self.compact_names
                        .entry(index)
                        .or_default()
                        .insert(sub, value);
                } else {
                    self.compact_values
                        .entry(index)
                        .or_default()
                        .insert(sub, (value, s.line + 1 + k));
                }
            }
        }
        Ok(())
    }

    /// A numeric key of `s` (absent or empty: `None`).
    fn num(&self, keys: &Keys, s: &Section, key: &str) -> Result<Option<EdsValue>, EdsError> {
        match keys.get(key) {
            None => Ok(None),
            Some((v, _)) if v.is_empty() => Ok(None),
            Some((v, l)) => parse_number(v)
                .map(Some)
                .ok_or_else(|| self.err(*l, format!("[{}] {key}: not a number: `{v}`", s.name))),
        }
    }

    /// One object section `[XXXX]` or sub-object section `[XXXXsubN]`.
    fn object(&mut self, s: &Section, index: u16, sub: Option<u8>) -> Result<(), EdsError> {
        let mut keys = Keys::new();
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
        let name = keys
            .get("parametername")
            .map(|(v, _)| v.clone())
            .ok_or_else(|| self.err(s.line, format!("[{}] has no ParameterName", s.name)))?;
        let object_type = self.num(&keys, s, "objecttype")?.map_or(7, |v| v.value);
        if !(0..=9).contains(&object_type) {
            return Err(self.err(s.line, format!("[{}] ObjectType {object_type}", s.name)));
        }
        let compact = self.compact(&keys, s, sub, object_type)?;
        if sub.is_none() {
            self.objects.insert(
                index,
                OdObject {
                    name: name.clone(),
                    object_type: object_type as u8,
                    compact,
                },
            );
            if (object_type == 8 || object_type == 9) && compact.is_none() {
                return Ok(()); // ARRAY/RECORD: the data are in the [XXXXsubN] sections
            }
        }
        let entry = self.entry(&keys, s, index, sub.unwrap_or(0), name)?;
        match compact {
            None => {
                self.entries.insert((index, entry.sub), entry);
            }
            Some(n) => self.expand_compact(entry, n, s.line)?,
        }
        Ok(())
    }

    /// `CompactSubObj=n` of an ARRAY's object section (1..=254, without SubNumber).
    fn compact(
        &self,
        keys: &Keys,
        s: &Section,
        sub: Option<u8>,
        object_type: i64,
    ) -> Result<Option<u8>, EdsError> {
        let Some(n) = self
            .num(keys, s, "compactsubobj")?
            .map(|v| v.value)
            .filter(|n| *n != 0)
        else {
            return Ok(None);
        };
        if sub.is_some() || object_type != 8 {
            return Err(self.err(
                s.line,
                format!(
                    "[{}] CompactSubObj belongs to the object section of an ARRAY \
                     (ObjectType=0x8)",
                    s.name
                ),
            ));
        }
        if !(1..=254).contains(&n) {
            return Err(self.err(
                s.line,
                format!("[{}] CompactSubObj={n}: must be 1..=254", s.name),
            ));
        }
        if self
            .num(keys, s, "subnumber")?
            .is_some_and(|v| v.value != 0)
        {
            return Err(self.err(
                s.line,
                format!("[{}] has both SubNumber and CompactSubObj", s.name),
            ));
        }
        Ok(Some(n as u8))
    }

    /// The entry a section describes: data type, access, default (range-checked), limits.
    fn entry(
        &self,
        keys: &Keys,
        s: &Section,
        index: u16,
        sub: u8,
        name: String,
    ) -> Result<OdEntry, EdsError> {
        let data_type = self
            .num(keys, s, "datatype")?
            .ok_or_else(|| self.err(s.line, format!("[{}] has no DataType", s.name)))?;
        let access = keys
            .get("accesstype")
            .ok_or_else(|| self.err(s.line, format!("[{}] has no AccessType", s.name)))?;
        let access = Access::parse(&access.0).ok_or_else(|| {
            self.err(
                access.1,
                format!(
                    "[{}] AccessType `{}` is not ro/wo/rw/rwr/rww/const",
                    s.name, access.0
                ),
            )
        })?;
        let pdo = self
            .num(keys, s, "pdomapping")?
            .is_some_and(|v| v.value != 0);
        let entry = OdEntry {
            index,
            sub,
            name,
            data_type: DataType::from_code(data_type.value as u16),
            access,
            default: self.num(keys, s, "defaultvalue").unwrap_or(None),
            default_text: keys
                .get("defaultvalue")
                .map(|(v, _)| v.clone())
                .filter(|v| !v.is_empty()),
            parameter_value: self.num(keys, s, "parametervalue").unwrap_or(None),
            pdo_mappable: pdo,
            low: self.num(keys, s, "lowlimit")?.map(|v| v.value),
            high: self.num(keys, s, "highlimit")?.map(|v| v.value),
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
                return Err(self.err(
                    s.line,
                    format!("[{}] DefaultValue {v} out of range", s.name),
                ));
            }
        }
        Ok(entry)
    }

    /// CompactSubObj=n: sub 0 holds n, subs 1..=n share the object's description (names and
    /// DCF values from `[XXXXName]` / `[XXXXValue]`).
    fn expand_compact(&mut self, entry: OdEntry, n: u8, line: usize) -> Result<(), EdsError> {
        let index = entry.index;
        self.entries.insert(
            (index, 0),
            OdEntry {
                index,
                sub: 0,
                name: "Highest sub-index supported".into(),
                data_type: DataType::Unsigned8,
                access: Access::Ro,
                default: Some(EdsValue {
                    value: i64::from(n),
                    plus_node_id: false,
                }),
                default_text: Some(n.to_string()),
                parameter_value: None,
                pdo_mappable: false,
                low: None,
                high: None,
                line,
            },
        );
        let names = self.compact_names.get(&index);
        let values = self.compact_values.get(&index);
        for k in 1..=n {
            let mut e = entry.clone();
            e.sub = k;
            e.name = names
                .and_then(|m| m.get(&k))
                .cloned()
                .unwrap_or_else(|| format!("{}{k}", entry.name));
            e.parameter_value = match values.and_then(|m| m.get(&k)) {
                None => None,
                Some((v, _)) if v.is_empty() => None,
                Some((v, l)) => Some(parse_number(v).ok_or_else(|| {
                    self.err(*l, format!("[{index:04X}Value] {k}: not a number: `{v}`"))
                })?),
            };
            self.entries.insert((index, k), e);
        }
        Ok(())
    }

    /// Every `[XXXXsubN]` has its object section `[XXXX]`.
    fn check_sub_sections(&self) -> Result<(), EdsError> {
        for ((index, sub), e) in &self.entries {
            if *sub != 0 && !self.objects.contains_key(index) {
                return Err(self.err(
                    e.line,
                    format!("[{index:04X}sub{sub:X}] without its object section [{index:04X}]"),
                ));
            }
        }
        Ok(())
    }
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

    /// The simulated pulley load cell's EDS (`config/eds/crs-load-cell.eds`, compiled in).
    pub fn builtin_load_cell() -> &'static Eds {
        static EDS: std::sync::OnceLock<Eds> = std::sync::OnceLock::new();
        EDS.get_or_init(|| {
            Eds::parse(BUILTIN_LOAD_CELL_EDS, BUILTIN_LOAD_CELL_EDS_NAME)
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
        let mut p = Parser {
            file,
            compact_names: BTreeMap::new(),
            compact_values: BTreeMap::new(),
            objects: BTreeMap::new(),
            entries: BTreeMap::new(),
        };
        let sections = p.sections(text)?;
        p.compact_tables(&sections)?;
        for s in &sections {
            if let Some((index, sub)) = object_section(&s.name) {
                p.object(s, index, sub)?;
            }
        }
        p.check_sub_sections()?;
        Ok(Self {
            file: file.to_string(),
            objects: p.objects,
            entries: p.entries,
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
        let values: Vec<(u16, u8, DcfValue)> = configured
            .iter()
            .map(|&(i, s, v)| (i, s, DcfValue::Raw(v)))
            .collect();
        self.write_dcf_values(node_id, node_name, baudrate_kbit, &values)
    }

    /// [`Eds::write_dcf`] with byte-string values too (segmented parameters). Values of signed
    /// types are written as signed decimals (`-1234`), unsigned ones as hex, strings as text
    /// (VISIBLE_STRING) or hex digits (OCTET_STRING, DOMAIN); compact arrays are written out as
    /// `[XXXXsubN]` sections so every sub-index can carry its own `ParameterValue`.
    pub fn write_dcf_values(
        &self,
        node_id: u8,
        node_name: &str,
        baudrate_kbit: u32,
        configured: &[(u16, u8, DcfValue)],
    ) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "; DCF written by drive-io from {} for node {node_id}",
            self.file
        );
        let value_of = |index: u16, sub: u8| -> Option<String> {
            let e = self.entry(index, sub)?;
            configured
                .iter()
                .rev()
                .find(|(i, s2, _)| *i == index && *s2 == sub)
                .and_then(|(_, _, v)| dcf_value_text(e.data_type, v))
        };
        let is_compact_aux = |name: &str| {
            let lower = name.to_ascii_lowercase();
            let idx = lower
                .strip_suffix("name")
                .or_else(|| lower.strip_suffix("value"));
            idx.and_then(|i| u16::from_str_radix(i, 16).ok().filter(|_| i.len() == 4))
                .and_then(|i| self.object(i))
                .is_some_and(|o| o.compact.is_some())
        };
        for s in &self.sections {
            if s.name.eq_ignore_ascii_case("DeviceComissioning") || is_compact_aux(&s.name) {
                continue;
            }
            let key = object_section(&s.name);
            if let Some((index, None)) = key
                && let Some(n) = self.object(index).and_then(|o| o.compact)
            {
                self.write_compact(&mut out, s, index, n, &value_of);
                continue;
            }
            let _ = writeln!(out, "[{}]", s.name);
            let value = key.and_then(|(index, sub)| value_of(index, sub.unwrap_or(0)));
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
                let _ = writeln!(out, "ParameterValue={v}");
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

    /// A `CompactSubObj=n` array written out: the object section with `SubNumber=n+1`, then
    /// `[XXXXsub0]` (n) and `[XXXXsub1..n]` with the shared description and each sub's value.
    fn write_compact(
        &self,
        out: &mut String,
        s: &Section,
        index: u16,
        n: u8,
        value_of: &dyn Fn(u16, u8) -> Option<String>,
    ) {
        const PER_SUB: [&str; 7] = [
            "datatype",
            "accesstype",
            "defaultvalue",
            "pdomapping",
            "lowlimit",
            "highlimit",
            "parametervalue",
        ];
        let key_of = |l: &str| {
            l.split_once('=')
                .map(|(k, _)| k.trim().to_ascii_lowercase())
                .unwrap_or_default()
        };
        let _ = writeln!(out, "[{}]", s.name);
        for l in s.lines.iter().filter(|l| !l.trim().is_empty()) {
            let k = key_of(l);
            if !PER_SUB.contains(&k.as_str()) && k != "compactsubobj" {
                let _ = writeln!(out, "{l}");
            }
        }
        let _ = writeln!(out, "SubNumber={}\n", u16::from(n) + 1);
        let _ = writeln!(
            out,
            "[{index:04X}sub0]\nParameterName=Highest sub-index supported\nObjectType=0x7\n\
             DataType=0x0005\nAccessType=ro\nDefaultValue={n}\nPDOMapping=0\n"
        );
        for k in 1..=n {
            let _ = writeln!(out, "[{index:04X}sub{k:X}]");
            if let Some(e) = self.entry(index, k) {
                let _ = writeln!(out, "ParameterName={}\nObjectType=0x7", e.name);
            }
            for l in s.lines.iter().filter(|l| !l.trim().is_empty()) {
                let key = key_of(l);
                if PER_SUB.contains(&key.as_str()) && key != "parametervalue" {
                    let _ = writeln!(out, "{}", l.trim());
                }
            }
            let value = value_of(index, k).or_else(|| {
                self.entry(index, k)
                    .and_then(|e| e.parameter_value)
                    .map(dcf_number_text)
            });
            if let Some(v) = value {
                let _ = writeln!(out, "ParameterValue={v}");
            }
            let _ = writeln!(out);
        }
    }
}

/// A value drive-io configured in a node, as its DCF records it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DcfValue {
    /// The raw little-endian bits of a value of an expedited type.
    Raw(u32),
    /// A byte string (segmented transfer).
    Bytes(Vec<u8>),
}

/// `ParameterValue` text of `v` for an entry of type `t` (None if they do not go together).
fn dcf_value_text(t: DataType, v: &DcfValue) -> Option<String> {
    match v {
        // Signed types as signed decimals: CiA 306 numbers are values, not bit patterns
        // (Lely's dcfchk rejects 0xF8... for an INTEGER32, python canopen reads it unsigned).
        DcfValue::Raw(raw) if t.is_signed() => Some(t.to_i64(*raw).to_string()),
        DcfValue::Raw(raw) if t.size().is_some() => Some(format!("0x{raw:X}")),
        DcfValue::Bytes(b) if t == DataType::Other(0x0009) => std::str::from_utf8(b)
            .ok()
            .filter(|s| !s.contains(['\n', '\r']))
            .map(str::to_string),
        DcfValue::Bytes(b) if t.is_string() => {
            Some(b.iter().map(|x| format!("{x:02X}")).collect::<String>())
        }
        _ => None,
    }
}

/// A number from the EDS as DCF text (`$NODEID+0x180` kept relative).
fn dcf_number_text(v: EdsValue) -> String {
    if v.plus_node_id {
        format!("$NODEID+0x{:X}", v.value)
    } else if v.value < 0 {
        v.value.to_string()
    } else {
        format!("0x{:X}", v.value)
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
        let cell = Eds::builtin_load_cell();
        assert_eq!(cell.entry(0x1000, 0).unwrap().default_for(1), 0x0002_0194);
        let pv = cell.entry(0x9130, 1).unwrap();
        assert!(pv.pdo_mappable && pv.data_type == DataType::Integer32);
        assert_eq!(cell.entry(0x6131, 1).unwrap().default_for(1), 0x0021_0000);
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
        // CompactSubObj needs an ARRAY and the sub description.
        let e = Eds::parse(
            "[1016]\nParameterName=x\nObjectType=0x9\nCompactSubObj=2\n",
            "a.eds",
        )
        .unwrap_err();
        assert!(e.reason.contains("CompactSubObj"), "{e}");
        let e = Eds::parse(
            "[1016]\nParameterName=x\nObjectType=0x8\nCompactSubObj=2\n",
            "a.eds",
        )
        .unwrap_err();
        assert!(e.reason.contains("DataType"), "{e}");
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

    const COMPACT: &str = "[1016]\nParameterName=Consumer heartbeat time\nObjectType=0x8\n\
        CompactSubObj=3\nDataType=0x0007\nAccessType=rw\nDefaultValue=0\nPDOMapping=0\n\
        [1016Name]\nNrOfEntries=1\n2=Second consumer\n\
        [1016Value]\nNrOfEntries=1\n3=0x007F0064\n\
        [607D]\nParameterName=Software position limit\nObjectType=0x8\nSubNumber=2\n\
        [607Dsub0]\nParameterName=n\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\n\
        [607Dsub1]\nParameterName=Min\nDataType=0x0004\nAccessType=rw\nDefaultValue=0\n\
        [1008]\nParameterName=Manufacturer device name\nDataType=0x0009\nAccessType=const\n\
        DefaultValue=ACME CSP-2000 servo\n";

    #[test]
    fn compact_arrays_expand_into_their_sub_indices() {
        let eds = Eds::parse(COMPACT, "vendor.eds").unwrap();
        let sub0 = eds.entry(0x1016, 0).unwrap();
        assert_eq!(
            (sub0.default_for(1), sub0.data_type),
            (3, DataType::Unsigned8)
        );
        assert!(!sub0.access.writable());
        for k in 1..=3 {
            let e = eds.entry(0x1016, k).unwrap();
            assert_eq!((e.data_type, e.access), (DataType::Unsigned32, Access::Rw));
        }
        assert!(eds.entry(0x1016, 4).is_none());
        assert_eq!(
            eds.entry(0x1016, 1).unwrap().name,
            "Consumer heartbeat time1"
        );
        assert_eq!(eds.entry(0x1016, 2).unwrap().name, "Second consumer");
        assert_eq!(
            eds.entry(0x1016, 3).unwrap().parameter_value.unwrap().value,
            0x007F_0064
        );
        assert_eq!(eds.object(0x1016).unwrap().compact, Some(3));
        let name = eds.entry(0x1008, 0).unwrap();
        assert!(name.data_type.is_string());
        assert_eq!(name.default_text.as_deref(), Some("ACME CSP-2000 servo"));
        assert_eq!(name.data_type.text_bytes("ACME").unwrap(), b"ACME".to_vec());
        assert_eq!(
            DataType::Other(0x000A).text_bytes("0A ff").unwrap(),
            vec![0x0A, 0xFF]
        );
    }

    #[test]
    fn dcf_writes_signed_values_signed_and_compact_arrays_out() {
        let eds = Eds::parse(COMPACT, "vendor.eds").unwrap();
        let dcf = eds.write_dcf_values(
            5,
            "winch 5",
            1000,
            &[
                (0x607D, 1, DcfValue::Raw((-1_234_567i32) as u32)),
                (0x1016, 1, DcfValue::Raw(0x007F_00C8)),
            ],
        );
        assert!(dcf.contains("ParameterValue=-1234567"), "{dcf}");
        assert!(!dcf.contains("CompactSubObj"), "{dcf}");
        assert!(!dcf.contains("[1016Name]"), "{dcf}");
        assert!(dcf.contains("SubNumber=4"), "{dcf}");
        let back = Eds::parse(&dcf, "node05.dcf").unwrap();
        let pv = |i, s| back.entry(i, s).unwrap().parameter_value.map(|v| v.value);
        assert_eq!(pv(0x607D, 1), Some(-1_234_567));
        assert_eq!(pv(0x1016, 1), Some(0x007F_00C8));
        assert_eq!(pv(0x1016, 2), None);
        assert_eq!(pv(0x1016, 3), Some(0x007F_0064));
        assert_eq!(back.entry(0x1016, 2).unwrap().name, "Second consumer");
        assert_eq!(back.entry(0x1016, 0).unwrap().default_for(1), 3);
        assert_eq!(back.object(0x1016).unwrap().compact, None);
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
