//! Lock-free loop statistics: per-cycle wake-up lateness and compute time in fixed-bucket
//! histograms of atomics (the loop only does relaxed `fetch_add`s; readers in other threads
//! take snapshots), plus the overrun counter.

use std::sync::atomic::{AtomicU64, Ordering};

/// Bucket upper bounds in ns: 1 µs resolution to 100 µs, then coarser up to 100 ms.
const fn bucket_bounds() -> [u64; 64] {
    let mut b = [0u64; 64];
    let mut i = 0;
    while i < 64 {
        b[i] = if i < 20 {
            (i as u64 + 1) * 1_000 // 1..20 µs
        } else if i < 36 {
            20_000 + (i as u64 - 19) * 5_000 // 25..100 µs
        } else if i < 54 {
            100_000 + (i as u64 - 35) * 50_000 // 150 µs..1 ms
        } else {
            let ms = 1u64 << (i - 53); // 2, 4, … ms, capped at 100 ms
            1_000_000 * if ms < 100 { ms } else { 100 }
        };
        i += 1;
    }
    b
}

pub const BUCKET_UPPER_NS: [u64; 64] = bucket_bounds();

/// One histogram of durations in ns.
pub struct Histogram {
    buckets: [AtomicU64; 65],
    count: AtomicU64,
    sum_ns: AtomicU64,
    max_ns: AtomicU64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            buckets: std::array::from_fn(|_| AtomicU64::new(0)),
            count: AtomicU64::new(0),
            sum_ns: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
        }
    }
}

impl Histogram {
    /// Records one value; wait-free, allocation-free.
    #[inline]
    pub fn record(&self, ns: u64) {
        let idx = BUCKET_UPPER_NS.partition_point(|&ub| ub < ns);
        self.buckets[idx].fetch_add(1, Ordering::Relaxed);
        self.count.fetch_add(1, Ordering::Relaxed);
        self.sum_ns.fetch_add(ns, Ordering::Relaxed);
        self.max_ns.fetch_max(ns, Ordering::Relaxed);
    }

    /// A consistent-enough copy for reporting (values may be one record apart).
    pub fn snapshot(&self) -> HistogramSnapshot {
        HistogramSnapshot {
            buckets: std::array::from_fn(|i| self.buckets[i].load(Ordering::Relaxed)),
            count: self.count.load(Ordering::Relaxed),
            sum_ns: self.sum_ns.load(Ordering::Relaxed),
            max_ns: self.max_ns.load(Ordering::Relaxed),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct HistogramSnapshot {
    pub buckets: [u64; 65],
    pub count: u64,
    pub sum_ns: u64,
    pub max_ns: u64,
}

impl HistogramSnapshot {
    /// Upper bound (ns) of the bucket holding quantile `q` (0..1); the max for q = 1. The
    /// quantile is the stack's one definition ([`crs_limits::quantile`], nearest rank ⌈q·n⌉)
    /// read off the histogram: the upper edge of the bin that holds that rank, so it bounds
    /// the exact nearest-rank sample from above by at most one bin width. The loop keeps a
    /// histogram and not the samples because recording must not allocate or sort.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        if q >= 1.0 {
            return self.max_ns;
        }
        let target = crs_limits::quantile::nearest_rank(self.count, q);
        let mut acc = 0;
        for (i, n) in self.buckets.iter().enumerate() {
            acc += n;
            if acc >= target {
                return if i < 64 {
                    BUCKET_UPPER_NS[i].min(self.max_ns)
                } else {
                    self.max_ns
                };
            }
        }
        self.max_ns
    }

    pub fn mean_ns(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64
        }
    }

    pub fn summary(&self) -> String {
        format!(
            "n={} mean={:.1}µs p50≤{:.0}µs p99≤{:.0}µs p99.9≤{:.0}µs max={:.1}µs",
            self.count,
            self.mean_ns() / 1e3,
            self.quantile_ns(0.5) as f64 / 1e3,
            self.quantile_ns(0.99) as f64 / 1e3,
            self.quantile_ns(0.999) as f64 / 1e3,
            self.max_ns as f64 / 1e3
        )
    }
}

/// The loop's statistics, shared with a reporting thread through an `Arc`.
#[derive(Default)]
pub struct LoopStats {
    /// Wake-up lateness: actual wake time − deadline.
    pub lateness: Histogram,
    /// Compute time of one cycle (wake-up to setpoint published).
    pub compute: Histogram,
    /// Cycles whose work ended after the next deadline.
    pub overruns: AtomicU64,
    /// Cycles run.
    pub cycles: AtomicU64,
    /// Setpoints published.
    pub published: AtomicU64,
    /// References rejected by the checks (each one latches a hold).
    pub rejected: AtomicU64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_distribution() {
        let h = Histogram::default();
        for v in 1..=1000u64 {
            h.record(v * 100); // 0.1 .. 100 µs uniformly
        }
        let s = h.snapshot();
        assert_eq!(s.count, 1000);
        assert_eq!(s.max_ns, 100_000);
        // p50 = 50 µs falls in the (45, 50] µs bucket.
        assert_eq!(s.quantile_ns(0.5), 50_000);
        assert_eq!(s.quantile_ns(0.99), 100_000);
        assert!((s.mean_ns() - 50_050.0).abs() < 1e-9);
    }

    #[test]
    fn huge_values_land_in_the_last_bucket() {
        let h = Histogram::default();
        h.record(10_000_000_000);
        let s = h.snapshot();
        assert_eq!(s.buckets[64], 1);
        assert_eq!(s.quantile_ns(0.5), 10_000_000_000);
    }
}
