//! drive-io's reset authority (issue 16; ISO 13849-1 §5.2.2: after a stop, only a manual reset
//! at the safety function, never the return of a signal or another process's say-so, may allow
//! a restart).
//!
//! The master leaves a latch (e-stop, stale stop, fault) only through [`Master::reset`], which
//! takes a [`ResetGrant`]. A grant has no public constructor: only a [`ResetGate`] makes one,
//! and only for a reset the safety monitor minted:
//!
//! * with the safety heartbeat watch (`[safety_heartbeat]`, every shipped config): the monitor's
//!   `StateEvent { source: SafetyMonitor, kind: Reset, detail: epoch }` counts only if `epoch`
//!   equals the reset epoch the watch VERIFIED on the monitor's own doubled CAN frames
//!   ([`VerifiedEpoch`]) and is newer than the epoch in force when drive-io latched. The
//!   iceoryx2 event alone authenticates nothing (its `source` is self-declared, see
//!   docs/safety-monitor.md, threat model); the CAN epoch is the authority.
//! * without the watch (bench setups only): the event's source and a newer epoch are checked,
//!   which stops accidents (an operator tool, a test, a stale event) but not a malicious local
//!   process.
//!
//! Anything else is [`Ignored`] and the caller logs it (rate-limited).
//!
//! [`Master::reset`]: crate::master::Master::reset

use crate::safety_watch::VerifiedEpoch;
use can_transport::safety_frame::epoch_newer;
use crs_ipc::{EventKind, ProcessId, StateEvent};

/// The right to leave the master's latch. Made only by [`ResetGate`] (private field): outside
/// this module it cannot be constructed.
///
/// ```compile_fail
/// let forged = drive_io::reset::ResetGrant { epoch: 1 };
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
    /// The epoch is not newer than the one in force (a replay, or a reset while running).
    NotNewer { epoch: u32, in_force: u32 },
    /// The epoch is not (yet) the one the safety watch verified on the bus.
    NotVerified { epoch: u32, on_bus: Option<u32> },
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

    fn epoch_of(&self, ev: &StateEvent) -> Result<u32, Ignored> {
        match ev.decode() {
            Ok(crs_ipc::Event::Reset {
                source: ProcessId::SafetyMonitor,
            }) => {}
            Ok(crs_ipc::Event::Reset { .. }) => return Err(Ignored::Source(ev.source)),
            _ => return Err(Ignored::NotAReset),
        }
        let epoch = ev.detail;
        match self.in_force {
            Some(f) if !epoch_newer(epoch, f) => Err(Ignored::NotNewer { epoch, in_force: f }),
            _ => Ok(epoch),
        }
    }

    /// With the safety watch: the monitor's reset event whose epoch the watch verified on CAN.
    pub fn check(
        &self,
        ev: &StateEvent,
        verified: Option<VerifiedEpoch>,
    ) -> Result<ResetGrant, Ignored> {
        let epoch = self.epoch_of(ev)?;
        match verified {
            Some(v) if v.get() == epoch => Ok(ResetGrant { epoch }),
            _ => Err(Ignored::NotVerified {
                epoch,
                on_bus: verified.map(VerifiedEpoch::get),
            }),
        }
    }

    /// Without the watch (bench): the event's source and a newer epoch only.
    pub fn check_unauthenticated(&self, ev: &StateEvent) -> Result<ResetGrant, Ignored> {
        self.epoch_of(ev).map(|epoch| ResetGrant { epoch })
    }

    /// The master accepted `grant`: its epoch is now in force.
    pub fn granted(&mut self, grant: ResetGrant) {
        self.in_force = Some(grant.epoch);
    }
}

/// True for a reset event (any source), for logging what was ignored.
pub fn is_reset_event(ev: &StateEvent) -> bool {
    ev.kind == EventKind::Reset as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety_watch::{SafetyWatch, SafetyWatchConfig};
    use can_transport::safety_frame::{DEFAULT_COB_ID, SafetyHeartbeat, SafetyState, encode};

    fn reset_event(source: ProcessId, epoch: u32) -> StateEvent {
        let mut ev = StateEvent::new(source, EventKind::Reset, 1);
        ev.detail = epoch;
        ev
    }

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
        // Forged sources.
        for src in [ProcessId::Operator, ProcessId::MotionCore, ProcessId::Test] {
            assert_eq!(
                gate.check(&reset_event(src, 6), w6.verified_epoch()),
                Err(Ignored::Source(src as u32))
            );
        }
        // The monitor's source but an epoch that does not advance (replay / reset while armed).
        assert_eq!(
            gate.check(
                &reset_event(ProcessId::SafetyMonitor, 5),
                w5.verified_epoch()
            ),
            Err(Ignored::NotNewer {
                epoch: 5,
                in_force: 5
            })
        );
        // A newer epoch the bus does not carry (forged event, monitor did not reset).
        assert_eq!(
            gate.check(
                &reset_event(ProcessId::SafetyMonitor, 6),
                w5.verified_epoch()
            ),
            Err(Ignored::NotVerified {
                epoch: 6,
                on_bus: Some(5)
            })
        );
        assert!(matches!(
            gate.check(&reset_event(ProcessId::SafetyMonitor, 6), None),
            Err(Ignored::NotVerified { on_bus: None, .. })
        ));
        // The monitor's reset, verified on CAN.
        let g = gate
            .check(
                &reset_event(ProcessId::SafetyMonitor, 6),
                w6.verified_epoch(),
            )
            .unwrap();
        gate.granted(g);
        assert_eq!(gate.in_force(), Some(6));
        // The same event again (replay) no longer grants.
        assert!(
            gate.check(
                &reset_event(ProcessId::SafetyMonitor, 6),
                w6.verified_epoch()
            )
            .is_err()
        );
        // Not a reset at all.
        let ev = StateEvent::new(ProcessId::SafetyMonitor, EventKind::EStop, 1);
        assert_eq!(
            gate.check(&ev, w6.verified_epoch()),
            Err(Ignored::NotAReset)
        );
    }

    #[test]
    fn unauthenticated_path_checks_source_and_order() {
        let mut gate = ResetGate::new();
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::Operator, 1))
                .is_err()
        );
        let g = gate
            .check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 1))
            .unwrap();
        gate.granted(g);
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 1))
                .is_err()
        );
        assert!(
            gate.check_unauthenticated(&reset_event(ProcessId::SafetyMonitor, 2))
                .is_ok()
        );
    }
}
