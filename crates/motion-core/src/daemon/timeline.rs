//! The loop's timeline, placed a fixed lead before drive-io's SYNC.
//!
//! With an isochronous drive bus (`sync_source = "isochronous"` in drives.toml) drive-io's SYNC
//! is the bus clock: the drives latch the last RPDO target at each SYNC, and drive-io announces
//! the SYNC grid (`crs/v1/sync_schedule`). A setpoint is worth the most when it arrives just
//! before a SYNC: earlier it ages, later it waits a whole period. So the loop ticks `lead` before
//! each SYNC (configured `[realtime] sync_lead_us`: the publish stage's phase, drive-io's
//! wake-up and the RPDOs' time on the wire must fit in it). Without an announced schedule the
//! loop runs on its own grid, as before.
//!
//! The publish stage learns the schedule (it owns the iceoryx2 ports) and stores the wanted
//! phase here; the loop reads it with one relaxed atomic load per cycle (no lock, no
//! allocation) and moves its next deadline onto it — once per change of the schedule, by at
//! most half a period, so the trajectory (sampled per cycle) never skips or doubles a cycle.

use std::sync::atomic::{AtomicU64, Ordering};

/// No phase announced: the loop keeps its own grid.
const NONE: u64 = u64::MAX;

/// The wanted phase of the loop's ticks (see the module docs).
#[derive(Debug)]
pub struct Timeline {
    period_ns: u64,
    phase_ns: AtomicU64,
}

impl Timeline {
    pub fn new(period_ns: u64) -> Self {
        Self {
            period_ns: period_ns.max(1),
            phase_ns: AtomicU64::new(NONE),
        }
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Ticks wanted at `phase_ns` (mod the period) from now on; a phase for another period is
    /// ignored (the drive bus and the loop disagree on the period: the loop keeps its grid).
    pub fn set_phase(&self, phase_ns: u64, period_ns: u64) -> bool {
        if period_ns != self.period_ns {
            return false;
        }
        self.phase_ns
            .store(phase_ns % self.period_ns, Ordering::Relaxed);
        true
    }

    /// The announced phase, if any.
    pub fn phase_ns(&self) -> Option<u64> {
        match self.phase_ns.load(Ordering::Relaxed) {
            NONE => None,
            p => Some(p),
        }
    }

    /// `deadline` moved to the nearest instant at the wanted phase plus `offset_ns` (within
    /// half a period either way); unchanged without an announced phase.
    #[inline]
    pub fn align(&self, deadline: u64, offset_ns: u64) -> u64 {
        let Some(phase) = self.phase_ns() else {
            return deadline;
        };
        let p = self.period_ns;
        let want = (phase + offset_ns) % p;
        let have = deadline % p;
        // Signed shift in (−p/2, p/2].
        let mut shift = want as i64 - have as i64;
        let half = (p / 2) as i64;
        if shift > half {
            shift -= p as i64;
        } else if shift <= -half {
            shift += p as i64;
        }
        deadline.saturating_add_signed(shift)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const US: u64 = 1_000;

    #[test]
    fn a_deadline_moves_to_the_announced_phase_by_at_most_half_a_period() {
        let t = Timeline::new(MS);
        assert_eq!(
            t.align(5 * MS + 123 * US, 0),
            5 * MS + 123 * US,
            "no schedule yet"
        );
        // SYNCs at k ms + 100 µs, the loop 700 µs before them: ticks at k ms + 400 µs.
        assert!(t.set_phase((100 * US + MS - 700 * US) % MS, MS));
        assert_eq!(t.align(5 * MS + 123 * US, 0), 5 * MS + 400 * US);
        assert_eq!(t.align(5 * MS + 950 * US, 0), 6 * MS + 400 * US);
        // On the phase already: unchanged; the publish stage 200 µs after the loop.
        assert_eq!(t.align(7 * MS + 400 * US, 0), 7 * MS + 400 * US);
        assert_eq!(t.align(7 * MS + 400 * US, 200 * US), 7 * MS + 600 * US);
        for d in (0..3000).map(|k| 10 * MS + k * 997) {
            let a = t.align(d, 0);
            assert_eq!(a % MS, 400 * US);
            assert!(a.abs_diff(d) <= MS / 2, "{d} -> {a}");
        }
        // Another period: refused, the grid stays as it was.
        assert!(!t.set_phase(0, 4 * MS));
        assert_eq!(t.phase_ns(), Some(400 * US));
    }
}
