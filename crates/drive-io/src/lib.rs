//! drive-io: CANopen CiA 402 master for the m winch drives of the cable robot, in cyclic
//! synchronous position mode (CSP, 0x6060 = 8), plus the drive-side emulation ([`slave`]) that
//! simulated plants embed and a kinematic winch emulator ([`emulator`], a TEST DOUBLE).
//!
//! * [`config`]: config/drives.toml (transport, timing, per-winch length <-> counts scaling).
//! * [`canopen`]: COB-IDs, objects, PDO/SDO/NMT encoding (docs/can-protocol.md).
//! * [`eds`]: CiA 306 EDS/DCF files; [`commissioning`]: the SDO start-up script from the EDS.
//! * [`master`]: pure master logic; [`runner`]: the 1 ms process loop with iceoryx2;
//!   [`sync_clock`]: when a cycle starts (phase-locked to the setpoints, or free-running).
//! * [`hil`]: hardware-in-the-loop scenarios run on the host (UDP bus) and in the vcan VM.

pub mod bank_set;
pub mod budget;
pub mod canopen;
pub mod cli;
pub mod commissioning;
pub mod config;
pub mod eds;
pub mod force_node;
pub mod force_sensor;
pub mod identity;
pub mod mapping;
pub mod master;
pub mod reset;
pub mod runner;
pub mod safety_io;
pub mod safety_watch;
pub mod sdo;
pub mod slave;
pub mod sync_clock;

pub use config::{ConfigError, DrivesConfig, WinchConfig};
pub use master::Master;
