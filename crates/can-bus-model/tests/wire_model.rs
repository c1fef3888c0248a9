//! The bus model in virtual time: bit times against hand computation, arbitration, FIFO per
//! node, queue overflow, load windows, violations, no allocation per frame.

use can_bus_model::{Bus, BusConfig, Delivery, IdStats, SubmitError, WINDOW_NS};
use can_transport::CanFrame;
use can_transport::wire::bits;

fn bus(bitrate: u32) -> Bus {
    Bus::new(BusConfig::new(bitrate), 0).unwrap()
}

fn std(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new(id, data).unwrap()
}

/// Runs the bus to `t` (no look-ahead) and returns what left the wire.
fn run(b: &mut Bus, t: u64) -> Vec<Delivery> {
    let mut out = Vec::new();
    b.poll(t, t, &mut |d| out.push(*d));
    out
}

#[test]
fn frame_times_are_the_exact_bits_at_the_bit_time() {
    // SYNC (0x080, no data): 34 bits SOF..CRC, 4 stuff bits (can-utils: 51 with intermission),
    // 10 trailer bits, 3 intermission = 51. At 500 kbit/s a bit is 2000 ns, so EOF ends
    // 48 * 2000 = 96000 ns after SOF and the bus is free 51 * 2000 = 102000 ns after it.
    let sync = std(0x080, &[]);
    assert_eq!(bits::exact(&sync).total(), 51);
    let mut b = bus(500_000);
    let n = b.add_node().unwrap();
    b.submit(n, sync, 1_000, 7).unwrap();
    b.submit(n, sync, 1_000, 8).unwrap();
    let d = run(&mut b, 1_000_000);
    assert_eq!(d.len(), 2);
    assert_eq!((d[0].start_ns, d[0].eof_ns, d[0].tag), (1_000, 97_000, 7));
    // Back to back: the second SOF follows the first frame's intermission.
    assert_eq!(
        (d[1].start_ns, d[1].eof_ns, d[1].tag),
        (103_000, 199_000, 8)
    );
    // An RPDO of 6 bytes at 1 Mbit/s: its exact bit count times 1000 ns.
    let rpdo = std(0x201, &[0x0F, 0, 0xA0, 0x86, 0x01, 0]);
    let fb = bits::exact(&rpdo);
    let mut b = bus(1_000_000);
    let n = b.add_node().unwrap();
    b.submit(n, rpdo, 5_000, 0).unwrap();
    let d = run(&mut b, 1_000_000);
    assert_eq!(d[0].eof_ns - d[0].start_ns, u64::from(fb.to_eof()) * 1000);
    assert!(fb.total() <= bits::worst_case_bits(false, 6));
}

#[test]
fn arbitration_lowest_field_wins_standard_before_extended_data_before_remote() {
    let mut b = bus(1_000_000);
    let nodes: Vec<usize> = (0..5).map(|_| b.add_node().unwrap()).collect();
    // Occupy the bus first so that all five are queued when it becomes free.
    b.submit(nodes[0], std(0x700, &[0]), 0, 0).unwrap();
    let _ = run(&mut b, 10);
    let ext_same_base = CanFrame::with_flags(0x100 << 18, true, false, &[1]).unwrap();
    let ext_lower_ext = CanFrame::with_flags((0x100 << 18) | 5, true, false, &[]).unwrap();
    let remote = CanFrame::remote(0x100, false, 1).unwrap();
    let data = std(0x100, &[1]);
    let low = std(0x0FF, &[1, 2, 3, 4, 5, 6, 7, 8]);
    b.submit(nodes[1], ext_lower_ext, 20, 1).unwrap();
    b.submit(nodes[2], remote, 20, 2).unwrap();
    b.submit(nodes[3], ext_same_base, 20, 3).unwrap();
    b.submit(nodes[4], data, 20, 4).unwrap();
    b.submit(nodes[0], low, 20, 5).unwrap();
    let d = run(&mut b, 10_000_000);
    let order: Vec<u32> = d.iter().skip(1).map(|d| d.tag).collect();
    // 0x0FF, then the standard data frame 0x100, its remote frame, then the extended frames
    // by their extension bits.
    assert_eq!(order, vec![5, 4, 2, 3, 1]);
    // Each started at the previous one's free time: back to back.
    for w in d.windows(2) {
        let prev_total = bits::exact(&w[0].frame).total() as u64 * 1000;
        assert_eq!(w[1].start_ns, w[0].start_ns + prev_total);
    }
}

