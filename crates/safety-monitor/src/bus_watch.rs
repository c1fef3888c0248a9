//! Health of the monitor's own bus reader thread, checked by the cycle (fail closed): the
//! RPDO, heartbeat and force checks only see what that thread reads, so a dead or stalled
//! reader, receive errors or dropped observations must trip instead of leaving them blind.

use std::sync::atomic::{AtomicU64, Ordering};

/// Counters the reader thread advances (lock-free, shared with the cycle).
#[derive(Debug, Default)]
pub struct ReaderHealth {
    /// Batches the reader completed (advances every batch period, with or without traffic).
    pub batches: AtomicU64,
    /// Observations the queue could not take.
    pub dropped: AtomicU64,
    /// Receive errors of the reader's socket.
    pub errors: AtomicU64,
}

/// What went wrong with the reader, for the trip log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReaderFault {
    /// No batch completed for this many monitor cycles (thread dead, hung or starved).
    Stalled(u32),
    /// This many observations were dropped since the last cycle.
    Dropped(u64),
    /// This many receive errors since the last cycle.
    ReceiveErrors(u64),
}

impl ReaderFault {
    /// The number recorded as the trip's value: stalled cycles, dropped observations or
    /// receive errors (negative for errors, so the trip log tells them apart).
    pub fn value(self) -> f64 {
        match self {
            ReaderFault::Stalled(n) => f64::from(n),
            ReaderFault::Dropped(n) => n as f64,
            ReaderFault::ReceiveErrors(n) => -(n as f64),
        }
    }
}

/// The cycle's view of [`ReaderHealth`]: call [`ReaderWatch::check`] once per cycle.
#[derive(Debug, Clone, Copy)]
pub struct ReaderWatch {
    stall_limit: u32,
    last_batches: u64,
    last_dropped: u64,
    last_errors: u64,
    stalled: u32,
}

impl ReaderWatch {
    /// `stall_limit`: cycles without a completed batch before the reader counts as dead.
    pub fn new(stall_limit: u32) -> Self {
        Self {
            stall_limit: stall_limit.max(1),
            last_batches: 0,
            last_dropped: 0,
            last_errors: 0,
            stalled: 0,
        }
    }

    pub fn check(&mut self, h: &ReaderHealth) -> Option<ReaderFault> {
        let (b, d, e) = (
            h.batches.load(Ordering::Relaxed),
            h.dropped.load(Ordering::Relaxed),
            h.errors.load(Ordering::Relaxed),
        );
        let (new_d, new_e) = (
            d.saturating_sub(self.last_dropped),
            e.saturating_sub(self.last_errors),
        );
        if b == self.last_batches {
            self.stalled = self.stalled.saturating_add(1);
        } else {
            self.stalled = 0;
        }
        (self.last_batches, self.last_dropped, self.last_errors) = (b, d, e);
        if new_e > 0 {
            Some(ReaderFault::ReceiveErrors(new_e))
        } else if new_d > 0 {
            Some(ReaderFault::Dropped(new_d))
        } else if self.stalled >= self.stall_limit {
            Some(ReaderFault::Stalled(self.stalled))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_reader_passes_and_each_failure_is_reported() {
        let h = ReaderHealth::default();
        let mut w = ReaderWatch::new(3);
        for _ in 0..10 {
            h.batches.fetch_add(5, Ordering::Relaxed);
            assert_eq!(w.check(&h), None);
        }
        // Stalled: the third cycle without a batch trips.
        assert_eq!(w.check(&h), None);
        assert_eq!(w.check(&h), None);
        assert_eq!(w.check(&h), Some(ReaderFault::Stalled(3)));
        h.batches.fetch_add(1, Ordering::Relaxed);
        assert_eq!(w.check(&h), None);
        h.dropped.fetch_add(7, Ordering::Relaxed);
        h.batches.fetch_add(1, Ordering::Relaxed);
        assert_eq!(w.check(&h), Some(ReaderFault::Dropped(7)));
        h.batches.fetch_add(1, Ordering::Relaxed);
        assert_eq!(w.check(&h), None, "counted once");
        h.errors.fetch_add(2, Ordering::Relaxed);
        h.batches.fetch_add(1, Ordering::Relaxed);
        assert_eq!(w.check(&h), Some(ReaderFault::ReceiveErrors(2)));
        assert_eq!(ReaderFault::ReceiveErrors(2).value(), -2.0);
    }
}
