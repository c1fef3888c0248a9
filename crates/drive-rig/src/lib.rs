//! Test rigs of the drive bus, out of drive-io's production library and binaries:
//! * [`emulator`]: the winch emulator (binary `winch-emulator`), a TEST DOUBLE of the drives
//!   (kinematic winches, no physics; sim-plant is the plant) for the safety monitor's fault
//!   matrix and the interop suite;
//! * [`hil`]: the drive adapter's hardware-in-the-loop scenarios (binary `drive-io-hil` in the
//!   vcan guest, `tests/hil_wire.rs` on the host's wire model);
//! * [`interop`]: drive-io against python canopen drives (binary `drive-io-interop`,
//!   tools/canopen-interop.sh);
//! * `bus-latency-bench`: the cycle designs side by side on the wire model (benches/RESULTS.md).

pub mod emulator;
pub mod hil;
pub mod interop;
