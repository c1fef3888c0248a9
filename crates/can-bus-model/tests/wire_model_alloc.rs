//! The bus model allocates nothing per frame once set up (counting allocator, this thread).

use can_bus_model::{Bus, BusConfig, BusStats};
use can_transport::CanFrame;
use crs_test_support::alloc::{CountingAlloc, count_allocations};

#[global_allocator]
static A: CountingAlloc = CountingAlloc;

#[test]
fn ten_thousand_frames_on_four_nodes_allocate_nothing() {
    let mut cfg = BusConfig::new(1_000_000);
    cfg.max_ids = 16; // fewer than the identifiers used: the pooled slot is exercised too
    let mut bus = Bus::new(cfg, 0).unwrap();
    let nodes: Vec<usize> = (0..4).map(|_| bus.add_node().unwrap()).collect();
    let mut spare = Box::new(BusStats::new(bus.config()));
    let mut total = BusStats::new(bus.config());
    let ext = CanFrame::with_flags(0x18FF_0001, true, false, &[1, 2, 3]).unwrap();
    let (delivered, allocs) = count_allocations(|| {
        let mut delivered = 0u64;
        for k in 0..2500u64 {
            let t = k * 400_000;
            for (i, &n) in nodes.iter().enumerate() {
                let f = if i == 3 {
                    ext
                } else {
                    CanFrame::new_std_lossy(0x180 + (k % 40) as u16 + i as u16, &[k as u8; 8])
                };
                let _ = bus.submit(n, f, t + i as u64 * 10_000, k as u32);
            }
            bus.poll(t + 350_000, t + 380_000, &mut |_| delivered += 1);
            if k % 250 == 249 {
                bus.swap_stats(&mut spare);
                total.merge(&spare);
                spare.reset();
            }
        }
        delivered
    });
    assert_eq!(allocs, 0, "the model allocated {allocs} times");
    assert!(delivered > 8_000, "{delivered}");
}
