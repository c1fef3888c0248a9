//! The drive side of the drive bus, as the simulated plant (`sim-plant`) and the winch emulator
//! (`drive-rig`) play it: pure logic, frames and times in, frames out, the physics the
//! embedder's. It shares the protocol with drive-io's master only through `drive-bus` (and
//! drives.toml through `drives-config`), so the plant stays an independent counterpart of the
//! master.
//!
//! * [`slave`]: one CiA 402 winch drive in cyclic synchronous position mode (NMT, SDO server
//!   over the object dictionary of its EDS, RPDO/SYNC, TPDOs, heartbeat) and [`slave::WinchAxis`],
//!   the emulator's kinematic axis.
//! * [`force_node`]: a CiA 404 force-measuring node (one analog input per pulley load cell).
//! * [`bank`]: the drives and force nodes of one interface, stepped together.
//! * [`bank_set`]: one bank per CAN interface, addressed by cable index.
//! * [`safety_io`]: the safety I/O node (the monitor's doubled heartbeat → STO).

pub mod bank;
pub mod bank_set;
pub mod force_node;
pub mod safety_io;
pub mod slave;
