//! The operator console: a web page that shows the running stack live and can stop it.
//!
//! * The iceoryx2 side runs in ONE plain thread ([`poller`]) that drains every topic of the
//!   contract 25 times a second (subscriber ports only: the hard loop's publishers never wait
//!   for it; iceoryx2's safe overflow drops the oldest samples of a slow reader) and hands a
//!   [`status::Status`] to tokio through a `watch` channel. The stop button's request travels
//!   the other way through a channel to the same thread, which owns the only publisher.
//! * The web side ([`server`]) is axum on tokio: one embedded page (HTML + JS, no build step),
//!   live updates as server-sent events at the poller's 25 Hz, `GET /api/status`,
//!   `GET /api/trips`, `POST /api/stop`.
//! * Stop publishes an e-stop `StateEvent` (source Operator) and the wake-up: motion-core
//!   latches E-STOPPED and holds, drive-io quick-stops the drives. There is no reset here:
//!   reset stays an operator action at the monitor (`safety-monitor reset`).
//! * Binds 127.0.0.1 by default; any other address needs a token, checked on every request.

pub mod poller;
pub mod server;
pub mod status;

use std::net::SocketAddr;

pub use status::{PlanView, PlatformView, Status, TripEntry};

/// Errors of the console.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    #[error(
        "console address {0}: binding anything but a loopback address needs a token (--token or CRS_CONSOLE_TOKEN)"
    )]
    TokenRequired(SocketAddr),
    #[error("console token: must be at least 16 characters")]
    TokenTooShort,
    #[error("console: binding {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("console: {0}")]
    Io(#[from] std::io::Error),
    #[error("console: iceoryx2: {0}")]
    Ipc(#[from] crs_ipc::IpcError),
    #[error("console: the iceoryx2 poller thread stopped")]
    PollerGone,
}

/// How a console runs.
#[derive(Debug, Clone)]
pub struct ConsoleConfig {
    pub addr: SocketAddr,
    /// Required unless `addr` is a loopback address; when set, checked on every request.
    pub token: Option<String>,
    /// iceoryx2 service prefix of the stack (`crs sim` uses one per run).
    pub prefix: String,
    pub platform: Option<PlatformView>,
    pub plan: Option<PlanView>,
}

impl ConsoleConfig {
    /// Refuses a non-loopback address without a token, and short tokens.
    pub fn validate(&self) -> Result<(), ConsoleError> {
        match &self.token {
            None if !self.addr.ip().is_loopback() => Err(ConsoleError::TokenRequired(self.addr)),
            Some(t) if t.len() < 16 => Err(ConsoleError::TokenTooShort),
            _ => Ok(()),
        }
    }
}

/// A console running in the background (its own tokio runtime on its own threads), as
/// `crs sim --console` starts it. Dropping it stops the server and the poller.
pub struct ConsoleHandle {
    pub addr: SocketAddr,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<Result<(), ConsoleError>>>,
}

impl ConsoleHandle {
    /// Stops the server and waits for it.
    pub fn stop(mut self) -> Result<(), ConsoleError> {
        self.stop_inner()
    }
    fn stop_inner(&mut self) -> Result<(), ConsoleError> {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        match self.thread.take() {
            Some(t) => t.join().map_err(|_| ConsoleError::PollerGone)?,
            None => Ok(()),
        }
    }
}

impl Drop for ConsoleHandle {
    fn drop(&mut self) {
        let _ = self.stop_inner();
    }
}

/// Starts the console in the background and returns once it listens.
pub fn spawn(cfg: ConsoleConfig) -> Result<ConsoleHandle, ConsoleError> {
    cfg.validate()?;
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (shutdown_tx, shutdown_rx) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::Builder::new()
        .name("crs-console".into())
        .spawn(move || {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .thread_name("crs-console-http")
                .enable_all()
                .build()?;
            rt.block_on(async move {
                let ready = move |addr: SocketAddr| {
                    let _ = ready_tx.send(Ok(addr));
                };
                let r = server::serve(cfg, ready, async {
                    let _ = shutdown_rx.await;
                })
                .await;
                r
            })
        })?;
    match ready_rx.recv() {
        Ok(Ok(addr)) => Ok(ConsoleHandle {
            addr,
            shutdown: Some(shutdown_tx),
            thread: Some(thread),
        }),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(thread
            .join()
            .map_err(|_| ConsoleError::PollerGone)?
            .err()
            .unwrap_or(ConsoleError::PollerGone)),
    }
}

/// Runs the console in the foreground until Ctrl-C (`crs console`).
pub fn run_blocking(cfg: ConsoleConfig) -> Result<(), ConsoleError> {
    cfg.validate()?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(server::serve(
        cfg,
        |addr| println!("crs console: http://{addr}/ (Ctrl-C stops the console, not the stack)"),
        async {
            let _ = tokio::signal::ctrl_c().await;
        },
    ))
}
