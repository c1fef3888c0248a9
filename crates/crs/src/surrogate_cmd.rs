//! `crs surrogate …`: offline fit of the polynomial surrogate of the elastostatic force control
//! (sec. 5.6, eq. 5.23–5.27), its file check, and its evaluation on the simulated plant.

use cdpr_model::config::{Platform, load_platform};
use cdpr_model::offset_target::{OffsetTarget, region_box};
use cdpr_model::{Data, Pose, kinematics};
use sim_plant::{Plant, load_plant};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use surrogate::{Basis, FitOptions, Region, Surrogate, fit};

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

/// The fit of `crs surrogate fit`: target q_off from [`OffsetTarget`] over the platform region.
pub fn fit_platform(
    pf: &Platform,
    opts: &FitOptions,
) -> Result<(Surrogate, surrogate::FitReport), BoxErr> {
    let m = pf.model.m();
    let (lower, upper) = region_box(&pf.region);
    let region = Region { lower, upper };
    let mut target = OffsetTarget::new(&pf.model);
    let r = fit(
        &region,
        opts,
        m,
        &pf.model.identity_hex(),
        |x: &[f64; 6]| {
            let mut out = vec![0.0; m];
            target.offset(&Pose::from_array(*x), &mut out).map(|_| out)
        },
    )?;
    Ok(r)
}

/// One controller's tracking on the plant over the evaluation grid.
#[derive(Clone, Debug, Default, serde::Serialize)]
struct Tracking {
    /// Per evaluated pose (same order for both controllers): max_i |f̂_i − f_ref,i| (N),
    /// position error (mm), orientation error (deg); NaN where the plant did not settle.
    force_error_n: Vec<f64>,
    position_error_mm: Vec<f64>,
    orientation_error_deg: Vec<f64>,
    /// Wrench-feasible poses where the plant's forces stayed in [f_min, f_max] (eq. 3.33).
    reachable: usize,
    /// Poses where the plant found no equilibrium.
    failed: usize,
}

#[derive(Debug, serde::Serialize)]
struct Evaluation {
    platform: String,
    plant: String,
    poses: usize,
    wrench_feasible: usize,
    kinematic: Tracking,
    surrogate: Tracking,
}

