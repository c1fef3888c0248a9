//! The checks of a `[[winch]]` entry that need no EDS (mapping lists, feedback rate, force
//! source, vendor parameters), and the vendor parameter type; the checks against the drive's
//! EDS are the commissioning plan's (`drive_commissioning::commissioning::plan_drive`).

use crate::{DrivesConfig, WinchConfig};
use drive_bus::force_sensor::ForceSource;
use drive_bus::mapping::{Direction, MappingMode, ObjectRef, predefined_cob_base};
use drive_bus::sdo::SDO_MAX;
use serde::Deserialize;

/// A vendor parameter written at start-up (`[[winch]] parameters = [{ object = "0x2000sub1",
/// value = 3 }]`; a string value is written as bytes, segmented beyond 4).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Parameter {
    pub object: ObjectRef,
    pub value: ParameterValue,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum ParameterValue {
    Integer(i64),
    Text(String),
}

/// The mapping mode of winch `w` (explicit lists imply custom).
pub fn winch_mapping_mode(w: &WinchConfig) -> MappingMode {
    match w.mapping {
        Some(m) => m,
        None if !w.rpdo.is_empty() || !w.tpdo.is_empty() => MappingMode::Custom,
        None => MappingMode::Default,
    }
}

/// Checks of winch `i`'s mapping, force and parameter keys that need no EDS; `(field, reason)`.
pub fn validate_winch(cfg: &DrivesConfig, i: usize) -> Result<(), (String, String)> {
    let w = &cfg.winches[i];
    let f = |k: &str| format!("winch[{i}].{k}");
    w.identity.validate(&format!("winch[{i}]"))?;
    let mode = winch_mapping_mode(w);
    let lists = !w.rpdo.is_empty() || !w.tpdo.is_empty();
    if mode == MappingMode::Custom && !lists {
        return Err((
            f("mapping"),
            "\"custom\" needs [[winch.rpdo]] and [[winch.tpdo]] lists".into(),
        ));
    }
    if mode != MappingMode::Custom && lists {
        return Err((
            f("mapping"),
            "[[winch.rpdo]] / [[winch.tpdo]] lists are a custom mapping: set mapping = \"custom\" or remove them".into(),
        ));
    }
    for (name, list, dir) in [
        ("rpdo", &w.rpdo, Direction::ToNode),
        ("tpdo", &w.tpdo, Direction::FromNode),
    ] {
        for (k, p) in list.iter().enumerate() {
            let key = |x: &str| format!("winch[{i}].{name}[{k}].{x}");
            if !(1..=512).contains(&p.number) || list[..k].iter().any(|o| o.number == p.number) {
                return Err((key("number"), "must be 1..=512 and unique".into()));
            }
            if p.cob_id.is_none() && predefined_cob_base(dir, p.number).is_none() {
                return Err((key("cob_id"), "required for PDOs beyond 4".into()));
            }
            if p.objects.is_empty() {
                return Err((key("objects"), "must name at least one object".into()));
            }
            if dir == Direction::ToNode
                && (p.inhibit_time_us.is_some() || p.event_timer_ms.is_some())
            {
                return Err((key("inhibit_time_us"), "TPDOs only".into()));
            }
            if p.inhibit_time_us
                .is_some_and(|us| us % 100 != 0 || us / 100 > u32::from(u16::MAX))
            {
                return Err((
                    key("inhibit_time_us"),
                    "must be a multiple of 100 µs up to 6553500".into(),
                ));
            }
        }
    }
    if let Some(n) = w.feedback_every_n_syncs {
        if !(1..=240).contains(&n) {
            return Err((f("feedback_every_n_syncs"), "must be 1..=240".into()));
        }
        if u64::from(n) * u64::from(cfg.bus.sync_period_us)
            >= u64::from(cfg.bus.heartbeat_timeout_ms) * 1000
        {
            return Err((
                f("feedback_every_n_syncs"),
                "the feedback must arrive within bus.heartbeat_timeout_ms".into(),
            ));
        }
    }
    if let Some(s) = w.force_n_per_unit
        && !(s.is_finite() && s != 0.0)
    {
        return Err((f("force_n_per_unit"), "must be finite and non-zero".into()));
    }
    match w.force {
        Some(ForceSource::Sensor(n)) => match cfg.force_sensors.iter().find(|s| s.node_id == n) {
            None => return Err((f("force"), format!("no [[force_sensor]] has node_id {n}"))),
            Some(s) if s.cable != i + 1 => {
                return Err((
                    f("force"),
                    format!(
                        "force sensor node {n} measures cable {}, not this one ({})",
                        s.cable,
                        i + 1
                    ),
                ));
            }
            Some(_) => {}
        },
        Some(ForceSource::Drive) if cfg.force_sensors.iter().any(|s| s.cable == i + 1) => {
            return Err((
                f("force"),
                format!("\"drive\", but a [[force_sensor]] measures cable {}", i + 1),
            ));
        }
        Some(ForceSource::Drive) => {}
        None => {}
    }
    if cfg.force_sensor_of(i).is_some()
        && (w.force_object.is_some() || w.force_n_per_unit.is_some())
    {
        return Err((f("force_object"), "only with force = \"drive\"".into()));
    }
    for (k, p) in w.parameters.iter().enumerate() {
        if let ParameterValue::Text(t) = &p.value
            && (t.is_empty() || t.len() > SDO_MAX)
        {
            return Err((
                format!("winch[{i}].parameters[{k}].value"),
                format!("a text value must be 1..={} bytes", SDO_MAX),
            ));
        }
    }
    Ok(())
}
