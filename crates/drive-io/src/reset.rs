//! drive-io's reset authority (ISO 13849-1 §5.2.2: after a stop, only a manual reset
//! at the safety function, never the return of a signal or another process's say-so, may allow
//! a restart).
//!
//! The master leaves a latch (e-stop, stale stop, fault) only through [`Master::reset`], which
//! takes a [`ResetGrant`]. A grant has no public constructor: only a [`ResetGate`] makes one,
//! and only for a reset the safety monitor minted:
//!
//! * with the safety heartbeat watch (`[safety_heartbeat]`, every shipped config): the monitor's
//!   `StateEvent { source: SafetyMonitor, kind: Reset, detail: epoch }` counts only if it is
//!   fresh (stamped within [`RESET_EVENT_MAX_AGE_NS`] before drive-io's clock, not in its
//!   future), `epoch` equals the reset epoch the watch VERIFIED on the CURRENT monitor's own
//!   doubled CAN frames ([`VerifiedEpoch`]), stands for an accepted operator reset (count >= 1
//!   of its instance: a restarted monitor's start epoch is no reset) and is one drive-io has not
//!   acted on ([`reset_epoch::releases`] against the epoch in force when it latched). Never
//!   "any epoch first": without an epoch in force the event's epoch must still be the verified
//!   one and a reset. The iceoryx2 event alone authenticates nothing (its `source` is
//!   self-declared, see docs/safety-monitor.md, threat model); the CAN epoch is the authority.
//! * without the watch (bench setups only, the `drive-io-bench` executable of crates/drive-rig):
//!   the event's source, freshness and epoch order are checked, which stops accidents (an
//!   operator tool, a test, a stale event) but not a malicious local process.
//!
//! Anything else is [`Ignored`] and the caller logs it (rate-limited).
//!
//! [`Master::reset`]: crate::master::Master::reset

use can_transport::safety_frame::reset_epoch;
use crs_ipc::{EventKind, ProcessId, StateEvent};
use drive_bus::safety_watch::VerifiedEpoch;

/// A reset event older than this (drive-io's clock) is stale: a replay or a history sample.
/// The monitor publishes its Reset a few cycles after the NMT start; drive-io reads events every
/// SYNC and may wait up to [`crate::runner`]'s verification window for its watch.
pub const RESET_EVENT_MAX_AGE_NS: u64 = 2_000_000_000;
/// How far in drive-io's future a reset event's stamp may lie (same CLOCK_MONOTONIC host: the
/// monitor may stamp just after drive-io's cycle began).
pub const RESET_EVENT_FUTURE_TOLERANCE_NS: u64 = 50_000_000;

/// The right to leave the master's latch. Made only by [`ResetGate`] (private field): outside
/// this module it cannot be constructed; not `Clone` or `Copy`: consumed by
/// [`crate::master::Master::reset`], which hands it back when it cannot apply it yet.
///
/// ```compile_fail,E0451
/// let forged = drive_io::reset::ResetGrant { epoch: 1 };
/// ```
///
/// ```compile_fail,E0382
/// fn twice(g: drive_io::reset::ResetGrant) -> (drive_io::reset::ResetGrant, drive_io::reset::ResetGrant) {
///     (g, g)
/// }
/// ```
#[derive(Debug, PartialEq, Eq)]
pub struct ResetGrant {
    epoch: u32,
}

impl ResetGrant {
    /// The monitor's reset epoch this grant is for.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }
}

/// Why a reset event did not yield a grant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ignored {
    /// Not a reset event of this contract version.
    NotAReset,
    /// A reset event from another process than the safety monitor (raw source code).
    Source(u32),
    /// The epoch is not a reset drive-io has not acted on (a replay, or a reset while
    /// running): see [`reset_epoch::releases`].
    NotNewer { epoch: u32, in_force: u32 },
    /// The epoch is a monitor instance's start epoch (count 0): no operator reset at all.
    StartEpoch { epoch: u32 },
    /// The epoch is not (yet) the one the safety watch verified on the bus.
    NotVerified { epoch: u32, on_bus: Option<u32> },
    /// Stamped outside [now − RESET_EVENT_MAX_AGE_NS, now + tolerance] of drive-io's clock.
    Stale { age_ns: i64 },
}

/// Tracks the reset epoch in force and decides which reset events may release the latch.
#[derive(Debug, Clone, Copy, Default)]
pub struct ResetGate {
    in_force: Option<u32>,
}

impl ResetGate {
    pub fn new() -> Self {
        Self::default()
    }

    /// The epoch in force (None: none seen yet).
    pub fn in_force(&self) -> Option<u32> {
        self.in_force
    }

    /// Called every cycle with the watch's verified epoch: while drive-io is not latched (or
    /// before any epoch was seen) that is the epoch in force; a latch then needs a newer one.
    pub fn note(&mut self, verified: Option<VerifiedEpoch>, latched: bool) {
        if let Some(v) = verified
            && (!latched || self.in_force.is_none())
        {
            self.in_force = Some(v.get());
        }
    }

