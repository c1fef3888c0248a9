//! crs-ipc (to be built; see the issue tracker).
