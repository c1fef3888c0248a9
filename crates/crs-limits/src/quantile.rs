//! The stack's one quantile definition: every p50 / p95 / p99 / p99.9 a report, a bench or a
//! figure prints is the NEAREST RANK — the smallest sample with at least a fraction `q` of the
//! samples at or below it, i.e. the sample of 1-based rank ⌈q·n⌉ (clamped to 1..n) in ascending
//! order. numpy calls it `method='inverted_cdf'` (Hyndman & Fan type 1). It always returns an
//! observed sample (a latency that happened, never an interpolated one), and a fixed-bin
//! histogram reports the same definition by returning the upper edge of the bin that holds
//! rank ⌈q·n⌉ ([`nearest_rank`]; motion-core's allocation-free loop statistics do).
//!
//! The independent safety monitor computes no quantiles; if it ever does, it keeps its own
//! (it shares no code with the controller) and states that it follows this definition.

/// The 1-based rank ⌈q·n⌉ of the `q`-quantile of `n` samples, clamped to 1..=n (`q` outside
/// 0..=1 is clamped too); 0 for n = 0. The product q·n is formed in f64 as numpy forms it, so
/// ranks agree with numpy's `inverted_cdf` also where q·n is not exact.
#[inline]
pub fn nearest_rank(n: u64, q: f64) -> u64 {
    if n == 0 {
        return 0;
    }
    ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).clamp(1, n)
}

/// The `q`-quantile (nearest rank, [`nearest_rank`]) of `sorted`, which must be in ascending
/// order; `None` if it is empty. Allocation-free: the hot paths sort their preallocated
/// buffers in place and call this.
#[inline]
pub fn quantile_sorted<T: Copy>(sorted: &[T], q: f64) -> Option<T> {
    let rank = nearest_rank(sorted.len() as u64, q);
    (rank > 0).then(|| sorted[rank as usize - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden values from numpy 2.4.6, produced by
    /// ```text
    /// python3 -c 'import numpy as np
    /// vs = {"one":[7.0],"two":[1.0,2.0],"five":[3.0,1.0,4.0,1.0,5.0],
    ///       "ten":[0.5*i*i for i in range(10)],
    ///       "hundred":[float((37*i)%101) for i in range(100)],
    ///       "thousand_and_one":[float((7919*i)%1009) for i in range(1001)]}
    /// qs = [0.0,0.07,0.25,0.5,0.9,0.95,0.99,0.999,1.0]
    /// for k,v in vs.items():
    ///     print(k, [float(np.quantile(v,q,method="inverted_cdf")) for q in qs])'
    /// ```
    #[test]
    fn agrees_with_numpys_inverted_cdf() {
        let qs = [0.0, 0.07, 0.25, 0.5, 0.9, 0.95, 0.99, 0.999, 1.0];
        let cases: [(Vec<f64>, [f64; 9]); 6] = [
            (vec![7.0], [7.0; 9]),
            (
                vec![1.0, 2.0],
                [1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 2.0],
            ),
            (
                vec![3.0, 1.0, 4.0, 1.0, 5.0],
                [1.0, 1.0, 1.0, 3.0, 5.0, 5.0, 5.0, 5.0, 5.0],
            ),
            (
                (0..10).map(|i| 0.5 * (i * i) as f64).collect(),
                [0.0, 0.0, 2.0, 8.0, 32.0, 40.5, 40.5, 40.5, 40.5],
            ),
            (
                (0..100).map(|i| ((37 * i) % 101) as f64).collect(),
                [0.0, 7.0, 24.0, 49.0, 90.0, 95.0, 99.0, 100.0, 100.0],
            ),
            (
                (0..1001).map(|i| ((7919 * i) % 1009) as f64).collect(),
                [0.0, 71.0, 253.0, 505.0, 907.0, 958.0, 998.0, 1007.0, 1008.0],
            ),
        ];
        for (mut v, want) in cases {
            v.sort_by(f64::total_cmp);
            for (q, w) in qs.iter().zip(want) {
                assert_eq!(quantile_sorted(&v, *q), Some(w), "n = {}, q = {q}", v.len());
            }
        }
    }

    #[test]
    fn ranks_are_clamped_and_an_empty_set_has_no_quantile() {
        assert_eq!(nearest_rank(0, 0.5), 0);
        assert_eq!(quantile_sorted::<u64>(&[], 0.5), None);
        assert_eq!(nearest_rank(10, 0.0), 1);
        assert_eq!(nearest_rank(10, -1.0), 1);
        assert_eq!(nearest_rank(10, 2.0), 10);
        assert_eq!(nearest_rank(1000, 0.999), 999);
        assert_eq!(quantile_sorted(&[1u64, 2, 3, 4], 0.5), Some(2));
    }
}
