//! `crs-fuzz [--target NAME]... [--cases N] [--seed S] [--out DIR]`: mutation fuzzing of the
//! stack's decoders and loaders (see the crate docs). Exit code 1 if any target panicked,
//! rejected without naming a line/key, or violated its property; reproducers go to DIR.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(about = "Mutation fuzzing of every decoder and loader of the CRS stack")]
struct Args {
    /// Targets to run (default: all). `--list` shows them.
    #[arg(long)]
    target: Vec<String>,
    /// Cases per target.
    #[arg(long, default_value_t = 100_000)]
    cases: u64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where reproducers and scratch files go.
    #[arg(long, default_value = "out/fuzz")]
    out: PathBuf,
    /// List the targets and exit.
    #[arg(long)]
    list: bool,
}

fn main() -> ExitCode {
    let a = Args::parse();
    let all = crs_fuzz::targets::all();
    if a.list {
        for t in &all {
            println!("{:<22} {}", t.name, t.what);
        }
        return ExitCode::SUCCESS;
    }
    for n in &a.target {
        if !all.iter().any(|t| t.name == n) {
            eprintln!("unknown target `{n}` (see --list)");
            return ExitCode::from(2);
        }
    }
    if let Err(e) = std::fs::create_dir_all(&a.out) {
        eprintln!("{}: {e}", a.out.display());
        return ExitCode::from(2);
    }
    crs_fuzz::quiet_panics();
    println!(
        "| target | cases | accepted | rejected | panics | rejections without line/key | property violations | time (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut failed = false;
    for t in all
        .iter()
        .filter(|t| a.target.is_empty() || a.target.iter().any(|n| n == t.name))
    {
        let st = crs_fuzz::run(t, a.cases, a.seed, &a.out.join("scratch"));
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.1} |",
            t.name,
            st.cases,
            st.accepted,
            st.rejected,
            st.panics,
            st.unlocated,
            st.violations,
            st.seconds
        );
        for (k, (what, input)) in st.failures.iter().enumerate() {
            let p = a.out.join(format!("{}-{k}.bin", t.name));
            let _ = std::fs::write(&p, input);
            eprintln!("  {}: {what} (input: {})", t.name, p.display());
        }
        failed |= st.failed();
    }
    if failed {
        eprintln!("FUZZ: FAIL");
        ExitCode::FAILURE
    } else {
        println!("FUZZ: PASS");
        ExitCode::SUCCESS
    }
}
