//! Where the cable forces come from: a drive's own force object (`force = "drive"`, the
//! simulated winch's 0x2110 in mN) or a separate force-measuring node per pulley load cell
//! (`[[force_sensor]]` in drives.toml): a CiA 404 measuring device whose analog input process
//! value (0x9130 sub n, INTEGER32; 0x7130 INTEGER16 or 0x6130 REAL32 on other devices) drive-io
//! reads from its TPDO, configures (PDO, transmission type, heartbeat) and checks (identity,
//! optionally the channel's physical unit 0x6131 and decimal digits 0x6132, which fix what one
//! unit of the process value is) like the drives.
//!
//! The simulated node that plays such a device is `cia402_drive::force_node::ForceNode`; its EDS is
//! `config/eds/crs-load-cell.eds` ([`crate::eds::Eds::builtin_load_cell`]).

use crate::identity::Identity;
use crate::mapping::{MappingMode, ObjectRef};
use serde::Deserialize;

/// CiA 404 analog input process value, INTEGER32 (sub n = channel n).
pub const OD_AI_PV_I32: u16 = 0x9130;
/// CiA 404 analog input physical unit of the process value (CiA 303-2 coding).
pub const OD_AI_PHYSICAL_UNIT: u16 = 0x6131;
/// CiA 404 analog input decimal digits of the process value.
pub const OD_AI_DECIMAL_DIGITS: u16 = 0x6132;
/// CiA 404 device type of a measuring device with analog inputs (profile 404 = 0x194,
/// additional information bit 1: analog input).
pub const DEVICE_TYPE_AI: u32 = 0x0002_0194;
/// CiA 303-2 physical unit: newton (unit 0x21, no prefix).
pub const UNIT_NEWTON: u32 = 0x0021_0000;

/// Where a winch's cable force comes from (`[[winch]] force`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(try_from = "ForceSourceText")]
pub enum ForceSource {
    /// The drive's own force object (`force_object`, default 0x2110sub0).
    Drive,
    /// The `[[force_sensor]]` with this node id.
    Sensor(u8),
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ForceSourceText {
    Node(i64),
    Text(String),
}

impl TryFrom<ForceSourceText> for ForceSource {
    type Error = String;
    fn try_from(t: ForceSourceText) -> Result<Self, String> {
        match t {
            ForceSourceText::Text(s) if s == "drive" => Ok(Self::Drive),
            ForceSourceText::Text(s) => Err(format!(
                "`{s}`: expected \"drive\" or the node id of a [[force_sensor]]"
            )),
            ForceSourceText::Node(n) => u8::try_from(n)
                .ok()
                .filter(|n| (1..=127).contains(n))
                .map(Self::Sensor)
                .ok_or_else(|| format!("node id {n} is not 1..=127")),
        }
    }
}

/// A `[[force_sensor]]`: one force-measuring node (a pulley load cell's CiA 404 device).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSensorConfig {
    /// CANopen node id (1..=127), unique on the bus.
    pub node_id: u8,
    /// The cable it measures: 1-based position in the `[[winch]]` list.
    pub cable: usize,
    /// The CAN interface the node is on (with several interfaces).
    #[serde(default)]
    pub interface: Option<String>,
    /// The node's EDS (relative to the TOML); absent = config/eds/crs-load-cell.eds.
    #[serde(default)]
    pub eds: Option<String>,
    #[serde(default)]
    pub identity: Identity,
    /// The measured value drive-io maps into the TPDO (default 0x9130sub1: channel 1's
    /// process value, INTEGER32).
    #[serde(default = "d_object")]
    pub object: ObjectRef,
    /// Newtons per unit of `object` (e.g. 0.1 for a value in 0.1 N).
    pub n_per_unit: f64,
    /// TPDO transmission type: every n-th SYNC (1..=240).
    #[serde(default = "d_every")]
    pub every_n_syncs: u8,
    /// Which TPDO carries the value (1-based; default 1).
    #[serde(default = "d_tpdo")]
    pub tpdo: u16,
    /// The TPDO's COB-ID (default: the predefined 0x180 + 0x100·(tpdo − 1) + node id).
    #[serde(default)]
    pub cob_id: Option<u16>,
    /// `"default"`: drive-io maps `object` into the TPDO; `"fixed"`: the node's TPDO as its
    /// EDS says (it must carry `object`).
    #[serde(default)]
    pub mapping: MappingMode,
    /// Checked at boot: the channel's physical unit (0x6131 sub n, CiA 303-2 coding).
    #[serde(default)]
    pub physical_unit: Option<u32>,
    /// Checked at boot: the channel's decimal digits (0x6132 sub n).
    #[serde(default)]
    pub decimal_digits: Option<u8>,
}

