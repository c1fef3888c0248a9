//! can-transport (to be built; see the issue tracker).
