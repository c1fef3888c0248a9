//! The drive bus as it is on the wire: frame lengths in bits ([`bits`]), the hub protocol
//! ([`proto`]) and the `wire:` transport through which a process is one node of a bus the
//! `can-wire` hub runs. The bus itself (bit time, arbitration, transmit queues) is the
//! `can-bus-model` crate, which only the hub links.
pub mod bits;
mod client;
pub mod proto;
pub use client::WireBus;
