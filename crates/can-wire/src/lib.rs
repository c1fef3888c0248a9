//! `can-wire`: the drive bus as it is on the wire, for every simulation of the stack.
//!
//! The hub runs the bus model (`can-bus-model`: bit time from the
//! exact stuffed frame length, arbitration by identifier, a FIFO transmit queue per node) for
//! one or more buses in real time and connects the stack's processes to it:
//! * host: each process opens the transport `wire:<socket path>` (a node per connection);
//! * guest (real vcan in QEMU): one vcan interface per node; the hub reads each with the
//!   kernel's receive stamp as the submit time and writes every frame to every other node's
//!   interface at its end-of-frame time.
//!
//! Frames are delivered not before their end of frame; hub time runs `lookahead` behind the
//! clock so that submissions still on their way take part in the arbitration at their stamp
//! (later ones are counted as model violations). Statistics: docs/can-protocol.md
//! "The wire model".

pub mod config;
mod counters;
pub mod hub;
pub mod stats;
pub mod thread;

pub use config::{BusSpec, Endpoint, HubConfig};
pub use hub::{Hub, HubError};
pub use thread::HubThread;
