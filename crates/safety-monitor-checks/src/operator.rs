//! Who may ask the monitor for a reset (ISO 13849-1 §5.2.2: the manual reset is a separate,
//! deliberate action of the operator at the safety function).
//!
//! Two channels, each of which yields an [`OperatorReset`] — the only value
//! [`crate::Monitor::request_reset`] takes, with no public constructor:
//!
//! * the **reset key** of the safety I/O node (drives file `[safety_io]`): the node reports its
//!   inputs in TPDO1 on the safety interface; the monitor reads them on its own socket. A reset
//!   is the key turned and RELEASED ([`KeyWatch`]): the request is made on the falling edge, so
//!   a key that is stuck, bridged or held is never a stream of resets; a key held longer than
//!   [`KEY_MAX_HOLD_NS`] is ignored until released and turned again.
//! * a **local socket** whose peer's credentials (SO_PEERCRED, checked by the kernel) show
//!   membership of the operator group (`[reset] operator_gid`): `safety-monitor reset` connects
//!   to it ([`crate::reset_socket`]).
//!
//! Everything else — in particular a reset request published on the process bus, which any
//! process of the stack's user can publish under any name — is refused and logged with what is
//! known of its sender.

use std::fmt;

/// Safety I/O node TPDO1 input bit: the e-stop circuit is closed (button released).
pub const INPUT_ESTOP_CLOSED: u8 = 0x01;
/// Safety I/O node TPDO1 input bit: the reset key is turned.
pub const INPUT_RESET_KEY: u8 = 0x02;
/// Safety I/O node TPDO1 output bit: STO released (torque permitted).
pub const OUTPUT_STO_RELEASED: u8 = 0x01;

/// A key held longer than this is not a reset (stuck, bridged or wedged): ignored until it is
/// released and turned again.
pub const KEY_MAX_HOLD_NS: u64 = 5_000_000_000;

/// Where an operator's reset came from (for the log and the answer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetChannel {
    /// The safety I/O node's reset key, turned and released.
    Key,
    /// The reset socket; the peer's process, user and group as the kernel reported them.
    Socket { pid: i32, uid: u32, gid: u32 },
}

impl fmt::Display for ResetChannel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ResetChannel::Key => f.write_str("reset key of the safety I/O node"),
            ResetChannel::Socket { pid, uid, gid } => {
                write!(f, "reset socket (pid {pid}, uid {uid}, gid {gid})")
            }
        }
    }
}

/// An operator's reset request from an authorised channel. No public constructor, not `Clone`
/// or `Copy`: made only by [`KeyWatch`] (the key turned and released) and by the reset socket's
/// credential check, and consumed by [`crate::Monitor::request_reset`].
///
/// ```compile_fail,E0451
/// let forged = safety_monitor_checks::operator::OperatorReset {
///     channel: safety_monitor_checks::operator::ResetChannel::Key,
/// };
/// ```
#[derive(Debug, PartialEq, Eq)]
pub struct OperatorReset {
    channel: ResetChannel,
}

impl OperatorReset {
    /// Only the authorised channels of this crate mint one.
    pub(crate) fn new(channel: ResetChannel) -> Self {
        Self { channel }
    }

    pub fn channel(&self) -> ResetChannel {
        self.channel
    }
}

/// Edge detection on the safety I/O node's reset key input: a reset is the key turned (seen in
/// at least one TPDO1) and released within [`KEY_MAX_HOLD_NS`].
#[derive(Debug, Default, Clone, Copy)]
pub struct KeyWatch {
    /// Receive time of the first report with the key turned, while it is turned.
    turned_since: Option<u64>,
    /// The current turn lasted too long: ignored until released.
    stuck: bool,
}

/// What one input report did to the key.
#[derive(Debug, PartialEq, Eq)]
pub enum KeyEvent {
    /// Nothing happened (no edge).
    None,
    /// The key was turned (rising edge): nothing is requested until it is released.
    Turned,
    /// The key was held too long: this turn is ignored.
    Stuck { held_ns: u64 },
    /// The key was released after a turn: the operator's reset.
    Reset(OperatorReset),
}

