//! Validation of the safety monitor's fail-safe heartbeat on the drive bus (consumer side of
//! `can_transport::safety_frame`, after CiA 304's SRDO).
//!
//! The safety monitor sends a doubled frame (data + bit-inverse on adjacent COB-IDs) every
//! 15 ms cycle. A [`SafetyWatch`] PERMITS motion only while valid pairs with state RUN keep
//! arriving; it INHIBITS (the drive brakes: quick stop, no enable) when
//! * no valid pair arrived within the validation time (CiA 304 SCT, default 50 ms): a dead,
//!   hung or disconnected monitor stops the robot;
//! * a pair is invalid (not the exact bit-inverse, incomplete within the pair window (SRVT),
//!   wrong length, unknown state/version): a corrupted safety frame stops the robot at once;
//! * the counter repeats or jumps backwards / too far (a stuck or replaying producer);
//! * the monitor says STOP (its latched e-stop).
//!
//! It starts inhibited (nothing received yet) and releases only after `release_pairs`
//! consecutive valid RUN pairs with consecutive counters. Releasing never moves anything: a drive
//! that was stopped stays in Quick Stop Active until the master re-enables it after an operator
//! reset (see docs/safety-monitor.md).
//!
//! Used by the drive side ([`crate::slave::DriveBank::enable_safety_watch`], the
//! `winch-emulator`) and by drive-io's master loop ([`crate::runner`]) when `drives.toml` has a
//! `[safety_heartbeat]` table. Pure logic: frames and times in, decisions out; no I/O, no
//! allocation.

use can_transport::CanFrame;
use can_transport::safety_frame::{DEFAULT_COB_ID, PairError, PairReceiver, SafetyState};
use serde::Deserialize;

/// Largest accepted counter step between consecutive valid pairs (a few lost frames are
/// tolerated within the validation time; 0 = repeat and backwards steps are not).
pub const MAX_COUNTER_STEP: u32 = 16;

/// `[safety_heartbeat]` table of drives.toml. Absent = no watch (the default).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SafetyWatchConfig {
    /// COB-ID of the normal frame; the inverted frame uses `cob_id + 1` (default 0x101, SRDO 1).
    #[serde(default = "d_cob")]
    pub cob_id: u16,
    /// Validation time (CiA 304 SCT): no valid RUN pair for longer => inhibit (ms).
    #[serde(default = "d_validation")]
    pub validation_time_ms: u32,
    /// Pair window (CiA 304 SRVT): the inverse must follow the normal frame within this (ms).
    #[serde(default = "d_window")]
    pub pair_window_ms: u32,
    /// Consecutive valid RUN pairs needed to release an inhibit.
    #[serde(default = "d_release")]
    pub release_pairs: u32,
}

fn d_cob() -> u16 {
    DEFAULT_COB_ID
}
fn d_validation() -> u32 {
    50
}
fn d_window() -> u32 {
    10
}
fn d_release() -> u32 {
    3
}

impl Default for SafetyWatchConfig {
    fn default() -> Self {
        Self {
            cob_id: d_cob(),
            validation_time_ms: d_validation(),
            pair_window_ms: d_window(),
            release_pairs: d_release(),
        }
    }
}

impl SafetyWatchConfig {
    /// Checks the values; the error names the field.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, r: &str| Err((format!("safety_heartbeat.{f}"), r.to_string()));
        if self.cob_id == 0 || self.cob_id >= 0x7FF || self.cob_id.is_multiple_of(2) {
            return bad(
                "cob_id",
                "must be an odd 11-bit id below 0x7FF (the pair uses cob_id and cob_id + 1)",
            );
        }
        if !(1..=10_000).contains(&self.validation_time_ms) {
            return bad("validation_time_ms", "must be in 1..=10000");
        }
        if self.pair_window_ms == 0 || self.pair_window_ms > self.validation_time_ms {
            return bad("pair_window_ms", "must be >= 1 and <= validation_time_ms");
        }
        if !(1..=1000).contains(&self.release_pairs) {
            return bad("release_pairs", "must be in 1..=1000");
        }
        Ok(())
    }
}

/// Why the watch inhibits motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InhibitReason {
    /// No valid pair seen since start (or not enough consecutive ones yet).
    NotYetValid,
    /// No valid RUN pair within the validation time.
    Timeout,
    /// An invalid frame/pair on the safety COB-IDs.
    Invalid(PairError),
    /// The counter repeated, went backwards or jumped more than [`MAX_COUNTER_STEP`].
    Counter { last: u32, got: u32 },
    /// The monitor commands STOP (cause code of its trip).
    Stop { cause: u8, cable: u8 },
}

