//! `crs`: the operator / commissioning command line of the cable-robot stack.

mod calibrate_cmd;
mod calibrate_loop_cmd;
mod console_cmd;
mod cueing_cmd;
mod figures_cmd;
mod gen_cmd;
mod load_cmd;
mod model_cmd;
mod plant_cmd;
mod ride_cmd;
mod ride_ctl_cmd;
mod sim_cmd;
mod surrogate_cmd;
mod timing_cmd;

use clap::{CommandFactory, Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "crs",
    version,
    about = "Cable-robot motion control stack (CableRobot Simulator model)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the whole simulated stack (sim-plant, safety-monitor, drive-io, motion-core) on the
    /// default platform and report tracking, forces, loop statistics and the monitor state.
    Sim(sim_cmd::SimArgs),
    /// Rides on the running stack: start (a ride file, verified before anything moves), abort,
    /// home, status. Talks to motion-core's control socket.
    #[command(subcommand)]
    Ride(ride_ctl_cmd::RideCommand),
    /// Model computations on a platform TOML: ik, fk, forces, stiffness, planar, truss,
    /// sensitivity, workspace.
    #[command(subcommand)]
    Model(model_cmd::ModelCommand),
    /// The simulated plant: check, record (measurement campaigns as data sets), evaluate.
    #[command(subcommand)]
    Plant(plant_cmd::PlantCommand),
    /// The polynomial surrogate of the elastostatic force control: fit, check, evaluate.
    #[command(subcommand)]
    Surrogate(surrogate_cmd::SurrogateCommand),
    /// Calibration from measured data (identification, residual diagnosis, model extension): run,
    /// demo, loop, campaign, bench-diagnosis, generate.
    #[command(subcommand)]
    Calibrate(calibrate_cmd::CalibrateCommand),
    /// Load tracking from the cable forces (eq. 5.9–5.10): track (the walking-subject
    /// experiment).
    #[command(subcommand)]
    Load(load_cmd::LoadCommand),
    /// Commissioning and pre-ride check on the running stack: set-up wrench, payload mass and
    /// COG, cable offsets, initial tension (eq. 6.21–6.24, 3.42); refuses (exit 1) when the
    /// payload is out of tolerance. Writes <out>/commission.toml for review.
    Commission(load_cmd::CommissionArgs),
    /// The operator console: a web page with the running stack's live state and a stop button
    /// (no reset), JSON at /api/status and /api/trips. Binds 127.0.0.1 unless given a token.
    Console(console_cmd::ConsoleArgs),
    /// Regenerate the docs' headline figures (not timings) into one JSON file:
    /// benches/figures.json is its last run, checked against the docs by the tests.
    Figures(figures_cmd::FiguresArgs),
    /// Write the daemon, drives and monitor configs of a timing profile (spec, relaxed,
    /// emulated) into DIR/timing-PROFILE/: the installed stack on a slow or emulated machine.
    Timing(timing_cmd::TimingArgs),
    /// Write man pages (crs.1, crs-sim.1, ...) into DIR.
    GenMan {
        /// Output directory.
        dir: std::path::PathBuf,
    },
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions { shell: clap_complete::Shell },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Sim(a) => sim_cmd::run(a),
        Command::Ride(cmd) => ride_ctl_cmd::run(cmd).map_err(Into::into),
        Command::Model(cmd) => model_cmd::run(cmd),
        Command::Plant(cmd) => plant_cmd::run(cmd),
        Command::Surrogate(cmd) => surrogate_cmd::run(cmd),
        Command::Calibrate(cmd) => calibrate_cmd::run(cmd),
        Command::Load(cmd) => load_cmd::run(cmd),
        Command::Commission(a) => load_cmd::commission(a),
        Command::Console(a) => console_cmd::run(a),
        Command::Figures(a) => figures_cmd::run(a),
        Command::Timing(a) => timing_cmd::run(a),
        Command::GenMan { dir } => gen_cmd::gen_man(Cli::command(), &dir)
            .map(|files| println!("wrote {} man pages to {}", files.len(), dir.display()))
            .map_err(Into::into),
        Command::Completions { shell } => {
            gen_cmd::completions(Cli::command(), shell).map_err(Into::into)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
