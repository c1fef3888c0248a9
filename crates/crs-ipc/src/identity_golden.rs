//! Golden test vector of the platform identity ([`crate::PlatformIdentity`]`::hash`).
//!
//! motion-core announces the identity computed by the model library
//! (`cdpr_model::config::Platform::identity`); the safety monitor recomputes it from its own,
//! independently written reading of the same file (`safety_monitor::identity`) and trips on a
//! mismatch. Two implementations that agree with each other could still both have drifted from
//! the contract together (a refactor of a shared assumption); this vector pins the contract
//! itself. Both sides have a test that computes the identity of this fixed platform with their
//! own code — from [`PLATFORM_TOML`] through their own parser, and from the numbers below
//! directly — and compares it with [`PLATFORM_IDENTITY`]
//! (crates/motion-core/tests/identity_golden.rs, crates/safety-monitor/tests/identity_golden.rs).
//!
//! The contract (exact f64 bits, little endian, SHA-256):
//!
//! * model identity: `"crs-model-v1"`, m as u64, a_1..a_m, b_1..b_m (x, y, z each),
//!   k_F,1..m, w_e (6), f_min, f_max, then either -1.0 (no pulleys) or r_p,1..m followed by the
//!   swivel axes normalised by their Euclidean norm (x² + y² + z², then each component divided);
//! * platform identity: `"crs-platform-v2"`, the model identity, position min, position max (m),
//!   rotation min, rotation max (rad = deg × (π/180)), then linear velocity (m/s), angular velocity
//!   (rad/s), linear acceleration (m/s²), angular acceleration (rad/s²).
//!
//! The numbers are in the platform file's units (degrees where an operator types degrees,
//! pulley axes as typed, not unit length), so that the unit conversion and the normalisation
//! are part of what is pinned, and chosen so that the arithmetic is pinned to the last bit: the
//! angles (7.3°, 12.2°, 29.5°, 45.2°, 60.3°/s, 88.6°/s²) give different bits for
//! deg × (π/180) than for deg / 180 × π or deg × π / 180, and the axes 2, 4, 6 and 8 give different
//! unit vectors for x² + y² + z² than for z² + y² + x², x² + (y² + z²), `hypot`, or a multiplication
//! by 1/‖u‖. The platform has pulleys, per-cable stiffness and an integer (`f_min_n = 200`), so
//! every branch of the serialisation and of the readers is exercised. The two hashes come from
//! a third implementation, not from either side's code: `tools/identity_golden.py` (Python's
//! `tomllib`, `hashlib` and `struct` over [`PLATFORM_TOML`] and the stated serialisation)
//! prints them, and `tools/test.sh` runs it with `--check` on this file.

/// Number of cables m of the golden platform.
pub const CABLES: usize = 8;

/// Frame-side cable exit points a_i, world frame, m (eq. 2.4).
pub const FRAME_ANCHORS_M: [[f64; 3]; CABLES] = [
    [-2.5, 2.3, 3.1],
    [-2.45, 2.2, 0.1],
    [2.4, 2.35, 3.05],
    [2.55, 2.25, 0.15],
    [2.5, -2.3, 3.0],
    [2.35, -2.4, 0.05],
    [-2.4, -2.5, 3.15],
    [-2.6, -2.35, 0.2],
];

/// Platform anchor points b_i, platform frame, m (eq. 2.4, 2.6).
pub const PLATFORM_ANCHORS_M: [[f64; 3]; CABLES] = [
    [-0.3, 0.25, -0.2],
    [-0.25, 0.3, 0.2],
    [0.3, 0.2, -0.2],
    [0.2, 0.3, 0.2],
    [0.3, -0.25, -0.2],
    [0.25, -0.3, 0.2],
    [-0.3, -0.2, -0.2],
    [-0.2, -0.3, 0.2],
];

/// Pulley radii r_p, m (eq. 2.18).
pub const PULLEY_RADIUS_M: [f64; CABLES] = [0.05, 0.06, 0.05, 0.055, 0.05, 0.045, 0.05, 0.06];

/// Pulley swivel axes u_Az as typed in the file (not unit length; each side normalises).
pub const PULLEY_SWIVEL_AXES: [[f64; 3]; CABLES] = [
    [0.0, 0.0, 2.0],
    [-0.6, -0.54, 1.2],
    [0.1, 0.0, 1.0],
    [-0.6, 0.36, 0.9],
    [0.0, 0.0, 1.0],
    [-0.6, -0.03, 1.3],
    [0.0, 0.0, -1.0],
    [-0.6, 0.45, 0.7],
];

/// Specific cable stiffness k_F = EA per cable, N.
pub const K_F_N: [f64; CABLES] = [1.5e6, 1.6e6, 1.55e6, 1.5e6, 1.45e6, 1.5e6, 1.65e6, 1.5e6];

/// External wrench w_e = [f; τ], N and N·m (eq. 2.30).
pub const WRENCH_N_NM: [f64; 6] = [10.0, -5.0, -2943.0, 1.5, -2.25, 0.0];

