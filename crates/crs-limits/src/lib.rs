//! # crs-limits: the limits, orders and definitions every layer agrees on, in one place
//!
//! A crate without dependencies so that the model library, the surrogate, the IPC contract and
//! the independent safety monitor can all name the same value without depending on each other
//! (the |Δq| limit once lived in three crates under three names, the cable count in three), and
//! every report, bench and figure prints its percentiles by one definition ([`quantile`]).

pub mod quantile;

/// Most cables any platform, payload or drive table of the stack holds: the fixed-size arrays of
/// the `#[repr(C)]` IPC payloads and the allocation-free hot paths are sized by it.
pub const MAX_CABLES: usize = 16;

/// True if the monitor's reset epoch `epoch` is newer than `than` in wrapping (serial number)
/// arithmetic: the difference is in 1..2^31. Epochs advance by one per accepted reset, so
/// wrapping is not reached in practice; the comparison still never treats an old epoch as new
/// across a wrap. The one order every receiver of the epoch uses (the CAN safety heartbeat's
/// watches, drive-io's and motion-core's reset gates).
#[inline]
pub fn epoch_newer(epoch: u32, than: u32) -> bool {
    let d = epoch.wrapping_sub(than);
    d != 0 && d < 0x8000_0000
}

/// The monitor's reset epoch as it travels (safety heartbeat bytes 4..8, the monitor's Reset
/// events): the monitor INSTANCE in the high 16 bits — a random nonce the monitor draws when it
/// starts — and the number of operator resets that instance accepted in the low 16 bits. A
/// reset is bound to the instance that verified it: a restarted monitor starts a new instance
/// at count 0, which is not a reset of anything, so consumers that were stopped under the old
/// instance stay stopped until the new instance accepts an operator reset (count >= 1).
pub mod reset_epoch {
    /// The instance nonce of an epoch.
    #[inline]
    pub fn instance(epoch: u32) -> u16 {
        (epoch >> 16) as u16
    }

    /// The number of resets the instance had accepted when it sent `epoch`.
    #[inline]
    pub fn count(epoch: u32) -> u16 {
        epoch as u16
    }

    /// The epoch of `instance` after `count` accepted resets.
    #[inline]
    pub fn new(instance: u16, count: u16) -> u32 {
        (u32::from(instance) << 16) | u32::from(count)
    }

    /// True if `epoch` stands for an operator reset that a consumer whose epoch in force is
    /// `in_force` has not yet acted on: a later reset of the same instance, or any reset
    /// (count >= 1) of another instance. A new instance's start epoch (count 0) releases
    /// nothing that was stopped, and an older count of the same instance (a replay) neither.
    /// Counts do not wrap: an instance refuses its 65 536th reset (the monitor must be
    /// restarted, which needs a reset of the new instance).
    #[inline]
    pub fn releases(epoch: u32, in_force: u32) -> bool {
        if instance(epoch) == instance(in_force) {
            count(epoch) > count(in_force)
        } else {
            count(epoch) >= 1
        }
    }
}

/// The spec's bound on the joint-space offset |Δq_i| = |q_θ,i − q_i| the surrogate may command
/// and the safety monitor lets through (sec. 5.6, eq. 5.27: 100 mm), m.
pub const DELTA_Q_LIMIT_M: f64 = 0.100;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_order_is_serial_number_arithmetic() {
        assert!(epoch_newer(1, 0));
        assert!(!epoch_newer(0, 0));
        assert!(!epoch_newer(0, 1));
        assert!(epoch_newer(0, u32::MAX));
        assert!(epoch_newer(0x7FFF_FFFF, 0));
        assert!(!epoch_newer(0x8000_0000, 0));
    }

    #[test]
    fn a_reset_is_bound_to_the_instance_that_accepted_it() {
        use reset_epoch::{count, instance, new, releases};
        let a0 = new(0xA11C, 0);
        assert_eq!((instance(a0), count(a0)), (0xA11C, 0));
        // The same instance: only a later count releases (a replay of an older one does not).
        assert!(releases(new(0xA11C, 1), a0));
        assert!(!releases(a0, a0));
        assert!(!releases(new(0xA11C, 3), new(0xA11C, 4)));
        // Another instance (a restarted monitor): its start epoch releases nothing, its first
        // accepted reset does, whatever its count says relative to the old instance's.
        assert!(!releases(new(0xB0B0, 0), new(0xA11C, 7)));
        assert!(releases(new(0xB0B0, 1), new(0xA11C, 7)));
        assert!(releases(new(0x0001, 1), new(0xFFFF, 0xFFFF)));
    }
}
