//! The monitor's stop frames on its own CAN socket, with retry and escalation when a frame
//! cannot be sent (ENOBUFS / EAGAIN: the interface's TX queue is full, [`CanError::TxFull`]).
//!
//! A stop that was not sent must not be assumed to have happened. The measures, weakest
//! dependency first:
//! 1. RPDO1 quick stop to every drive and **NMT stop** (all nodes): sent on the trip and the NMT
//!    stop every cycle while tripped; each frame is retried [`RETRIES`] times within the cycle
//!    (the queue drains at the bus rate: ~0.1 ms per frame at 1 Mbit/s).
//! 2. If the NMT stop still could not be sent: **escalated** to the safety heartbeat's inhibit.
//!    The STOP pair (data + bit-inverse) is retried the same way; the drives' watch inhibits
//!    on the first valid STOP pair, or on an invalid one (one half lost), at once.
//! 3. If no STOP pair could be sent either: the drives' watch inhibits when no valid RUN pair
//!    arrived within its validation time (SCT, 50 ms): the monitor sends nothing that permits.
//!
//! Every unsent frame is counted per kind and every escalation is logged (rate-limited) and
//! reported by [`StopPath::stage`]; the process writes it to the trip log.

use crate::bus_frames;
use can_transport::{CanBus, CanError, CanFrame};

/// Attempts per frame and cycle (the first send + retries).
pub const RETRIES: u32 = 3;
/// Pause between two attempts (lets the TX queue drain; 3 × 0.2 ms within a 15 ms cycle).
pub const RETRY_PAUSE: std::time::Duration = std::time::Duration::from_micros(200);

/// The strongest stop measure that reached the bus in the last tripped cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopStage {
    /// NMT stop sent (and the STOP heartbeat).
    NmtStop,
    /// NMT stop unsent: escalated to the STOP heartbeat pair, which was sent.
    HeartbeatInhibit,
    /// Neither sent: the drives' watch inhibits after its validation time without RUN.
    WatchTimeout,
}

impl StopStage {
    pub fn name(self) -> &'static str {
        match self {
            StopStage::NmtStop => "nmt_stop",
            StopStage::HeartbeatInhibit => "heartbeat_inhibit",
            StopStage::WatchTimeout => "watch_timeout",
        }
    }
}

/// Counts of frames that could not be sent (after every retry), and of retries that helped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StopCounts {
    pub quick_stop_unsent: u64,
    pub nmt_stop_unsent: u64,
    pub heartbeat_unsent: u64,
    pub other_unsent: u64,
    /// Sends that succeeded only on a retry.
    pub retried_ok: u64,
    /// Cycles escalated to the heartbeat's inhibit / to the watch's timeout.
    pub escalated_heartbeat: u64,
    pub escalated_watch: u64,
}

impl StopCounts {
    pub fn total_unsent(&self) -> u64 {
        self.quick_stop_unsent + self.nmt_stop_unsent + self.heartbeat_unsent + self.other_unsent
    }
}

/// What was sent this cycle.
#[derive(Debug, Clone, Copy, Default)]
struct Cycle {
    nmt_stop: Option<bool>,
}

/// Sends the monitor's frames with retries and tracks the stop's escalation.
#[derive(Debug, Default)]
pub struct StopPath {
    counts: StopCounts,
    cycle: Cycle,
    stage: Option<StopStage>,
    /// Log rate limit: the last stage logged.
    logged: Option<StopStage>,
}