/// Commands the plant over a grid in the platform region with (a) kinematics + set-up offsets
/// (eq. 3.14/6.24) and (b) kinematics + surrogate (eq. 5.26) + set-up offsets; compares to
/// f_ref (eq. 3.41). The kinematic controller's force error is mostly the level of its set-up
/// tension f_ini (eq. 6.22) propagated through the workspace (ch. 3.4): it has no force goal.
fn evaluate(
    pf: &Platform,
    sg: &Surrogate,
    plant_path: &Path,
    grid: usize,
) -> Result<Evaluation, BoxErr> {
    if !(2..=25).contains(&grid) {
        return Err(format!("--grid must lie in 2..=25, got {grid}").into());
    }
    let cfg = load_plant(plant_path)?;
    let plant_name = cfg.name.clone();
    let m = pf.model.m();
    if cfg.platform.model.m() != m {
        return Err(format!(
            "plant {} has {} cables, platform {} has {m}",
            plant_path.display(),
            cfg.platform.model.m(),
            pf.name
        )
        .into());
    }
    let f_ini = pf.f_ini.clone().ok_or_else(|| {
        format!(
            "platform `{}` has no [home] f_ini_n: the kinematic controller needs the initial tension (eq. 6.22)",
            pf.name
        )
    })?;
    let mut plant = Plant::new(cfg)?;
    let (lo, hi) = region_box(&pf.region);
    let mut poses = Vec::new();
    let at = |d: usize, k: usize, n: usize| lo[d] + (hi[d] - lo[d]) * k as f64 / (n - 1) as f64;
    let rot = |d: usize, k: usize| match k {
        0 => lo[d],
        1 => 0.0f64.clamp(lo[d], hi[d]),
        _ => hi[d],
    };
    for iz in 0..grid {
        for iy in 0..grid {
            for ix in 0..grid {
                for r in 0..27 {
                    poses.push(Pose::from_array([
                        at(0, ix, grid),
                        at(1, iy, grid),
                        at(2, iz, grid),
                        rot(3, r % 3),
                        rot(4, (r / 3) % 3),
                        rot(5, r / 9),
                    ]));
                }
            }
        }
    }
    let mut target = OffsetTarget::new(&pf.model);
    let mut f_ref = Vec::with_capacity(poses.len());
    let mut feasible = Vec::with_capacity(poses.len());
    for x in &poses {
        let (f, fd) = target.reference_forces(x)?;
        f_ref.push(f.to_vec());
        feasible.push(fd.feasible);
    }
    let p = pf.model.params();
    let mut data = Data::new(&pf.model);
    let mut run = |use_surrogate: bool| -> Result<Tracking, BoxErr> {
        // Set-up at home (sec. 6.1, eq. 3.14/6.24): the operator tensions the cables at the home
        // pose and zeroes the cable offsets there. The kinematic controller is set up with the
        // spec's initial tension f_ini (eq. 6.22); the surrogate controller with its own
        // reference f_ref(home) (eq. 3.41), so the offsets c only absorb what the control model
        // does not know (encoder offsets, drive-train length): c = q_setup − (φ + φ_sg)(home).
        let f_setup: Vec<f64> = if use_surrogate {
            target.reference_forces(&pf.home)?.0.to_vec()
        } else {
            f_ini.clone()
        };
        let setup = plant.setup_tension(&pf.home, &f_setup)?;
        kinematics::inverse(&pf.model, &mut data, &pf.home)?;
        let mut sg_home = vec![0.0; m];
        if use_surrogate {
            sg.eval(&pf.home.to_array(), &mut sg_home)
                .map_err(|e| format!("surrogate: {e}"))?;
        }
        let q_setup: Vec<f64> = (0..m)
            .map(|i| setup.q_cmd[i] - data.q[i] - sg_home[i])
            .collect();
        plant.step(&setup.q_cmd)?;
        let mut last_pose = pf.home;
        let mut t = Tracking::default();
        let mut q = vec![0.0; m];
        let mut qs = vec![0.0; m];
        let mut off = vec![0.0; m];
        let mut command = |x: &Pose, q: &mut [f64]| -> Result<(), BoxErr> {
            kinematics::inverse(&pf.model, &mut data, x)?;
            if use_surrogate {
                sg.eval(&x.to_array(), &mut off)
                    .map_err(|e| format!("surrogate: {e}"))?;
            } else {
                off.fill(0.0);
            }
            for i in 0..m {
                q[i] = data.q[i] + off[i] + q_setup[i];
            }
            Ok(())
        };
        for (k, x) in poses.iter().enumerate() {
            command(x, &mut q)?;
            let before = plant.state();
            // Move there as the robot would: along the straight pose path from the last
            // settled pose in sub-steps of ≤ 50 mm and ≤ 1°, each commanded by the same
            // controller, so the plant's equilibrium search starts close (continuation).
            let a = last_pose.to_array();
            let b = x.to_array();
            let dp = (0..3).map(|d| (b[d] - a[d]).abs()).fold(0.0, f64::max);
            let dr = (3..6).map(|d| (b[d] - a[d]).abs()).fold(0.0, f64::max);
            let n_sub = ((dp / 0.05).max(dr / 1f64.to_radians()).ceil() as usize).max(1);
            let mut result = Err(sim_plant::PlantError::WrongLength {
                expected: m,
                got: 0,
            });
            for s in 1..=n_sub {
                let w = s as f64 / n_sub as f64;
                let mut xs = [0.0; 6];
                for d in 0..6 {
                    xs[d] = a[d] + w * (b[d] - a[d]);
                }
                command(&Pose::from_array(xs), &mut qs)?;
                result = plant.step(&qs);
                if result.is_err() {
                    break;
                }
            }
            match result {
                Ok(eq) => {
                    last_pose = *x;
                    let (dp, dr) = eq.pose.error_to(x);
                    let fe = eq
                        .forces
                        .iter()
                        .zip(&f_ref[k])
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f64::max);
                    t.force_error_n.push(fe);
                    t.position_error_mm.push(dp * 1e3);
                    t.orientation_error_deg.push(dr.to_degrees());
                    let ok = eq.forces.iter().all(|f| *f >= p.f_min && *f <= p.f_max);
                    if feasible[k] && ok {
                        t.reachable += 1;
                    }
                }
                Err(e) => {
                    if std::env::var_os("CRS_DEBUG_PLANT").is_some() {
                        eprintln!("pose {k} {:?}: {e}", x.to_array());
                    }
                    plant.restore(&before);
                    t.failed += 1;
                    t.force_error_n.push(f64::NAN);
                    t.position_error_mm.push(f64::NAN);
                    t.orientation_error_deg.push(f64::NAN);
                }
            }
        }
        Ok(t)
    };
    let kinematic = run(false)?;
    let surrogate = run(true)?;
    Ok(Evaluation {
        platform: pf.name.clone(),
        plant: plant_name,
        poses: poses.len(),
        wrench_feasible: feasible.iter().filter(|f| **f).count(),
        kinematic,
        surrogate,
    })
}

