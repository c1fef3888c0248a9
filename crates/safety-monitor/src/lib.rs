//! safety-monitor (to be built; see the issue tracker).
