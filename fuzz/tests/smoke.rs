//! A short fuzz run of every target (the long run is `crs-fuzz --cases 1000000`, figures in
//! benches/RESULTS.md): no panic, every text rejection names its line or key, no property
//! violation. `CRS_FUZZ_CASES` overrides the count.

#[test]
fn every_target_survives_a_short_run() {
    crs_fuzz::quiet_panics();
    let cases: u64 = std::env::var("CRS_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2_000);
    let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-smoke");
    let mut report = String::new();
    for t in crs_fuzz::targets::all() {
        let st = crs_fuzz::run(&t, cases, 42, &out);
        assert_eq!(st.cases, cases);
        // The mutator must reach both sides of every text loader, or the run proves little.
        if t.locate == crs_fuzz::targets::Locate::LineOrKey {
            assert!(st.rejected > 0, "{}: no case was rejected", t.name);
        }
        if st.failed() {
            report.push_str(&format!(
                "{}: {:?}\n",
                t.name,
                st.failures.iter().map(|f| &f.0).collect::<Vec<_>>()
            ));
        }
    }
    assert!(report.is_empty(), "fuzz failures:\n{report}");
}

#[test]
fn the_location_check_can_fail() {
    assert!(crs_fuzz::names_line_or_key("x.toml:12:3: expected value"));
    assert!(crs_fuzz::names_line_or_key("`limits.f_max`: out of range"));
    assert!(!crs_fuzz::names_line_or_key("invalid configuration"));
}

#[test]
fn a_panicking_decoder_is_caught_and_counted() {
    use crs_fuzz::targets::{Locate, Target, Verdict};
    crs_fuzz::quiet_panics();
    let t = Target {
        name: "panics-on-digit-nine",
        what: "a decoder with a bug",
        locate: Locate::No,
        seeds: |_| vec![b"x = 12345\n".to_vec()],
        run: |b, _| {
            if b.contains(&b'9') {
                panic!("found a nine");
            }
            Verdict::Accepted
        },
    };
    let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-selftest");
    let st = crs_fuzz::run(&t, 2_000, 1, &out);
    assert!(st.panics > 0 && st.failed(), "{st:?}");
    assert!(st.failures[0].0.contains("found a nine"));
}
