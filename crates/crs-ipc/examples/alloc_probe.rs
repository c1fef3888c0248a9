//! Counts heap operations of iceoryx2 publish/receive on the calling thread and prints the
//! backtrace of the first allocation. Why `motion-core` publishes from a separate stage:
//! iceoryx2 0.10's `loan_uninit` allocates one `Rc` per sample; `receive` allocates nothing.
//!
//! `cargo run -p crs-ipc --example alloc_probe`
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

struct Probe;
static ARMED: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
std::thread_local! { static REPORTING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) }; }

unsafe impl GlobalAlloc for Probe {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if ARMED.load(Ordering::Relaxed) && !REPORTING.with(|c| c.get()) {
            let n = ALLOCS.fetch_add(1, Ordering::Relaxed);
            if n == 0 {
                REPORTING.with(|c| c.set(true));
                eprintln!(
                    "first allocation: {} bytes\n{}",
                    l.size(),
                    std::backtrace::Backtrace::force_capture()
                );
                REPORTING.with(|c| c.set(false));
            }
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static GLOBAL: Probe = Probe;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let prefix = format!("probe{}/", std::process::id());
    let node = crs_ipc::IpcNode::with_prefix("alloc_probe", &prefix)?;
    let publisher = node.publisher::<crs_ipc::JointSetpoint>()?;
    let subscriber = node.subscriber::<crs_ipc::JointSetpoint>()?;
    let v = crs_ipc::JointSetpoint::default();
    for _ in 0..10 {
        publisher.publish(&v)?;
    }
    ARMED.store(true, Ordering::Relaxed);
    let mut received = 0;
    while subscriber.receive()?.is_some() {
        received += 1;
    }
    ARMED.store(false, Ordering::Relaxed);
    println!(
        "receive: {} allocations for {received} samples + 1 empty poll",
        ALLOCS.swap(0, Ordering::Relaxed)
    );
    ARMED.store(true, Ordering::Relaxed);
    for _ in 0..100 {
        publisher.publish(&v)?;
    }
    ARMED.store(false, Ordering::Relaxed);
    println!(
        "publish: {} allocations for 100 samples",
        ALLOCS.load(Ordering::Relaxed)
    );
    Ok(())
}
