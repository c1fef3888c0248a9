//! The monitor's fixed capacities: its preallocated buffers have these sizes, and the
//! configuration is refused beyond them (config.rs), so neither needs the other.

/// Setpoints remembered for matching drive feedback and RPDO targets (256 ms at 1 kHz).
pub const HISTORY: usize = 256;
/// Largest gap window (cycles).
pub const MAX_GAP_WINDOW: usize = 10_000;
/// Largest force window (readings per cable).
pub const MAX_FORCE_WINDOW: u32 = 64;
/// Longest bus-reader stall the configuration allows (`can.reader_stall_cycles`, cycles); a
/// longer one trips `bus_observation` by itself.
pub const MAX_READER_STALL_CYCLES: u32 = 67;
/// Frames the monitor sends on its own identifiers per cycle: the configuration signature pair
/// and the heartbeat pair.
pub const OWN_FRAMES_PER_CYCLE: usize = 4;
/// Own frames remembered to recognise their echo on the bus: every frame of the longest reader
/// stall the configuration allows, and one cycle more (a stalled reader must not take the
/// monitor's own frames, read late, for another node's).
pub const SENT_OWN_FRAMES: usize = OWN_FRAMES_PER_CYCLE * (MAX_READER_STALL_CYCLES as usize + 1);
