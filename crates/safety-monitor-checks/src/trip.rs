//! Trip causes and the trip log (cause, cable, Δq / value, time), fixed capacity.

use std::fmt;

/// Why the monitor trips: the contract's [`crs_ipc::TripCause`] (the numeric code is sent in
/// `StateEvent::detail` and in byte 1 of the safety heartbeat, so it is part of the process-bus
/// contract; the names are the monitor's log and report words).
pub use crs_ipc::TripCause as Cause;

/// The cause's bit in a [`CauseSet`] (codes 1..=30 fit a u32).
fn bit(c: Cause) -> u32 {
    1 << c.code()
}

/// A set of causes (bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CauseSet(u32);

impl CauseSet {
    pub fn insert(&mut self, c: Cause) {
        self.0 |= bit(c);
    }
    pub fn contains(&self, c: Cause) -> bool {
        self.0 & bit(c) != 0
    }
    pub fn is_empty(&self) -> bool {
        self.0 == 0
    }
    pub fn clear(&mut self) {
        self.0 = 0;
    }
    /// The causes in code order.
    pub fn iter(&self) -> impl Iterator<Item = Cause> + '_ {
        Cause::ALL.iter().copied().filter(|c| self.contains(*c))
    }
    /// The first cause in code order.
    pub fn first(&self) -> Option<Cause> {
        self.iter().next()
    }
}

/// One detected fault: what, where, how much, when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    pub cause: Cause,
    /// 0-based cable index, if the fault concerns one cable.
    pub cable: Option<u8>,
    /// The offending value: Δq (m) for dq_limit / rpdo_mismatch / following_error, the force (N)
    /// for force_slack / force_overload, m/s or rad/s (m/s², rad/s²) for motion_velocity
    /// (motion_acceleration), a count for sequence_gaps / *_silence, NaN if not applicable.
    pub value: f64,
    /// The limit it was compared with (same unit), NaN if not applicable.
    pub limit: f64,
    /// Sequence number of the setpoint concerned (0 = none).
    pub sequence: u64,
}

impl Fault {
    pub fn new(cause: Cause) -> Self {
        Self {
            cause,
            cable: None,
            value: f64::NAN,
            limit: f64::NAN,
            sequence: 0,
        }
    }
}

/// A trip: the first fault that latched the e-stop, and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TripRecord {
    pub fault: Fault,
    /// CLOCK_MONOTONIC ns of the monitor cycle that detected it.
    pub detected_ns: u64,
    /// Monitor cycle number.
    pub cycle: u64,
}

impl fmt::Display for TripRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fl = &self.fault;
        write!(f, "cause={}", fl.cause)?;
        match fl.cable {
            Some(c) => write!(f, " cable={}", u32::from(c) + 1)?,
            None => write!(f, " cable=-")?,
        }
        if is_length(fl.cause) {
            write!(
                f,
                " dq_mm={:.3} limit_mm={:.3}",
                fl.value * 1e3,
                fl.limit * 1e3
            )?;
        } else {
            write!(f, " value={} limit={}", fl.value, fl.limit)?;
        }
        write!(
            f,
            " sequence={} cycle={} t_ns={}",
            fl.sequence, self.cycle, self.detected_ns
        )
    }
}

/// True if the fault's value is a length (m).
pub fn is_length(c: Cause) -> bool {
    matches!(
        c,
        Cause::DqLimit | Cause::RpdoMismatch | Cause::FollowingError
    )
}

/// The last [`TripLog::CAPACITY`] trips, oldest overwritten (no allocation).
#[derive(Debug, Clone)]
pub struct TripLog {
    entries: [Option<TripRecord>; Self::CAPACITY],
    next: usize,
    total: u64,
}

impl Default for TripLog {
    fn default() -> Self {
        Self {
            entries: [None; Self::CAPACITY],
            next: 0,
            total: 0,
        }
    }
}

impl TripLog {
    pub const CAPACITY: usize = 64;

    pub fn push(&mut self, r: TripRecord) {
        self.entries[self.next] = Some(r);
        self.next = (self.next + 1) % Self::CAPACITY;
        self.total += 1;
    }

    /// Trips ever recorded.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The most recent trip.
    pub fn last(&self) -> Option<&TripRecord> {
        self.entries[(self.next + Self::CAPACITY - 1) % Self::CAPACITY].as_ref()
    }

    /// Oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &TripRecord> {
        (0..Self::CAPACITY)
            .map(move |k| &self.entries[(self.next + k) % Self::CAPACITY])
            .filter_map(Option::as_ref)
    }
}
