//! Service names and per-service port settings: the one place every process takes them from.

use crate::payloads::*;
use iceoryx2::prelude::ZeroCopySend;

/// Event service used only for rare wake-ups (e-stop); see [`crate::IpcNode::wakeup_notifier`].
pub const WAKEUP_EVENT: &str = "crs/v1/wakeup";

/// Event service "a setpoint was published": motion-core's publish stage
/// notifies it once per pass, after the setpoints are in shared memory; drive-io waits on it
/// (next to its CAN socket) to send the RPDOs and SYNC of that setpoint at once instead of at
/// its next free-running tick. See [`crate::IpcNode::setpoint_ready_notifier`].
pub const SETPOINT_READY_EVENT: &str = "crs/v1/setpoint_ready";

/// A publish-subscribe topic of the contract: payload type + service name + port settings.
///
/// Buffer sizes: the slowest reader is the 15 ms safety monitor; a buffer of 32 holds 32 ms of a
/// 1 kHz stream, so it sees every sample with margin (iceoryx2's default of 2 would drop 13/15).
/// The setpoint stream buffers 64 (64 ms at 1 kHz, 256 ms at the 4 ms test loop): longer than
/// the drives' safety-heartbeat validation time (50 ms; 150 ms in the relaxed test profile), so
/// a monitor stalled by its host either catches up and checks every setpoint, or is stopped by
/// the drives' watch of its heartbeat — a late MONITOR is not misreported as a lossy STREAM
/// (`sequence_gaps`). Seen in CI: a monitor starved > 128 ms on a shared 2-core host tripped
/// `sequence_gaps` with the 32-sample buffer while the stream itself had no gap.
pub trait Topic: Copy + core::fmt::Debug + ZeroCopySend + 'static {
    /// Service name without prefix, e.g. `crs/v1/joint_setpoints`.
    const NAME: &'static str;
    /// Samples buffered per subscriber before the oldest is overwritten (safe overflow).
    const SUBSCRIBER_BUFFER: usize;
    /// Samples delivered to a late-joining subscriber.
    const HISTORY: usize;
    const MAX_PUBLISHERS: usize;
    const MAX_SUBSCRIBERS: usize;
    const MAX_NODES: usize = 16;
    /// Contract version carried in the payload.
    fn version(&self) -> u32;
}

macro_rules! topic {
    ($t:ty, $name:expr, buffer = $b:expr, history = $h:expr, publishers = $p:expr, subscribers = $s:expr) => {
        impl Topic for $t {
            const NAME: &'static str = $name;
            const SUBSCRIBER_BUFFER: usize = $b;
            const HISTORY: usize = $h;
            const MAX_PUBLISHERS: usize = $p;
            const MAX_SUBSCRIBERS: usize = $s;
            fn version(&self) -> u32 {
                self.version
            }
        }
    };
}

// motion-core -> drive-io, safety monitor, loggers. One producer (motion-core), 1 kHz.
topic!(
    JointSetpoint,
    "crs/v1/joint_setpoints",
    buffer = 64,
    history = 0,
    publishers = 1,
    subscribers = 8
);
// drive-io -> motion-core, safety monitor, loggers. 1 kHz (one per SYNC).
topic!(
    DriveFeedback,
    "crs/v1/drive_feedback",
    buffer = 32,
    history = 0,
    publishers = 1,
    subscribers = 8
);
// Any process -> all: e-stop, faults, state changes. Rare but must never be lost: big buffer,
// short history so a process that starts late still sees a latched e-stop.
topic!(
    StateEvent,
    "crs/v1/state_events",
    buffer = 64,
    history = 8,
    publishers = 8,
    subscribers = 8
);
// Every process publishes its heartbeat (typ. 10-100 Hz); watchers poll at >= 15 ms.
topic!(
    Heartbeat,
    "crs/v1/heartbeats",
    buffer = 64,
    history = 0,
    publishers = 8,
    subscribers = 8
);
// Simulated plant (or a real tracker) -> calibration, safety monitor, tests. 1 kHz.
topic!(
    TrackerPose,
    "crs/v1/tracker_pose",
    buffer = 32,
    history = 0,
    publishers = 1,
    subscribers = 8
);
// motion-core -> safety monitor: which platform model the motion core runs. Announced at start
// and re-announced about once per second: iceoryx2 0.10 hands history to a late subscriber only
// when the publisher next acts, so history 1 alone is not enough.
topic!(
    PlatformIdentity,
    "crs/v1/platform_identity",
    buffer = 4,
    history = 1,
    publishers = 1,
    subscribers = 8
);
// Motion-cueing source -> motion-core. Reference poses at up to 1 kHz; motion-core takes the
// newest each cycle.
topic!(
    CueingPose,
    "crs/v1/cueing_pose",
    buffer = 32,
    history = 0,
    publishers = 1,
    subscribers = 4
);
// motion-core -> launcher, loggers: loop statistics about once per second.
topic!(
    LoopStatsSample,
    "crs/v1/loop_stats",
    buffer = 8,
    history = 1,
    publishers = 1,
    subscribers = 8
);
// sim-plant -> launcher, tests: ground truth of the simulated plant (a real robot has none).
topic!(
    PlantTruth,
    "crs/v1/plant_truth",
    buffer = 64,
    history = 1,
    publishers = 1,
    subscribers = 8
);
// drive-io -> motion-core: the isochronous SYNC schedule, about once per second (history 1 so a
// motion-core that starts later learns it at the next announcement).
topic!(
    SyncSchedule,
    "crs/v1/sync_schedule",
    buffer = 4,
    history = 1,
    publishers = 1,
    subscribers = 8
);
