//! The counter counts what it should and nothing else: a test that could not fail would make
//! every no-allocation test built on it meaningless.

use crs_test_support::alloc::{CountingAlloc, count_allocations};

#[global_allocator]
static A: CountingAlloc = CountingAlloc;

#[test]
fn counts_allocations_and_reallocations_of_this_thread_only() {
    let (_, n) = count_allocations(|| {
        let mut v: Vec<u64> = Vec::with_capacity(1);
        v.extend(0..100); // grows: reallocations
        std::hint::black_box(v)
    });
    assert!(
        n >= 2,
        "expected an allocation and reallocations, counted {n}"
    );
    let (_, n) = count_allocations(|| std::hint::black_box(3 + 4));
    assert_eq!(n, 0);
    // Another thread's allocations while this one counts are not this thread's.
    let (_, n) = count_allocations(|| {
        std::thread::scope(|s| {
            s.spawn(|| {
                for _ in 0..200 {
                    std::hint::black_box(vec![0u8; 16]);
                }
            });
        })
    });
    // Spawning itself allocates a few times on this thread (the thread's handle and packet),
    // but the child's 200 vectors are not counted.
    assert!(
        n < 50,
        "counted {n}: the child's allocations leaked into this thread's count"
    );
}

#[test]
fn the_fixtures_exist() {
    assert!(crs_test_support::fixtures::config("crs-nominal.toml").is_file());
}
