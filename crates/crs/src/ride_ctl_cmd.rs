//! `crs ride`: an operator's rides on the running stack — start a ride file, abort it, return
//! home, ask what the loop is doing — through motion-core's control socket
//! (`crs_ipc::ride_control`). motion-core verifies every ride with the loop's own
//! checks before anything moves and answers with the plan's duration or the refusal.

use crs_ipc::ride_control::{self as ride_socket, DEFAULT_SOCKET, Request};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct Socket {
    /// motion-core's control socket (`motion-core --control PATH`).
    #[arg(long, env = "CRS_CONTROL_SOCKET", default_value = DEFAULT_SOCKET)]
    socket: PathBuf,
}

#[derive(clap::Subcommand, Debug)]
pub enum RideCommand {
    /// Start a ride: the waypoint CSV FILE (t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg) is
    /// verified by motion-core (region, limits, wrench feasibility along the planned path) and
    /// run from the home pose. Refused (exit 1, naming file, line, axis and bound) unless the
    /// loop is idle at home and the whole plan passes.
    Start {
        file: PathBuf,
        #[command(flatten)]
        socket: Socket,
    },
    /// Abort the running ride: the loop brakes every axis at the planner's accelerations to
    /// rest and holds there (not an e-stop: the drives keep following). Then `crs ride home`.
    Abort {
        #[command(flatten)]
        socket: Socket,
    },
    /// Return to the home pose from where the platform holds (after an abort, or after the
    /// safety monitor's reset of a latched loop).
    Home {
        #[command(flatten)]
        socket: Socket,
    },
    /// What the loop is doing: idle, riding, braking or latched; its pose; rides started.
    Status {
        #[command(flatten)]
        socket: Socket,
    },
}

/// `crs ride` cannot do what it was asked.
#[derive(Debug, thiserror::Error)]
pub enum RideCmdError {
    #[error("{}: cannot read: {source}", file.display())]
    Read {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Daemon(#[from] ride_socket::ClientError),
}

pub fn run(cmd: RideCommand) -> Result<(), RideCmdError> {
    let (socket, req) = match cmd {
        RideCommand::Start { file, socket } => {
            let text = std::fs::read_to_string(&file).map_err(|source| RideCmdError::Read {
                file: file.clone(),
                source,
            })?;
            let name = file.display().to_string();
            (socket, Request::Start { name, text })
        }
        RideCommand::Abort { socket } => (socket, Request::Abort),
        RideCommand::Home { socket } => (socket, Request::Home),
        RideCommand::Status { socket } => (socket, Request::Status),
    };
    let reply = ride_socket::request(&socket.socket, &req)?;
    println!("{reply}");
    Ok(())
}
