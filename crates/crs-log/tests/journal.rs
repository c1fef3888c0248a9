//! Under systemd (JOURNAL_STREAM names our stderr) a daemon logs to the journal: one datagram per
//! event in journald's native protocol with PRIORITY, SYSLOG_IDENTIFIER, MESSAGE and the
//! tracing fields. journald itself does not run here, so the test stands in for its socket
//! (only where no journald socket exists; elsewhere the real journald would get the line).
use std::os::unix::fs::MetadataExt;
use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::Duration;

const SOCKET: &str = "/run/systemd/journal/socket";

#[test]
fn trip_is_one_structured_journal_entry() {
    if std::path::Path::new(SOCKET).exists() {
        eprintln!("a journald socket exists: not replacing it (nothing checked here)");
        return;
    }
    if std::fs::create_dir_all("/run/systemd/journal").is_err() {
        eprintln!("cannot create /run/systemd/journal (not root): nothing checked here");
        return;
    }
    let sock = UnixDatagram::bind(SOCKET).expect("bind the stand-in journal socket");
    sock.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let dir = std::env::temp_dir().join(format!("crs-log-journal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let stderr_file = std::fs::File::create(dir.join("stderr")).unwrap();
    let m = stderr_file.metadata().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_crs-log-demo"))
        .env("JOURNAL_STREAM", format!("{}:{}", m.dev(), m.ino()))
        .stderr(Stdio::from(stderr_file))
        .output()
        .expect("run crs-log-demo");
    let mut buf = vec![0u8; 65536];
    // tracing-journald probes the socket with an empty datagram first.
    let got = loop {
        match sock.recv(&mut buf) {
            Ok(0) => continue,
            other => break other,
        }
    };
    let _ = std::fs::remove_file(SOCKET);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(out.status.success());
    let n = got.expect("a journal datagram from the daemon");
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
