//! The console's start button: the ride it was given (verified with the loop's own checks when
//! the console was set up), motion-core's control socket (`motion-core --control PATH`, the
//! socket `crs ride` uses) and what that socket last said about the loop.
//!
//! The button starts the ride only when the pre-ride checks pass ([`crate::status`]: stack
//! running, motion-core idle and holding, the safety monitor armed, no latched trip, a ride
//! loaded); motion-core verifies the ride once more before anything moves, as for `crs ride
//! start`.

use crs_ipc::ride_control::{self as ride_socket, Request};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How often the console asks motion-core what its loop does.
pub const CONTROL_POLL: Duration = Duration::from_millis(400);

/// A ride the console may start: a waypoint file's text as motion-core's ride verification
/// (`ConfiguredController::verify_ride`) accepted it when the console was set up.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedRide {
    name: String,
    text: String,
    waypoints: usize,
    plan_s: f64,
}

impl LoadedRide {
    /// A ride whose `text` (the file `name` as the operator gave it) passed motion-core's ride
    /// verification: `waypoints` waypoints, a plan of `plan_s` seconds.
    pub fn verified(name: String, text: String, waypoints: usize, plan_s: f64) -> Self {
        Self {
            name,
            text,
            waypoints,
            plan_s,
        }
    }
    pub fn name(&self) -> &str {
        &self.name
    }
    /// `NAME (N waypoints, plan T s)`.
    pub fn describe(&self) -> String {
        format!(
            "{} ({} waypoints, plan {:.1} s)",
            self.name, self.waypoints, self.plan_s
        )
    }
    /// The request `crs ride start NAME` sends.
    pub fn start_request(&self) -> Request {
        Request::Start {
            name: self.name.clone(),
            text: self.text.clone(),
        }
    }
}

/// Rides from the console: motion-core's control socket and the ride loaded (None: the start
/// button stays disabled and says why).
#[derive(Debug, Clone)]
pub struct RideSetup {
    pub socket: PathBuf,
    pub ride: Option<LoadedRide>,
}

/// motion-core's last answer on its control socket.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ControlSeen {
    /// The loop's phase (`idle, holding`, `riding`, …): the answer's first part.
    pub phase: Option<String>,
    /// The whole answer, or why the socket could not be asked.
    pub reply: String,
    /// When the answer came (an old answer says nothing about the loop now).
    pub at: Option<std::time::Instant>,
}

/// Asks motion-core's control socket `status` every [`CONTROL_POLL`] until `stop`, and keeps
/// the newest answer in `seen`. Its own thread: a control thread busy verifying a ride must not
/// stall the console's updates.
pub fn spawn_control_watch(
    socket: PathBuf,
    stop: Arc<AtomicBool>,
    seen: Arc<Mutex<ControlSeen>>,
    avoid_cpu: Option<usize>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new()
        .name("crs-console-ride".into())
        .spawn(move || {
            crate::background_thread(avoid_cpu);
            while !stop.load(Ordering::Relaxed) {
                let now = match ride_socket::request(&socket, &Request::Status) {
                    Ok(reply) => ControlSeen {
                        phase: reply.split(';').next().map(|p| p.trim().to_string()),
                        reply,
                        at: Some(std::time::Instant::now()),
                    },
                    Err(e) => ControlSeen {
                        phase: None,
                        reply: e.to_string(),
                        at: Some(std::time::Instant::now()),
                    },
                };
                if let Ok(mut s) = seen.lock() {
                    *s = now;
                }
                std::thread::sleep(CONTROL_POLL);
            }
        })
}
