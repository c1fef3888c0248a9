//! drive-io (to be built; see the issue tracker).
