//! can-utils candump log format: `(1700000000.123456) vcan0 123#DEADBEEF` (`candump -l`,
//! readable by `canplayer`, `log2asc`, ...). Standard ids have 3 hex digits, extended 8, remote
//! frames are `ID#R` (optionally followed by the DLC digit).

use crate::frame::{CanFrame, RxFrame};
use crate::{CanBus, CanError};
use std::io::Write;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    #[error("missing '(seconds.micros)' timestamp")]
    Timestamp,
    #[error("missing interface name")]
    Interface,
    #[error("missing 'ID#DATA'")]
    MissingFrame,
    #[error("bad CAN id {0:?} (3 hex digits standard, 8 hex digits extended)")]
    Id(String),
    #[error("bad data {0:?} (even number of hex digits, at most 8 bytes)")]
    Data(String),
    #[error("CAN FD ('##') frames are not supported")]
    CanFd,
}

/// A parsed log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    pub seconds: u64,
    pub micros: u32,
    pub iface: String,
    pub frame: CanFrame,
}

/// Writes one log line (without allocation) for `frame` at wall time `t`.
pub fn write_line(
    w: &mut impl Write,
    t: SystemTime,
    iface: &str,
    frame: &CanFrame,
) -> std::io::Result<()> {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    write!(w, "({}.{:06}) {} ", d.as_secs(), d.subsec_micros(), iface)?;
    if frame.is_extended() {
        write!(w, "{:08X}#", frame.id())?;
    } else {
        write!(w, "{:03X}#", frame.id())?;
    }
    if frame.is_rtr() {
        write!(w, "R")?;
        if !frame.is_empty() {
            write!(w, "{}", frame.len())?;
        }
    } else {
        for b in frame.data() {
            write!(w, "{b:02X}")?;
        }
    }
    writeln!(w)
}

/// Writes an error frame as `candump -l` does: the id word with `CAN_ERR_FLAG` as 8 hex
/// digits, 8 data bytes (python-can's canutils reader and `canplayer` read it back as an error
/// frame; [`parse_line`] refuses it: data frames only).
pub fn write_error_line(
    w: &mut impl Write,
    t: SystemTime,
    iface: &str,
    error: &crate::BusErrorFrame,
) -> std::io::Result<()> {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    write!(
        w,
        "({}.{:06}) {} {:08X}#",
        d.as_secs(),
        d.subsec_micros(),
        iface,
        error.class() | 0x2000_0000
    )?;
    for b in error.data() {
        write!(w, "{b:02X}")?;
    }
    writeln!(w)
}

/// Parses one log line (what `candump -l` writes; trailing ` T`/` R` direction flags are ignored).
pub fn parse_line(line: &str) -> Result<LogLine, ParseError> {
    let line = line.trim();
    let rest = line.strip_prefix('(').ok_or(ParseError::Timestamp)?;
    let (ts, rest) = rest.split_once(')').ok_or(ParseError::Timestamp)?;
    let (s, us) = ts.split_once('.').ok_or(ParseError::Timestamp)?;
    let seconds: u64 = s.parse().map_err(|_| ParseError::Timestamp)?;
    if us.is_empty() || us.len() > 6 || !us.bytes().all(|b| b.is_ascii_digit()) {
        return Err(ParseError::Timestamp);
    }
    let micros: u32 =
        us.parse::<u32>().map_err(|_| ParseError::Timestamp)? * 10u32.pow(6 - us.len() as u32);
    let mut parts = rest.split_whitespace();
    let iface = parts.next().ok_or(ParseError::Interface)?.to_string();
    let fr = parts.next().ok_or(ParseError::MissingFrame)?;
    let (id_s, data_s) = fr.split_once('#').ok_or(ParseError::MissingFrame)?;
    if data_s.starts_with('#') {
        return Err(ParseError::CanFd);
    }
    let extended = match id_s.len() {
        3 => false,
        8 => true,
        _ => return Err(ParseError::Id(id_s.to_string())),
    };
    if !id_s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(ParseError::Id(id_s.to_string()));
    }
    let id = u32::from_str_radix(id_s, 16).map_err(|_| ParseError::Id(id_s.to_string()))?;
    let frame = if let Some(dlc) = data_s.strip_prefix(['R', 'r']) {
        let len = match dlc {
            "" => 0,
            d if d.len() == 1 && d.as_bytes()[0].is_ascii_digit() => d.as_bytes()[0] - b'0',
            _ => return Err(ParseError::Data(data_s.to_string())),
        };
        CanFrame::remote(id, extended, len).map_err(|_| ParseError::Data(data_s.to_string()))?
    } else {
        let hex = data_s.replace('.', "");
        if hex.len() % 2 != 0 || hex.len() > 16 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(ParseError::Data(data_s.to_string()));
        }
        let mut d = [0u8; 8];
        let n = hex.len() / 2;
        for (i, byte) in d.iter_mut().take(n).enumerate() {
            *byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16)
                .map_err(|_| ParseError::Data(data_s.to_string()))?;
        }
        CanFrame::with_flags(id, extended, false, &d[..n])
            .map_err(|_| ParseError::Id(id_s.to_string()))?
    };
    Ok(LogLine {
        seconds,
        micros,
        iface,
        frame,
    })
}

