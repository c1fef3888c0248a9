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
//! It starts inhibited (nothing received yet) and the FIRST release (power-on) needs
//! `release_pairs` consecutive valid RUN pairs of one reset epoch. After it has permitted once,
//! an inhibit is never left by itself (no self-release): only `release_pairs` consecutive valid
//! RUN pairs carrying an epoch that stands for an operator reset this watch has not acted on
//! release it ([`reset_epoch::releases`]): a later reset count of the same monitor instance, or
//! a reset (count >= 1) of another instance. The epoch is the monitor instance (a random nonce
//! drawn at its start) and the count of operator resets that instance accepted (ISO 13849-1
//! §5.2.2: a manual reset, not the return of a signal, ends a stop). A RESTARTED monitor is a
//! new instance at count 0: its RUN pairs release nothing that stopped, until an operator
//! resets the new instance. A replay of recorded heartbeats after the monitor died, or a second
//! producer repeating its frames, carries an old epoch and releases nothing. While permitted, a pair with another epoch (a
//! second producer) inhibits. Releasing never moves anything: a drive that was stopped stays in
//! Quick Stop Active until the master re-enables it, and drive-io's master leaves its latch
//! only with the monitor's reset of the epoch this watch verified ([`VerifiedEpoch`]; see
//! docs/safety-monitor.md).
//!
//! SRDO configuration: the monitor sends a doubled configuration signature
//! (`can_transport::safety_frame::ConfigSignature`) before every heartbeat pair; a RUN pair
//! counts only if a signature carrying the CRC of THIS consumer's configuration
//! ([`SafetyWatchConfig::srdo_crc`]: COB-ID, refresh time, validation time, pair window) arrived
//! within the validation time before it. A signature with another CRC inhibits at once
//! ([`InhibitReason::ConfigCrc`]), so a consumer configured differently from the producer never
//! permits.
//!
//! Used by the drive side (`cia402_drive::bank::DriveBank::enable_safety_watch`, the
//! `winch-emulator`) and by drive-io's master loop (`drive_io::runner`) when `drives.toml` has a
//! `[safety_heartbeat]` table. Pure logic: frames and times in, decisions out; no I/O, no
//! allocation.

use can_transport::CanFrame;
use can_transport::safety_frame::{
    ConfigSignature, DEFAULT_COB_ID, PairError, PairReceiver, SafetyState, SrdoParams,
    config_cob_id, reset_epoch,
};
use serde::Deserialize;

/// Largest accepted counter step between consecutive valid pairs (a few lost frames are
/// tolerated within the validation time; 0 = repeat and backwards steps are not).
pub const MAX_COUNTER_STEP: u16 = 16;

/// `[safety_heartbeat]` table of drives.toml: mandatory for the drive-io daemon (a
/// bench-only override exists), absent = no watch on the drive side (winch emulator, plant).
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
    /// Consecutive valid RUN pairs (of one epoch, newer than the one in force at the inhibit
    /// once the watch has permitted) needed to release an inhibit.
    #[serde(default = "d_release")]
    pub release_pairs: u32,
    /// The producer's refresh time (the monitor's cycle, ms): part of the SRDO configuration
    /// whose CRC the watch compares with the monitor's configuration signature.
    #[serde(default = "d_refresh")]
    pub refresh_time_ms: u32,
}

fn d_refresh() -> u32 {
    15
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
            refresh_time_ms: d_refresh(),
        }
    }
}

impl SafetyWatchConfig {
    /// The SRDO communication parameters this consumer is configured with.
    pub fn srdo_params(&self) -> SrdoParams {
        SrdoParams {
            cob_id: self.cob_id,
            refresh_time_ms: self.refresh_time_ms,
            validation_time_ms: self.validation_time_ms,
            pair_window_ms: self.pair_window_ms,
        }
    }

    /// CRC of this consumer's SRDO configuration ([`SrdoParams::crc`]): the monitor's
    /// configuration signature must carry the same value, otherwise the watch never permits.
    pub fn srdo_crc(&self) -> u16 {
        self.srdo_params().crc()
    }

