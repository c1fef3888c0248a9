//! What both sides of the drive bus share — drive-io's CiA 402 master and the drive side that
//! the simulated plant and the winch emulator play (`cia402-drive`) — written once:
//!
//! * [`canopen`]: COB-IDs, objects, NMT/SYNC/PDO/SDO/EMCY encoding, the CiA 402 state word
//!   (docs/can-protocol.md).
//! * [`eds`]: CiA 306 EDS/DCF files (the object dictionary a node implements, the objects the
//!   master configures).
//! * [`sdo`]: the SDO client (master) and server (drive side), expedited and segmented.
//! * [`mapping`]: PDO layouts (default and custom mappings, their decoding).
//! * [`identity`]: the identity objects (0x1018, 0x1008) and their checks.
//! * [`force_sensor`]: CiA 404 force-measuring devices' objects and their drives.toml entry.
//! * [`safety_watch`]: validation of the safety monitor's doubled heartbeat (the consumer side
//!   of `can_transport::safety_frame`), used by the drives, the safety I/O node and the master.

pub mod canopen;
pub mod eds;
pub mod force_sensor;
pub mod identity;
pub mod mapping;
pub mod safety_watch;
pub mod sdo;