/// Watch state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchState {
    Permit,
    Inhibit(InhibitReason),
}

/// The consumer of the safety heartbeat. Create once; feed every received frame with
/// [`SafetyWatch::on_frame`] and ask [`SafetyWatch::permits`] before letting anything move.
#[derive(Debug, Clone)]
pub struct SafetyWatch {
    cfg: SafetyWatchConfig,
    rx: PairReceiver,
    state: WatchState,
    validation_ns: u64,
    last_valid_ns: u64,
    /// First time the watch was asked (start of the start-up grace), 0 = not yet.
    started_ns: u64,
    last_counter: Option<u32>,
    consecutive: u32,
    /// Time of the last Permit -> Inhibit transition (0 = never).
    tripped_ns: u64,
    trips: u64,
    /// A trip not yet reported through [`SafetyWatch::take_trip`].
    unreported: Option<(InhibitReason, u64)>,
}

impl SafetyWatch {
    pub fn new(cfg: SafetyWatchConfig) -> Self {
        Self {
            cfg,
            rx: PairReceiver::new(cfg.cob_id, u64::from(cfg.pair_window_ms) * 1_000_000),
            state: WatchState::Inhibit(InhibitReason::NotYetValid),
            validation_ns: u64::from(cfg.validation_time_ms) * 1_000_000,
            last_valid_ns: 0,
            started_ns: 0,
            last_counter: None,
            consecutive: 0,
            tripped_ns: 0,
            trips: 0,
            unreported: None,
        }
    }

    pub fn config(&self) -> &SafetyWatchConfig {
        &self.cfg
    }

    pub fn state(&self) -> WatchState {
        self.state
    }

    /// Number of Permit -> Inhibit transitions so far.
    pub fn trips(&self) -> u64 {
        self.trips
    }

    /// CLOCK_MONOTONIC ns of the last Permit -> Inhibit transition (0 = never).
    pub fn tripped_ns(&self) -> u64 {
        self.tripped_ns
    }

    /// The last trip (reason, time) once, for logging outside the hot path.
    pub fn take_trip(&mut self) -> Option<(InhibitReason, u64)> {
        self.unreported.take()
    }

    fn inhibit(&mut self, reason: InhibitReason, now_ns: u64) {
        if self.state == WatchState::Permit {
            self.trips += 1;
            self.tripped_ns = now_ns;
            self.unreported = Some((reason, now_ns));
        }
        // While already inhibited keep the first reason, except that a later explicit STOP or
        // corruption is more informative than "not yet valid".
        match self.state {
            WatchState::Permit | WatchState::Inhibit(InhibitReason::NotYetValid) => {
                self.state = WatchState::Inhibit(reason)
            }
            WatchState::Inhibit(_) => {}
        }
        self.consecutive = 0;
    }

    /// Feeds one received frame (frames on other ids are ignored cheaply). Returns the new
    /// state.
    pub fn on_frame(&mut self, frame: &CanFrame, now_ns: u64) -> WatchState {
        let Some(result) = self.rx.on_frame(frame, now_ns) else {
            return self.state;
        };
        match result {
            Err(e) => {
                self.last_counter = None;
                self.inhibit(InhibitReason::Invalid(e), now_ns);
            }
            Ok(msg) => {
                let counter_ok = match self.last_counter {
                    None => true,
                    Some(last) => {
                        let step = msg.counter.wrapping_sub(last);
                        (1..=MAX_COUNTER_STEP).contains(&step)
                    }
                };
                if !counter_ok {
                    let last = self.last_counter.unwrap_or(0);
                    self.last_counter = Some(msg.counter);
                    self.inhibit(
                        InhibitReason::Counter {
                            last,
                            got: msg.counter,
                        },
                        now_ns,
                    );
                    return self.state;
                }
                self.last_counter = Some(msg.counter);
                match msg.state {
                    SafetyState::Stop => {
                        self.inhibit(
                            InhibitReason::Stop {
                                cause: msg.cause,
                                cable: msg.cable,
                            },
                            now_ns,
                        );
                        // A STOP pair is valid: it refreshes nothing that permits motion.
                    }
                    SafetyState::Run => {
                        self.last_valid_ns = now_ns;
                        self.consecutive = self.consecutive.saturating_add(1);
                        if self.state != WatchState::Permit
                            && self.consecutive >= self.cfg.release_pairs
                        {
                            self.state = WatchState::Permit;
                        }
                    }
                }
            }
        }
        self.state
    }

