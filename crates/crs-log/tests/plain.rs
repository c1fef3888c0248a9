//! A daemon whose output goes to a file (as under `crs sim`) logs plain text: no ANSI escapes.
use std::process::Command;

#[test]
fn redirected_output_has_no_ansi_escapes() {
    let exe = env!("CARGO_BIN_EXE_crs-log-demo");
    let out = Command::new(exe)
        .env_remove("JOURNAL_STREAM")
        .env_remove("NO_COLOR")
        .env("RUST_LOG", "info")
        .output()
        .expect("run crs-log-demo");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf-8");
    assert!(text.contains("SAFETY TRIP"), "log line missing: {text:?}");
    assert!(text.contains("sink=Plain"), "{text:?}");
    assert!(
        !text.contains('\u{1b}'),
        "ANSI escape in redirected log: {text:?}"
    );
}

#[test]
fn journal_stream_of_another_file_is_not_the_journal() {
    // JOURNAL_STREAM naming a file that is not our stderr (an inherited variable) must not
    // switch to the journal.
    let exe = env!("CARGO_BIN_EXE_crs-log-demo");
    let out = Command::new(exe)
        .env("JOURNAL_STREAM", "1:1")
        .output()
        .expect("run crs-log-demo");
    let text = String::from_utf8(out.stdout).expect("utf-8");
    assert!(text.contains("sink=Plain"), "{text:?}");
}
