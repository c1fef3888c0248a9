//! # motion-core: the 1 ms hard-loop daemon
//!
//! The daemon of sec. 5.5: per cycle the next reference (a ruckig plan or the motion-cueing
//! stream), the checks (finite, workspace box, wrench feasibility eq. 3.29 in closed form
//! eq. 3.41, velocity/acceleration limits), q_θ = φ(x) + φ_sg(x) (eq. 5.26) and the setpoint,
//! published on iceoryx2 by a stage off the loop thread. The model it evaluates lives in
//! [`cdpr_model`]; this crate adds real time, IPC and the lifecycle.

// Per-cable loops index several parallel arrays by the cable number, as the equations do.
#![allow(clippy::needless_range_loop)]

pub mod daemon;