    fn epoch_of(&self, ev: &StateEvent, now_ns: u64) -> Result<u32, Ignored> {
        match ev.decode() {
            Ok(crs_ipc::Event::Reset {
                source: ProcessId::SafetyMonitor,
            }) => {}
            Ok(crs_ipc::Event::Reset { .. }) => return Err(Ignored::Source(ev.source)),
            _ => return Err(Ignored::NotAReset),
        }
        let fresh = ev.timestamp_ns <= now_ns.saturating_add(RESET_EVENT_FUTURE_TOLERANCE_NS)
            && now_ns.saturating_sub(ev.timestamp_ns) <= RESET_EVENT_MAX_AGE_NS;
        if !fresh {
            return Err(Ignored::Stale {
                age_ns: now_ns as i64 - ev.timestamp_ns as i64,
            });
        }
        let epoch = ev.detail;
        if reset_epoch::count(epoch) == 0 {
            return Err(Ignored::StartEpoch { epoch });
        }
        match self.in_force {
            Some(f) if !reset_epoch::releases(epoch, f) => {
                Err(Ignored::NotNewer { epoch, in_force: f })
            }
            _ => Ok(epoch),
        }
    }

    /// With the safety watch: the monitor's fresh reset event whose epoch the watch verified on
    /// CAN (`now_ns`: drive-io's clock).
    pub fn check(
        &self,
        ev: &StateEvent,
        verified: Option<VerifiedEpoch>,
        now_ns: u64,
    ) -> Result<ResetGrant, Ignored> {
        let epoch = self.epoch_of(ev, now_ns)?;
        match verified {
            Some(v) if v.get() == epoch => Ok(ResetGrant { epoch }),
            _ => Err(Ignored::NotVerified {
                epoch,
                on_bus: verified.map(VerifiedEpoch::get),
            }),
        }
    }

    /// Without the watch (bench): the event's source, freshness and epoch order only.
    pub fn check_unauthenticated(
        &self,
        ev: &StateEvent,
        now_ns: u64,
    ) -> Result<ResetGrant, Ignored> {
        self.epoch_of(ev, now_ns).map(|epoch| ResetGrant { epoch })
    }

    /// The master applied the grant of `epoch` (the epoch [`crate::master::Master::reset`]
    /// returned): it is now in force.
    pub fn granted(&mut self, epoch: u32) {
        self.in_force = Some(epoch);
    }
}

