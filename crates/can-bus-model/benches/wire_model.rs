//! The bus model's cost per frame (the hub's pure-logic share): `cargo bench -p can-bus-model
//! --bench wire_model`.

use can_bus_model::{Bus, BusConfig};
use can_transport::CanFrame;
use can_transport::wire::bits;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn model(c: &mut Criterion) {
    let f = CanFrame::new(0x201, &[0x0F, 0, 0xA0, 0x86, 0x01, 0]).unwrap();
    c.bench_function("bits::exact, 6-byte frame", |b| {
        b.iter(|| black_box(bits::exact(black_box(&f))))
    });
    // One SYNC and 9 frames of 4 bytes per ms from 3 nodes, as the load tool sends: per
    // iteration one frame submitted and the bus advanced by its share of the period.
    let mut bus = Bus::new(BusConfig::new(1_000_000), 0).unwrap();
    let nodes: Vec<usize> = (0..3).map(|_| bus.add_node().unwrap()).collect();
    let mut k = 0u64;
    c.bench_function(
        "model: submit + poll, per frame (10 frames/ms, 3 nodes)",
        |b| {
            b.iter(|| {
                let t = k * 100_000;
                let frame = if k.is_multiple_of(10) {
                    CanFrame::new(0x080, &[]).unwrap()
                } else {
                    CanFrame::new(0x180 + (k % 10) as u16, &[k as u8, 0, 0, 0]).unwrap()
                };
                let _ = bus.submit(nodes[(k % 3) as usize], frame, t, k as u32);
                let mut n = 0;
                bus.poll(t, t, &mut |_| n += 1);
                k += 1;
                black_box(n)
            })
        },
    );
}

criterion_group!(benches, model);
criterion_main!(benches);
