//! The monitor's fixed capacities: its preallocated buffers have these sizes, and the
//! configuration is refused beyond them (config.rs), so neither needs the other.

/// Setpoints remembered for matching drive feedback and RPDO targets (256 ms at 1 kHz).
pub const HISTORY: usize = 256;
/// Largest gap window (cycles).
pub const MAX_GAP_WINDOW: usize = 10_000;
/// Largest force window (readings per cable).
pub const MAX_FORCE_WINDOW: u32 = 64;
