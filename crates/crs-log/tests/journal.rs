//! Under systemd (JOURNAL_STREAM names our stderr) a daemon logs to the journal: one datagram per
//! event in journald's native protocol with PRIORITY, SYSLOG_IDENTIFIER, MESSAGE and the
//! tracing fields.
//!
//! The test stands in for journald's socket, on every host: the daemon runs in a private mount
//! namespace (`unshare(1)`; a user namespace too when not root) whose
//! `/run/systemd/journal` is the test's own directory, so a real journald is neither needed
//! nor touched and no root is needed where user namespaces are allowed. Where neither root nor
//! user namespaces are available the test FAILS saying so: it never passes without checking.
use std::os::unix::fs::MetadataExt;
use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn trip_is_one_structured_journal_entry() {
    let dir = std::env::temp_dir().join(format!("crs-log-journal-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let journal = dir.join("journal");
    std::fs::create_dir_all(&journal).unwrap();
    let sock =
        UnixDatagram::bind(journal.join("socket")).expect("bind the stand-in journal socket");
    sock.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let stderr_file = std::fs::File::create(dir.join("stderr")).unwrap();
    let m = stderr_file.metadata().unwrap();
    // /proc/self belongs to the process's effective uid.
    let root = std::fs::metadata("/proc/self").is_ok_and(|m| m.uid() == 0);
    let namespaces: &[&str] = if root {
        &["--mount", "--propagation", "private"]
    } else {
        &[
            "--user",
            "--map-root-user",
            "--mount",
            "--propagation",
            "private",
        ]
    };
    // Inside: a fresh /run, our directory as /run/systemd/journal, then the daemon.
    let script = format!(
        "mount -t tmpfs tmpfs /run && mkdir -p /run/systemd/journal && \
         mount --bind '{}' /run/systemd/journal && exec \"$0\"",
        journal.display()
    );
    let out = Command::new("unshare")
        .args(namespaces)
        .args(["sh", "-c", &script, env!("CARGO_BIN_EXE_crs-log-demo")])
        .env("JOURNAL_STREAM", format!("{}:{}", m.dev(), m.ino()))
        .stderr(Stdio::from(stderr_file))
        .output()
        .expect("run unshare(1) (util-linux)");
    let stderr = std::fs::read_to_string(dir.join("stderr")).unwrap_or_default();
    assert!(
        out.status.success(),
        "cannot run the daemon with a stand-in journald: unshare {} failed ({}): {stderr}\n\
         this test needs unshare(1) and root or unprivileged user namespaces",
        namespaces.join(" "),
        out.status
    );
    let mut buf = vec![0u8; 65536];
    // tracing-journald probes the socket with an empty datagram first.
    let got = loop {
        match sock.recv(&mut buf) {
            Ok(0) => continue,
            other => break other,
        }
    };
    let _ = std::fs::remove_dir_all(&dir);
    let n = got.unwrap_or_else(|e| {
        panic!("no journal datagram from the daemon ({e}); its stderr: {stderr}")
    });
    let fields = parse_native(&buf[..n]);
    for (k, v) in [
        ("PRIORITY", "3"),
        ("SYSLOG_IDENTIFIER", "crs-log-demo"),
        ("MESSAGE", "SAFETY TRIP: demo line"),
        ("F_CAUSE", "test"),
        ("F_SINK", "Journal"),
    ] {
        assert_eq!(
            fields.get(k).map(String::as_str),
            Some(v),
            "{k} in {fields:?}"
        );
    }
    // Nothing went to stdout: the journal got it.
    assert!(
        out.stdout.is_empty(),
        "{:?}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// journald's native protocol (systemd.io/JOURNAL_NATIVE_PROTOCOL): `NAME=value\n`, or
/// `NAME\n` + little-endian u64 length + value + `\n` for values that may hold newlines.
fn parse_native(mut b: &[u8]) -> std::collections::HashMap<String, String> {
    let mut out = std::collections::HashMap::new();
    while !b.is_empty() {
        let nl = b
            .iter()
            .position(|&c| c == b'\n')
            .expect("field ends with a newline");
        let line = &b[..nl];
        if let Some(eq) = line.iter().position(|&c| c == b'=') {
            out.insert(
                String::from_utf8_lossy(&line[..eq]).into_owned(),
                String::from_utf8_lossy(&line[eq + 1..]).into_owned(),
            );
            b = &b[nl + 1..];
        } else {
            let name = String::from_utf8_lossy(line).into_owned();
            let rest = &b[nl + 1..];
            let len = u64::from_le_bytes(rest[..8].try_into().unwrap()) as usize;
            out.insert(
                name,
                String::from_utf8_lossy(&rest[8..8 + len]).into_owned(),
            );
            assert_eq!(rest[8 + len], b'\n');
            b = &rest[8 + len + 1..];
        }
    }
    out
}
