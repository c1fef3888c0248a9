//! # crs-limits: the fixed limits (and the reset-epoch order) every layer agrees on, in one place
//!
//! A crate without dependencies so that the model library, the surrogate, the IPC contract and
//! the independent safety monitor can all name the same value without depending on each other
//! (issue 14: the |Δq| limit lived in three crates under three names, the cable count in three).

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
}
