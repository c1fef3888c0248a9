//! Receiving from several CAN interfaces in one thread (drive-io, the plant, the emulator and
//! the safety monitor's reader serve up to eight interfaces each).

use crate::{CanBus, CanError, RxEvent, wait_readable_any};
use std::time::Duration;

/// Most interfaces one [`recv_any`] call waits on.
pub const MAX_WAIT_BUSES: usize = 8;

/// Waits up to `timeout` until one of `buses` has an event (frame or error frame) and returns
/// it with the bus's index. Buses are scanned from `*cursor` on, and the cursor moves past the
/// bus served, so a busy interface cannot starve the others. With one bus this is
/// [`CanBus::recv_event_timeout`]; with several, the buses' readiness descriptors are waited on
/// in one `ppoll` (a bus without a descriptor is polled every 100 µs). `Ok(None)` on timeout.
pub fn recv_any<B: CanBus>(
    buses: &mut [B],
    timeout: Duration,
    cursor: &mut usize,
) -> Result<Option<(usize, RxEvent)>, CanError> {
    let n = buses.len().min(MAX_WAIT_BUSES);
    if n == 0 {
        std::thread::sleep(timeout);
        return Ok(None);
    }
    if n == 1 {
        return Ok(buses[0].recv_event_timeout(timeout)?.map(|e| (0, e)));
    }
    let deadline = std::time::Instant::now() + timeout;
    loop {
        for k in 0..n {
            let i = (*cursor + k) % n;
            if let Some(ev) = buses[i].try_recv_event()? {
                *cursor = (i + 1) % n;
                return Ok(Some((i, ev)));
            }
        }
        let now = std::time::Instant::now();
        if now >= deadline {
            return Ok(None);
        }
        let left = deadline - now;
        let mut fds = [-1; MAX_WAIT_BUSES];
        let mut all = true;
        for (fd, b) in fds.iter_mut().zip(buses.iter()) {
            match b.readiness_fd() {
                Some(f) => *fd = f,
                None => all = false,
            }
        }
        if all {
            wait_readable_any(fds, left).map_err(|source| CanError::Io {
                iface: buses[0].interface().to_string(),
                op: "ppoll",
                source,
            })?;
        } else {
            std::thread::sleep(left.min(Duration::from_micros(100)));
        }
    }
}
