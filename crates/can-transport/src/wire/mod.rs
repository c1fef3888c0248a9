//! The drive bus as it is on the wire: frame lengths in bits ([`bits`]), a model of one CAN
//! bus with bit time, arbitration and per-node transmit queues ([`model`]), and the `wire:`
//! transport through which a process is one node of a bus the `can-wire` hub runs.
pub mod bits;
mod client;
pub mod model;
pub mod proto;
pub use client::WireBus;
