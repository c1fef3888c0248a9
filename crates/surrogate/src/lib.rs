//! surrogate (to be built; see the issue tracker).
