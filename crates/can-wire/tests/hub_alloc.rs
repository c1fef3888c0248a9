//! The hub's loop allocates nothing while frames flow, statistics hand-overs included
//! (counting allocator on the hub's thread; nodes join before counting starts).

use can_transport::wire::WireBus;
use can_transport::{CanBus, CanFrame, monotonic_ns};
use can_wire::{Hub, HubConfig};
use crs_test_support::alloc::{CountingAlloc, count_allocations};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[global_allocator]
static A: CountingAlloc = CountingAlloc;

#[test]
fn the_hub_loop_allocates_nothing_per_frame() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("hub-alloc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let sock = dir.join("can0.sock");
    let cfg = HubConfig {
        buses: vec![
            format!("name=can0,bitrate=1000000,socket={}", sock.display())
                .parse()
                .unwrap(),
        ],
        lookahead_ns: 50_000,
        coalesce_ns: 50_000,
        stats_path: Some(dir.join("wire.json")),
        stats_period_ns: 200_000_000, // several hand-overs in the counted second
        ready_file: None,
    };
    let mut hub = Hub::open(cfg, "test".into()).unwrap();
    let mut st = hub.loop_state();
    let s2 = sock.clone();
    let joiner = std::thread::spawn(move || {
        let a = WireBus::connect(&s2).unwrap();
        let b = WireBus::connect(&s2).unwrap();
        (a, b)
    });
    while hub.connected(0) < 2 {
        hub.pass(&mut st);
    }
    let (mut a, mut b) = joiner.join().unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let d2 = done.clone();
    let traffic = std::thread::spawn(move || {
        let mut received = 0u64;
        let t0 = monotonic_ns() + 5_000_000;
        for c in 0..1000u64 {
            crs_rt::sleep_until(t0 + c * 1_000_000);
            for i in 0..5u16 {
                let _ = a.send(&CanFrame::new(0x181 + i, &[c as u8, 1, 2, 3]).unwrap());
            }
            while let Ok(Some(_)) = b.recv_timeout(Duration::ZERO) {
                received += 1;
            }
        }
        d2.store(true, Ordering::SeqCst);
        (a, b, received)
    });
    let ((), allocs) = count_allocations(|| {
        while !done.load(Ordering::SeqCst) {
            hub.pass(&mut st);
        }
    });
    let (a, b, received) = traffic.join().unwrap();
    assert_eq!(allocs, 0, "the hub's loop allocated {allocs} times");
    assert!(
        received > 2500,
        "only {received} frames reached the other node"
    );
    drop((a, b));
    hub.finish(&st);
}