/// Operating cable force range, N (eq. 3.29).
pub const F_MIN_N: f64 = 200.0;
pub const F_MAX_N: f64 = 6000.0;

/// Workspace box: position in m, rotation in degrees (as in the file).
pub const POSITION_MIN_M: [f64; 3] = [-1.0, -1.1, 0.9];
pub const POSITION_MAX_M: [f64; 3] = [1.0, 1.2, 2.3];
pub const ROTATION_MIN_DEG: [f64; 3] = [-7.3, -12.2, -29.5];
pub const ROTATION_MAX_DEG: [f64; 3] = [7.3, 12.2, 45.2];

/// Table 5.1 motion limits in the file's units.
pub const LINEAR_VELOCITY_MAX_M_PER_S: f64 = 2.5;
pub const ANGULAR_VELOCITY_MAX_DEG_PER_S: f64 = 60.3;
pub const LINEAR_ACCELERATION_MAX_M_PER_S2: f64 = 7.5;
pub const ANGULAR_ACCELERATION_MAX_DEG_PER_S2: f64 = 88.6;

/// The golden platform as a platform file (the numbers above, plus the tables only the motion
/// core reads and that the identity does not cover: `f_abs_max_n`, `[winch]`, `[home]`).
pub const PLATFORM_TOML: &str = r#"# Golden identity test vector (crates/crs-ipc/src/identity_golden.rs).
[platform]
name = "crs-identity-golden"

[geometry]
frame_anchors_m = [
  [-2.5, 2.3, 3.1],
  [-2.45, 2.2, 0.1],
  [2.4, 2.35, 3.05],
  [2.55, 2.25, 0.15],
  [2.5, -2.3, 3.0],
  [2.35, -2.4, 0.05],
  [-2.4, -2.5, 3.15],
  [-2.6, -2.35, 0.2],
]
platform_anchors_m = [
  [-0.3, 0.25, -0.2],
  [-0.25, 0.3, 0.2],
  [0.3, 0.2, -0.2],
  [0.2, 0.3, 0.2],
  [0.3, -0.25, -0.2],
  [0.25, -0.3, 0.2],
  [-0.3, -0.2, -0.2],
  [-0.2, -0.3, 0.2],
]

[pulleys]
radius_m = [0.05, 0.06, 0.05, 0.055, 0.05, 0.045, 0.05, 0.06]
swivel_axes = [
  [0.0, 0.0, 2.0],
  [-0.6, -0.54, 1.2],
  [0.1, 0.0, 1.0],
  [-0.6, 0.36, 0.9],
  [0.0, 0.0, 1.0],
  [-0.6, -0.03, 1.3],
  [0.0, 0.0, -1.0],
  [-0.6, 0.45, 0.7],
]

[elasticity]
k_f_n = [1.5e6, 1.6e6, 1.55e6, 1.5e6, 1.45e6, 1.5e6, 1.65e6, 1.5e6]

[load]
wrench_n_nm = [10.0, -5.0, -2943.0, 1.5, -2.25, 0.0]

[forces]
f_min_n = 200
f_max_n = 6000.0
f_abs_max_n = 9000.0

[limits]
linear_velocity_max_m_per_s = 2.5
angular_velocity_max_deg_per_s = 60.3
linear_acceleration_max_m_per_s2 = 7.5
angular_acceleration_max_deg_per_s2 = 88.6

[winch]
drum_diameter_m = 0.2
rope_diameter_m = 0.01

[workspace]
position_min_m = [-1.0, -1.1, 0.9]
position_max_m = [1.0, 1.2, 2.3]
rotation_min_deg = [-7.3, -12.2, -29.5]
rotation_max_deg = [7.3, 12.2, 45.2]

[home]
position_m = [0.0, 0.0, 1.6]
rotation_deg = [0.0, 0.0, 0.0]
"#;

/// Model identity (`"crs-model-v1"`) of the golden platform.
pub const MODEL_IDENTITY: [u8; 32] = [
    0xc8, 0xbe, 0x17, 0xf2, 0x3e, 0x51, 0x40, 0x40, 0xb2, 0x77, 0xf1, 0x29, 0xcf, 0xc8, 0x3f, 0xcd,
    0x30, 0xcc, 0x05, 0x83, 0xc4, 0x59, 0xf1, 0x76, 0x9c, 0xed, 0x12, 0xa4, 0x9d, 0x26, 0x85, 0x0e,
];

/// Platform identity (`"crs-platform-v2"`) of the golden platform: what motion-core announces
/// and the monitor recomputes for [`PLATFORM_TOML`].
pub const PLATFORM_IDENTITY: crate::PlatformId = crate::PlatformId::new([
    0x3b, 0x8d, 0x8c, 0x28, 0x4c, 0x85, 0xbb, 0x37, 0x8e, 0x5e, 0xfa, 0x76, 0x13, 0xf7, 0x30, 0x24,
    0x42, 0x6c, 0x4a, 0x7a, 0x78, 0x9d, 0x49, 0x08, 0x9d, 0x51, 0xdf, 0xe9, 0x0d, 0x80, 0x16, 0xcb,
]);
