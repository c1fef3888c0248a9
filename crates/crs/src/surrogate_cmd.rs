//! `crs surrogate …`: offline fit of the polynomial surrogate of the elastostatic force control
//! (sec. 5.6, eq. 5.23–5.27), its file check, and its evaluation on the simulated plant.

use cdpr_model::config::load_platform;
use plant_experiments::surrogate_evaluation::{evaluate, fit_and_save, load_for_platform};
use stack_reports::surrogate_report;
use std::path::PathBuf;
use surrogate::{Basis, FitOptions};

#[derive(clap::Subcommand, Debug)]
pub enum SurrogateCommand {
    /// Fit φ_sg to q_off(x) = φ_el(x, f_ref(x)) − φ(x) over the platform's operating region,
    /// prove |φ_sg| < 100 mm (eq. 5.27) with margin, write the file; with --plant also
    /// evaluate it on the simulated plant against the plain kinematic controller.
    Fit(FitArgs),
    /// Load a surrogate file as the daemon does (format, checksum, platform identity, bound).
    Check {
        #[arg(long)]
        file: PathBuf,
        /// Platform TOML the file must belong to.
        #[arg(long, default_value = "config/crs-nominal.toml")]
        platform: PathBuf,
    },
    /// Evaluate an existing surrogate on the plant (kinematics + surrogate vs kinematics alone).
    Evaluate(EvaluateArgs),
}

#[derive(clap::Args, Debug)]
pub struct EvaluateArgs {
    #[arg(long)]
    file: PathBuf,
    #[arg(long, default_value = "config/crs-nominal.toml")]
    platform: PathBuf,
    #[arg(long, default_value = "config/plant/crs-ideal.toml")]
    plant: PathBuf,
    #[arg(long, default_value_t = 5)]
    grid: usize,
    #[arg(long, default_value = "out/surrogate-report")]
    report_dir: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Platform TOML with the elastostatic model (nominal or identified).
    #[arg(long, default_value = "config/crs-nominal.toml")]
    platform: PathBuf,
    /// Total polynomial degree (84 coefficients per cable at 3).
    #[arg(long, default_value_t = 3)]
    degree: usize,
    /// Basis family: legendre or monomial.
    #[arg(long, default_value = "legendre")]
    basis: String,
    /// Ridge (Tikhonov) parameter of the column-scaled least squares.
    #[arg(long, default_value_t = 0.0)]
    ridge: f64,
    /// Fit samples (Halton); default 6 × coefficients.
    #[arg(long)]
    fit_samples: Option<usize>,
    /// Validation samples (Halton) in addition to the 3^6 grid.
    #[arg(long, default_value_t = 10_000)]
    validation_samples: usize,
    /// Margin below the 100 mm bound the fit must keep, mm.
    #[arg(long, default_value_t = 10.0)]
    margin_mm: f64,
    /// Also require the certified all-pose bound Σ|c| < bound − margin.
    #[arg(long)]
    require_certified_bound: bool,
    /// Output surrogate file.
    #[arg(long, default_value = "out/surrogate.json")]
    out: PathBuf,
    /// Plant TOML to evaluate on (e.g. config/plant/crs-ideal.toml); none = skip.
    #[arg(long)]
    plant: Option<PathBuf>,
    /// Evaluation grid: points per position axis (rotations at min/0/max per axis).
    #[arg(long, default_value_t = 5)]
    grid: usize,
    /// Directory for report.md, report.json and the SVG plot.
    #[arg(long, default_value = "out/surrogate-report")]
    report_dir: PathBuf,
}

type BoxErr = Box<dyn std::error::Error>;

pub fn run(cmd: SurrogateCommand) -> Result<(), BoxErr> {
    match cmd {
        SurrogateCommand::Fit(a) => fit(a),
        SurrogateCommand::Check { file, platform } => {
            let (pf, sg) = load_for_platform(&file, &platform)?;
            let r = sg.report();
            println!(
                "{}: ok — platform `{}`, {} cables, degree {}, max |φ_sg| {:.2} mm, certified {:.2} mm, fit error max {:.4} mm",
                file.display(),
                pf.name,
                sg.n_cables(),
                r.degree,
                r.max_abs_offset_mm,
                r.certified_bound_mm,
                r.max_fit_error_mm
            );
            Ok(())
        }
        SurrogateCommand::Evaluate(a) => {
            let (pf, sg) = load_for_platform(&a.file, &a.platform)?;
            let ev = evaluate(&pf, &sg, &a.plant, a.grid)?;
            print!(
                "{}",
                surrogate_report::write(&ev, &a.report_dir, Some(sg.report()))?
            );
            Ok(())
        }
    }
}

fn fit(a: FitArgs) -> Result<(), BoxErr> {
    let pf = load_platform(&a.platform)?;
    let basis = match a.basis.as_str() {
        "legendre" => Basis::Legendre,
        "monomial" => Basis::Monomial,
        other => {
            return Err(
                format!("--basis: expected `legendre` or `monomial`, got `{other}`").into(),
            );
        }
    };
    if !(a.margin_mm.is_finite() && a.margin_mm >= 0.0) {
        return Err(format!(
            "--margin-mm must be a finite value ≥ 0, got {}",
            a.margin_mm
        )
        .into());
    }
    let opts = FitOptions {
        degree: a.degree,
        basis,
        fit_samples: a.fit_samples,
        validation_samples: a.validation_samples,
        ridge: a.ridge,
        margin_m: a.margin_mm * 1e-3,
        require_certified_bound: a.require_certified_bound,
        ..FitOptions::default()
    };
    let fitted = fit_and_save(&pf, &opts, &a.out)?;
    print!("{fitted}");
    if let Some(plant) = &a.plant {
        let ev = evaluate(&pf, &fitted.surrogate, plant, a.grid)?;
        print!(
            "{}",
            surrogate_report::write(&ev, &a.report_dir, Some(&fitted.report))?
        );
    }
    Ok(())
}
