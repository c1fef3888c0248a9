//! The operator console: a web page that shows the running stack live and can stop it.
//!
//! * The iceoryx2 side runs in ONE plain thread ([`poller`]) that drains every topic of the
//!   contract 25 times a second (subscriber ports only: the hard loop's publishers never wait
//!   for it; iceoryx2's safe overflow drops the oldest samples of a slow reader) and hands a
//!   [`status::Status`] to tokio through a `watch` channel. The stop button's request travels
//!   the other way through a channel to the same thread, which owns the only publisher.
//! * The web side ([`server`]) is axum on tokio: one embedded page (HTML + JS, no build step),
//!   live updates as server-sent events at the poller's 25 Hz, `GET /api/status`,
//!   `GET /api/trips` (the trip log in time order, oldest first), `POST /api/stop`,
//!   `POST /api/ride/start`.
//! * Stop publishes an e-stop `StateEvent` (source Operator) and the wake-up: motion-core
//!   latches E-STOPPED and holds, drive-io quick-stops the drives. There is no reset here:
//!   reset stays an operator action at the monitor (`safety-monitor reset`). STOP is always
//!   enabled.
//! * Start ([`ride`]): with motion-core's control socket and a verified ride, the start button
//!   sends the ride as `crs ride start` does — only while the pre-ride checks pass (stack
//!   running, motion-core idle and holding, the monitor armed, no latched trip, a ride
//!   loaded), checked again by the server when the request arrives.
//! * Binds 127.0.0.1 by default; any other address needs a token, checked on every request.

pub mod poller;
pub mod ride;
pub mod server;
pub mod status;

use std::net::SocketAddr;

pub use ride::{LoadedRide, RideSetup};
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
    /// The hard loop's CPU (motion-core's `[realtime] cpu`): every console thread keeps off it
    /// and runs at nice 10, so web clients compete with nothing on the motion CPU.
    pub avoid_cpu: Option<usize>,
    /// The start button's control socket and ride (None: rides start from `crs ride` only).
    pub rides: Option<RideSetup>,
}

/// Makes the calling thread a background thread: nice 10 and, when given and other CPUs exist,
/// off `avoid_cpu`. Best effort (a refused call leaves the thread as it is).
pub fn background_thread(avoid_cpu: Option<usize>) {
    // Best effort by design: a console thread that could not be moved still serves the page.
    // (Nice 10 is refused only below an inherited higher nice value without CAP_SYS_NICE; the
    // affinity only for a CPU set the process may not use.)
    let _ = crs_rt::set_thread_nice(10);
    if let Some(cpu) = avoid_cpu {
        let _ = crs_rt::keep_off_cpu(cpu);
    }
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
            let avoid = cfg.avoid_cpu;
            background_thread(avoid);
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .thread_name("crs-console-http")
                .on_thread_start(move || background_thread(avoid))
                .enable_all()
                .build()?;
            rt.block_on(async move {
                let ready = move |addr: SocketAddr| {
                    let _ = ready_tx.send(Ok(addr));
                };
                server::serve(cfg, ready, async {
                    let _ = shutdown_rx.await;
                })
                .await
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
    let avoid = cfg.avoid_cpu;
    background_thread(avoid);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .on_thread_start(move || background_thread(avoid))
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

#[cfg(test)]
mod tests {
    #[test]
    fn background_threads_keep_off_the_motion_cpu_at_nice_10() {
        // SAFETY: sysconf has no preconditions.
        let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) } as usize;
        let (cpu1_allowed, nice) = std::thread::spawn(move || {
            super::background_thread(Some(1));
            // SAFETY: reading the calling thread's affinity and priority.
            unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
                let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
                (
                    libc::CPU_ISSET(1, &set),
                    libc::getpriority(libc::PRIO_PROCESS, tid),
                )
            }
        })
        .join()
        .unwrap();
        assert_eq!(nice, 10);
        if n > 1 {
            assert!(!cpu1_allowed, "the console thread may still run on CPU 1");
        }
    }
}
