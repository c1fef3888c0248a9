//! When drive-io starts a cycle (RPDOs + SYNC): phase-locked to motion-core's setpoints, with
//! its own clock as the fallback (docs/can-protocol.md "Cycle timing").
//!
//! Free-running (`sync_source = "clock"`), drive-io's tick and motion-core's loop are two 1 ms
//! clocks with an arbitrary phase: a setpoint waits on average half a period (p50 566 µs,
//! p99 1073 µs measured) for the next SYNC. Phase-locked (`"setpoint"`, the default), motion-core's
//! publish stage notifies an iceoryx2 event after each setpoint and drive-io starts the cycle on
//! it, so the setpoint is on the bus tens of µs after it was published.
//!
//! Why an event and not one shared clock: a shared CLOCK_MONOTONIC schedule (drive-io ticking a
//! fixed offset after motion-core's cycle start) must budget the offset for motion-core's worst
//! compute time plus its scheduling lateness, so every setpoint would wait that budget; the event
//! costs the waiting side nothing and the publishing side one notify (10–30 µs) in its publish
//! stage, off the hard loop.
//!
//! Failure behaviour:
//! * motion-core stalls or dies: no notification; drive-io starts the cycle on its own clock
//!   `setpoint_wait` after the nominal tick (the first miss), then every period — SYNC and
//!   heartbeats go on, the drives hold, and after `stale_setpoint_cycles` without a new
//!   setpoint drive-io stops the bus exactly as in clock mode. The cycles run on the fallback
//!   clock are counted.
//! * drive-io stalls: motion-core's notify never blocks (iceoryx2's counting bit set plus a
//!   non-blocking datagram), setpoints queue in the subscriber buffer (the newest is taken),
//!   and the drives' heartbeat consumer (0x1016) and the safety monitor see the silent master.
//! * notifications faster than half a period (a burst after a stall, a foreign notifier) never
//!   send SYNC faster than that: the drives' interpolation sees at most 2 kHz.

use drives_config::SyncSource;

/// What started a cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trigger {
    /// motion-core's "setpoint published" notification.
    Setpoint,
    /// drive-io's own clock (clock mode, or the fallback when no setpoint came in time).
    Clock,
}

/// The cycle scheduler (pure logic, time passed in; the runner does the waiting).
#[derive(Clone, Debug)]
pub struct SyncClock {
    source: SyncSource,
    period_ns: u64,
    wait_ns: u64,
    /// Clock mode: the next tick. Setpoint mode: the fallback deadline.
    next_ns: u64,
    last_start_ns: u64,
    pending: bool,
    locked: u64,
    on_clock: u64,
}

impl SyncClock {
    /// First cycle one period after `now_ns`. `wait_ns` is ignored in clock mode.
    pub fn new(source: SyncSource, period_ns: u64, wait_ns: u64, now_ns: u64) -> Self {
        Self {
            source,
            period_ns,
            wait_ns,
            next_ns: now_ns + period_ns,
            last_start_ns: now_ns,
            pending: false,
            locked: 0,
            on_clock: 0,
        }
    }

    /// Falls back to clock mode for good (the notification channel failed).
    pub fn degrade_to_clock(&mut self) {
        self.source = SyncSource::Clock;
        self.pending = false;
    }

    /// Wait for frames (and notifications) until this time; then the cycle is due.
    pub fn wake_at_ns(&self) -> u64 {
        match (self.source, self.pending) {
            // Never two SYNCs closer than half a period.
            (SyncSource::Setpoint, true) => self.last_start_ns + self.period_ns / 2,
            _ => self.next_ns,
        }
    }

    /// A "setpoint published" notification arrived.
    pub fn notified(&mut self) {
        if self.source == SyncSource::Setpoint {
            self.pending = true;
        }
    }

    /// Starts the cycle at `now_ns` (≥ [`SyncClock::wake_at_ns`]): what triggered it and how
    /// many whole periods the clock missed (an overrun: this host preempted drive-io).
    pub fn start(&mut self, now_ns: u64) -> (Trigger, u32) {
        let trigger = if self.pending {
            Trigger::Setpoint
        } else {
            Trigger::Clock
        };
        let late = now_ns.saturating_sub(self.next_ns);
        let missed = if trigger == Trigger::Clock && late >= self.period_ns {
            u32::try_from(late / self.period_ns).unwrap_or(u32::MAX)
        } else {
            0
        };
        match trigger {
            Trigger::Setpoint => {
                self.locked += 1;
                self.next_ns = now_ns + self.period_ns + self.wait_ns;
            }
            Trigger::Clock => {
                self.on_clock += 1;
                // Re-anchor after a miss: never burst SYNCs to catch up.
                self.next_ns = if missed > 0 {
                    now_ns + self.period_ns
                } else {
                    self.next_ns + self.period_ns
                };
            }
        }
        self.pending = false;
        self.last_start_ns = now_ns;
        (trigger, missed)
    }

