#!/bin/sh
# rustdoc with its nightly switch, for the doc tests only (tools/test.sh sets RUSTDOC to this):
# stable rustdoc ignores the error code of a ```compile_fail,E0603``` test, so any compile
# error would pass it; with RUSTC_BOOTSTRAP=1 rustdoc checks that the expected code is emitted
# (as rustc's own error index does). rustc itself, and so cargo's build cache, is not affected.
RUSTC_BOOTSTRAP=1 exec rustdoc "$@"