fn try_send(bus: &mut dyn CanBus, f: &CanFrame, pause: bool) -> Result<u32, CanError> {
    let mut last = None;
    for attempt in 0..RETRIES {
        match bus.send(f) {
            Ok(()) => return Ok(attempt),
            // Only a full queue is worth retrying; any other error will not change.
            Err(e @ CanError::TxFull { .. }) => {
                last = Some(e);
                if pause && attempt + 1 < RETRIES {
                    std::thread::sleep(RETRY_PAUSE);
                }
            }
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or(CanError::TxFull {
        iface: bus.interface().to_string(),
    }))
}

impl StopPath {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn counts(&self) -> StopCounts {
        self.counts
    }

    /// The stage the last tripped cycle reached (None before the first trip).
    pub fn stage(&self) -> Option<StopStage> {
        self.stage
    }

    fn send(&mut self, bus: &mut dyn CanBus, f: &CanFrame) -> bool {
        match try_send(bus, f, true) {
            Ok(0) => true,
            Ok(_) => {
                self.counts.retried_ok += 1;
                true
            }
            Err(e) => {
                let n = self.counts.total_unsent() + 1;
                if n.is_power_of_two() {
                    tracing::error!(error = %e, id = format_args!("{:#05x}", f.id()), unsent = n,
                        "stop path: frame NOT sent after {RETRIES} attempts");
                }
                false
            }
        }
    }

    /// RPDO1 quick stop to `node` (target: the last one seen, so the drive stays where it is).
    /// Quick stop to one drive in its RPDO's configured layout, holding `target_counts`.
    pub fn quick_stop(
        &mut self,
        bus: &mut dyn CanBus,
        rpdo: &crate::bus_layout::RpdoLayout,
        target_counts: i32,
    ) -> bool {
        let ok = self.send(bus, &rpdo.encode(bus_frames::CW_QUICK_STOP, target_counts));
        if !ok {
            self.counts.quick_stop_unsent += 1;
        }
        ok
    }

    /// NMT stop addressed to each drive (`(interface, node id)`) on its own interface (on the
    /// trip and every tripped cycle). Addressed, not broadcast: the safety I/O node (whose
    /// TPDO1 carries the operator's reset key and e-stop circuit, sent only while it is
    /// operational) and the load cells (whose readings are the evidence that the forces are
    /// back in range) keep running; the drives' torque is removed by the STOP pairs through the
    /// node's STO outputs and by their own NMT stop.
    pub fn nmt_stop_drives(
        &mut self,
        tx: &mut crate::tx_buses::TxBuses,
        drives: impl Iterator<Item = (usize, u8)>,
    ) -> bool {
        let mut ok = true;
        for (iface, node) in drives {
            let sent = match tx.on(iface) {
                Some(bus) => self.send(bus, &bus_frames::nmt(bus_frames::NMT_STOP, node)),
                None => false,
            };
            ok &= sent;
        }
        // Counted once per cycle (like the broadcast), whichever drives' frames stayed unsent.
        if !ok {
            self.counts.nmt_stop_unsent += 1;
        }
        self.cycle.nmt_stop = Some(ok);
        ok
    }

    /// NMT stop, all nodes (on the trip and every tripped cycle).
    pub fn nmt_stop(&mut self, bus: &mut dyn CanBus) -> bool {
        let ok = self.send(bus, &bus_frames::nmt(bus_frames::NMT_STOP, 0));
        if !ok {
            self.counts.nmt_stop_unsent += 1;
        }
        self.cycle.nmt_stop = Some(ok);
        ok
    }

    /// Any other frame of the monitor (NMT start after a reset).
    pub fn other(&mut self, bus: &mut dyn CanBus, f: &CanFrame) -> bool {
        let ok = self.send(bus, f);
        if !ok {
            self.counts.other_unsent += 1;
        }
        ok
    }

    /// The safety heartbeat pair of this cycle; `stopping` while tripped. Closes the cycle's
    /// escalation: returns the stage reached when `stopping`.
    pub fn heartbeat(
        &mut self,
        bus: &mut dyn CanBus,
        pair: &[CanFrame; 2],
        stopping: bool,
    ) -> Option<StopStage> {
        let mut sent = true;
        for f in pair {
            if !self.send(bus, f) {
                self.counts.heartbeat_unsent += 1;
                sent = false;
            }
        }
        let cycle = std::mem::take(&mut self.cycle);
        if !stopping {
            return None;
        }
        let stage = match (cycle.nmt_stop, sent) {
            (Some(false), true) => {
                self.counts.escalated_heartbeat += 1;
                StopStage::HeartbeatInhibit
            }
            (Some(false), false) | (None, false) => {
                self.counts.escalated_watch += 1;
                StopStage::WatchTimeout
            }
            (Some(true), false) => StopStage::NmtStop,
            (Some(true), true) | (None, true) => StopStage::NmtStop,
        };
        if stage != StopStage::NmtStop && self.logged != Some(stage) {
            match stage {
                StopStage::HeartbeatInhibit => tracing::error!(
                    counts = ?self.counts,
                    "stop path ESCALATED: the NMT stop could not be sent; the drives stop on \
                     the safety heartbeat's STOP (inhibit)"
                ),
                _ => tracing::error!(
                    counts = ?self.counts,
                    "stop path ESCALATED: neither the NMT stop nor the STOP heartbeat could be \
                     sent; the drives' watch inhibits after its validation time without RUN"
                ),
            }
        }
        self.logged = Some(stage);
        self.stage = Some(stage);
        Some(stage)
    }
}

/// Fault injection (the HIL matrix's `stop_frame_lost`, tests): a bus whose sends of frames
/// with the given id fail with [`CanError::TxFull`], as on a full TX queue (ENOBUFS);
/// everything else passes through.
pub struct FailingSends<B: CanBus> {
    inner: B,
    fail_id: u32,
    /// Failures so far.
    pub failed: u64,
}

impl<B: CanBus> FailingSends<B> {
    pub fn new(inner: B, fail_id: u32) -> Self {
        Self {
            inner,
            fail_id,
            failed: 0,
        }
    }
}

impl<B: CanBus> CanBus for FailingSends<B> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        if frame.id() == self.fail_id && !frame.is_extended() {
            self.failed += 1;
            return Err(CanError::TxFull {
                iface: self.inner.interface().to_string(),
            });
        }
        self.inner.send(frame)
    }
    fn recv_timeout(
        &mut self,
        timeout: std::time::Duration,
    ) -> Result<Option<can_transport::RxFrame>, CanError> {
        self.inner.recv_timeout(timeout)
    }
    fn interface(&self) -> &str {
        self.inner.interface()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::safety_frame::{self, SafetyHeartbeat, SafetyState};
    use can_transport::{CanBus, RxFrame};
    use std::time::Duration;

    /// Records what was sent; fails sends of `fail_id` the next `fail_n` times (u32::MAX:
    /// always), with `TxFull` (ENOBUFS) or, with `hard`, an I/O error.
    struct Bus {
        sent: Vec<CanFrame>,
        fail_id: Option<u32>,
        fail_n: u32,
        hard: bool,
        attempts: u32,
    }

    impl Bus {
        fn new(fail_id: Option<u32>, fail_n: u32) -> Self {
            Self {
                sent: Vec::new(),
                fail_id,
                fail_n,
                hard: false,
                attempts: 0,
            }
        }
    }

    impl CanBus for Bus {
        fn send(&mut self, f: &CanFrame) -> Result<(), CanError> {
            self.attempts += 1;
            if self.fail_id.is_none_or(|id| id == f.id()) && self.fail_n > 0 {
                self.fail_n = self.fail_n.saturating_sub(1);
                return Err(if self.hard {
                    CanError::Io {
                        iface: "t".into(),
                        op: "write",
                        source: std::io::Error::other("down"),
                    }
                } else {
                    CanError::TxFull { iface: "t".into() }
                });
            }
            self.sent.push(*f);
            Ok(())
        }
        fn recv_timeout(&mut self, _: Duration) -> Result<Option<RxFrame>, CanError> {
            Ok(None)
        }
        fn interface(&self) -> &str {
            "t"
        }
    }

    fn stop_pair() -> [CanFrame; 2] {
        safety_frame::encode(
            &SafetyHeartbeat {
                state: SafetyState::Stop,
                cause: 1,
                counter: 1,
                epoch: 1,
            },
            0x101,
        )
    }

    #[test]
    fn a_full_queue_is_retried_within_the_cycle() {
        let mut bus = Bus::new(Some(0), 2);
        let mut p = StopPath::new();
        assert!(p.nmt_stop(&mut bus));
        assert_eq!(bus.attempts, 3);
        assert_eq!(bus.sent, vec![bus_frames::nmt(bus_frames::NMT_STOP, 0)]);
        assert_eq!(
            p.heartbeat(&mut bus, &stop_pair(), true),
            Some(StopStage::NmtStop)
        );
        assert_eq!(p.counts().retried_ok, 1);
        assert_eq!(p.counts().nmt_stop_unsent, 0);
    }

    #[test]
    fn an_unsent_nmt_stop_escalates_to_the_heartbeat_inhibit() {
        let mut bus = Bus::new(Some(0), u32::MAX);
        let mut p = StopPath::new();
        for cycle in 1..=3u64 {
            assert!(!p.nmt_stop(&mut bus));
            assert_eq!(
                p.heartbeat(&mut bus, &stop_pair(), true),
                Some(StopStage::HeartbeatInhibit)
            );
            assert_eq!(p.counts().nmt_stop_unsent, cycle);
            assert_eq!(p.counts().escalated_heartbeat, cycle);
        }
        // Only the STOP pairs reached the bus, every cycle.
        assert!(bus.sent.iter().all(|f| f.id() == 0x101 || f.id() == 0x102));
        assert_eq!(bus.sent.len(), 6);
        assert_eq!(bus.attempts, 3 * (RETRIES + 2));
    }

    #[test]
    fn nothing_sent_leaves_the_watch_timeout_and_says_so() {
        let mut bus = Bus::new(None, u32::MAX);
        let mut p = StopPath::new();
        assert!(!p.quick_stop(
            &mut bus,
            &crate::bus_layout::RpdoLayout::default_for(0, 3),
            0
        ));
        assert!(!p.nmt_stop(&mut bus));
        assert_eq!(
            p.heartbeat(&mut bus, &stop_pair(), true),
            Some(StopStage::WatchTimeout)
        );
        let c = p.counts();
        assert_eq!(
            (c.quick_stop_unsent, c.nmt_stop_unsent, c.heartbeat_unsent),
            (1, 1, 2)
        );
        assert_eq!(c.escalated_watch, 1);
        assert_eq!(p.stage(), Some(StopStage::WatchTimeout));
        // A hard error is not retried (it will not drain).
        let mut bus = Bus::new(Some(0), u32::MAX);
        bus.hard = true;
        assert!(!p.nmt_stop(&mut bus));
        assert_eq!(bus.attempts, 1);
    }

    #[test]
    fn armed_cycles_do_not_escalate() {
        let mut bus = Bus::new(None, 0);
        let mut p = StopPath::new();
        assert_eq!(p.heartbeat(&mut bus, &stop_pair(), false), None);
        assert_eq!(p.stage(), None);
        let mut f = FailingSends::new(Bus::new(None, 0), 0);
        assert!(matches!(
            f.send(&bus_frames::nmt(bus_frames::NMT_STOP, 0)),
            Err(CanError::TxFull { .. })
        ));
        f.send(&stop_pair()[0]).unwrap();
        assert_eq!((f.failed, f.inner.sent.len()), (1, 1));
    }
}