    /// Cycles started by a setpoint notification.
    pub fn locked_cycles(&self) -> u64 {
        self.locked
    }

    /// Cycles started by drive-io's own clock.
    pub fn clock_cycles(&self) -> u64 {
        self.on_clock
    }
}

/// What the isochronous scheduler wants done now ([`IsoClock::due`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IsoDue {
    /// Nothing yet: wait until [`IsoClock::wake_at_ns`] (or a notification).
    Wait,
    /// Run the cycle (its RPDOs belong to the next SYNC): a setpoint arrived, or the guard
    /// time before the SYNC is reached without one.
    Cycle,
    /// Wait actively until [`IsoClock::sync_at_ns`], then send the SYNC.
    Sync,
}

/// The isochronous schedule (`sync_source = "isochronous"`): drive-io's SYNC is the bus clock,
/// sent at `t0 + k·period` whatever motion-core does (a CSP drive interpolates assuming a
/// constant SYNC period, so SYNC jitter is velocity ripple on the cables). Each period has one
/// cycle (the RPDOs for the next SYNC), started by motion-core's "setpoint published"
/// notification, or `guard` before the SYNC without one (holding the last target, like EtherCAT
/// distributed clocks or Lely's SYNC producer, which never wait for the application). A
/// notification still pending when the SYNC goes out (its setpoint missed that SYNC) does not
/// start a cycle right after it: that cycle would spend the next period's one cycle on the late
/// setpoint, the next on-time notification would find it spent and wait for the SYNC after,
/// and so on — one late setpoint would lock the stream a period behind its SYNCs. The late
/// setpoint is still the newest one at the guard time if no newer one comes. After a
/// stall no SYNC is sent closer than 0.9 periods to the previous one: grid instants are skipped
/// (counted), never compressed. Pure logic; the runner does the waiting.
#[derive(Clone, Debug)]
pub struct IsoClock {
    period_ns: u64,
    guard_ns: u64,
    spin_ns: u64,
    /// The next SYNC instant on the grid.
    next_sync_ns: u64,
    /// The cycle for `next_sync_ns` ran.
    cycle_done: bool,
    pending: bool,
    last_sync_ns: Option<u64>,
    locked: u64,
    on_guard: u64,
    skipped: u64,
}

impl IsoClock {
    /// First SYNC one period after `now_ns` (the grid's origin).
    pub fn new(period_ns: u64, guard_ns: u64, spin_ns: u64, now_ns: u64) -> Self {
        Self {
            period_ns,
            guard_ns: guard_ns.min(period_ns / 2),
            spin_ns: spin_ns.min(period_ns / 4),
            next_sync_ns: now_ns + period_ns,
            cycle_done: false,
            pending: false,
            last_sync_ns: None,
            locked: 0,
            on_guard: 0,
            skipped: 0,
        }
    }