/// Wraps a bus and appends every sent and received frame to a candump log.
/// Logging is buffered; an I/O error disables the log (reported once) instead of failing the bus.
///
/// The buffer is shared with the interface's priority path ([`CanBus::open_priority_path`]):
/// one buffer per interface keeps that interface's lines in time order (two buffers would
/// flush the SYNCs apart from the frames around them). Both handles are used by drive-io's one
/// cycle thread, so the lock is never contended; it exists because a `CanBus` is `Send`.
pub struct LoggingBus<B: CanBus> {
    inner: B,
    out: Shared,
}

type Shared = std::sync::Arc<std::sync::Mutex<Option<std::io::BufWriter<std::fs::File>>>>;

impl<B: CanBus> LoggingBus<B> {
    pub fn create(inner: B, path: &std::path::Path) -> std::io::Result<Self> {
        let f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        Ok(Self {
            inner,
            out: std::sync::Arc::new(std::sync::Mutex::new(Some(
                std::io::BufWriter::with_capacity(64 * 1024, f),
            ))),
        })
    }

    fn log(&mut self, frame: &CanFrame) {
        // The line is formatted on the stack and handed to the buffer in one piece, so the
        // buffer is only ever flushed between whole lines: several interfaces (one LoggingBus
        // each) append to the same file with O_APPEND and their lines must not interleave.
        let mut line = [0u8; 160];
        let mut cur = std::io::Cursor::new(&mut line[..]);
        let formatted = write_line(&mut cur, SystemTime::now(), self.inner.interface(), frame);
        let n = cur.position() as usize;
        let mut out = self
            .out
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(w) = out.as_mut()
            && let Err(e) = formatted.and_then(|()| w.write_all(&line[..n]))
        {
            tracing::error!(error = %e, "candump log write failed; logging disabled");
            *out = None;
        }
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        match self
            .out
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .as_mut()
        {
            Some(w) => w.flush(),
            None => Ok(()),
        }
    }
}

impl<B: CanBus> Drop for LoggingBus<B> {
    fn drop(&mut self) {
        let _ = self.flush();
    }
}

impl<B: CanBus> CanBus for LoggingBus<B> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        self.inner.send(frame)?;
        self.log(frame);
        Ok(())
    }
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        let r = self.inner.recv_timeout(timeout)?;
        // An own frame's echo was logged when it was sent.
        if let Some(rx) = r.as_ref().filter(|rx| !rx.own) {
            self.log(&rx.frame);
        }
        Ok(r)
    }
    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        self.inner.readiness_fd()
    }
    fn interface(&self) -> &str {
        self.inner.interface()
    }
    fn rx_errors(&self) -> u64 {
        self.inner.rx_errors()
    }
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        self.inner.subscribe_bus_errors()
    }
    fn recv_event_timeout(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<crate::RxEvent>, CanError> {
        let r = self.inner.recv_event_timeout(timeout)?;
        match &r {
            Some(crate::RxEvent::Frame(rx)) if !rx.own => self.log(&rx.frame),
            Some(crate::RxEvent::Frame(_)) => {}
            Some(crate::RxEvent::BusError(e)) => {
                let mut out = self
                    .out
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                if let Some(w) = out.as_mut()
                    && let Err(err) =
                        write_error_line(w, SystemTime::now(), self.inner.interface(), &e.error)
                {
                    tracing::error!(error = %err, "candump log write failed; logging disabled");
                    *out = None;
                }
            }
            None => {}
        }
        Ok(r)
    }
    fn send_bus_error(&mut self, error: &crate::BusErrorFrame) -> Result<(), CanError> {
        self.inner.send_bus_error(error)
    }
    fn bus_errors(&self) -> u64 {
        self.inner.bus_errors()
    }
    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        self.inner.enable_tx_echo()
    }
    /// The inner transport's priority path, logging into this interface's own buffer.
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        let Some(path) = self.inner.open_priority_path()? else {
            return Ok(None);
        };
        Ok(Some(Box::new(LoggingBus {
            inner: path,
            out: self.out.clone(),
        })))
    }
    fn tx_backlog(&self) -> Option<u64> {
        self.inner.tx_backlog()
    }
}