fn stats(v: &[f64]) -> (f64, f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    s.sort_by(f64::total_cmp);
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let p95 = s[((s.len() - 1) as f64 * 0.95).round() as usize];
    (mean, p95, *s.last().unwrap_or(&f64::NAN))
}

fn write_report(
    ev: &Evaluation,
    dir: &Path,
    fit: Option<&surrogate::FitReport>,
) -> Result<(), BoxErr> {
    std::fs::create_dir_all(dir)?;
    let mut md = String::new();
    writeln!(
        md,
        "Surrogate evaluation on plant `{}` (platform `{}`): {} poses, {} wrench feasible (eq. 3.29/3.41)\n",
        ev.plant, ev.platform, ev.poses, ev.wrench_feasible
    )?;
    if let Some(r) = fit {
        writeln!(
            md,
            "Fit: degree {}, {} coefficients/cable, condition {:.2}; error vs full model max {:.4} mm, mean {:.4} mm; max |φ_sg| {:.2} mm\n",
            r.degree,
            r.n_coeffs_per_cable,
            r.condition_number,
            r.max_fit_error_mm,
            r.mean_fit_error_mm,
            r.max_abs_offset_mm
        )?;
    }
    writeln!(
        md,
        "| controller | force error mean / p95 / max (N) | position error mean / max (mm) | orientation error mean / max (deg) | reachable (eq. 3.33) | no equilibrium |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    for (name, t) in [
        (
            "kinematics, set up with f_ini (eq. 3.14, 6.22)",
            &ev.kinematic,
        ),
        (
            "kinematics + surrogate (eq. 5.26), set up with f_ref(home)",
            &ev.surrogate,
        ),
    ] {
        let f = stats(&t.force_error_n);
        let p = stats(&t.position_error_mm);
        let o = stats(&t.orientation_error_deg);
        let pct = if ev.wrench_feasible > 0 {
            100.0 * t.reachable as f64 / ev.wrench_feasible as f64
        } else {
            f64::NAN
        };
        writeln!(
            md,
            "| {name} | {:.0} / {:.0} / {:.0} | {:.3} / {:.3} | {:.4} / {:.4} | {} of {} ({pct:.1} %) | {} |",
            f.0, f.1, f.2, p.0, p.2, o.0, o.2, t.reachable, ev.wrench_feasible, t.failed
        )?;
    }
    print!("\n{md}");
    std::fs::write(dir.join("report.md"), &md)?;
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(ev)?)?;
    let svg = dir.join("tracking.svg");
    plot(ev, &svg).map_err(|e| format!("{}: {e}", svg.display()))?;
    println!(
        "wrote {}, {} and {}",
        dir.join("report.md").display(),
        dir.join("report.json").display(),
        svg.display()
    );
    Ok(())
}

/// Two panels: sorted force error and sorted position error of both controllers.
fn plot(ev: &Evaluation, path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    let series = |v: &[f64]| {
        let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        s.sort_by(f64::total_cmp);
        s
    };
    for (area, (title, unit, kin, sg)) in panels.iter().zip([
        (
            "max cable force error |f̂ − f_ref|",
            "N",
            series(&ev.kinematic.force_error_n),
            series(&ev.surrogate.force_error_n),
        ),
        (
            "position error |r̂ − r|",
            "mm",
            series(&ev.kinematic.position_error_mm),
            series(&ev.surrogate.position_error_mm),
        ),
    ]) {
        let n = kin.len().max(sg.len()).max(2);
        let y_max = kin
            .iter()
            .chain(sg.iter())
            .copied()
            .fold(0.0f64, f64::max)
            .max(1e-9)
            * 1.05;
        let mut chart = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..100f64, 0f64..y_max)?;
        chart
            .configure_mesh()
            .x_desc("poses, sorted (%)")
            .y_desc(unit)
            .draw()?;
        let line = |s: &[f64]| {
            let len = s.len().max(2) as f64 - 1.0;
            s.iter()
                .enumerate()
                .map(move |(i, v)| (100.0 * i as f64 / len, *v))
                .collect::<Vec<_>>()
        };
        let _ = n;
        chart
            .draw_series(LineSeries::new(line(&kin), RED.stroke_width(2)))?
            .label("kinematics + set-up offsets")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RED));
        chart
            .draw_series(LineSeries::new(line(&sg), BLUE.stroke_width(2)))?
            .label("kinematics + surrogate")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLUE));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