    /// Checks the values; the error names the field.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, r: &str| Err((format!("safety_heartbeat.{f}"), r.to_string()));
        if self.cob_id == 0 || self.cob_id >= 0x7FC || self.cob_id.is_multiple_of(2) {
            return bad(
                "cob_id",
                "must be an odd 11-bit id below 0x7FC (the heartbeat pair uses cob_id and \
                 cob_id + 1, the configuration signature cob_id + 2 and cob_id + 3)",
            );
        }
        if self.refresh_time_ms == 0 || self.refresh_time_ms >= self.validation_time_ms {
            return bad(
                "refresh_time_ms",
                "must be >= 1 and below validation_time_ms (the producer's cycle)",
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
    Counter { last: u16, got: u16 },
    /// The monitor commands STOP (cause code of its trip).
    Stop { cause: u8 },
    /// While permitted, a RUN pair carried another reset epoch than the one in force (a
    /// second producer, or a reset the watch did not see the STOP of).
    Epoch { in_force: u32, got: u32 },
    /// The producer's configuration signature carries another SRDO configuration CRC than
    /// this consumer's own (COB-IDs, refresh time, SCT or SRVT differ): never permit.
    ConfigCrc { expected: u16, got: u16 },
    /// No valid configuration signature within the validation time.
    ConfigMissing,
    /// The device's own safety input stopped it (the safety I/O node's e-stop circuit opened,
    /// or it was NMT-stopped): like any inhibit, left only on a reset the watch has not acted
    /// on, never by the input returning.
    Local,
    /// The heartbeat was overdue (no valid RUN pair for `silent_ms`, more than two refresh
    /// times) and `drives_off` drives reported their torque off (Switch On Disabled) without
    /// drive-io commanding it: the safety I/O node's STO on the same missing heartbeat reached
    /// the drives before this watch's validation time ran out. The stop this watch was about to
    /// command, a little earlier ([`SafetyWatch::inhibit_on_torque_off`]).
    Overdue { silent_ms: u32, drives_off: u8 },
}

/// A reset epoch read from a valid, complete RUN pair on the monitor's own COB-IDs while the
/// watch permits: the only authenticated statement of "the monitor accepted reset number N"
/// on this side of the bus. It has no public constructor; only [`SafetyWatch::verified_epoch`]
/// makes one (type-state for drive-io's reset authority).
///
/// ```compile_fail,E0603
/// let forged = drive_bus::safety_watch::VerifiedEpoch(7);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VerifiedEpoch(u32);

impl VerifiedEpoch {
    pub fn get(self) -> u32 {
        self.0
    }
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
    last_counter: Option<u16>,
    consecutive: u32,
    /// Epoch of the consecutive RUN pairs being counted towards a release.
    candidate: Option<u32>,
    /// Epoch in force: of the pairs that released the watch last (None = never permitted).
    epoch: Option<u32>,
    /// Time of the last Permit -> Inhibit transition (0 = never).
    tripped_ns: u64,
    trips: u64,
    /// A trip not yet reported through [`SafetyWatch::take_trip`].
    unreported: Option<(InhibitReason, u64)>,
    /// The configuration signature pair: receiver, own CRC, time of the last
    /// signature with a matching CRC (0 = none), the last signature received.
    sig_rx: PairReceiver,
    srdo_crc: u16,
    sig_ok_ns: u64,
    last_signature: Option<ConfigSignature>,
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
            candidate: None,
            epoch: None,
            tripped_ns: 0,
            trips: 0,
            unreported: None,
            sig_rx: PairReceiver::new(
                config_cob_id(cfg.cob_id),
                u64::from(cfg.pair_window_ms) * 1_000_000,
            ),
            srdo_crc: cfg.srdo_crc(),
            sig_ok_ns: 0,
            last_signature: None,
        }
    }

    /// The last configuration signature received (valid pair), for diagnosis: its SRDO CRC
    /// and the monitor's safety parameter CRC.
    pub fn last_signature(&self) -> Option<ConfigSignature> {
        self.last_signature
    }

