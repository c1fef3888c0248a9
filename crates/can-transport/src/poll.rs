//! ppoll(2) with a sub-millisecond timeout (poll(2) only has ms resolution, too coarse for 1 ms cycles).

use std::os::fd::RawFd;
use std::time::Duration;

/// Waits until `fd` is readable or `timeout` passes. Returns Ok(true) if readable.
pub(crate) fn wait_readable(fd: RawFd, timeout: Duration) -> std::io::Result<bool> {
    Ok(wait_readable_any([fd], timeout)?[0])
}

/// Waits until one of `fds` is readable or `timeout` passes (ppoll, ns resolution); returns
/// which are readable (all false on timeout). A negative descriptor is ignored (poll(2)).
pub fn wait_readable_any<const N: usize>(
    fds: [RawFd; N],
    timeout: Duration,
) -> std::io::Result<[bool; N]> {
    let mut pfd = fds.map(|fd| libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    });
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i64::MAX as u64) as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    loop {
        // SAFETY: N valid pollfds, a valid timespec, no signal mask.
        let r = unsafe { libc::ppoll(pfd.as_mut_ptr(), N as libc::nfds_t, &ts, std::ptr::null()) };
        if r >= 0 {
            // POLLERR/POLLHUP count as readable: the next receive reports the error.
            return Ok(pfd.map(|p| p.revents != 0));
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::fd::AsRawFd;

    #[test]
    fn any_reports_which_descriptor_is_readable() {
        let a = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let b = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let fds = [a.as_raw_fd(), b.as_raw_fd()];
        assert_eq!(
            wait_readable_any(fds, Duration::from_millis(1)).unwrap(),
            [false, false]
        );
        a.send_to(b"x", b.local_addr().unwrap()).unwrap();
        assert_eq!(
            wait_readable_any(fds, Duration::from_secs(5)).unwrap(),
            [false, true]
        );
        // A negative descriptor is skipped.
        assert_eq!(
            wait_readable_any([-1, b.as_raw_fd()], Duration::from_secs(5)).unwrap(),
            [false, true]
        );
    }
}
