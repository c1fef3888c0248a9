//! Shared fixtures for the surrogate integration tests.
#![allow(dead_code)]

use surrogate::Region;

/// CRS-sized pose region (m, rad).
pub fn crs_region() -> Region {
    Region {
        lower: [-3.0, -2.5, 0.5, -0.3, -0.3, -0.5],
        upper: [3.0, 2.5, 4.0, 0.3, 0.3, 0.5],
    }
}

/// A smooth, non-polynomial offset of a few cm for `m` cables (m).
pub fn smooth_target<const M: usize>(x: &[f64; 6]) -> [f64; M] {
    std::array::from_fn(|j| {
        let w = 0.3 + 0.07 * j as f64;
        0.02 * (w * x[0] + 0.2 * x[1]).sin() * (-0.1 * x[2]).exp()
            + 0.01 * (2.0 * x[3] + x[5] + 0.1 * j as f64).cos()
            + 0.004 * x[4] * x[1]
    })
}
