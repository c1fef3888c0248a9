//! sim-plant (to be built; see the issue tracker).
