//! drive-io: CANopen CiA 402 master for the m winch drives of the cable robot, in cyclic
//! synchronous position mode (CSP, 0x6060 = 8).
//!
//! * [`master`]: pure master logic (the drives' state machines, RPDOs, TPDO decoding, the
//!   nodes' start-up scripts); [`runner`]: the process loop with iceoryx2;
//!   [`sync_clock`]: when a cycle starts (isochronous, phase-locked or free-running);
//!   [`reset`]: the one gate that accepts the safety monitor's reset; [`cli`]: the command line.
//!
//! The protocol both sides of the bus share is `drive-bus`, drives.toml is `drives-config`,
//! the start-up scripts and the bus budget are `drive-commissioning`; the drive side the
//! simulated plant plays is `cia402-drive`.

pub mod cli;
pub mod master;
pub mod reset;
pub mod runner;
pub mod sync_clock;

pub use master::Master;