#[test]
fn only_the_head_of_each_node_queue_competes() {
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    b.submit(a, std(0x300, &[]), 0, 1).unwrap();
    b.submit(a, std(0x100, &[]), 0, 2).unwrap();
    b.submit(c, std(0x200, &[]), 0, 3).unwrap();
    let d = run(&mut b, 10_000_000);
    // 0x100 waits behind 0x300 in node a's FIFO although it would win arbitration.
    assert_eq!(d.iter().map(|d| d.tag).collect::<Vec<_>>(), vec![3, 1, 2]);
}

#[test]
fn a_frame_submitted_after_sof_waits_for_the_next_arbitration() {
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    b.submit(a, std(0x700, &[0; 8]), 0, 1).unwrap();
    b.submit(c, std(0x001, &[]), 1, 2).unwrap(); // 1 ns too late for the SOF at 0
    let d = run(&mut b, 10_000_000);
    assert_eq!(d.iter().map(|d| d.tag).collect::<Vec<_>>(), vec![1, 2]);
    assert_eq!(
        d[1].start_ns,
        bits::exact(&d[0].frame).total() as u64 * 1000
    );
    assert_eq!(b.stats().violations, 0);
}

#[test]
fn a_full_queue_refuses_and_counts() {
    let mut cfg = BusConfig::new(125_000);
    cfg.queue_len = 3;
    let mut b = Bus::new(cfg, 0).unwrap();
    let n = b.add_node().unwrap();
    for i in 0..3 {
        b.submit(n, std(0x181, &[i]), 0, i.into()).unwrap();
    }
    assert_eq!(
        b.submit(n, std(0x181, &[9]), 0, 9),
        Err(SubmitError::QueueFull { node: n, len: 3 })
    );
    assert_eq!(b.queue_depth(n), 3);
    assert_eq!(b.stats().nodes[n].dropped, 1);
    assert_eq!(b.stats().nodes[n].max_depth, 3);
    // The one on the wire still counts until its end of frame; then a slot is free.
    let first = run(&mut b, 1_000).len();
    assert_eq!(first, 0);
    assert_eq!(b.queue_depth(n), 3);
    let eof = b.next_delivery_ns().unwrap();
    assert_eq!(run(&mut b, eof).len(), 1);
    assert_eq!(b.queue_depth(n), 2);
    b.submit(n, std(0x181, &[4]), eof, 4).unwrap();
    assert_eq!(
        b.submit(n, std(0x555, &[]), 0, 0),
        Err(SubmitError::QueueFull { node: n, len: 3 })
    );
    assert_eq!(
        b.submit(7, std(0x1, &[]), 0, 0),
        Err(SubmitError::NoNode(7))
    );
}

/// `per_ms` frames of 8 bytes from one node every 1 ms for `ms` ms at 1 Mbit/s; returns the
/// bus with what it counted.
fn periodic(per_ms: usize, ms: u64) -> (Bus, usize, u64) {
    let mut b = bus(1_000_000);
    let n = b.add_node().unwrap();
    let mut refused = 0;
    let mut delivered = 0u64;
    for k in 0..ms {
        let t = k * 1_000_000;
        delivered += run(&mut b, t).len() as u64;
        for i in 0..per_ms {
            let f = std(0x180 + i as u16, &[0x5A; 8]);
            if b.submit(n, f, t, 0).is_err() {
                refused += 1;
            }
        }
        delivered += run(&mut b, t).len() as u64;
    }
    delivered += run(&mut b, ms * 1_000_000).len() as u64;
    (b, refused, delivered)
}