/// True for a reset event (any source), for logging what was ignored.
pub fn is_reset_event(ev: &StateEvent) -> bool {
    ev.kind == EventKind::Reset as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::safety_frame::{DEFAULT_COB_ID, SafetyHeartbeat, SafetyState, encode};
    use drive_bus::safety_watch::{SafetyWatch, SafetyWatchConfig};

    fn reset_event(source: ProcessId, epoch: u32) -> StateEvent {
        let mut ev = StateEvent::new(source, EventKind::Reset, 1);
        ev.detail = epoch;
        ev.timestamp_ns = NOW;
        ev
    }

    const NOW: u64 = 100_000_000_000;

    /// A watch that permits on `epoch` (a real verification of real frames: the only way to
    /// get a VerifiedEpoch).
    fn watch_on(epoch: u32) -> SafetyWatch {
        let cfg = SafetyWatchConfig::default();
        let mut w = SafetyWatch::new(cfg);
        for k in 0..3u16 {
            let sig = can_transport::safety_frame::ConfigSignature {
                srdo_crc: cfg.srdo_crc(),
                safety_params_crc: 0,
            };
            for f in sig.encode(DEFAULT_COB_ID) {
                w.on_frame(&f, u64::from(k) * 1_000_000);
            }
            for f in encode(
                &SafetyHeartbeat {
                    state: SafetyState::Run,
                    cause: 0,
                    counter: k,
                    epoch,
                },
                DEFAULT_COB_ID,
            ) {
                w.on_frame(&f, u64::from(k) * 1_000_000);
            }
        }
        assert!(w.permits(3_000_000));
        w
    }

    #[test]
    fn only_the_monitors_verified_newer_epoch_grants() {
        let mut gate = ResetGate::new();
        let w5 = watch_on(5);
        gate.note(w5.verified_epoch(), false);
        assert_eq!(gate.in_force(), Some(5));
        // Latched now: the epoch in force stays 5.
        gate.note(w5.verified_epoch(), true);
        let w6 = watch_on(6);
        let check = |gate: &ResetGate, src, epoch, w: &SafetyWatch| {
            gate.check(&reset_event(src, epoch), w.verified_epoch(), NOW)
        };
        // Forged sources.
        for src in [ProcessId::Operator, ProcessId::MotionCore, ProcessId::Test] {
            assert_eq!(check(&gate, src, 6, &w6), Err(Ignored::Source(src as u32)));
        }
        // The monitor's source but an epoch that does not advance (replay / reset while armed).
        assert_eq!(
            check(&gate, ProcessId::SafetyMonitor, 5, &w5),
            Err(Ignored::NotNewer {
                epoch: 5,
                in_force: 5
            })
        );
        // A newer epoch the bus does not carry (forged event, monitor did not reset).
        assert_eq!(
            check(&gate, ProcessId::SafetyMonitor, 6, &w5),
            Err(Ignored::NotVerified {
                epoch: 6,
                on_bus: Some(5)
            })
        );
        assert!(matches!(
            gate.check(&reset_event(ProcessId::SafetyMonitor, 6), None, NOW),
            Err(Ignored::NotVerified { on_bus: None, .. })
        ));
        // Stale (a replay of the real event later) or stamped in drive-io's future.
        for stamp in [
            NOW - RESET_EVENT_MAX_AGE_NS - 1,
            NOW + RESET_EVENT_FUTURE_TOLERANCE_NS + 1,
        ] {
            let mut ev = reset_event(ProcessId::SafetyMonitor, 6);
            ev.timestamp_ns = stamp;
            assert!(matches!(
                gate.check(&ev, w6.verified_epoch(), NOW),
                Err(Ignored::Stale { .. })
            ));
        }
        // The monitor's reset, verified on CAN.
        let g = check(&gate, ProcessId::SafetyMonitor, 6, &w6).unwrap();
        assert_eq!(g.epoch(), 6);
        gate.granted(g.epoch());
        assert_eq!(gate.in_force(), Some(6));
        // The same event again (replay) no longer grants.
        assert!(check(&gate, ProcessId::SafetyMonitor, 6, &w6).is_err());
        // Not a reset at all.
        let ev = StateEvent::new(ProcessId::SafetyMonitor, EventKind::EStop, 1);
        assert_eq!(
            gate.check(&ev, w6.verified_epoch(), NOW),
            Err(Ignored::NotAReset)
        );
    }

    /// A restarted monitor is a new instance: its start epoch (count 0) is no reset, even when
    /// the watch verified it (it released nothing that stopped; a drive-io that never permitted
    /// may have verified it at power-on), and no event of another epoch than the verified one
    /// grants — never "any epoch first", not even without an epoch in force.
    #[test]
    fn a_restarted_monitor_s_start_epoch_and_unverified_epochs_never_grant() {
        use reset_epoch::new;
        let mut gate = ResetGate::new();
        let old = watch_on(new(0x1111, 3));
        gate.note(old.verified_epoch(), false);
        gate.note(old.verified_epoch(), true);
        // A drive-io whose watch verifies the new instance's start epoch (it never saw it
        // stop): the start epoch is not a reset.
        let restarted = watch_on(new(0x2222, 0));
        assert_eq!(
            gate.check(
                &reset_event(ProcessId::SafetyMonitor, new(0x2222, 0)),
                restarted.verified_epoch(),
                NOW
            ),
            Err(Ignored::StartEpoch {
                epoch: new(0x2222, 0)
            })
        );
        // A forged reset of the new instance that the bus does not carry.
        assert!(matches!(
            gate.check(
                &reset_event(ProcessId::SafetyMonitor, new(0x2222, 1)),
                restarted.verified_epoch(),
                NOW
            ),
            Err(Ignored::NotVerified { .. })
        ));
        // The new instance's first operator reset, verified on CAN: granted.
        let reset = watch_on(new(0x2222, 1));
        let g = gate
            .check(
                &reset_event(ProcessId::SafetyMonitor, new(0x2222, 1)),
                reset.verified_epoch(),
                NOW,
            )
            .unwrap();
        assert_eq!(g.epoch(), new(0x2222, 1));
        // Without any epoch in force (drive-io latched before it ever permitted): still only
        // the verified epoch, and only a reset.
        let fresh = ResetGate::new();
        assert!(
            fresh
                .check(
                    &reset_event(ProcessId::SafetyMonitor, new(0x3333, 1)),
                    None,
                    NOW
                )
                .is_err()
        );
        assert!(
            fresh
                .check(
                    &reset_event(ProcessId::SafetyMonitor, new(0x2222, 1)),
                    reset.verified_epoch(),
                    NOW
                )
                .is_ok()
        );
    }

    #[test]
    fn unauthenticated_path_checks_source_freshness_and_order() {
        let mut gate = ResetGate::new();
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::Operator, 1), NOW)
                .is_err()
        );
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 0), NOW)
                .is_err(),
            "a start epoch is no reset"
        );
        let g = gate
            .check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 1), NOW)
            .unwrap();
        gate.granted(g.epoch());
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 1), NOW)
                .is_err()
        );
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 2), NOW)
                .is_ok()
        );
        assert!(
            gate.check_unauthenticated(
                &reset_event(ProcessId::SafetyMonitor, 2),
                NOW + RESET_EVENT_MAX_AGE_NS + 1
            )
            .is_err(),
            "stale"
        );
    }
}
