//! The counter table of one bus: per node, how many of its frames the hub has resolved (left
//! the wire or refused by the model). A memfd the hub maps read-write; each `wire:` client gets
//! the descriptor in its welcome and maps it read-only (can_transport::wire::proto).

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::sync::atomic::{AtomicU64, Ordering};

pub struct Counters {
    fd: OwnedFd,
    base: *mut libc::c_void,
    entries: usize,
}

// SAFETY: the mapping is owned by this value; the hub thread is its only writer and writes
// through atomics.
unsafe impl Send for Counters {}

impl Counters {
    pub fn new(name: &str, entries: usize) -> std::io::Result<Self> {
        let cname = std::ffi::CString::new(format!("can-wire-{name}"))
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        // SAFETY: memfd_create with a valid C string; the result is checked.
        let raw = unsafe { libc::memfd_create(cname.as_ptr(), libc::MFD_CLOEXEC) };
        if raw < 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: a descriptor memfd_create just returned, owned from here.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        let len = entries * 8;
        // SAFETY: ftruncate on our descriptor.
        if unsafe { libc::ftruncate(fd.as_raw_fd(), len as libc::off_t) } < 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: a shared read-write mapping of `len` bytes of our memfd; checked below.
        let base = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                fd.as_raw_fd(),
                0,
            )
        };
        if base == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Self { fd, base, entries })
    }

    pub fn fd(&self) -> RawFd {
        self.fd.as_raw_fd()
    }

    pub fn entries(&self) -> usize {
        self.entries
    }

    fn slot(&self, node: usize) -> &AtomicU64 {
        assert!(node < self.entries, "node {node} beyond the counter table");
        // SAFETY: node < entries: inside the page-aligned mapping, 8-byte aligned; only
        // accessed atomically (here and by the clients).
        unsafe { &*self.base.cast::<AtomicU64>().add(node) }
    }

    /// One more frame of `node` resolved (visible to its client at once).
    pub fn resolve(&self, node: usize) {
        self.slot(node).fetch_add(1, Ordering::Release);
    }
}

impl Drop for Counters {
    fn drop(&mut self) {
        // SAFETY: unmapping exactly the mapping made in `new`.
        unsafe { libc::munmap(self.base, self.entries * 8) };
    }
}