    /// The next SYNC instant.
    pub fn sync_at_ns(&self) -> u64 {
        self.next_sync_ns
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// A "setpoint published" notification arrived.
    pub fn notified(&mut self) {
        self.pending = true;
    }

    /// Until when to wait for frames and notifications.
    pub fn wake_at_ns(&self) -> u64 {
        let spin_from = self.next_sync_ns - self.spin_ns;
        if self.cycle_done {
            spin_from
        } else if self.pending {
            0
        } else {
            spin_from.min(self.next_sync_ns - self.guard_ns)
        }
    }

    /// What is due at `now_ns`. The cycle comes first: a SYNC is never sent before its
    /// period's cycle ran (even when drive-io was preempted past both).
    pub fn due(&self, now_ns: u64) -> IsoDue {
        if !self.cycle_done && (self.pending || now_ns >= self.next_sync_ns - self.guard_ns) {
            IsoDue::Cycle
        } else if now_ns >= self.next_sync_ns - self.spin_ns {
            IsoDue::Sync
        } else {
            IsoDue::Wait
        }
    }

    /// The period's cycle starts: what triggered it.
    pub fn cycle_started(&mut self) -> Trigger {
        self.cycle_done = true;
        if std::mem::take(&mut self.pending) {
            self.locked += 1;
            Trigger::Setpoint
        } else {
            self.on_guard += 1;
            Trigger::Clock
        }
    }

    /// The SYNC was sent at `at_ns`: advances the grid. Returns the grid instants skipped (an
    /// overrun: drive-io was late by more than 0.1 period, so the next SYNC moves to the first
    /// grid instant at least 0.9 periods after this one).
    pub fn sync_sent(&mut self, at_ns: u64) -> u32 {
        let min_next = at_ns + self.period_ns - self.period_ns / 10;
        let mut next = self.next_sync_ns + self.period_ns;
        let mut skipped = 0u32;
        while next < min_next {
            next += self.period_ns;
            skipped = skipped.saturating_add(1);
        }
        self.skipped += u64::from(skipped);
        self.next_sync_ns = next;
        self.last_sync_ns = Some(at_ns);
        self.cycle_done = false;
        // A notification from before this SYNC: its setpoint goes with the next notification's
        // cycle (superseded) or the guard's (read as the newest), not right now (see the type).
        self.pending = false;
        skipped
    }

    /// Cycles started by a setpoint notification.
    pub fn locked_cycles(&self) -> u64 {
        self.locked
    }

    /// Cycles started at the guard time without a new setpoint.
    pub fn guard_cycles(&self) -> u64 {
        self.on_guard
    }

    /// Grid instants skipped after stalls.
    pub fn skipped_syncs(&self) -> u64 {
        self.skipped
    }

    /// A SYNC instant of the grid (for the announcement of the schedule).
    pub fn grid_origin_ns(&self) -> u64 {
        self.next_sync_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const US: u64 = 1_000;

    /// Runs the scheduler against a setpoint stream (notification times), returning the cycle
    /// start times and triggers up to `until`.
    fn simulate(clock: &mut SyncClock, notes: &[u64], until: u64) -> Vec<(u64, Trigger)> {
        let mut out = Vec::new();
        let mut i = 0;
        let mut now = 0;
        loop {
            // The runner waits until wake_at or a notification, whichever is first.
            let wake = clock.wake_at_ns();
            if i < notes.len() && notes[i] <= wake {
                if notes[i] > until {
                    break;
                }
                now = now.max(notes[i]);
                clock.notified();
                i += 1;
                continue;
            }
            now = now.max(wake);
            if now > until {
                break;
            }
            out.push((now, clock.start(now).0));
        }
        out
    }

    #[test]
    fn clock_mode_ticks_every_period_and_ignores_setpoints() {
        let mut c = SyncClock::new(SyncSource::Clock, MS, 250 * US, 0);
        let notes: Vec<u64> = (0..10).map(|k| k * MS + 300 * US).collect();
        let cycles = simulate(&mut c, &notes, 5 * MS);
        let times: Vec<u64> = cycles.iter().map(|c| c.0).collect();
        assert_eq!(times, vec![MS, 2 * MS, 3 * MS, 4 * MS, 5 * MS]);
        assert!(cycles.iter().all(|c| c.1 == Trigger::Clock));
    }

    #[test]
    fn setpoint_mode_follows_the_stream_at_its_phase() {
        // Setpoints published at k ms + 300 µs (any phase to drive-io's own start).
        let mut c = SyncClock::new(SyncSource::Setpoint, MS, 250 * US, 0);
        let notes: Vec<u64> = (0..20).map(|k| k * MS + 300 * US).collect();
        let cycles = simulate(&mut c, &notes, 19 * MS);
        // The first setpoint (at 0.3 ms, before drive-io's first tick) starts a cycle once half
        // a period has passed since drive-io started; every later one at its own time.
        assert_eq!(cycles[0], (500 * US, Trigger::Setpoint));
        for (k, cy) in cycles.iter().enumerate().skip(1) {
            assert_eq!(
                *cy,
                (k as u64 * MS + 300 * US, Trigger::Setpoint),
                "cycle {k}"
            );
        }
        assert_eq!(c.clock_cycles(), 0);
    }

    #[test]
    fn a_stalled_stream_falls_back_to_the_clock_and_relocks() {
        let mut c = SyncClock::new(SyncSource::Setpoint, MS, 250 * US, 0);
        // Setpoints at 1.3 .. 5.3 ms, then motion-core stalls until 10.3 ms.
        let mut notes: Vec<u64> = (1..=5).map(|k| k * MS + 300 * US).collect();
        notes.extend((10..=12).map(|k| k * MS + 300 * US));
        let cycles = simulate(&mut c, &notes, 12 * MS + 400 * US);
        let want = [
            (MS, Trigger::Clock), // no setpoint yet: own clock
            // The first setpoint 0.3 ms after that tick waits until half a period has passed.
            (MS + 500 * US, Trigger::Setpoint),
            (2 * MS + 300 * US, Trigger::Setpoint),
            (3 * MS + 300 * US, Trigger::Setpoint),
            (4 * MS + 300 * US, Trigger::Setpoint),
            (5 * MS + 300 * US, Trigger::Setpoint),
            // The stall: the first fallback `wait` after the missing setpoint's tick, then
            // every period.
            (6 * MS + 550 * US, Trigger::Clock),
            (7 * MS + 550 * US, Trigger::Clock),
            (8 * MS + 550 * US, Trigger::Clock),
            (9 * MS + 550 * US, Trigger::Clock),
            // Relocked at once (the last own cycle is > half a period ago).
            (10 * MS + 300 * US, Trigger::Setpoint),
            (11 * MS + 300 * US, Trigger::Setpoint),
            (12 * MS + 300 * US, Trigger::Setpoint),
        ];
        assert_eq!(cycles, want);
        assert_eq!((c.locked_cycles(), c.clock_cycles()), (8, 5));
    }

    #[test]
    fn a_burst_of_notifications_never_sends_sync_faster_than_half_a_period() {
        let mut c = SyncClock::new(SyncSource::Setpoint, MS, 250 * US, 0);
        // 40 notifications 50 µs apart (a queue drained after a stall, or a foreign notifier).
        let notes: Vec<u64> = (0..40).map(|k| MS + k * 50 * US).collect();
        let cycles = simulate(&mut c, &notes, 3 * MS);
        for w in cycles.windows(2) {
            assert!(w[1].0 - w[0].0 >= MS / 2, "{cycles:?}");
        }
    }

    #[test]
    fn a_preempted_clock_counts_missed_periods_and_reanchors() {
        let mut c = SyncClock::new(SyncSource::Clock, MS, 0, 0);
        assert_eq!(c.start(MS), (Trigger::Clock, 0));
        // Woken 3.4 ms late.
        assert_eq!(c.start(5 * MS + 400 * US), (Trigger::Clock, 3));
        assert_eq!(c.wake_at_ns(), 6 * MS + 400 * US);
        // After degrading, notifications are ignored.
        let mut s = SyncClock::new(SyncSource::Setpoint, MS, 250 * US, 0);
        s.degrade_to_clock();
        s.notified();
        assert_eq!(s.wake_at_ns(), MS);
        assert_eq!(s.start(MS).0, Trigger::Clock);
    }

    /// Drives the isochronous clock like the runner: setpoint notifications at `notes`, the
    /// SYNC sent `late(k)` after its instant. Returns (sync times, cycle triggers).
    fn simulate_iso(
        c: &mut IsoClock,
        notes: &[u64],
        until: u64,
        late: impl Fn(usize) -> u64,
    ) -> (Vec<u64>, Vec<Trigger>) {
        let (syncs, trig, _) = simulate_iso_timed(c, notes, until, late);
        (syncs, trig)
    }

    /// [`simulate_iso`] with the cycles' start times.
    fn simulate_iso_timed(
        c: &mut IsoClock,
        notes: &[u64],
        until: u64,
        late: impl Fn(usize) -> u64,
    ) -> (Vec<u64>, Vec<Trigger>, Vec<u64>) {
        let (mut syncs, mut trig, mut at) = (Vec::new(), Vec::new(), Vec::new());
        let mut i = 0;
        let mut now = 0;
        loop {
            let wake = c.wake_at_ns().max(now);
            if i < notes.len() && notes[i] <= wake {
                now = now.max(notes[i]);
                c.notified();
                i += 1;
            } else {
                now = wake;
            }
            if now > until {
                break;
            }
            match c.due(now) {
                IsoDue::Cycle => {
                    trig.push(c.cycle_started());
                    at.push(now);
                }
                IsoDue::Sync => {
                    let at = c.sync_at_ns().max(now) + late(syncs.len());
                    now = at;
                    syncs.push(at);
                    c.sync_sent(at);
                }
                IsoDue::Wait => {}
            }
        }
        (syncs, trig, at)
    }

    #[test]
    fn isochronous_sync_is_periodic_whatever_the_setpoints_do() {
        let mut c = IsoClock::new(MS, 400 * US, 100 * US, 0);
        // Setpoints 500 µs before each SYNC, but jittering ±200 µs and with a 5 ms stall.
        let mut notes: Vec<u64> = (0..20)
            .filter(|k| !(8..13).contains(k))
            .map(|k| k * MS + 500 * US + (k % 3) * 150 * US)
            .collect();
        notes.sort_unstable();
        let (syncs, trig) = simulate_iso(&mut c, &notes, 20 * MS, |_| 0);
        for (k, t) in syncs.iter().enumerate() {
            assert_eq!(
                *t,
                (k as u64 + 1) * MS,
                "SYNC {k} off its instant: {syncs:?}"
            );
        }
        // One cycle per SYNC; the stall's periods ran on the guard.
        assert!(
            (syncs.len()..=syncs.len() + 1).contains(&trig.len()),
            "{trig:?}"
        );
        assert!(c.guard_cycles() >= 5, "{trig:?}");
        assert_eq!(c.skipped_syncs(), 0);
    }

    #[test]
    fn a_setpoint_too_late_for_its_sync_goes_to_the_next_one() {
        let mut c = IsoClock::new(MS, 400 * US, 100 * US, 0);
        // 300 µs before SYNC 2 (at 2 ms): past the 400 µs guard, so SYNC 2's cycle already ran
        // on the guard; this setpoint is read by SYNC 3's cycle at its guard (2.6 ms), not by a
        // cycle right after SYNC 2.
        let notes = [MS + 700 * US];
        let (_, trig, at) = simulate_iso_timed(&mut c, &notes, 3 * MS + 700 * US, |_| 0);
        assert_eq!(trig, vec![Trigger::Clock; 4]);
        assert_eq!(at, vec![600 * US, 1600 * US, 2600 * US, 3600 * US]);
    }

    #[test]
    fn one_late_setpoint_does_not_lock_the_stream_a_period_behind() {
        let mut c = IsoClock::new(MS, 400 * US, 100 * US, 0);
        // The first setpoint comes 300 µs before SYNC 2 (past the guard), every later one on
        // time, 500 µs before its SYNC: each on-time one starts its period's cycle when it
        // arrives (before its SYNC), none waits for the SYNC after; one cycle per SYNC.
        let mut notes = vec![MS + 700 * US];
        notes.extend((2..10).map(|k| k * MS + 500 * US));
        let (syncs, trig, at) = simulate_iso_timed(&mut c, &notes, 10 * MS, |_| 0);
        assert!(
            syncs
                .iter()
                .enumerate()
                .all(|(k, t)| *t == (k as u64 + 1) * MS)
        );
        for &n in &notes[1..] {
            assert!(
                at.contains(&n),
                "the setpoint of {} µs waited: cycles at {at:?} ({trig:?})",
                n / US
            );
        }
        assert!(
            !at.contains(&(2 * MS)),
            "a cycle right after SYNC 2: {at:?}"
        );
        assert!(
            (syncs.len()..=syncs.len() + 1).contains(&trig.len()),
            "{trig:?}"
        );
    }

    #[test]
    fn a_late_sync_never_makes_the_next_interval_short() {
        let mut c = IsoClock::new(MS, 400 * US, 100 * US, 0);
        // SYNC 3 goes out 2.35 ms late (drive-io preempted), every other one on time.
        let (syncs, _) = simulate_iso(&mut c, &[], 10 * MS, |k| if k == 2 { 2350 * US } else { 0 });
        for w in syncs.windows(2) {
            assert!(
                w[1] - w[0] >= MS * 9 / 10,
                "interval {} µs: {syncs:?}",
                (w[1] - w[0]) / US
            );
        }
        // Back on the grid afterwards, with the skipped instants counted.
        assert!(syncs.iter().skip(3).all(|t| t % MS == 0), "{syncs:?}");
        // The SYNC of 3 ms left at 5.35 ms; 4, 5 and 6 ms are skipped (6 ms would be 0.65
        // periods later), the next is 7 ms.
        assert_eq!(c.skipped_syncs(), 3);
    }
}