#[test]
fn an_overloaded_bus_drops_and_its_latency_grows_a_light_one_does_not() {
    // 20 frames of 8 bytes per ms: ~20 * 130 bits = 2.6 ms of wire per 1 ms period.
    let (heavy, refused, _) = periodic(20, 1100);
    let st = heavy.stats();
    assert!(refused > 10_000, "refused {refused}");
    assert_eq!(st.nodes[0].dropped, refused as u64);
    let worst = st.ids.iter().map(|s| s.latency_max_ns).max().unwrap();
    assert!(
        worst > 1_000_000,
        "worst latency {worst} ns within the period"
    );
    assert!(st.window_load_max > 0.99, "load {}", st.window_load_max);
    // 2 frames per ms: ~26 % of the bus, nothing refused, everything within 300 µs.
    let (light, refused, delivered) = periodic(2, 1100);
    let st = light.stats();
    assert_eq!((refused, st.nodes[0].dropped), (0, 0));
    assert_eq!(delivered, 2200);
    // Load = wire time per period: the two frames' exact bits at 1 µs per 1 ms.
    let per_ms: u32 = (0..2)
        .map(|i| bits::exact(&std(0x180 + i, &[0x5A; 8])).total())
        .sum();
    let load = f64::from(per_ms) / 1000.0;
    assert!(
        (st.window_load_max - load).abs() < 1e-9,
        "load {} vs {load}",
        st.window_load_max
    );
    assert!((st.window_load_mean().unwrap() - load).abs() < 1e-9);
    let worst = st.ids.iter().map(|s| s.latency_max_ns).max().unwrap();
    assert!(worst < 300_000, "worst latency {worst} ns");
    let p99 = IdStats::quantile(&st.ids[1].latency, 0.99).unwrap();
    assert!(p99 <= worst + worst / 100 + 1, "p99 {p99} > max {worst}");
}

#[test]
fn load_windows_are_busy_time_per_second() {
    // One SYNC (51 bits = 51 µs at 1 Mbit/s, intermission included) every 1 ms for 3.5 s:
    // three completed windows of exactly 1000 frames each, load 0.051.
    let mut b = bus(1_000_000);
    let n = b.add_node().unwrap();
    for k in 0..3500u64 {
        let t = k * 1_000_000;
        b.submit(n, std(0x080, &[]), t, 0).unwrap();
        let _ = run(&mut b, t + 500_000);
    }
    let st = b.stats();
    assert_eq!(st.windows, 3);
    assert!(
        (st.window_load_max - 0.051).abs() < 1e-12,
        "{}",
        st.window_load_max
    );
    assert!((st.window_load_mean().unwrap() - 0.051).abs() < 1e-12);
    assert_eq!(st.busy_ns, 3500 * 51_000);
    assert_eq!(st.frames, 3500);
    let _ = WINDOW_NS;
}

#[test]
fn a_submission_older_than_a_decision_taken_is_a_violation() {
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    b.submit(a, std(0x300, &[]), 200, 1).unwrap();
    b.poll(250, 250, &mut |_| {}); // decided at 200
    b.submit(c, std(0x100, &[]), 100, 2).unwrap(); // it would have won at 200
    assert_eq!(b.stats().violations, 1);
    assert_eq!(b.stats().violation_max_ns, 100);
    let d = run(&mut b, 10_000_000);
    assert_eq!(d.iter().map(|d| d.tag).collect::<Vec<_>>(), vec![1, 2]);
}

