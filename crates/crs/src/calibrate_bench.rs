//! `crs calibrate bench-diagnosis`: its options; the benchmark is
//! [`crs_stack::diagnosis_bench`].

use clap::Args;
use crs_stack::diagnosis_bench::{BenchConfig, run as run_bench};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Nominal platform (the control model and the plant's nominal).
    #[arg(long, default_value = "config/crs-nominal.toml")]
    platform: PathBuf,
    /// Plant whose effect magnitudes are the 1× reference.
    #[arg(long, default_value = "config/plant/crs-like.toml")]
    plant: PathBuf,
    /// Seeds per scenario.
    #[arg(long, default_value_t = 5)]
    seeds: u64,
    /// Random poses of the identification campaign (each with a tension test: 2 rows per pose
    /// plus the return); the validation campaign has 3/4 of them.
    #[arg(long, default_value_t = 40)]
    poses: usize,
    /// Scenarios (comma separated): baseline and catalogue effect names; default all.
    #[arg(long, value_delimiter = ',')]
    scenarios: Option<Vec<String>>,
    /// A scenario's effect "matters" when the true-effect model cuts the held-out mean
    /// position error of the base model by at least this fraction ...
    #[arg(long, default_value_t = 0.05)]
    matters_pos: f64,
    /// ... or its held-out mean force error by at least this fraction. Both sit above what a
    /// catalogue candidate gains on data without any effect (≤ 1.3 % position, ≤ 12.1 % force
    /// on 20 baseline sets), so "matters" means "can be told from the noise of the fit".
    #[arg(long, default_value_t = 0.15)]
    matters_force: f64,
    /// Seeds of the baseline scenario (no effect): the false-addition rate needs more than the
    /// effect scenarios' seeds to be a rate.
    #[arg(long, default_value_t = 20)]
    baseline_seeds: u64,
    /// First seed: another value draws other magnitudes, poses and noise (the selection's
    /// thresholds were set on seeds 0–19 of the baseline, so a run from another first seed is
    /// an out-of-sample check of them).
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
    /// Print every candidate's evidence (round, held-out gains, verdict) of runs where the
    /// true effect matters but was not chosen, or where another effect was chosen.
    #[arg(long)]
    explain_misses: bool,
}

pub fn run(a: BenchArgs) -> Result<(), Box<dyn std::error::Error>> {
    run_bench(&BenchConfig {
        platform: a.platform,
        plant: a.plant,
        seeds: a.seeds,
        poses: a.poses,
        scenarios: a.scenarios,
        matters_pos: a.matters_pos,
        matters_force: a.matters_force,
        baseline_seeds: a.baseline_seeds,
        first_seed: a.first_seed,
        explain_misses: a.explain_misses,
    })
}