    /// True while nothing has ever been valid and less than the validation time has passed
    /// since the watch was first asked: the producer may simply not have sent `release_pairs`
    /// pairs yet (start-up). Still not a permit: nothing may be enabled.
    pub fn in_startup_grace(&mut self, now_ns: u64) -> bool {
        if self.started_ns == 0 {
            self.started_ns = now_ns.max(1);
        }
        self.state == WatchState::Inhibit(InhibitReason::NotYetValid)
            && self.trips == 0
            && now_ns.saturating_sub(self.started_ns) <= self.validation_ns
    }

    /// Applies the validation-time check at `now_ns`; true if motion is permitted.
    pub fn permits(&mut self, now_ns: u64) -> bool {
        if self.state == WatchState::Permit
            && now_ns.saturating_sub(self.last_valid_ns) > self.validation_ns
        {
            self.last_counter = None;
            self.inhibit(InhibitReason::Timeout, now_ns);
        }
        self.state == WatchState::Permit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::safety_frame::{NO_CABLE, SafetyHeartbeat, encode};

    const MS: u64 = 1_000_000;

    fn pair(counter: u32, state: SafetyState) -> [CanFrame; 2] {
        encode(
            &SafetyHeartbeat {
                state,
                cause: if state == SafetyState::Stop { 1 } else { 0 },
                counter,
                cable: NO_CABLE,
            },
            DEFAULT_COB_ID,
        )
    }

    fn feed(w: &mut SafetyWatch, counter: u32, state: SafetyState, t: u64) -> WatchState {
        let [a, b] = pair(counter, state);
        w.on_frame(&a, t);
        w.on_frame(&b, t + 10_000)
    }

    #[test]
    fn starts_inhibited_releases_after_consecutive_pairs() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        assert!(!w.permits(0));
        assert_ne!(feed(&mut w, 1, SafetyState::Run, 0), WatchState::Permit);
        assert_ne!(
            feed(&mut w, 2, SafetyState::Run, 15 * MS),
            WatchState::Permit
        );
        assert_eq!(
            feed(&mut w, 3, SafetyState::Run, 30 * MS),
            WatchState::Permit
        );
        assert!(w.permits(31 * MS));
    }