impl KeyWatch {
    pub fn new() -> Self {
        Self::default()
    }

    /// One TPDO1 of the safety I/O node: `inputs` (bit 1 = key turned) received at `rx_ns`.
    pub fn on_inputs(&mut self, inputs: u8, rx_ns: u64) -> KeyEvent {
        let turned = inputs & INPUT_RESET_KEY != 0;
        match (turned, self.turned_since) {
            (true, None) => {
                self.turned_since = Some(rx_ns);
                self.stuck = false;
                KeyEvent::Turned
            }
            (true, Some(t0)) => {
                let held_ns = rx_ns.saturating_sub(t0);
                if held_ns > KEY_MAX_HOLD_NS && !self.stuck {
                    self.stuck = true;
                    KeyEvent::Stuck { held_ns }
                } else {
                    KeyEvent::None
                }
            }
            (false, Some(t0)) => {
                self.turned_since = None;
                let stuck = std::mem::take(&mut self.stuck);
                if stuck || rx_ns.saturating_sub(t0) > KEY_MAX_HOLD_NS {
                    KeyEvent::None
                } else {
                    KeyEvent::Reset(OperatorReset::new(ResetChannel::Key))
                }
            }
            (false, None) => KeyEvent::None,
        }
    }

    /// The node went silent or was restarted: a turn in progress does not count.
    pub fn forget(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_reset_is_a_turn_and_a_release() {
        let mut k = KeyWatch::new();
        assert_eq!(k.on_inputs(INPUT_ESTOP_CLOSED, 0), KeyEvent::None);
        assert_eq!(
            k.on_inputs(INPUT_ESTOP_CLOSED | INPUT_RESET_KEY, 10 * MS),
            KeyEvent::Turned
        );
        // Held: repeated reports of the turned key request nothing.
        for t in 2..20 {
            assert_eq!(
                k.on_inputs(INPUT_ESTOP_CLOSED | INPUT_RESET_KEY, t * 10 * MS),
                KeyEvent::None
            );
        }
        match k.on_inputs(INPUT_ESTOP_CLOSED, 300 * MS) {
            KeyEvent::Reset(r) => assert_eq!(r.channel(), ResetChannel::Key),
            other => panic!("{other:?}"),
        }
        // Released: nothing more until the next turn.
        assert_eq!(k.on_inputs(INPUT_ESTOP_CLOSED, 310 * MS), KeyEvent::None);
    }

    #[test]
    fn a_key_held_too_long_is_ignored_until_turned_again() {
        let mut k = KeyWatch::new();
        assert_eq!(k.on_inputs(INPUT_RESET_KEY, 0), KeyEvent::Turned);
        assert!(matches!(
            k.on_inputs(INPUT_RESET_KEY, KEY_MAX_HOLD_NS + 1),
            KeyEvent::Stuck { .. }
        ));
        assert_eq!(
            k.on_inputs(INPUT_RESET_KEY, KEY_MAX_HOLD_NS + 10 * MS),
            KeyEvent::None
        );
        assert_eq!(k.on_inputs(0, KEY_MAX_HOLD_NS + 20 * MS), KeyEvent::None);
        // A stuck key whose release is reported after the hold time without an intermediate
        // report is ignored too.
        assert_eq!(k.on_inputs(INPUT_RESET_KEY, 0), KeyEvent::Turned);
        assert_eq!(k.on_inputs(0, KEY_MAX_HOLD_NS + 1), KeyEvent::None);
        // Turned again: a normal reset.
        assert_eq!(k.on_inputs(INPUT_RESET_KEY, 1), KeyEvent::Turned);
        assert!(matches!(k.on_inputs(0, 100 * MS), KeyEvent::Reset(_)));
        // A turn whose node went silent in between does not count.
        assert_eq!(k.on_inputs(INPUT_RESET_KEY, 0), KeyEvent::Turned);
        k.forget();
        assert_eq!(k.on_inputs(0, 10 * MS), KeyEvent::None);
    }
}
