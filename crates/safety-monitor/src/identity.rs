//! The platform identity the motion core announces (`crs_ipc::PlatformIdentity`), recomputed by
//! the monitor from the parameters IT parsed: SHA-256 over a canonical serialisation of every
//! model parameter (exact f64 bits, little endian):
//!
//! `"crs-model-v1"`, m as u64, a_1..a_m, b_1..b_m (x, y, z each), k_F,1..m, w_e (6),
//! f_min, f_max, then either -1.0 (no pulleys) or r_p,1..m followed by the unit swivel axes.
//!
//! If the monitor and the motion core read different files, or read the same file differently,
//! the hashes differ and the monitor trips (identity mismatch) before anything moves.

use crate::platform::PlatformParams;
use sha2::{Digest, Sha256};

/// Domain tag of the canonical serialisation (version 1).
pub const IDENTITY_TAG: &[u8] = b"crs-model-v1";

/// SHA-256 identity of the platform parameters.
pub fn platform_identity(p: &PlatformParams) -> [u8; 32] {
    let mut h = Sha256::new();
    h.update(IDENTITY_TAG);
    h.update((p.cables() as u64).to_le_bytes());
    let mut put = |x: f64| h.update(x.to_bits().to_le_bytes());
    for v in p.frame_anchors_m.iter().chain(&p.platform_anchors_m) {
        put(v.x);
        put(v.y);
        put(v.z);
    }
    for k in &p.k_f_n {
        put(*k);
    }
    for w in p.wrench_n_nm {
        put(w);
    }
    put(p.f_min_n);
    put(p.f_max_n);
    match &p.pulleys {
        None => put(-1.0),
        Some(pl) => {
            for r in &pl.radius_m {
                put(*r);
            }
            for ax in &pl.axis {
                put(ax.x);
                put(ax.y);
                put(ax.z);
            }
        }
    }
    h.finalize().into()
}

/// Lower-case hex of a hash.
pub fn hex(hash: &[u8; 32]) -> String {
    hash.iter().map(|b| format!("{b:02x}")).collect()
}