    #[test]
    fn startup_grace_only_before_anything_was_valid() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        assert!(w.in_startup_grace(100 * MS));
        assert!(!w.permits(100 * MS));
        assert!(w.in_startup_grace(150 * MS));
        assert!(!w.in_startup_grace(150 * MS + 1));
        // After a release and a loss there is no grace any more.
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        assert!(w.in_startup_grace(0));
        for k in 0..3 {
            feed(&mut w, k, SafetyState::Run, u64::from(k) * MS);
        }
        assert!(!w.in_startup_grace(3 * MS));
        assert!(!w.permits(200 * MS));
        assert!(!w.in_startup_grace(200 * MS));
    }

    #[test]
    fn timeout_after_validation_time_exactly() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 0..3 {
            feed(&mut w, k, SafetyState::Run, k as u64 * 15 * MS);
        }
        let last = 30 * MS + 10_000;
        assert!(w.permits(last + 50 * MS));
        assert!(!w.permits(last + 50 * MS + 1));
        assert_eq!(w.state(), WatchState::Inhibit(InhibitReason::Timeout));
        assert_eq!(w.trips(), 1);
        assert_eq!(w.tripped_ns(), last + 50 * MS + 1);
        assert!(w.take_trip().is_some());
        assert!(w.take_trip().is_none());
    }

    #[test]
    fn corrupted_pair_inhibits_immediately() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 0..3 {
            feed(&mut w, k, SafetyState::Run, k as u64 * 15 * MS);
        }
        assert!(w.permits(40 * MS));
        let [a, b] = pair(3, SafetyState::Run);
        let mut d = [0u8; 8];
        d.copy_from_slice(b.data());
        d[3] ^= 0x10;
        w.on_frame(&a, 45 * MS);
        w.on_frame(&CanFrame::new(b.id() as u16, &d).unwrap(), 45 * MS);
        assert!(!w.permits(45 * MS));
        assert!(matches!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Invalid(PairError::InverseMismatch))
        ));
    }

    #[test]
    fn stop_and_repeated_counter_inhibit() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 10..13 {
            feed(&mut w, k, SafetyState::Run, k as u64 * MS);
        }
        assert!(w.permits(13 * MS));
        feed(&mut w, 12, SafetyState::Run, 14 * MS);
        assert_eq!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Counter { last: 12, got: 12 })
        );
        // Recovers only after release_pairs consecutive valid RUN pairs.
        for k in 13..16 {
            feed(&mut w, k, SafetyState::Run, (k as u64 + 10) * MS);
        }
        assert!(w.permits(26 * MS));
        feed(&mut w, 16, SafetyState::Stop, 27 * MS);
        assert!(!w.permits(27 * MS));
        assert!(matches!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Stop { cause: 1, .. })
        ));
        // STOP pairs keep it inhibited; RUN pairs release it again.
        feed(&mut w, 17, SafetyState::Stop, 28 * MS);
        assert!(!w.permits(28 * MS));
        for k in 18..21 {
            feed(&mut w, k, SafetyState::Run, (k as u64 + 20) * MS);
        }
        assert!(w.permits(41 * MS));
    }

    #[test]
    fn config_validation_names_fields() {
        let mut c = SafetyWatchConfig::default();
        assert!(c.validate().is_ok());
        c.cob_id = 0x100;
        assert_eq!(c.validate().unwrap_err().0, "safety_heartbeat.cob_id");
        c = SafetyWatchConfig {
            pair_window_ms: 60,
            ..Default::default()
        };
        assert_eq!(
            c.validate().unwrap_err().0,
            "safety_heartbeat.pair_window_ms"
        );
    }

    /// The drive side: no enable without the heartbeat; a lost heartbeat quick-stops an enabled
    /// drive within the validation time; the release does not re-enable by itself.
    #[test]
    fn drive_bank_with_watch_blocks_enable_and_quick_stops() {
        use crate::canopen::*;
        use crate::slave::{DriveBank, MotionDemand};
        let mut bank = DriveBank::new(&[1, 2], 10);
        bank.enable_safety_watch(SafetyWatchConfig::default());
        bank.start(0);
        bank.handle_frame(&nmt(NMT_START, 0), 0);
        for node in [1, 2] {
            bank.handle_frame(&sdo_download(node, OD_MODES_OF_OPERATION, 0, 8, 1), 0);
        }
        let enable = |bank: &mut DriveBank, t: u64| {
            for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
                for node in [1, 2] {
                    bank.handle_frame(&rpdo1(node, cw, 0), t);
                }
            }
        };
        enable(&mut bank, MS);
        for i in 0..2 {
            assert_eq!(bank.slave(i).unwrap().ds402_state(), Ds402State::SwitchedOn);
            assert_eq!(bank.demand(i), MotionDemand::Hold);
        }
        // Valid heartbeats: the watch releases, now the master can enable.
        for k in 0..3u32 {
            for f in pair(k, SafetyState::Run) {
                bank.handle_frame(&f, (2 + u64::from(k)) * MS);
            }
        }
        enable(&mut bank, 5 * MS);
        for i in 0..2 {
            assert_eq!(
                bank.slave(i).unwrap().ds402_state(),
                Ds402State::OperationEnabled
            );
        }
        // Silence: still permitted at the validation time, quick stop right after it.
        let last = 4 * MS;
        bank.poll(last + 50 * MS);
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::OperationEnabled
        );
        bank.poll(last + 50 * MS + 1);
        for i in 0..2 {
            assert_eq!(
                bank.slave(i).unwrap().ds402_state(),
                Ds402State::QuickStopActive
            );
            assert_eq!(bank.demand(i), MotionDemand::QuickStop);
        }
        assert!(matches!(
            bank.take_safety_trip(),
            Some((InhibitReason::Timeout, _))
        ));
        // A master trying to re-enable (transition 16) is refused while inhibited.
        for node in [1, 2] {
            bank.handle_frame(&rpdo1(node, CW_ENABLE_OPERATION, 0), 60 * MS);
        }
        assert_eq!(
            bank.slave(1).unwrap().ds402_state(),
            Ds402State::QuickStopActive
        );
        // Heartbeats back: released, but the drives stay stopped until the master enables.
        for k in 10..13u32 {
            for f in pair(k, SafetyState::Run) {
                bank.handle_frame(&f, (60 + u64::from(k)) * MS);
            }
        }
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::QuickStopActive
        );
        for node in [1, 2] {
            bank.handle_frame(&rpdo1(node, CW_ENABLE_OPERATION, 0), 80 * MS);
        }
        assert_eq!(
            bank.slave(0).unwrap().ds402_state(),
            Ds402State::OperationEnabled
        );
    }
}
