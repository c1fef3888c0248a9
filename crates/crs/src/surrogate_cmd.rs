//! `crs surrogate …`: offline fit of the polynomial surrogate of the elastostatic force control
//! (sec. 5.6, eq. 5.23–5.27), its file check, and its evaluation on the simulated plant.

use cdpr_model::config::load_platform;
pub use crs_stack::surrogate_evaluation::fit_platform;
use crs_stack::surrogate_evaluation::{Evaluation, evaluate};
use crs_stack::surrogate_report;
use std::path::{Path, PathBuf};
use surrogate::{Basis, FitOptions, Surrogate};

#[derive(clap::Subcommand, Debug)]
pub enum SurrogateCommand {
    /// Fit φ_sg to q_off(x) = φ_el(x, f_ref(x)) − φ(x) over the platform's operating region,
    /// prove |φ_sg| < 100 mm (eq. 5.27) with margin, write the file; with --plant also
    /// evaluate it on the simulated plant against the plain kinematic controller.
    Fit {
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
    },
    /// Load a surrogate file as the daemon does (format, checksum, platform identity, bound).
    Check {
        #[arg(long)]
        file: PathBuf,
        /// Platform TOML the file must belong to.
        #[arg(long, default_value = "config/crs-nominal.toml")]
        platform: PathBuf,
    },
    /// Evaluate an existing surrogate on the plant (kinematics + surrogate vs kinematics alone).
    Evaluate {
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
    },
}

type BoxErr = Box<dyn std::error::Error>;

pub fn run(cmd: SurrogateCommand) -> Result<(), BoxErr> {
    match cmd {
        SurrogateCommand::Fit {
            platform,
            degree,
            basis,
            ridge,
            fit_samples,
            validation_samples,
            margin_mm,
            require_certified_bound,
            out,
            plant,
            grid,
            report_dir,
        } => {
            let pf = load_platform(&platform)?;
            let basis = match basis.as_str() {
                "legendre" => Basis::Legendre,
                "monomial" => Basis::Monomial,
                other => {
                    return Err(format!(
                        "--basis: expected `legendre` or `monomial`, got `{other}`"
                    )
                    .into());
                }
            };
            if !(margin_mm.is_finite() && margin_mm >= 0.0) {
                return Err(
                    format!("--margin-mm must be a finite value ≥ 0, got {margin_mm}").into(),
                );
            }
            let opts = FitOptions {
                degree,
                basis,
                fit_samples,
                validation_samples,
                ridge,
                margin_m: margin_mm * 1e-3,
                require_certified_bound,
                ..FitOptions::default()
            };
            let t0 = std::time::Instant::now();
            let (sg, report) = fit_platform(&pf, &opts)?;
            let dt = t0.elapsed().as_secs_f64();
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)?;
            }
            sg.save(&out)
                .map_err(|e| format!("{}: {e}", out.display()))?;
            println!(
                "fitted `{}` ({} cables) over its operating region in {dt:.2} s",
                pf.name,
                pf.model.m()
            );
            println!(
                "  degree {}, {} coefficients/cable, {} fit / {} validation samples, condition {:.2}",
                report.degree,
                report.n_coeffs_per_cable,
                report.n_fit_samples,
                report.n_validation_samples,
                report.condition_number
            );
            println!(
                "  fit error vs the full model: max {:.4} mm, mean {:.4} mm",
                report.max_fit_error_mm, report.mean_fit_error_mm
            );
            println!(
                "  max |φ_sg| {:.2} mm (sampled), certified Σ|c| {:.2} mm < bound {:.0} mm − margin {:.0} mm (eq. 5.27)",
                report.max_abs_offset_mm,
                report.certified_bound_mm,
                report.bound_mm,
                report.margin_mm
            );
            println!("wrote {}", out.display());
            if let Some(plant) = plant {
                let ev = evaluate(&pf, &sg, &plant, grid)?;
                write_report(&ev, &report_dir, Some(&report))?;
            }
            Ok(())
        }
        SurrogateCommand::Check { file, platform } => {
            let pf = load_platform(&platform)?;
            let sg = Surrogate::load(&file, &pf.model.identity_hex())
                .map_err(|e| format!("{}: {e}", file.display()))?;
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
        SurrogateCommand::Evaluate {
            file,
            platform,
            plant,
            grid,
            report_dir,
        } => {
            let pf = load_platform(&platform)?;
            let sg = Surrogate::load(&file, &pf.model.identity_hex())
                .map_err(|e| format!("{}: {e}", file.display()))?;
            let ev = evaluate(&pf, &sg, &plant, grid)?;
            let report = sg.report().clone();
            write_report(&ev, &report_dir, Some(&report))
        }
    }
}

fn write_report(
    ev: &Evaluation,
    dir: &Path,
    fit: Option<&surrogate::FitReport>,
) -> Result<(), BoxErr> {
    let w = surrogate_report::write(ev, dir, fit)?;
    print!("\n{}", w.markdown);
    let names: Vec<String> = w.files.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    Ok(())
}
