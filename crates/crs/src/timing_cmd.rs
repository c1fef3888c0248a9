//! `crs timing PROFILE --out DIR`: the daemon, drives and monitor configs of a timing profile
//! (`crs_supervisor::timing`), for running the installed units on a slow or emulated machine: point
//! the units at DIR (e.g. a drop-in with `Environment=CRS_CONFIG_DIR=DIR`). The files are the
//! configuration directory's (installed: /etc/crs/config) with only the timing keys changed.

use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct TimingArgs {
    /// spec (the configs as shipped), relaxed (debug builds on a loaded host) or emulated (a
    /// QEMU guest under software emulation).
    pub profile: String,
    /// The platform whose configs are copied (icosahedron, helicopter); default: the one the
    /// configuration directory's motion-core.toml runs.
    #[arg(long)]
    pub platform: Option<String>,
    /// Where the copies go (written under DIR/timing-PROFILE/).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: TimingArgs) -> Result<(), Box<dyn std::error::Error>> {
    let files = sim_runs::platforms::run_files(
        a.platform.as_deref(),
        &sim_runs::platforms::Overrides::default(),
        &a.profile,
        &a.out,
    )?;
    for p in [&files.daemon, &files.drives, &files.monitor] {
        println!("{}", p.display());
    }
    Ok(())
}
