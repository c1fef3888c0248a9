//! A counting global allocator that counts only on the threads that asked for it.
//!
//! Install it in a test crate with
//! ```ignore
//! #[global_allocator]
//! static A: crs_test_support::alloc::CountingAlloc = crs_test_support::alloc::CountingAlloc;
//! ```
//! and wrap the hot path in [`count_allocations`]. Counting is per thread (a thread-local gate
//! and counter, const-initialised, no destructor: reading them never allocates, also inside the
//! allocator): the test harness's own threads may print or bookkeep while a test counts on a
//! loaded machine, and parallel tests in one binary do not see each other's allocations.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

thread_local! {
    static GATE: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

/// The system allocator plus a per-thread count of allocations and reallocations.
pub struct CountingAlloc;

fn note() {
    if GATE.with(Cell::get) {
        COUNT.with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; the only addition is a
// thread-local counter that does not allocate.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(p, l, n) }
    }
}

/// Runs `f` on this thread and returns its result with the number of heap allocations
/// (including reallocations) it made on this thread.
///
/// Panics first if the counter does not see a known allocation: [`CountingAlloc`] is not the
/// global allocator of this binary, and a count of 0 would prove nothing.
pub fn count_allocations<R>(f: impl FnOnce() -> R) -> (R, u64) {
    assert!(
        counter_sees_allocations(),
        "crs_test_support::alloc::CountingAlloc is not this binary's #[global_allocator]"
    );
    let before = COUNT.with(Cell::get);
    GATE.with(|g| g.set(true));
    let r = f();
    GATE.with(|g| g.set(false));
    (r, COUNT.with(Cell::get) - before)
}

/// True when a 64-byte vector allocated on this thread is counted.
pub fn counter_sees_allocations() -> bool {
    let before = COUNT.with(Cell::get);
    GATE.with(|g| g.set(true));
    let v = std::hint::black_box(vec![1u8; 64]);
    GATE.with(|g| g.set(false));
    drop(v);
    COUNT.with(Cell::get) > before
}
