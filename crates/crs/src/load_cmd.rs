//! `crs load track` (the seed's walking-subject load tracking on the plant, sec. 5.3) and
//! `crs commission` (set-up identification and the pre-ride payload check, eq. 6.21–6.24,
//! 3.42). The work is in `crs_stack::{load_experiment, commission}`.

use crate::sim_cmd::SimArgs;
use crs_stack::commission::{self, CommissionConfig, Verdict};
use crs_stack::load_experiment::{self, SEED_TRACKING_M, WalkConfig};
use std::path::PathBuf;

type BoxErr = Box<dyn std::error::Error>;

#[derive(clap::Subcommand, Debug)]
pub enum LoadCommand {
    /// A subject walks a rectangle on the cabin floor of the simulated plant while the cabin is
    /// held; the cable forces alone track where it stands (eq. 5.9–5.10). Prints the tracking
    /// error against the seed's ±9.7 cm, writes walk.svg and walk.json.
    Track {
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
    },
}

pub fn run(cmd: LoadCommand) -> Result<(), BoxErr> {
    match cmd {
        LoadCommand::Track {
            plant,
            subject_kg,
            laps,
            seed,
            out,
        } => {
            if !(subject_kg.is_finite() && subject_kg > 0.0) {
                return Err(format!("--subject-kg must be > 0, got {subject_kg}").into());
            }
            let r = load_experiment::run(&WalkConfig {
                plant,
                subject_kg,
                laps,
                seed,
                ..WalkConfig::default()
            })?;
            std::fs::create_dir_all(&out)?;
            let svg = out.join("walk.svg");
            load_experiment::plot(&r, &svg)?;
            std::fs::write(out.join("walk.json"), serde_json::to_string_pretty(&r)?)?;
            println!(
                "walking subject {:.0} kg on plant `{}`: {} samples, {} without an estimate",
                r.subject_kg,
                r.plant,
                r.samples.len(),
                r.failed
            );
            println!(
                "  tracking error: mean {:.1} cm, p95 {:.1} cm, max {:.1} cm; {:.0} % within the seed's ±{:.1} cm",
                r.error_mean_m * 100.0,
                r.error_p95_m * 100.0,
                r.error_max_m * 100.0,
                r.within_seed_share * 100.0,
                SEED_TRACKING_M * 100.0
            );
            println!(
                "  estimated mass mean {:.1} kg; stated 1σ (10 N sensor noise) {:.1} cm",
                r.mass_mean_kg,
                r.stated_std_mean_m * 100.0
            );
            println!(
                "wrote {} and {}",
                svg.display(),
                out.join("walk.json").display()
            );
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
    let p = &c.payload;
    println!(
        "commissioning `{}`: {} rest points",
        c.platform, c.rest_points
    );
    println!(
        "  w_e at the set-up pose (eq. 6.23): [{}] N, N·m",
        c.w_e_setup.map(|v| format!("{v:.1}")).join(", ")
    );
    let cog = |k: usize| match (p.cog_m[k], p.cog_std_m[k]) {
        (Some(v), Some(s)) => format!("{v:.3} ± {s:.3} m"),
        _ => "not observable".into(),
    };
    println!(
        "  payload: {:.1} ± {:.1} kg, COG x {}, y {}, z {} (configured {:.1} kg, COG x {:.3} m, y {:.3} m)",
        p.mass_kg,
        p.mass_std_kg,
        cog(0),
        cog(1),
        cog(2),
        c.configured.0,
        c.configured.1[0],
        c.configured.1[1]
    );
    if let Some((m, t)) = c.truth {
        println!(
            "  plant truth: {m:.1} kg, COG ({:.3}, {:.3}, {:.3}) m",
            t[0], t[1], t[2]
        );
    }
    println!(
        "  q_off (eq. 6.24): [{}] mm",
        c.q_off_m
            .iter()
            .map(|v| format!("{:.1}", v * 1e3))
            .collect::<Vec<_>>()
            .join(", ")
    );
    match &c.f_ini {
        Ok(t) => println!(
            "  f_ini (eq. 3.42 along the daemon's tour): [{}] N; RMS to f_ref {:.0} N (start {:.0} N)",
            t.f_ini
                .iter()
                .map(|v| format!("{v:.0}"))
                .collect::<Vec<_>>()
                .join(", "),
            t.rms_chosen_n,
            t.rms_start_n
        ),
        Err(e) => println!("  f_ini (eq. 3.42): not chosen: {e}"),
    }
    println!("wrote {} (review it; config/ is unchanged)", path.display());
    match c.verdict {
        Verdict::Ready => {
            println!("PRE-RIDE CHECK: READY");
            Ok(())
        }
        Verdict::Refused(why) => {
            println!("PRE-RIDE CHECK: REFUSED — do not arm for rides:");
            for w in &why {
                println!("  - {w}");
            }
            Err(format!("pre-ride check refused: {}", why.join("; ")).into())
        }
    }
}
