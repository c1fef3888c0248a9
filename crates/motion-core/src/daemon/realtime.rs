//! Real-time set-up of the hard loop (SCHED_FIFO, mlockall, CPU affinity, timer slack) and the
//! absolute-deadline periodic timer: the stack's one implementation lives in `crs-rt`; the
//! daemon's `[realtime]` section is its [`RealtimeSettings`].

pub use crs_rt::{Applied, RealtimeReport, RealtimeSettings, apply, monotonic_ns, sleep_until};
