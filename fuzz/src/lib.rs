//! # crs-fuzz: mutation fuzzing of every decoder and loader
//!
//! Runs on stable Rust (no cargo-fuzz/nightly on the control PC or in CI): a seeded,
//! structure-aware mutator ([`mutate`]) starts from the shipped configs, files the stack writes
//! and valid frames, and every case runs under `catch_unwind`. A target fails on
//! * a panic (a daemon must never panic on input from a file, a socket or the bus),
//! * a text loader's rejection that names neither a line nor a key (`Locate::LineOrKey`),
//! * a property violation of the target (e.g. the SafetyWatch permitting with a silent bus).
//!
//! `crs-fuzz --cases 1000000` is the long run recorded in benches/RESULTS.md; `cargo test -p
//! crs-fuzz` runs a short one of every target in CI.

pub mod mutate;
pub mod targets;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::Instant;
use targets::{Locate, Scratch, Target, Verdict};

/// The outcome of one target's run.
#[derive(Debug, Default)]
pub struct RunStats {
    pub cases: u64,
    pub accepted: u64,
    pub rejected: u64,
    pub panics: u64,
    pub unlocated: u64,
    pub violations: u64,
    pub seconds: f64,
    /// The first few failures: (what, input).
    pub failures: Vec<(String, Vec<u8>)>,
}

impl RunStats {
    pub fn failed(&self) -> bool {
        self.panics + self.unlocated + self.violations > 0
    }
}

/// True if a rejection message points at a line or a key.
pub fn names_line_or_key(msg: &str) -> bool {
    let m = msg.to_ascii_lowercase();
    if m.contains("line") || m.contains('`') || m.contains("field") || m.contains("key") {
        return true;
    }
    // `file:12` / `file:12:3`
    msg.as_bytes()
        .windows(2)
        .any(|w| w[0] == b':' && w[1].is_ascii_digit())
}

/// The workspace's config directory.
pub fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../config")
}

/// Runs `cases` mutated inputs through `t` with seed `seed`.
pub fn run(t: &Target, cases: u64, seed: u64, scratch_root: &Path) -> RunStats {
    let scratch = Scratch {
        config_dir: config_dir(),
        dir: scratch_root.join(t.name),
    };
    std::fs::create_dir_all(&scratch.dir).expect("scratch directory");
    // Loaders that resolve sibling files (the monitor's platform and drives) find them next to
    // the case.
    for f in [
        "icosahedron.toml",
        "drives.toml",
        "crs-nominal.toml",
        "helicopter.toml",
    ] {
        let _ = std::fs::copy(scratch.config_dir.join(f), scratch.dir.join(f));
    }
    let mut m = mutate::Mutator::new(seed, (t.seeds)(&scratch.config_dir));
    let mut st = RunStats::default();
    let t0 = Instant::now();
    for _ in 0..cases {
        let case = m.next_case();
        st.cases += 1;
        let r = catch_unwind(AssertUnwindSafe(|| (t.run)(&case, &scratch)));
        let fail = match r {
            Err(p) => {
                st.panics += 1;
                let msg = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Some(format!("panic: {msg}"))
            }
            Ok(Verdict::Accepted) => {
                st.accepted += 1;
                None
            }
            Ok(Verdict::Rejected(msg)) => {
                st.rejected += 1;
                if t.locate == Locate::LineOrKey && !names_line_or_key(&msg) {
                    st.unlocated += 1;
                    Some(format!("rejection names no line or key: {msg}"))
                } else {
                    None
                }
            }
            Ok(Verdict::Violation(msg)) => {
                st.violations += 1;
                Some(format!("property violated: {msg}"))
            }
        };
        if let Some(f) = fail
            && st.failures.len() < 5
        {
            st.failures.push((f, case));
        }
    }
    st.seconds = t0.elapsed().as_secs_f64();
    st
}

/// Installs a panic hook that stays quiet (panics are counted and reported per case).
pub fn quiet_panics() {
    std::panic::set_hook(Box::new(|_| {}));
}
