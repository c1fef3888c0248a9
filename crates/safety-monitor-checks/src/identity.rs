//! The platform identity the motion core announces (`crs_ipc::PlatformIdentity`), recomputed by
//! the monitor from the parameters IT parsed: SHA-256 over a canonical serialisation (exact f64
//! bits, little endian) of the model ([`model_identity`]):
//!
//! `"crs-model-v1"`, m as u64, a_1..a_m, b_1..b_m (x, y, z each), k_F,1..m, w_e (6),
//! f_min, f_max, then either -1.0 (no pulleys) or r_p,1..m followed by the unit swivel axes;
//!
//! and, around it ([`platform_identity`]), the workspace box and the motion limits:
//! `"crs-platform-v2"`, the model identity, position min/max, rotation min/max (rad), the four
//! table 5.1 limits (SI).
//!
//! If the monitor and the motion core read different files, or read the same file differently,
//! the hashes differ and the monitor trips (identity mismatch) before anything moves.

use crate::platform::PlatformParams;
use crs_ipc::PlatformId;
use sha2::{Digest, Sha256};

/// Domain tag of the canonical serialisation (version 1).
pub const IDENTITY_TAG: &[u8] = b"crs-model-v1";

/// Domain tag of the platform identity (version 2): the model identity above, the
/// workspace box and the motion limits.
pub const PLATFORM_TAG: &[u8] = b"crs-platform-v2";

/// SHA-256 identity of everything the monitor checks the stream against: the model
/// ([`model_identity`]), then the workspace box (position min/max in m, rotation min/max in
/// rad) and the table 5.1 motion limits (SI), exact f64 bits, little endian; identical to
/// `cdpr_model::config::Platform::identity` (tests/agreement.rs) and pinned by the golden vector
/// `crs_ipc::identity_golden` (tests/identity_golden.rs). The drive scaling is not in
/// it (motion-core does not know it): the monitor's safety parameter CRC, announced on the
/// bus, covers the drives file.
pub fn platform_identity(p: &PlatformParams) -> PlatformId {
    let mut h = Sha256::new();
    h.update(PLATFORM_TAG);
    h.update(model_identity(p));
    let w = &p.workspace;
    for v in [
        w.position_min_m,
        w.position_max_m,
        w.rotation_min_rad,
        w.rotation_max_rad,
    ] {
        for c in [v.x, v.y, v.z] {
            h.update(c.to_bits().to_le_bytes());
        }
    }
    let l = &p.limits;
    for c in [
        l.linear_velocity_m_per_s,
        l.angular_velocity_rad_per_s,
        l.linear_acceleration_m_per_s2,
        l.angular_acceleration_rad_per_s2,
    ] {
        h.update(c.to_bits().to_le_bytes());
    }
    PlatformId::new(h.finalize().into())
}

/// SHA-256 identity of the model parameters (`cdpr_model::Model::identity`).
pub fn model_identity(p: &PlatformParams) -> [u8; 32] {
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

/// Lower-case hex of a hash: a [`PlatformId`] (whose `Display` is the same) or the bytes of
/// another one (a file's SHA-256).
pub fn hex<H: AsRef<[u8]> + ?Sized>(hash: &H) -> String {
    hash.as_ref().iter().map(|b| format!("{b:02x}")).collect()
}