#[test]
fn look_ahead_decides_late_and_delivers_on_time() {
    // The hub polls with decide_until = now - L: a submission that reaches it within L of its
    // stamp still competes in the arbitration at that stamp.
    const T: u64 = 1_000_000;
    const L: u64 = 30_000;
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    b.submit(a, std(0x300, &[]), T, 1).unwrap();
    assert_eq!(b.next_decision_ns(), Some(T));
    let now = T + 20_000;
    b.poll(now - L, now, &mut |_| {});
    assert_eq!(
        b.next_delivery_ns(),
        None,
        "decided before the look-ahead passed"
    );
    b.submit(c, std(0x100, &[]), T, 2).unwrap(); // stamped T, arrived 20 µs later
    let mut out = Vec::new();
    let now = T + L;
    b.poll(now - L, now, &mut |d| out.push(*d));
    assert!(out.is_empty());
    // Node c's frame won the SOF at T; it is delivered at its EOF, not L later.
    let eof = b.next_delivery_ns().unwrap();
    b.poll(eof - L, eof, &mut |d| out.push(*d));
    assert_eq!(out.len(), 1);
    assert_eq!((out[0].tag, out[0].start_ns, out[0].eof_ns), (2, T, eof));
    assert_eq!(b.stats().violations, 0);
}

#[test]
fn a_node_that_leaves_loses_its_waiting_frames() {
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    for i in 0..4 {
        b.submit(a, std(0x181, &[i]), 0, i.into()).unwrap();
    }
    b.submit(c, std(0x182, &[]), 0, 9).unwrap();
    let _ = run(&mut b, 0); // 0x181 #0 on the wire
    assert_eq!(b.remove_node(a), 3);
    let d = run(&mut b, 10_000_000);
    assert_eq!(d.iter().map(|d| d.tag).collect::<Vec<_>>(), vec![0, 9]);
    assert_eq!(b.stats().nodes[a].lost_at_leave, 3);
    assert!(b.submit(a, std(0x181, &[]), 0, 0).is_err());
}

#[test]
fn swapped_statistics_merge_to_the_whole() {
    let mut b = bus(1_000_000);
    let n = b.add_node().unwrap();
    let mut spare = Box::new(can_bus_model::BusStats::new(b.config()));
    let mut total = can_bus_model::BusStats::new(b.config());
    for k in 0..100u64 {
        b.submit(n, std(0x201, &[1, 2]), k * 100_000, 0).unwrap();
        let _ = run(&mut b, k * 100_000 + 90_000);
        if k % 10 == 9 {
            b.swap_stats(&mut spare);
            total.merge(&spare);
            spare.reset();
        }
    }
    assert_eq!(total.frames, 100);
    assert_eq!(total.ids[0].count, 100);
    assert_eq!(total.ids[0].latency.len(), 100);
    assert_eq!(total.id_keys[0].unwrap().id, 0x201);
    assert_eq!(b.stats().frames, 0);
}

#[test]
fn the_next_decision_is_known_while_a_frame_is_on_the_wire() {
    let mut b = bus(1_000_000);
    let a = b.add_node().unwrap();
    let c = b.add_node().unwrap();
    b.submit(a, std(0x080, &[]), 0, 1).unwrap();
    assert!(!b.is_quiet() && b.next_decision_ns() == Some(0));
    let _ = run(&mut b, 0); // SYNC on the wire, nothing else queued
    assert_eq!(b.next_decision_ns(), None);
    b.submit(a, std(0x201, &[]), 10, 2).unwrap(); // behind the SYNC in a's queue
    assert_eq!(b.next_decision_ns(), Some(51_000)); // the SYNC's free time
    b.submit(c, std(0x202, &[]), 60_000, 3).unwrap();
    assert_eq!(b.next_decision_ns(), Some(51_000));
    assert_eq!(b.next_delivery_ns(), Some(48_000));
    let d = run(&mut b, 10_000_000);
    assert_eq!(d.iter().map(|d| d.tag).collect::<Vec<_>>(), vec![1, 2, 3]);
    assert!(b.is_quiet());
}