    /// A signature with this consumer's CRC within the validation time before `now_ns`:
    /// required for every RUN pair that permits or keeps permitting.
    fn signature_fresh(&self, now_ns: u64) -> bool {
        self.sig_ok_ns != 0 && now_ns.saturating_sub(self.sig_ok_ns) <= self.validation_ns
    }

    fn on_signature_frame(&mut self, frame: &CanFrame, now_ns: u64) -> Option<WatchState> {
        let result = self.sig_rx.on_frame_raw(frame, now_ns)?;
        match result.and_then(|d| ConfigSignature::from_bytes(&d)) {
            Err(e) => {
                self.sig_ok_ns = 0;
                self.inhibit(InhibitReason::Invalid(e), now_ns);
            }
            Ok(sig) => {
                self.last_signature = Some(sig);
                if sig.srdo_crc == self.srdo_crc {
                    self.sig_ok_ns = now_ns.max(1);
                } else {
                    self.sig_ok_ns = 0;
                    self.inhibit(
                        InhibitReason::ConfigCrc {
                            expected: self.srdo_crc,
                            got: sig.srdo_crc,
                        },
                        now_ns,
                    );
                }
            }
        }
        Some(self.state)
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

    /// The epoch in force (that of the pairs the watch last released on), None before the
    /// first release.
    pub fn epoch_in_force(&self) -> Option<u32> {
        self.epoch
    }

    /// The monitor's reset epoch, only while the watch permits (valid RUN pairs of that epoch
    /// keep arriving): see [`VerifiedEpoch`].
    pub fn verified_epoch(&self) -> Option<VerifiedEpoch> {
        match (self.state, self.epoch) {
            (WatchState::Permit, Some(e)) => Some(VerifiedEpoch(e)),
            _ => None,
        }
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
        self.candidate = None;
    }

    /// Feeds one received frame (frames on other ids are ignored cheaply). Returns the new
    /// state.
    pub fn on_frame(&mut self, frame: &CanFrame, now_ns: u64) -> WatchState {
        if let Some(st) = self.on_signature_frame(frame, now_ns) {
            return st;
        }
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
                        self.inhibit(InhibitReason::Stop { cause: msg.cause }, now_ns);
                        // A STOP pair is valid: it refreshes nothing that permits motion.
                    }
                    SafetyState::Run => self.on_run(msg.epoch, now_ns),
                }
            }
        }
        self.state
    }

    fn on_run(&mut self, epoch: u32, now_ns: u64) {
        // SRDO configuration check (CiA 304's signature idea): no RUN pair counts without a
        // recent signature whose CRC equals this consumer's own.
        if !self.signature_fresh(now_ns) {
            if !matches!(
                self.state,
                WatchState::Inhibit(InhibitReason::ConfigCrc { .. })
            ) {
                self.inhibit(InhibitReason::ConfigMissing, now_ns);
            }
            return;
        }
        if self.state == WatchState::Permit {
            if self.epoch == Some(epoch) {
                self.last_valid_ns = now_ns;
            } else {
                let in_force = self.epoch.unwrap_or(0);
                self.inhibit(
                    InhibitReason::Epoch {
                        in_force,
                        got: epoch,
                    },
                    now_ns,
                );
            }
            return;
        }
        if self.candidate != Some(epoch) {
            self.candidate = Some(epoch);
            self.consecutive = 0;
        }
        self.consecutive = self.consecutive.saturating_add(1);
        // No self-release: once permitted, only an operator reset this watch has not acted on
        // (a later count of the same instance, or a reset of a new instance — not a restarted
        // monitor's start epoch) may end an inhibit; the first release is the power-on.
        let may_release = self.epoch.is_none_or(|e| reset_epoch::releases(epoch, e));
        if may_release && self.consecutive >= self.cfg.release_pairs {
            self.state = WatchState::Permit;
            self.epoch = Some(epoch);
            self.last_valid_ns = now_ns;
        }
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

    /// Inhibits from the device's own side (see [`InhibitReason::Local`]): the release then needs
    /// a reset of the monitor, as after any other inhibit.
    pub fn inhibit_locally(&mut self, now_ns: u64) {
        if self.state == WatchState::Permit {
            self.inhibit(InhibitReason::Local, now_ns);
        }
    }

    /// True while the watch permits but no valid RUN pair arrived for more than two refresh
    /// times (`refresh_time_ms`): at least one of the monitor's cycles is missing; the
    /// validation time will inhibit unless a pair arrives.
    pub fn heartbeat_overdue(&self, now_ns: u64) -> bool {
        self.state == WatchState::Permit
            && now_ns.saturating_sub(self.last_valid_ns)
                > 2 * u64::from(self.cfg.refresh_time_ms) * 1_000_000
    }

    /// `drives_off` drives report their torque off (Switch On Disabled: their STO input) while
    /// drive-io commanded operation. If the heartbeat is overdue ([`Self::heartbeat_overdue`])
    /// that is the safety I/O node's stop on the same missing heartbeat: inhibit now
    /// ([`InhibitReason::Overdue`]), one trip naming the cause. While valid pairs keep
    /// arriving nothing changes here: a drive leaving operation under a live monitor is the
    /// master's fault to report. Returns true if it inhibited.
    pub fn inhibit_on_torque_off(&mut self, now_ns: u64, drives_off: usize) -> bool {
        if drives_off == 0 || !self.heartbeat_overdue(now_ns) {
            return false;
        }
        let silent_ms = (now_ns.saturating_sub(self.last_valid_ns) / 1_000_000) as u32;
        self.last_counter = None;
        self.inhibit(
            InhibitReason::Overdue {
                silent_ms,
                drives_off: drives_off.min(usize::from(u8::MAX)) as u8,
            },
            now_ns,
        );
        true
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
    use can_transport::safety_frame::{SafetyHeartbeat, encode};

    const MS: u64 = 1_000_000;

    /// The monitor's configuration signature pair for the default SRDO configuration.
    fn signature(srdo_crc: u16) -> [CanFrame; 2] {
        ConfigSignature {
            srdo_crc,
            safety_params_crc: 0x1234_5678,
        }
        .encode(DEFAULT_COB_ID)
    }

    /// One monitor cycle: the configuration signature pair (matching the default
    /// configuration), then the heartbeat pair.
    fn pair_e(counter: u16, state: SafetyState, epoch: u32) -> [CanFrame; 4] {
        let [s1, s2] = signature(SafetyWatchConfig::default().srdo_crc());
        let [a, b] = encode(
            &SafetyHeartbeat {
                state,
                cause: if state == SafetyState::Stop { 1 } else { 0 },
                counter,
                epoch,
            },
            DEFAULT_COB_ID,
        );
        [s1, s2, a, b]
    }

    fn pair(counter: u16, state: SafetyState) -> [CanFrame; 4] {
        pair_e(counter, state, 1)
    }

    fn feed_e(
        w: &mut SafetyWatch,
        counter: u16,
        state: SafetyState,
        epoch: u32,
        t: u64,
    ) -> WatchState {
        let [s1, s2, a, b] = pair_e(counter, state, epoch);
        w.on_frame(&s1, t);
        w.on_frame(&s2, t);
        w.on_frame(&a, t);
        w.on_frame(&b, t + 10_000)
    }

    fn feed(w: &mut SafetyWatch, counter: u16, state: SafetyState, t: u64) -> WatchState {
        feed_e(w, counter, state, 1, t)
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
    fn drives_torque_off_under_an_overdue_heartbeat_is_its_stop_under_a_live_one_nothing() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 0..3 {
            feed(&mut w, k + 1, SafetyState::Run, u64::from(k) * 15 * MS);
        }
        assert!(w.permits(31 * MS));
        // Pairs on time (the last one 30 ms ago, two refresh times): a drive reporting its
        // torque off is not the heartbeat's stop; the watch keeps permitting.
        assert!(!w.heartbeat_overdue(60 * MS));
        assert!(!w.inhibit_on_torque_off(60 * MS, 8));
        assert!(w.permits(60 * MS));
        assert_eq!(w.take_trip(), None);
        // Overdue (31 ms since the last pair), nothing off: still permitted.
        assert!(w.heartbeat_overdue(61 * MS));
        assert!(!w.inhibit_on_torque_off(61 * MS, 0));
        assert!(w.permits(61 * MS));
        // Overdue and the drives off: one trip, naming the silence and the drives.
        assert!(w.inhibit_on_torque_off(70 * MS + 1, 8));
        assert!(!w.permits(70 * MS + 1));
        let want = InhibitReason::Overdue {
            silent_ms: 39,
            drives_off: 8,
        };
        assert_eq!(w.take_trip(), Some((want, 70 * MS + 1)));
        assert_eq!(w.state(), WatchState::Inhibit(want));
        // The validation time running out later adds no second trip.
        assert!(!w.permits(200 * MS));
        assert_eq!((w.trips(), w.take_trip()), (1, None));
        // Like every inhibit: the pairs of the epoch in force do not release it.
        for k in 0..5 {
            feed(
                &mut w,
                10 + k,
                SafetyState::Run,
                210 * MS + u64::from(k) * 15 * MS,
            );
        }
        assert!(!w.permits(300 * MS));
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
        let [_, _, a, b] = pair(3, SafetyState::Run);
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
        // No self-release: valid RUN pairs of the same epoch do not end the inhibit...
        for k in 13..23 {
            feed(&mut w, k, SafetyState::Run, (k as u64 + 10) * MS);
        }
        assert!(!w.permits(33 * MS));
        assert!(w.verified_epoch().is_none());
        // ... only release_pairs pairs of a NEWER epoch (an accepted reset) do.
        for k in 23..25 {
            feed_e(&mut w, k, SafetyState::Run, 2, (k as u64 + 10) * MS);
        }
        assert!(!w.permits(35 * MS));
        feed_e(&mut w, 25, SafetyState::Run, 2, 35 * MS);
        assert!(w.permits(36 * MS));
        assert_eq!(w.verified_epoch().map(VerifiedEpoch::get), Some(2));
        feed_e(&mut w, 26, SafetyState::Stop, 2, 37 * MS);
        assert!(!w.permits(37 * MS));
        assert!(matches!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Stop { cause: 1 })
        ));
        // STOP pairs keep it inhibited; RUN pairs of the same epoch too; a newer epoch releases.
        feed_e(&mut w, 27, SafetyState::Stop, 2, 38 * MS);
        for k in 28..31 {
            feed_e(&mut w, k, SafetyState::Run, 2, (k as u64 + 20) * MS);
        }
        assert!(!w.permits(51 * MS));
        for k in 31..34 {
            feed_e(&mut w, k, SafetyState::Run, 3, (k as u64 + 20) * MS);
        }
        assert!(w.permits(54 * MS));
        // While permitted, a pair of another epoch (a second producer) inhibits.
        feed_e(&mut w, 34, SafetyState::Run, 4, 55 * MS);
        assert_eq!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Epoch {
                in_force: 3,
                got: 4
            })
        );
    }

    /// A restarted monitor (a new instance at count 0) releases nothing that stopped under the
    /// previous one; the new instance's first operator reset does.
    #[test]
    fn a_restarted_monitor_releases_only_with_a_reset_of_the_new_instance() {
        use reset_epoch::new;
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 0..3u16 {
            feed_e(
                &mut w,
                k,
                SafetyState::Run,
                new(0xAAAA, 4),
                u64::from(k) * 15 * MS,
            );
        }
        assert!(w.permits(40 * MS));
        // The monitor dies: timeout. A new instance starts (count 0) and sends RUN pairs.
        assert!(!w.permits(200 * MS));
        for k in 0..100u16 {
            let t = 300 * MS + u64::from(k) * 15 * MS;
            feed_e(&mut w, k, SafetyState::Run, new(0x5555, 0), t);
            assert!(!w.permits(t + MS), "released on a start epoch");
        }
        // The operator resets the new instance: released on its count 1.
        let t0 = 300 * MS + 100 * 15 * MS;
        for k in 100..103u16 {
            feed_e(
                &mut w,
                k,
                SafetyState::Run,
                new(0x5555, 1),
                t0 + u64::from(k) * MS,
            );
        }
        assert!(w.permits(t0 + 103 * MS));
        assert_eq!(
            w.verified_epoch().map(VerifiedEpoch::get),
            Some(new(0x5555, 1))
        );
    }

    /// A replay of recorded heartbeats after the monitor died (counter continued, same epoch)
    /// never releases; neither does an older epoch or a mix of epochs.
    #[test]
    fn replay_after_monitor_death_stays_inhibited() {
        let mut w = SafetyWatch::new(SafetyWatchConfig::default());
        for k in 0..5u16 {
            feed_e(&mut w, k, SafetyState::Run, 9, u64::from(k) * 15 * MS);
        }
        assert!(w.permits(70 * MS));
        // The monitor dies: timeout.
        assert!(!w.permits(200 * MS));
        for k in 5..200u16 {
            let t = 200 * MS + u64::from(k) * 15 * MS;
            feed_e(&mut w, k, SafetyState::Run, 9, t);
            assert!(!w.permits(t + MS));
        }
        for k in 200..300u16 {
            let t = 200 * MS + u64::from(k) * 15 * MS;
            feed_e(&mut w, k, SafetyState::Run, 9 - u32::from(k % 3), t);
            assert!(!w.permits(t + MS));
        }
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

    /// A consumer whose SRDO configuration differs from the producer's
    /// (here its validation time) never permits, however many valid RUN pairs arrive; a
    /// signature mismatch while permitting inhibits at once; without any signature the RUN
    /// pairs release nothing; a signature that stops arriving inhibits after the validation time.
    #[test]
    fn configuration_crc_mismatch_never_permits() {
        let producer = SafetyWatchConfig::default();
        let consumer = SafetyWatchConfig {
            validation_time_ms: 500,
            ..producer
        };
        assert_ne!(producer.srdo_crc(), consumer.srdo_crc());
        let mut w = SafetyWatch::new(consumer);
        for k in 0..20u16 {
            let t = u64::from(k) * 15 * MS;
            feed_e(&mut w, k, SafetyState::Run, 5 + u32::from(k), t);
            assert!(!w.permits(t + MS), "pair {k}");
        }
        assert_eq!(
            w.state(),
            WatchState::Inhibit(InhibitReason::ConfigCrc {
                expected: consumer.srdo_crc(),
                got: producer.srdo_crc(),
            })
        );
        assert_eq!(
            w.last_signature().map(|s| s.srdo_crc),
            Some(producer.srdo_crc())
        );

        // No signature at all: heartbeats alone release nothing.
        let mut w = SafetyWatch::new(producer);
        for k in 0..10u16 {
            let [_, _, a, b] = pair(k, SafetyState::Run);
            let t = u64::from(k) * 15 * MS;
            w.on_frame(&a, t);
            w.on_frame(&b, t + 10_000);
            assert!(!w.permits(t + MS));
        }
        assert_eq!(w.state(), WatchState::Inhibit(InhibitReason::ConfigMissing));

        // Permitting, then a mismatching signature: inhibit at once, and the matching one
        // back with the same epoch does not release (no self-release).
        let mut w = SafetyWatch::new(producer);
        for k in 0..3u16 {
            feed(&mut w, k, SafetyState::Run, u64::from(k) * 15 * MS);
        }
        assert!(w.permits(31 * MS));
        for f in signature(producer.srdo_crc() ^ 1) {
            w.on_frame(&f, 40 * MS);
        }
        assert!(!w.permits(40 * MS));
        assert_eq!(w.trips(), 1);
        for k in 3..10u16 {
            feed(&mut w, k, SafetyState::Run, u64::from(k) * 15 * MS);
        }
        assert!(!w.permits(150 * MS));

        // Permitting, then only heartbeats (signature lost): the first RUN pair more than the
        // validation time after the last signature inhibits.
        let mut w = SafetyWatch::new(producer);
        for k in 0..3u16 {
            feed(&mut w, k, SafetyState::Run, u64::from(k) * 15 * MS);
        }
        assert!(w.permits(30 * MS));
        for k in 3..7u16 {
            let [_, _, a, b] = pair(k, SafetyState::Run);
            let t = u64::from(k) * 15 * MS;
            w.on_frame(&a, t);
            w.on_frame(&b, t + 10_000);
            // The last signature came at 30 ms: pairs at 45, 60, 75 ms still count, 90 ms not.
            assert_eq!(w.permits(t + 20_000), k < 6, "pair at {} ms", k * 15);
        }
        assert_eq!(w.state(), WatchState::Inhibit(InhibitReason::ConfigMissing));
    }

    mod props {
        use super::*;
        use proptest::prelude::*;

        #[derive(Debug, Clone)]
        enum Ev {
            /// A valid pair: counter step, RUN?, epoch delta from the current producer epoch.
            Pair {
                step: u16,
                run: bool,
                epoch_delta: i8,
            },
            /// A corrupted pair.
            Corrupt,
            /// Time passes without frames (ms).
            Silence(u16),
        }

        fn ev() -> impl Strategy<Value = Ev> {
            prop_oneof![
                8 => (0u16..20, any::<bool>(), -2i8..=2).prop_map(|(step, run, epoch_delta)| Ev::Pair { step, run, epoch_delta }),
                1 => Just(Ev::Corrupt),
                1 => (0u16..200).prop_map(Ev::Silence),
            ]
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(2000))]
            /// The watch's invariants over random heartbeat streams: it permits only after a valid
            /// RUN pair within the validation time; once it has permitted, every release from an
            /// inhibit is on an epoch newer than the one in force before (no self-release); the
            /// verified epoch is the epoch of the pairs it permits on.
            #[test]
            fn never_self_releases(events in proptest::collection::vec(ev(), 0..200)) {
                let cfg = SafetyWatchConfig::default();
                let mut w = SafetyWatch::new(cfg);
                let (mut t, mut counter, mut epoch) = (0u64, 0u16, 100u32);
                let mut last_valid: Option<u64> = None;
                for e in events {
                    let before = w.state();
                    let epoch_before = w.epoch_in_force();
                    match e {
                        Ev::Pair { step, run, epoch_delta } => {
                            counter = counter.wrapping_add(step);
                            let ep = epoch.wrapping_add_signed(i32::from(epoch_delta));
                            if epoch_delta > 0 { epoch = ep; }
                            let st = if run { SafetyState::Run } else { SafetyState::Stop };
                            feed_e(&mut w, counter, st, ep, t);
                            if run { last_valid = Some(t + 10_000); }
                        }
                        Ev::Corrupt => {
                            let [_, _, a, b] = pair_e(counter, SafetyState::Run, epoch);
                            let mut d = [0u8; 8];
                            d.copy_from_slice(b.data());
                            d[0] ^= 1;
                            w.on_frame(&a, t);
                            w.on_frame(&CanFrame::new(b.id() as u16, &d).unwrap(), t + 10_000);
                        }
                        Ev::Silence(ms) => t += u64::from(ms) * MS,
                    }
                    t += 15 * MS;
                    let permits = w.permits(t);
                    if permits {
                        // A valid RUN pair within the validation time.
                        let lv = last_valid.expect("permit without any RUN pair");
                        prop_assert!(t.saturating_sub(lv) <= 50 * MS);
                        let v = w.verified_epoch().expect("permit without a verified epoch");
                        prop_assert_eq!(Some(v.get()), w.epoch_in_force());
                        if before != WatchState::Permit && let Some(old) = epoch_before {
                            prop_assert!(
                                reset_epoch::releases(v.get(), old),
                                "released from {:?} on epoch {} (in force {})", before, v.get(), old
                            );
                        }
                    } else {
                        prop_assert!(w.verified_epoch().is_none());
                    }
                }
            }
        }
    }
}
