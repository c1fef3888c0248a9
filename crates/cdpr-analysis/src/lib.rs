//! # cdpr-analysis: design analyses on the model library
//!
//! What a designer asks of a cable robot before it is built, on top of `cdpr-model`'s
//! equations; none of it runs in the hard loop, and its functions allocate:
//!
//! | job | module | equations |
//! |---|---|---|
//! | pose sensitivity to parameter errors | [`sensitivity`] | 3.25–3.28 |
//! | planar robots (n = 2, 3; any m > n): IK with pulleys, forces, W_WF, W_R, cond(J_qa) | [`planar`] | 2.3–2.8, 2.30, 2.42, 3.29, 3.33–3.41, 4.23 |
//! | icosahedron space-frame truss check (matrix stiffness method) | [`truss`] | 5.2–5.7 |
//!
//! Like the model library it knows nothing of IPC, real time, CAN or command lines;
//! `model-analysis` turns these into the reports of `crs model …`.

// Per-cable loops index several parallel arrays (q, f, columns of A^T) by the cable number,
// as the equations do; iterator zips of four slices would hide that.
#![allow(clippy::needless_range_loop)]

pub mod planar;
pub mod sensitivity;
pub mod truss;
