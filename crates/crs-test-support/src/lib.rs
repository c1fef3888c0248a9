//! # crs-test-support: what the tests share
//!
//! - [`alloc`]: the counting global allocator behind every "the hot path allocates nothing"
//!   test (cdpr-model, surrogate, the monitor's cycle, motion-core's loop), one copy instead of
//!   one per test crate.
//! - [`fixtures`]: paths of the shipped configs and data the tests load.
//! - [`ports`]: UDP ports for the tests' buses that no two tests can share.
//!
//! A dev-dependency only: no library or binary of the stack depends on it.

pub mod alloc;
pub mod fixtures;
pub mod ports;
