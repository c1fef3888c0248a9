//! One tracing initialisation for every daemon of the stack (`crs_log::init`).
//!
//! * Under systemd (`JOURNAL_STREAM` names our stderr, systemd.exec(5)) the daemon logs to the
//!   journal with structured fields (tracing-journald): every event is one journal entry with its
//!   level as PRIORITY, the daemon as SYSLOG_IDENTIFIER and each tracing field as a `F_<NAME>`
//!   field, so `journalctl -u crs-safety-monitor -p warning` finds a trip or a refused reset.
//! * Anywhere else it writes human-readable lines to stdout, with ANSI colours only when stdout
//!   is a terminal (`std::io::IsTerminal`) and `NO_COLOR` is unset: logs redirected to files
//!   (`crs sim` writes `out/sim/*.log`) stay plain text.
//! * The level filter is `RUST_LOG` (default `info`).

use std::io::IsTerminal;
use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// Where [`init`] sends the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogSink {
    /// The systemd journal, structured.
    Journal,
    /// Plain text lines on stdout.
    Plain,
    /// Coloured text lines on stdout (a terminal).
    Coloured,
}

/// True if `JOURNAL_STREAM` ("<dev>:<inode>") names the file our stderr is connected to, i.e.
/// systemd connected this process's output to the journal (systemd.exec(5), $JOURNAL_STREAM).
pub fn stderr_is_journal() -> bool {
    let Ok(v) = std::env::var("JOURNAL_STREAM") else {
        return false;
    };
    let Some((dev, ino)) = v.split_once(':') else {
        return false;
    };
    let (Ok(dev), Ok(ino)) = (dev.parse::<u64>(), ino.parse::<u64>()) else {
        return false;
    };
    use std::os::unix::fs::MetadataExt;
    match std::fs::metadata("/proc/self/fd/2") {
        Ok(m) => m.dev() == dev && m.ino() == ino,
        Err(_) => false,
    }
}

/// The sink [`init`] chooses for this process's environment.
pub fn choose_sink() -> LogSink {
    if stderr_is_journal() {
        LogSink::Journal
    } else if std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none() {
        LogSink::Coloured
    } else {
        LogSink::Plain
    }
}

fn filter() -> EnvFilter {
    EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"))
}

/// Installs the global tracing subscriber for daemon `process` (used as the journal's
/// SYSLOG_IDENTIFIER). Returns the sink chosen. Falls back to plain text when the journal
/// socket cannot be opened (and says so in the first line).
pub fn init(process: &str) -> LogSink {
    let mut sink = choose_sink();
    if sink == LogSink::Journal {
        match tracing_journald::layer() {
            Ok(layer) => {
                let layer = layer.with_syslog_identifier(process.to_string());
                if tracing_subscriber::registry()
                    .with(filter())
                    .with(layer)
                    .try_init()
                    .is_ok()
                {
                    return sink;
                }
            }
            Err(e) => {
                eprintln!("{process}: cannot open the journal socket ({e}); logging to stdout");
            }
        }
        sink = LogSink::Plain;
    }
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter())
        .with_ansi(sink == LogSink::Coloured)
        .try_init();
    sink
}
