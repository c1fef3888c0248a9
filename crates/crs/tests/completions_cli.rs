//! `crs completions SHELL` into a reader that has already gone (`… | grep -q`, `… | head`): the
//! write fails with EPIPE, which is the reader's choice, not a crash. clap_complete panics on a
//! failed write; crs must exit cleanly instead (CI once failed on exactly this).

use std::process::{Command, Stdio};

#[test]
fn completions_into_a_closed_pipe_exit_cleanly() {
    for shell in ["bash", "zsh", "fish"] {
        // The read end is dropped before the child starts, so every write gets EPIPE.
        let (reader, writer) = std::io::pipe().expect("pipe");
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_crs"))
            .args(["completions", shell])
            .stdout(Stdio::from(writer))
            .stderr(Stdio::piped())
            .output()
            .expect("run crs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{shell}: {stderr}");
        assert!(out.status.success(), "{shell}: {:?} {stderr}", out.status);
    }
}

#[test]
fn completions_are_written_in_full() {
    let out = Command::new(env!("CARGO_BIN_EXE_crs"))
        .args(["completions", "zsh"])
        .output()
        .expect("run crs");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf-8");
    assert!(
        text.starts_with("#compdef crs"),
        "{}",
        &text[..text.len().min(80)]
    );
    assert!(text.contains("console"), "subcommands are completed");
}
