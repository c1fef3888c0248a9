//! `crs load track` (the seed's walking-subject load tracking on the plant, sec. 5.3) and
//! `crs commission` (set-up identification and the pre-ride payload check, eq. 6.21–6.24,
//! 3.42). The work is in `plant_experiments::load_experiment` and `calibration_campaigns::commission`.

use crate::sim_cmd::SimArgs;
use calibration_campaigns::commission::{self, CommissionConfig, Verdict};
use plant_experiments::load_experiment::{self, WalkConfig};
use stack_reports::commission_report::CommissionReport;
use std::path::PathBuf;

type BoxErr = Box<dyn std::error::Error>;

#[derive(clap::Subcommand, Debug)]
pub enum LoadCommand {
    /// A subject walks a rectangle on the cabin floor of the simulated plant while the cabin is
    /// held; the cable forces alone track where it stands (eq. 5.9–5.10). Prints the tracking
    /// error against the seed's ±9.7 cm, writes walk.svg and walk.json.
    Track(TrackArgs),
}

#[derive(clap::Args, Debug)]
pub struct TrackArgs {
    /// Plant TOML (the controller's model is its nominal platform).
    #[arg(long, default_value = "config/plant/icosahedron.toml")]
    plant: PathBuf,
    /// Subject mass, kg.
    #[arg(long, default_value_t = 80.0)]
    subject_kg: f64,
    /// Laps of the 1.2 m × 1.0 m rectangle at 0.5 m/s, forces sampled at 10 Hz.
    #[arg(long, default_value_t = 2)]
    laps: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[arg(long, default_value = "out/load-track")]
    out: PathBuf,
}

pub fn run(cmd: LoadCommand) -> Result<(), BoxErr> {
    match cmd {
        LoadCommand::Track(a) => {
            if !(a.subject_kg.is_finite() && a.subject_kg > 0.0) {
                return Err(format!("--subject-kg must be > 0, got {}", a.subject_kg).into());
            }
            let r = load_experiment::run(&WalkConfig {
                plant: a.plant,
                subject_kg: a.subject_kg,
                laps: a.laps,
                seed: a.seed,
                ..WalkConfig::default()
            })?;
            let (svg, json) = load_experiment::write(&r, &a.out)?;
            print!("{r}");
            println!("wrote {} and {}", svg.display(), json.display());
            Ok(())
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct CommissionArgs {
    #[command(flatten)]
    sim: SimArgs,
    /// Level offsets of the commissioning poses from the set-up pose, m.
    #[arg(long, default_value_t = 0.3)]
    offset_m: f64,
    /// Roll and pitch of the tilted poses, degrees (the COG height needs them).
    #[arg(long, default_value_t = 2.0)]
    tilt_deg: f64,
    /// The measured payload mass must match the configured within this, kg.
    #[arg(long, default_value_t = 30.0)]
    mass_tolerance_kg: f64,
    /// ... and its centre of gravity (x, y) within this, m.
    #[arg(long, default_value_t = 0.05)]
    cog_tolerance_m: f64,
}

pub fn commission(a: CommissionArgs) -> Result<(), BoxErr> {
    for (name, v) in [
        ("--offset-m", a.offset_m),
        ("--tilt-deg", a.tilt_deg),
        ("--mass-tolerance-kg", a.mass_tolerance_kg),
        ("--cog-tolerance-m", a.cog_tolerance_m),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("{name} must be a finite value ≥ 0, got {v}").into());
        }
    }
    let sim = a.sim.options()?;
    let out = sim.out.clone();
    let c = commission::run(&CommissionConfig {
        dwell_s: a.sim.dwell_s.unwrap_or(2.0),
        sim,
        offset_m: a.offset_m,
        tilt_rad: a.tilt_deg.to_radians(),
        mass_tolerance_kg: a.mass_tolerance_kg,
        cog_tolerance_m: a.cog_tolerance_m,
    })?;
    let path = commission::write(&c, &out)?;
    print!(
        "{}",
        CommissionReport {
            commission: &c,
            written: &path
        }
    );
    match c.verdict {
        Verdict::Ready => Ok(()),
        Verdict::Refused(why) => Err(format!("pre-ride check refused: {}", why.join("; ")).into()),
    }
}
