//! `crs figures`: regenerate the docs' headline figures into one JSON file
//! ([`stack_reports::figures`]; the repository keeps the last run in benches/figures.json).

use stack_reports::figures::{Context, GROUPS, regenerate};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct FiguresArgs {
    /// The JSON file to write.
    #[arg(long, default_value = "out/figures.json")]
    out: PathBuf,
    /// Regenerate only this group (repeatable; `--list` names them). Default: every group,
    /// including those that run the stack (needs the stack's release binaries next to `crs`).
    #[arg(long)]
    only: Vec<String>,
    /// Only the groups the test suite regenerates (deterministic, quick in a debug build).
    #[arg(long, conflicts_with = "only")]
    ci: bool,
    /// Scratch directory for the groups' own outputs.
    #[arg(long, default_value = "out/figures-work")]
    scratch: PathBuf,
    /// List the groups with their commands and exit.
    #[arg(long)]
    list: bool,
}

pub fn run(a: FiguresArgs) -> Result<(), Box<dyn std::error::Error>> {
    if a.list {
        for g in GROUPS {
            println!(
                "{:<20} {}{}",
                g.name,
                g.command,
                if g.in_ci { "  [in CI]" } else { "" }
            );
        }
        return Ok(());
    }
    let names: Vec<String> = if a.ci {
        GROUPS
            .iter()
            .filter(|g| g.in_ci)
            .map(|g| g.name.to_string())
            .collect()
    } else {
        a.only.clone()
    };
    let ctx = Context {
        root: std::env::current_dir()?,
        crs: std::env::current_exe()?,
        scratch: a.scratch.clone(),
    };
    let file = regenerate(&ctx, &names)?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&a.out, serde_json::to_string_pretty(&file)? + "\n")?;
    let n: usize = file.groups.values().map(|g| g.figures.len()).sum();
    println!(
        "wrote {n} figures of {} groups to {}",
        file.groups.len(),
        a.out.display()
    );
    Ok(())
}