fn d_object() -> ObjectRef {
    ObjectRef {
        index: OD_AI_PV_I32,
        sub: 1,
    }
}
fn d_every() -> u8 {
    1
}
fn d_tpdo() -> u16 {
    1
}

impl ForceSensorConfig {
    /// Validates one sensor (`j` its position in the list) against the drives config;
    /// `(field, reason)` naming the key.
    pub fn validate(
        &self,
        j: usize,
        cables: usize,
        sync_period_us: u32,
        heartbeat_timeout_ms: u32,
    ) -> Result<(), (String, String)> {
        let f = |k: &str| format!("force_sensor[{j}].{k}");
        if !(1..=127).contains(&self.node_id) {
            return Err((f("node_id"), "must be in 1..=127".into()));
        }
        if !(1..=cables).contains(&self.cable) {
            return Err((
                f("cable"),
                format!("must be 1..={cables} (the position of its [[winch]])"),
            ));
        }
        if !(self.n_per_unit.is_finite() && self.n_per_unit != 0.0) {
            return Err((f("n_per_unit"), "must be finite and non-zero".into()));
        }
        if !(1..=240).contains(&self.every_n_syncs) {
            return Err((f("every_n_syncs"), "must be 1..=240".into()));
        }
        if u64::from(self.every_n_syncs) * u64::from(sync_period_us)
            >= u64::from(heartbeat_timeout_ms) * 1000
        {
            return Err((
                f("every_n_syncs"),
                "the force must arrive within bus.heartbeat_timeout_ms (its TPDO timeout)".into(),
            ));
        }
        if !(1..=512).contains(&self.tpdo) {
            return Err((f("tpdo"), "must be 1..=512".into()));
        }
        if self.cob_id.is_none() && self.tpdo > 4 {
            return Err((
                f("cob_id"),
                "required for TPDOs beyond 4 (no predefined COB-ID)".into(),
            ));
        }
        if let Some(c) = self.cob_id
            && !(0x181..=0x57F).contains(&c)
        {
            return Err((f("cob_id"), "must be a PDO COB-ID in 0x181..=0x57F".into()));
        }
        if self.mapping == MappingMode::Custom {
            return Err((
                f("mapping"),
                "\"default\" or \"fixed\" (a force sensor maps one object)".into(),
            ));
        }
        self.identity.validate(&format!("force_sensor[{j}]"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_source_is_drive_or_a_node_id() {
        #[derive(Deserialize)]
        struct T {
            force: ForceSource,
        }
        let t = |s: &str| toml::from_str::<T>(s).map(|t| t.force);
        assert_eq!(t("force = \"drive\"").unwrap(), ForceSource::Drive);
        assert_eq!(t("force = 33").unwrap(), ForceSource::Sensor(33));
        assert!(t("force = 0").is_err());
        assert!(t("force = \"sensor\"").is_err());
    }

    #[test]
    fn sensor_keys_are_named_in_errors() {
        let s: ForceSensorConfig =
            toml::from_str("node_id = 33\ncable = 1\nn_per_unit = 0.1").unwrap();
        assert_eq!(s.object.to_string(), "0x9130sub1");
        assert!(s.validate(0, 8, 1000, 50).is_ok());
        assert_eq!(
            s.validate(0, 0, 1000, 50).unwrap_err().0,
            "force_sensor[0].cable"
        );
        let mut b = s.clone();
        b.every_n_syncs = 60;
        assert_eq!(
            b.validate(2, 8, 1000, 50).unwrap_err().0,
            "force_sensor[2].every_n_syncs"
        );
        let mut b = s.clone();
        b.tpdo = 5;
        assert_eq!(
            b.validate(0, 8, 1000, 50).unwrap_err().0,
            "force_sensor[0].cob_id"
        );
        assert!(toml::from_str::<ForceSensorConfig>("node_id = 33\ncable = 1").is_err());
    }
}
