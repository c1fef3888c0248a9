//! # safety-monitor-config: the safety monitor's settings
//!
//! config/safety-monitor.toml as serde sections with a `validate()` each ([`config`]), the CAN
//! interfaces and node layout it watches ([`bus_layout`]), the operator group of the reset
//! socket ([`group`]) and the acceptance of a changed platform file ([`accept`]). The limits
//! the checks use are `Limits::from(&MonitorConfig)`.

pub mod accept;
pub mod bus_layout;
pub mod config;
pub mod group;

// The checks' modules under the paths the configuration has always used.
pub(crate) use safety_monitor_checks::{capacity, identity, platform};
