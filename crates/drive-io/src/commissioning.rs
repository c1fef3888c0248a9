//! What drive-io writes into each drive at start-up, derived from the drive's EDS and
//! drives.toml: the SDO script ([`plan`]) of PDO communication/mapping (CiA 301 §7.5.2.35-38,
//! the "disable PDO, clear mapping, write entries, set count, enable" order of §7.2.2.3.4),
//! SYNC, heartbeats, the CiA 402 option codes, the mode and the limits the drive supports.
//! Every written value is read back afterwards ([`SdoOp::Verify`]). Nothing here does I/O.
//!
//! Objects are *required* (start-up stops if the EDS lacks them) or *optional* (written only
//! if the EDS lists them: the limits and the communication cycle period).

use crate::canopen::*;
use crate::config::{BusConfig, WinchConfig};
use crate::eds::{Eds, OdEntry};

/// One SDO transfer of the start-up script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoOp {
    /// Expedited download of `len` bytes.
    Write {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
    /// Upload; the value (masked to `len` bytes) must equal `value`.
    Verify {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
}

impl SdoOp {
    pub fn index_sub(&self) -> (u16, u8) {
        match *self {
            Self::Write { index, sub, .. } | Self::Verify { index, sub, .. } => (index, sub),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    #[error("drive node {node}: EDS {eds} lacks required object {object}")]
    Missing {
        node: u8,
        eds: String,
        object: String,
    },
    #[error("drive node {node}: EDS {eds}: {object} {reason}")]
    Unsuitable {
        node: u8,
        eds: String,
        object: String,
        reason: String,
    },
}

/// PDO layout drive-io configures and decodes (docs/can-protocol.md): RPDO1 = controlword +
/// target position, TPDO1 = statusword + position actual, TPDO2 = velocity actual + pulley
/// force; all synchronous (transmission type 1: every SYNC).
pub const RPDO1_MAP: [(u16, u8, u8); 2] = [(OD_CONTROLWORD, 0, 16), (OD_TARGET_POSITION, 0, 32)];
pub const TPDO1_MAP: [(u16, u8, u8); 2] = [(OD_STATUSWORD, 0, 16), (OD_POSITION_ACTUAL, 0, 32)];
pub const TPDO2_MAP: [(u16, u8, u8); 2] =
    [(OD_VELOCITY_ACTUAL, 0, 32), (OD_PULLEY_FORCE_MN, 0, 32)];

/// CiA 402 0x6007 abort connection option codes.
pub const ABORT_CONNECTION_NO_ACTION: i16 = 0;
pub const ABORT_CONNECTION_FAULT: i16 = 1;
pub const ABORT_CONNECTION_DISABLE_VOLTAGE: i16 = 2;
pub const ABORT_CONNECTION_QUICK_STOP: i16 = 3;
/// CiA 402 0x605A quick stop option code 6: slow down on the quick stop ramp and stay in
/// Quick Stop Active (the drive holds under control; the master decides what follows).
pub const QUICK_STOP_STAY: i16 = 6;

struct Builder<'a> {
    eds: &'a Eds,
    node: u8,
    ops: Vec<SdoOp>,
    verify: Vec<SdoOp>,
}

impl Builder<'_> {
    fn missing(&self, index: u16, sub: u8) -> PlanError {
        PlanError::Missing {
            node: self.node,
            eds: self.eds.file.clone(),
            object: format!("0x{index:04X}sub{sub}"),
        }
    }
    fn unsuitable(&self, index: u16, sub: u8, reason: impl Into<String>) -> PlanError {
        PlanError::Unsuitable {
            node: self.node,
            eds: self.eds.file.clone(),
            object: self.eds.describe(index, sub),
            reason: reason.into(),
        }
    }
    fn entry(&self, index: u16, sub: u8) -> Result<&OdEntry, PlanError> {
        self.eds
            .entry(index, sub)
            .ok_or_else(|| self.missing(index, sub))
    }
    /// Writes `value` (range-checked against the EDS); `verify` = read back afterwards.
    fn write(&mut self, index: u16, sub: u8, value: i64, verify: bool) -> Result<(), PlanError> {
        let e = self.entry(index, sub)?;
        if !e.access.writable() {
            return Err(self.unsuitable(index, sub, format!("is {:?}, not writable", e.access)));
        }
        let Some(len) = e.data_type.size() else {
            return Err(self.unsuitable(index, sub, "has no expedited data type"));
        };
        // Unsigned32 COB-IDs / mapping entries are bit patterns; signed values are checked.
        if let Err(r) = e.check_range(value) {
            return Err(self.unsuitable(index, sub, format!("cannot take {r}")));
        }
        let op = SdoOp::Write {
            index,
            sub,
            value: value as u32,
            len,
        };
        self.ops.push(op);
        if verify {
            self.verify.retain(|v| v.index_sub() != (index, sub));
            self.verify.push(SdoOp::Verify {
                index,
                sub,
                value: value as u32,
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
    fn check_mappable(&self, index: u16, sub: u8, bits: u8, tx: bool) -> Result<(), PlanError> {
        let e = self.entry(index, sub)?;
        if !e.pdo_mappable {
            return Err(self.unsuitable(index, sub, "is not PDO-mappable (PDOMapping=0)"));
        }
        if e.data_type.size().map(|s| s * 8) != Some(bits) {
            return Err(self.unsuitable(index, sub, format!("is not {bits} bits wide")));
        }
        if tx && !e.access.readable() || !tx && !e.access.writable() {
            return Err(self.unsuitable(
                index,
                sub,
                format!("access {:?} cannot be mapped", e.access),
            ));
        }
        Ok(())
    }
    /// One PDO: disable, clear the mapping, map, set the count, transmission type, enable.
    fn pdo(
        &mut self,
        comm: u16,
        map: u16,
        cob_id: u16,
        objects: &[(u16, u8, u8)],
        tx: bool,
    ) -> Result<(), PlanError> {
        for &(i, s, b) in objects {
            self.check_mappable(i, s, b, tx)?;
        }
        let valid = i64::from(cob_id);
        self.write(comm, 1, valid | 0x8000_0000, false)?;
        self.write(map, 0, 0, false)?;
        for (k, &(i, s, b)) in objects.iter().enumerate() {
            let entry = (u32::from(i) << 16) | (u32::from(s) << 8) | u32::from(b);
            self.write(map, k as u8 + 1, i64::from(entry), true)?;
        }
        self.write(map, 0, objects.len() as i64, true)?;
        self.write(comm, 2, 1, true)?;
        self.write(comm, 1, valid, true)?;
        Ok(())
    }
    /// Disables a PDO the layout does not use (its default might be valid).
    fn disable_pdo(&mut self, comm: u16) -> Result<(), PlanError> {
        if let Some(e) = self.eds.entry(comm, 1) {
            let cob = e.default_for(self.node) & 0x7FF;
            self.write(comm, 1, cob | 0x8000_0000, true)?;
        }
        Ok(())
    }
}

/// The start-up script of drive `w` on `bus` from its EDS: writes in order, then the read-back
/// of every value written and of 0x6061 == CSP. The error names drive, EDS and object.
pub fn plan(eds: &Eds, w: &WinchConfig, bus: &BusConfig) -> Result<Vec<SdoOp>, PlanError> {
    let n = w.node_id;
    let mut b = Builder {
        eds,
        node: n,
        ops: Vec::new(),
        verify: Vec::new(),
    };
    let nid = |base: u16| base + u16::from(n);
    b.pdo(0x1400, 0x1600, nid(COB_RPDO1_BASE), &RPDO1_MAP, false)?;
    b.pdo(0x1800, 0x1A00, nid(COB_TPDO1_BASE), &TPDO1_MAP, true)?;
    b.pdo(0x1801, 0x1A01, nid(COB_TPDO2_BASE), &TPDO2_MAP, true)?;
    for comm in [0x1401, 0x1402, 0x1403, 0x1802, 0x1803] {
        b.disable_pdo(comm)?;
    }
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
    b.write(OD_MODES_OF_OPERATION, 0, i64::from(MODE_CSP), true)?;
    b.entry(OD_MODES_DISPLAY, 0)?;
    let mut ops = b.ops;
    ops.extend(b.verify);
    ops.push(SdoOp::Verify {
        index: OD_MODES_DISPLAY,
        sub: 0,
        value: u32::from(MODE_CSP as u8),
        len: 1,
    });
    Ok(ops)
}

/// The `(index, sub, value)` a drive holds after the script (what the DCF records).
pub fn configured_values(ops: &[SdoOp]) -> Vec<(u16, u8, u32)> {
    ops.iter()
        .filter_map(|op| match *op {
            SdoOp::Verify {
                index, sub, value, ..
            } if index != OD_MODES_DISPLAY => Some((index, sub, value)),
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::DrivesConfig;

    fn cfg() -> DrivesConfig {
        DrivesConfig::parse(
            "[bus]\ntransport = \"udpbus:239.255.70.1:20000\"\n[[winch]]\nnode_id = 3\n\
             drum_diameter_m = 0.305\ngear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = -1\n\
             max_cable_length_m = 20.0\n",
        )
        .unwrap()
    }

    #[test]
    fn plan_maps_pdos_in_the_cia301_order_and_verifies_everything() {
        let c = cfg();
        let ops = plan(Eds::builtin_winch(), &c.winches[0], &c.bus).unwrap();
        let writes: Vec<(u16, u8, u32)> = ops
            .iter()
            .filter_map(|o| match *o {
                SdoOp::Write {
                    index, sub, value, ..
                } => Some((index, sub, value)),
                _ => None,
            })
            .collect();
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
        assert!(writes.contains(&(0x1A01, 2, 0x2110_0020)));
        assert!(writes.contains(&(0x1401, 1, 0x8000_0303)));
        assert!(writes.contains(&(0x6007, 0, 2)));
        assert!(writes.contains(&(0x605A, 0, 6)));
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
    }

    #[test]
    fn missing_or_unmappable_objects_name_drive_eds_and_object() {
        let c = cfg();
        let text = crate::eds::BUILTIN_WINCH_EDS.replace("[6007]", "[2FF7]");
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan(&eds, &c.winches[0], &c.bus).unwrap_err().to_string();
        assert!(
            e.contains("node 3") && e.contains("vendor.eds") && e.contains("0x6007"),
            "{e}"
        );
        // Pulley force not mappable: refused before anything is written.
        let text = crate::eds::BUILTIN_WINCH_EDS.replace(
            "ParameterName=Pulley force (mN)\nObjectType=0x7\nDataType=0x0004\nAccessType=ro\nDefaultValue=0\nPDOMapping=1",
            "ParameterName=Pulley force (mN)\nObjectType=0x7\nDataType=0x0004\nAccessType=ro\nDefaultValue=0\nPDOMapping=0",
        );
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan(&eds, &c.winches[0], &c.bus).unwrap_err().to_string();
        assert!(
            e.contains("0x2110") && e.contains("not PDO-mappable"),
            "{e}"
        );
        // A limit outside the EDS range is refused with the reason.
        let mut bus = c.bus.clone();
        bus.abort_connection_option = 3;
        let text = crate::eds::BUILTIN_WINCH_EDS
            .replace("LowLimit=0\nHighLimit=3", "LowLimit=0\nHighLimit=1");
        let eds = Eds::parse(&text, "vendor.eds").unwrap();
        let e = plan(&eds, &c.winches[0], &bus).unwrap_err().to_string();
        assert!(e.contains("0x6007") && e.contains("HighLimit"), "{e}");
    }
}
