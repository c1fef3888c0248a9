//! Commissioning the drive bus from drives.toml and each node's EDS (CiA 306):
//!
//! * [`commissioning`]: per node the SDO start-up script (identity checks, PDO mapping,
//!   settings, read-back) and its PDO layout; drive-io's master runs the scripts at start,
//!   `drive-io --print-plan` and `crs commission` print them.
//! * [`budget`]: the bus budget of every interface from those layouts (frames per SYNC period
//!   at worst-case bit stuffing, the RPDO guard before the SYNC), which drive-io and `crs sim`
//!   check before anything starts.

pub mod budget;
pub mod commissioning;
