//! The calibration report: Markdown, JSON, SVG plots, and the identified model as a platform
//! TOML (same schema as config/*.toml, loadable by `cdpr_model::config::load_platform`) plus
//! a side file for the effects the platform schema cannot express.

use crate::effects::Effect;
use crate::pipeline::{PipelineReport, Stage};
use calibrate::params::{CalModel, ParamId};
use calibrate::residual::Kind;
use calibrate::validate;
use cdpr_model::ModelError;
use cdpr_model::config::Platform;
use crs_plot::{BarSeries, Bars, Chart, Figure, Markers, Panel, Rgb};
use std::fmt::Write as _;

/// A figure that may not have been computed (a screening fit has no condition numbers).
fn finite_or_dash(v: f64, f: impl Fn(f64) -> String) -> String {
    if v.is_finite() { f(v) } else { "–".into() }
}

fn fmt_opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("–".into(), |x| format!("{x:.prec$}"))
}

/// The 1σ of free parameter `k` of a fit, or why there is none (never NaN or ±0).
pub fn std_text(f: &calibrate::identify::Fit, k: usize) -> String {
    let p = f.free[k];
    if f.at_bound.contains(&p) {
        "at physical bound".into()
    } else if f.unidentifiable.contains(&p) || f.std[k].is_nan() || f.std[k] <= 0.0 {
        "unidentifiable".into()
    } else {
        format!("{:.2e}", f.std[k])
    }
}

fn name_list(ps: &[ParamId]) -> String {
    if ps.is_empty() {
        "none".into()
    } else {
        ps.iter().map(|p| p.name()).collect::<Vec<_>>().join(", ")
    }
}

/// The spec's comparison numbers (ch. 6.2–6.5), next to ours.
pub const SPEC_ROWS: [(&str, &str); 5] = [
    (
        "nominal kinematic",
        "39.80 mm, 1.19°, ε_q 23.52 mm (eq. 6.4–6.6)",
    ),
    (
        "optimal kinematic",
        "9.66 mm, 0.29°, ε_q 4.08 mm (sec. 6.2)",
    ),
    (
        "nominal elastostatic",
        "34.5 mm, 1.03°, 2426.84 N (eq. 6.25–6.26)",
    ),
    (
        "optimal elastostatic",
        "2.73 mm, 0.11°, 582 N (sec. 6.5, 7.1)",
    ),
    ("+ effects", "– (beyond the spec)"),
];

/// Table of the stages in the spec's form.
pub fn stage_table(rep: &PipelineReport) -> String {
    let mut s = String::new();
    s.push_str("| step | model | mean / max position error (mm) | mean / max rotation error (deg) | mean cable-length error (mm) | mean / max force error ‖f_P − f_M‖ (N) | spec |\n");
    s.push_str("|---|---|---|---|---|---|---|\n");
    for (k, st) in rep.stages.iter().enumerate() {
        let spec = SPEC_ROWS
            .iter()
            .find(|(n, _)| *n == st.name)
            .map_or(SPEC_ROWS[4].1, |(_, v)| *v);
        let h = &st.holdout;
        // A step whose FK failed anywhere prints no figure: its statistics would describe a
        // subset (or nothing) and read as a result.
        if let Some(fail) = h.failure_text() {
            let _ = writeln!(
                s,
                "| {} | {} (**failed**) | {fail} | {fail} | {:.2} | {fail} | {} |",
                k + 1,
                st.name,
                h.len_mean_mm,
                spec
            );
            continue;
        }
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} / {:.2} | {:.3} / {:.3} | {:.2} | {} / {} | {} |",
            k + 1,
            st.name,
            h.pos_mean_mm,
            h.pos_max_mm,
            h.rot_mean_deg,
            h.rot_max_deg,
            h.len_mean_mm,
            fmt_opt(h.force_mean_n, 1),
            fmt_opt(h.force_max_n, 1),
            spec
        );
    }
    s
}

/// Markdown report.
pub fn markdown(rep: &PipelineReport, command: &str, plots: &[String]) -> String {
    let mut s = String::new();
    s.push_str("# Calibration report\n\n");
    let _ = writeln!(s, "Command: `{command}`\n");
    let _ = writeln!(
        s,
        "Training samples: {}; held-out samples: {} (every figure below is on the held-out samples, computed through the model's forward kinematics, eq. 3.3–3.8).\n",
        rep.n_train, rep.n_holdout
    );
    let failed = rep.failed_stages();
    if !failed.is_empty() {
        s.push_str("## Failures\n\n");
        for (name, text) in &failed {
            let _ = writeln!(
                s,
                "* **{name}: failed** — {text} held-out samples; its errors are not reported."
            );
        }
        match rep.last_validated_stage() {
            Some(st) if rep.final_stage().failed() => {
                let _ = writeln!(
                    s,
                    "\nThe final step failed; the last validated step is **{}**.\n",
                    st.name
                );
            }
            None => s.push_str("\nNo step validated.\n\n"),
            _ => s.push('\n'),
        }
    }
    s.push_str("## Errors per step (held out)\n\n");
    s.push_str(&stage_table(rep));
    s.push_str("\n## Identification\n\n| step | parameters | residual rows | iterations | cond(J) SI (tab. 4.3 d) | cond(J W_pc) start (tab. 4.3 e) | cond(J W_pc) end | RMS wrench (N) | RMS length (mm) | fixed (unobservable) | unidentifiable (no finite 1σ) | at physical bound |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for st in &rep.stages {
        if let Some(f) = &st.fit {
            let fixed: Vec<String> = f.fixed_unobservable.iter().map(|(p, _)| p.name()).collect();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {:.3} | {} | {} | {} |",
                st.name,
                f.free.len(),
                f.n_residuals,
                f.iterations,
                finite_or_dash(f.cond_start_unscaled, |v| format!("{v:.3e}")),
                finite_or_dash(f.cond_start_scaled, |v| format!("{v:.1}")),
                finite_or_dash(f.cond_end_scaled, |v| format!("{v:.1}")),
                f.rms_wrench,
                f.rms_length * 1e3,
                if fixed.is_empty() {
                    "none".into()
                } else {
                    fixed.join(", ")
                },
                name_list(&f.unidentifiable),
                name_list(&f.at_bound)
            );
        }
    }
    if rep.ridge_kf_sweep.is_empty() {
        if rep.ridge_kf > 0.0 {
            let _ = writeln!(
                s,
                "\nRidge on k_F towards the nominal (eq. 4.32): λ = {} (configured).",
                rep.ridge_kf
            );
        }
    } else {
        let _ = writeln!(
            s,
            "\nRidge on k_F towards the nominal (eq. 4.32), chosen on the held-out set (combined relative position + force error through the FK; a larger λ must pay by 1 %): **λ = {}**.\n\n| λ | held-out position (mm) | held-out force (N) |\n|---|---|---|",
            rep.ridge_kf
        );
        for p in &rep.ridge_kf_sweep {
            match &p.failure {
                Some(f) => {
                    let _ = writeln!(s, "| {} | {f} | {f} |", p.lambda);
                }
                None => {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {} |",
                        p.lambda,
                        fmt_opt(p.pos_mm, 2),
                        fmt_opt(p.force_n, 1)
                    );
                }
            }
        }
    }
    if let Some(sel) = &rep.selection {
        s.push_str("\n## Residual diagnosis and model extension\n\n");
        if sel.chosen.is_empty() {
            s.push_str("No candidate effect is supported by the data: the base elastostatic model is kept.\n\n");
        } else {
            let names: Vec<String> = sel
                .chosen
                .iter()
                .zip(&sel.forms)
                .map(|(e, f)| effect_label(*e, *f))
                .collect();
            let _ = writeln!(s, "Chosen effects, in order: **{}**.\n", names.join(", "));
            match &rep.all_samples {
                Some(all) => {
                    let _ = writeln!(
                        s,
                        "Sizes in the final estimate of the chosen model on all {} samples (training + held-out), made after the held-out set chose it; the held-out errors above are those of the fit on the {} training samples, whose sizes follow below it (±1σ from the fit's covariance; \"at bound\" where a parameter rests on its physical range and has no 1σ):\n",
                        all.samples, rep.n_train
                    );
                    sizes_table(&mut s, &all.sizes);
                    let _ = writeln!(
                        s,
                        "\nSizes in the fit on the {} training samples:\n",
                        rep.n_train
                    );
                }
                None => {
                    if let Some(e) = &rep.all_samples_failure {
                        let _ = writeln!(
                            s,
                            "The final estimate on all samples failed ({e}); the sizes are those of the fit on the training samples.\n"
                        );
                    }
                    s.push_str("Sizes in the final model (±1σ from the fit's covariance; \"at bound\" where a parameter rests on its physical range and has no 1σ):\n\n");
                }
            }
            sizes_table(&mut s, &sel.sizes);
            s.push('\n');
        }
        let c = &rep.config.select;
        let _ = writeln!(
            s,
            "A candidate is judged on what a user cares about: the held-out position and force errors through the model's forward kinematics. It is added when, in the channel where its effect must show (drum: position, or {:.0} % in force — refitting its eight per-cable scales on data without any effect moves the force by up to 31 % —, or {:.0} % in force with a significant score; force sensors: force; the others: either), the mean error drops by at least {:.0} % (position) or {:.0} % (force) with a paired z ≥ {:.2} over the held-out samples, neither error gets worse by more than {:.0} % (position) / {:.0} % (force), the FK converges on every held-out sample, and no parameter is pressed against a physical range limit away from zero. Among those that pass, the one whose signature explains the training rows best (largest BIC drop) is chosen, one per round; when none passes alone, the pairs of the candidates with a significant score are fitted together and a pair is added when it beats each of its members alone; when some pass, the best of them (and those refused only for a parameter at its range limit) are also fitted in pairs, and such a competing pair is ranked with the singles when each member is needed next to the other (likelihood ratio on the training rows above the χ²_k 0.999 value). Each candidate is fitted in each of its forms (the lowest BIC represents it) from its parameters at 0 with the base parameters free (a base parameter at its bound can leave it), and again from non-degenerate starts when its parameters do not move; a candidate whose parameters stay at 0 is said so, not given a gain. Thresholds from baseline data: docs/calibration.md.\n",
            c.min_gain_force_length * 100.0,
            c.min_gain_force * 100.0,
            c.min_gain_pos * 100.0,
            c.min_gain_force * 100.0,
            c.z_gain,
            c.max_loss_pos * 100.0,
            c.max_loss_force * 100.0
        );
        s.push_str("| round | effect (form) | k | score | χ² crit | held-out position (mm) before → after, FK | gain (paired z) | held-out force (N) before → after, FK | gain (paired z) | BIC before → after | fitted parameters (±1σ) | verdict |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for (r, round) in sel.rounds.iter().enumerate() {
            for c in round {
                let params: Vec<String> = c
                    .params
                    .iter()
                    .take(8)
                    .map(|(n, v, sd)| {
                        if sd.is_finite() && *sd > 0.0 {
                            format!("{n} = {v:.4e} ± {sd:.1e}")
                        } else {
                            format!("{n} = {v:.4e} (unidentifiable or at bound)")
                        }
                    })
                    .collect();
                // A candidate whose parameters stayed at 0 has no model of its own: no
                // "after" figures, never a 0.0 % gain.
                let unevaluated = !c.moved;
                let fk_after = |v: Option<f64>, prec: usize| match (&c.fk_failure, v) {
                    _ if unevaluated => "not fitted (see verdict)".to_string(),
                    (Some(t), _) => t.clone(),
                    (None, v) => fmt_opt(v, prec),
                };
                let gain = |g: Option<f64>, z: Option<f64>| match (g, z) {
                    _ if unevaluated => "–".into(),
                    (Some(g), Some(z)) => format!("{:+.1} % ({z:.1})", 100.0 * g),
                    _ => "–".into(),
                };
                let mut label = effect_label(c.effect, c.form);
                if let Some((e, f)) = c.pair {
                    label = format!("{label} + {}", effect_label(e, f));
                }
                let mut verdict = c.verdict.clone();
                if !c.freed.is_empty() {
                    let _ = write!(verdict, " (took {} off its bound)", c.freed.join(", "));
                }
                if c.start.starts_with("restart") {
                    let _ = write!(verdict, " (fitted from its {})", c.start);
                }
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {:.3e} | {:.1} | {} → {} | {} | {} → {} | {} | {:.1} → {:.1} | {} | {} |",
                    r + 1,
                    label,
                    c.n_params,
                    c.score,
                    c.score_critical,
                    fmt_opt(c.holdout_pos_mm_before, 2),
                    fk_after(c.holdout_pos_mm_after, 2),
                    gain(c.gain_pos, c.z_pos),
                    fmt_opt(c.holdout_force_n_before, 1),
                    fk_after(c.holdout_force_n_after, 1),
                    gain(c.gain_force, c.z_force),
                    c.bic_before,
                    c.bic_after,
                    params.join("; "),
                    verdict
                );
            }
        }
    }
    if let Some(st) = &rep.structure {
        structure_section(&mut s, st);
    }
    if let Some(e) = &rep.flexible_failure {
        let _ = writeln!(
            s,
            "\nThe flexible length correction (--flexible) could not be fitted: {e}.\n"
        );
    } else if rep.config.flexible {
        s.push_str("\nThe last step adds the **flexible per-cable length correction** (`--flexible`): δq_i = c_i0 u + c_i1 u² + c_i2 v + c_i3 v², u = f_i/f_s − 1, v = q_i/10 m, |c| ≤ 5 mm. It is fitted for accuracy, not as an explanation: it is **not a physical diagnosis**; its coefficients are in the side file.\n");
    }
    if let Some(r) = &rep.repeatability {
        repeatability_section(&mut s, r);
    }
    let fin = rep.final_stage();
    if let Some(f) = &fin.fit {
        s.push_str("\n## Parameter changes of the final model (nominal → identified, ±1σ)\n\n| parameter | nominal | identified | change | 1σ |\n|---|---|---|---|---|\n");
        let nominal = &rep.stages[0].model;
        for (k, p) in f.free.iter().enumerate() {
            let v0 = if p.is_base() && !matches!(p, ParamId::Offset(_)) {
                nominal.get(*p)
            } else {
                0.0
            };
            let v = f.model.get(*p);
            let _ = writeln!(
                s,
                "| {} | {:.6} | {:.6} | {:+.6} | {} |",
                p.name(),
                v0,
                v,
                v - v0,
                std_text(f, k)
            );
        }
    }
    if !plots.is_empty() {
        s.push_str("\n## Plots\n\n");
        for p in plots {
            let _ = writeln!(s, "![{p}]({p})\n");
        }
    }
    s
}

/// Why the identified platform cannot be written.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlatformTomlError {
    #[error("identified model: {0}")]
    Model(#[from] ModelError),
    #[error(transparent)]
    Write(#[from] cdpr_model::config_writer::WriteError),
}

/// The identified platform as platform TOML: `base` with the calibrated geometry, pulleys,
/// k_F, w_e and force limits of `cal`, named `name`. The text is written by the model crate's
/// writer ([`cdpr_model::config_writer::platform_toml`]), next to the reader the daemon uses.
pub fn platform_toml(
    base: &Platform,
    cal: &CalModel,
    name: &str,
) -> Result<String, PlatformTomlError> {
    // [dynamics] describes the same body whose weight [load] carries: the identified load
    // (eq. 6.23) moves its mass and the COG's x, y with it (the loader refuses the two when
    // they disagree); the COG height and the inertia's shape are not identified and stay,
    // the inertia scaled with the mass. An identified load that no point weight can produce
    // (a yaw torque, horizontal forces: eq. 6.23 has them) leaves no consistent [dynamics]:
    // it is then left out, and the header says so for the reviewer.
    let g = cdpr_model::dynamics::GRAVITY_M_PER_S2;
    let m_id = -cal.w_e[2] / g;
    let dynamics = base.dynamics.map(|d| {
        if m_id > 0.0 && d.mass_kg > 0.0 {
            cdpr_model::dynamics::RigidBody {
                mass_kg: m_id,
                cog_m: nalgebra::Vector3::new(
                    cal.w_e[4] / (m_id * g),
                    -cal.w_e[3] / (m_id * g),
                    d.cog_m.z,
                ),
                inertia_kg_m2: d.inertia_kg_m2 * (m_id / d.mass_kg),
            }
        } else {
            d
        }
    });
    let mut p = Platform {
        name: name.to_string(),
        description: format!("calibrated from {}", base.name),
        model: cal.model()?,
        dynamics,
        ..base.clone()
    };
    let identified = format!(
        "Identified by `crs calibrate` from {} (spec ch. 4).",
        base.name
    );
    let side =
        "Effects the platform schema cannot express are in the side file named in the report.";
    let text = cdpr_model::config_writer::platform_toml(&p, &[&identified, side])?;
    if p.dynamics.is_none() || cdpr_model::config::parse_platform(&text, name).is_ok() {
        return Ok(text);
    }
    p.dynamics = None;
    Ok(cdpr_model::config_writer::platform_toml(
        &p,
        &[
            &identified,
            side,
            "[dynamics] LEFT OUT: the identified load is not a pure weight (yaw torque or horizontal",
            "force), so no mass/COG agrees with it; set [dynamics] after review (docs/ride-physics.md).",
        ],
    )?)
}

/// The chosen effects' sizes as a table (each parameter ±1σ, a drum's RMS, a force band's
/// length equivalent).
fn sizes_table(s: &mut String, sizes: &[crate::effects::EffectSize]) {
    s.push_str("| effect | parameter | value | ±1σ |\n|---|---|---|---|\n");
    for size in sizes {
        for (n, v, sd) in &size.params {
            let _ = writeln!(
                s,
                "| {} | {n} | {v:.4e} | {} |",
                effect_label(size.effect, size.form),
                if sd.is_finite() && *sd > 0.0 {
                    format!("{sd:.2e}")
                } else {
                    "at bound or unidentifiable".into()
                }
            );
        }
        if let Some(r) = size.rms {
            let _ = writeln!(
                s,
                "| {} | size: RMS over the cables (noise bias taken off; plain RMS {:.3} ‰) | {:.3} ‰ | {:.3} ‰ |",
                effect_label(size.effect, size.form),
                r.raw * 1e3,
                r.value * 1e3,
                r.sigma * 1e3
            );
        }
        if let Some((h, sd)) = size.length_equivalent {
            let _ = writeln!(
                s,
                "| {} | ≙ length offset h (H × mean compliance of the samples fitted) | {:.3} mm | {:.3} mm |",
                effect_label(size.effect, size.form),
                h * 1e3,
                sd * 1e3
            );
        }
    }
}

/// An effect with its form, e.g. "hysteresis (±h length offset, direction from the command
/// sequence)".
pub fn effect_label(e: Effect, f: crate::effects::Form) -> String {
    if f.describe().is_empty() {
        e.name().to_string()
    } else {
        format!("{} ({})", e.name(), f.describe())
    }
}

/// Side file (TOML) with the cable offsets and every extension parameter of the model.
pub fn side_file(cal: &CalModel, chosen: &[Effect]) -> String {
    let mut s = String::new();
    s.push_str("# Calibration quantities the platform schema cannot express (crates/calibrate).\n");
    s.push_str(
        "# q_theta = (1 + drum_scale_i) q_cmd + cable_offset_i (m); see docs/calibration.md.\n\n",
    );
    let names: Vec<String> = chosen.iter().map(|e| format!("{:?}", e.name())).collect();
    let _ = writeln!(s, "effects = [{}]", names.join(", "));
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(s, "cable_offset_m = [{}]", list(&cal.offset));
    let _ = writeln!(s, "drum_scale = [{}]", list(&cal.drum_scale));
    let _ = writeln!(s, "extra_length_m = [{}]", list(&cal.extra_length));
    let _ = writeln!(s, "stiffness_kappa = {:?}", cal.stiffness_kappa);
    let _ = writeln!(
        s,
        "stiffness_reference_force_n = {:?}",
        calibrate::params::STIFFNESS_REFERENCE_FORCE_N
    );
    let _ = writeln!(s, "hysteresis_half_width_n = {:?}", cal.hysteresis);
    let _ = writeln!(s, "hysteresis_length_m = {:?}", cal.hysteresis_length);
    let _ = writeln!(
        s,
        "hysteresis_direction = {:?}",
        match cal.hysteresis_source {
            calibrate::observation::DirectionSource::Force => "force change",
            calibrate::observation::DirectionSource::ForceBeyondNoise =>
                "force change beyond the noise",
            calibrate::observation::DirectionSource::Command => "command sequence (held)",
        }
    );
    let _ = writeln!(
        s,
        "drive_train_compliance_m_per_n = {:?}",
        cal.series_compliance
    );
    let _ = writeln!(s, "sag_weight_squared_n2_per_m2 = {:?}", cal.sag_w2);
    let _ = writeln!(
        s,
        "center_of_gravity_m = [{:?}, {:?}, {:?}]",
        cal.cog.x, cal.cog.y, cal.cog.z
    );
    if cal
        .flex
        .iter()
        .any(|c| *c != [0.0; calibrate::params::FLEX_TERMS])
    {
        s.push_str("\n# Flexible per-cable length correction (NOT a physical effect; --flexible):\n# delta_q_i = c_i0 u + c_i1 u^2 + c_i2 v + c_i3 v^2, u = f_i/5000 N - 1, v = q_i/10 m (m).\n");
        let rows: Vec<String> = cal
            .flex
            .iter()
            .map(|c| format!("[{:?}, {:?}, {:?}, {:?}]", c[0], c[1], c[2], c[3]))
            .collect();
        let _ = writeln!(s, "flexible_correction_m = [{}]", rows.join(", "));
    }
    s
}

// ----------------------------------------------------------------------------------------
// Plots, drawn with the plot layer (`crs-plot`).

const SIZE: (u32, u32) = (760, 400);

/// Grouped bar chart: `series` (name, colour, values per group).
pub fn bar_chart(
    title: &str,
    ylabel: &str,
    groups: &[String],
    series: &[(String, Rgb, Vec<f64>)],
) -> String {
    let bars = Bars {
        title: String::new(),
        y_label: ylabel.to_string(),
        groups: groups.to_vec(),
        series: series
            .iter()
            .map(|(label, color, values)| BarSeries {
                label: label.clone(),
                color: *color,
                values: values.clone(),
            })
            .collect(),
    };
    Figure::single(title, SIZE, Panel::Bars(bars)).render()
}

/// A named, coloured set of (x, y) points.
pub type PointSeries = (String, Rgb, Vec<(f64, f64)>);

/// Scatter of (x, y) point sets.
pub fn scatter(title: &str, xlabel: &str, ylabel: &str, series: &[PointSeries]) -> String {
    let mut c = Chart::new("", xlabel, ylabel);
    c.markers = series
        .iter()
        .map(|(label, color, pts)| Markers::new(label.as_str(), *color, pts.clone()))
        .collect();
    Figure::single(title, SIZE, Panel::Chart(c)).render()
}

const RED: Rgb = Rgb(214, 39, 40);
const BLUE: Rgb = Rgb(31, 119, 180);
const GREEN: Rgb = Rgb(44, 160, 44);
const ORANGE: Rgb = Rgb(255, 127, 14);

/// The report's plots: (file name, SVG text).
pub fn plots(rep: &PipelineReport, holdout: &[calibrate::Observation]) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let first: &Stage = &rep.stages[0];
    let last = rep.final_stage();
    let m = first.model.m();
    let cables: Vec<String> = (1..=m).map(|i| format!("cable {i}")).collect();
    let rms_per_cable = |st: &Stage| -> Vec<f64> {
        validate::length_errors(st.kind, &st.model, holdout)
            .iter()
            .map(|v| 1e3 * (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt())
            .collect()
    };
    let mut series = vec![(first.name.clone(), RED, rms_per_cable(first))];
    if let Some(e) = rep.stage("optimal elastostatic") {
        series.push((e.name.clone(), BLUE, rms_per_cable(e)));
    }
    if last.name != "optimal elastostatic" {
        series.push((last.name.clone(), GREEN, rms_per_cable(last)));
    }
    out.push((
        "residuals_per_cable.svg".into(),
        bar_chart(
            "Held-out cable-length residual per cable (RMS)",
            "mm",
            &cables,
            &series,
        ),
    ));
    // Error over the workspace: position error vs distance from the workspace centre.
    let mut sc = Vec::new();
    for (st, colour) in [(first, RED), (last, GREEN)] {
        let mut pts = Vec::new();
        for o in holdout {
            if let Ok(p) = validate::predict(st.kind, &st.model, o) {
                let (dp, _) = p.pose.error_to(&o.pose);
                pts.push((o.pose.r.x.hypot(o.pose.r.y), dp * 1e3));
            }
        }
        sc.push((st.name.clone(), colour, pts));
    }
    out.push((
        "error_over_workspace.svg".into(),
        scatter(
            "Held-out position error over the workspace",
            "horizontal distance from the centre (m)",
            "mm",
            &sc,
        ),
    ));
    // Steps: mean position error.
    // A failed step gets no bar (a bar of its partial mean would read as a result).
    let shown: Vec<(usize, &Stage)> = rep
        .stages
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.failed())
        .collect();
    let names: Vec<String> = shown
        .iter()
        .map(|(k, _)| format!("step {}", k + 1))
        .collect();
    let pos: Vec<f64> = shown.iter().map(|(_, s)| s.holdout.pos_mean_mm).collect();
    out.push((
        "steps.svg".into(),
        bar_chart(
            "Mean held-out position error per step",
            "mm",
            &names,
            &[("position".into(), BLUE, pos)],
        ),
    ));
    // Condition numbers.
    let fits: Vec<&Stage> = rep.stages.iter().filter(|s| s.fit.is_some()).collect();
    let labels: Vec<String> = fits
        .iter()
        .map(|s| s.name.chars().take(24).collect())
        .collect();
    let cu: Vec<f64> = fits
        .iter()
        .map(|s| {
            s.fit
                .as_ref()
                .map_or(0.0, |f| f.cond_start_unscaled.log10())
        })
        .collect();
    let cs: Vec<f64> = fits
        .iter()
        .map(|s| s.fit.as_ref().map_or(0.0, |f| f.cond_start_scaled.log10()))
        .collect();
    out.push((
        "condition.svg".into(),
        bar_chart(
            "log10 cond(J): SI units vs preconditioned (eq. 4.42)",
            "log10",
            &labels,
            &[("SI".into(), RED, cu), ("W_pc".into(), BLUE, cs)],
        ),
    ));
    // Parameter changes of the geometry with uncertainty.
    if let Some(f) = &last.fit {
        let mut pts = Vec::new();
        let mut sds = Vec::new();
        for (k, p) in f.free.iter().enumerate() {
            if matches!(p, ParamId::A(..) | ParamId::B(..)) {
                pts.push((
                    k as f64,
                    1e3 * (f.model.get(*p) - first.model.get(*p)).abs(),
                ));
                if f.std[k].is_finite() {
                    sds.push((k as f64, 1e3 * f.std[k]));
                }
            }
        }
        out.push((
            "parameter_changes.svg".into(),
            scatter(
                "|Δ geometry| (nominal → identified) and 1σ",
                "parameter index (a, b)",
                "mm",
                &[("|Δp|".into(), BLUE, pts), ("1σ".into(), ORANGE, sds)],
            ),
        ));
    }
    // Scores of the candidates (first round).
    if let Some(r0) = rep.selection.as_ref().and_then(|sel| sel.rounds.first()) {
        {
            let names: Vec<String> = r0
                .iter()
                .map(|c| match c.pair {
                    Some((e, _)) => format!("{}+{}", c.effect.name(), e.name()),
                    None => c.effect.name().to_string(),
                })
                .collect();
            // The chart shows reductions only: a worse error or one that could not be measured
            // (FK failed) is drawn as 0; the report's table has the signed values.
            let pct = |g: Option<f64>| g.map_or(0.0, |g| (100.0 * g).max(0.0));
            let pos: Vec<f64> = r0.iter().map(|c| pct(c.gain_pos)).collect();
            let force: Vec<f64> = r0.iter().map(|c| pct(c.gain_force)).collect();
            out.push((
                "candidates.svg".into(),
                bar_chart(
                    "Candidate effects, round 1: held-out error reduction through the FK (≤ 0 drawn as 0)",
                    "%",
                    &names,
                    &[
                        ("position".into(), BLUE, pos),
                        ("force".into(), GREEN, force),
                    ],
                ),
            ));
        }
    }
    if let Some(st) = &rep.structure {
        let names: Vec<String> = st.cables.iter().map(|c| format!("{}", c.cable)).collect();
        out.push((
            "structure.svg".into(),
            bar_chart(
                "Held-out cable-length residual per cable and its structured part",
                "mm RMS",
                &names,
                &[
                    (
                        "residual".into(),
                        BLUE,
                        st.cables.iter().map(|c| c.residual_rms_mm).collect(),
                    ),
                    (
                        "structured part (regression)".into(),
                        RED,
                        st.cables.iter().map(|c| c.structured_rms_mm).collect(),
                    ),
                ],
            ),
        ));
    }
    let _ = Kind::Kinematic;
    out
}

/// "Repeatability": multi-start, second run, bootstrap. A test that failed
/// says so and how often; it never prints a number for it.
fn repeatability_section(s: &mut String, r: &crate::repeatability_figures::Repeatability) {
    s.push_str("\n## Repeatability\n\n");
    if let Some(ms) = &r.multi_start {
        let _ = writeln!(
            s,
            "**Multi-start** (eq. 6.8: frame anchors a_N + U(−0.5, 0.5) m, optimal elastostatic fit, {} starts): {} reached the pipeline's optimum (cost within 1e-6, anchors within 1 mm), {} ended at a lower cost, {} failed; largest anchor distance from the optimum {}, lowest cost ratio {}.{}\n",
            ms.starts,
            ms.same_optimum,
            ms.lower_cost,
            ms.failed,
            ms.max_anchor_distance_mm
                .map_or("– (no start converged)".into(), |d| format!("{d:.2} mm")),
            ms.best_cost_ratio.map_or("–".into(), |c| format!("{c:.6}")),
            if ms.lower_cost > 0 {
                " **A start found a better optimum than the pipeline: its parameters are a local optimum.**"
            } else {
                ""
            }
        );
    }
    if let Some(sr) = &r.second_run {
        match &sr.failure {
            Some(e) => {
                let _ = writeln!(
                    s,
                    "**Second run** (eq. 6.10, the same fit on the held-out set): failed: {e}.\n"
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "**Second run** (eq. 6.10, the same fit on the held-out set): frame anchors moved by {} mean, {} max; largest |Δa₂| / (√2 σ) = {} (≈ 1–3 when both runs agree within their statistics; the spec's second run moved anchors by up to 87 mm at an unchanged accuracy level).\n",
                    sr.mean_anchor_change_mm
                        .map_or("–".into(), |v| format!("{v:.1} mm")),
                    sr.max_anchor_change_mm
                        .map_or("–".into(), |v| format!("{v:.1} mm")),
                    sr.max_change_over_sigma
                        .map_or("– (no finite 1σ)".into(), |v| format!("{v:.1}"))
                );
            }
        }
    }
    if let Some(b) = &r.bootstrap {
        let ok = b.runs - b.failed;
        let _ = writeln!(
            s,
            "**Bootstrap** ({} resamples of the training poses, the whole pipeline each, validated on the same held-out set): {} failed (pipeline error or final step not validated); of the {ok} others, {} chose exactly the same effects as this run. Largest bootstrap sd of a frame-anchor coordinate: {}.\n",
            b.runs,
            b.failed,
            b.same_effects,
            b.max_anchor_sd_mm
                .map_or("–".into(), |v| format!("{v:.1} mm"))
        );
        s.push_str("| effect | chosen in runs |\n|---|---|\n");
        for (e, n) in &b.effect_counts {
            let _ = writeln!(s, "| {} | {n}/{ok} |", e.name());
        }
        if !b.params.is_empty() {
            s.push_str("\n| parameter | this run ± 1σ | bootstrap runs | bootstrap mean ± sd |\n|---|---|---|---|\n");
            for p in &b.params {
                let this = if p.value.is_finite() {
                    if p.sigma.is_finite() && p.sigma > 0.0 {
                        format!("{:.4e} ± {:.1e}", p.value, p.sigma)
                    } else {
                        format!("{:.4e} (no 1σ)", p.value)
                    }
                } else {
                    "not in this run's model".into()
                };
                let boot = if p.sd.is_finite() {
                    format!("{:.4e} ± {:.1e}", p.mean, p.sd)
                } else {
                    format!("{:.4e} (one run)", p.mean)
                };
                let _ = writeln!(s, "| {} | {this} | {} | {boot} |", p.name, p.runs);
            }
        }
    }
}

/// "Unexplained structure": what the best model leaves in the held-out residuals.
fn structure_section(s: &mut String, st: &crate::structure::StructureReport) {
    s.push_str("\n## Unexplained structure\n\n");
    let flagged: Vec<&crate::structure::CableStructure> =
        st.cables.iter().filter(|c| c.significant).collect();
    if flagged.is_empty() {
        let _ = writeln!(
            s,
            "No structure left in the held-out cable-length residuals of \"{}\" (F test per cable against position, orientation, cable length, force and direction of motion, family-wise level {}).\n",
            st.model, st.alpha
        );
    } else {
        let where_: Vec<String> = flagged
            .iter()
            .map(|c| {
                format!(
                    "cable {} along {}",
                    c.cable,
                    c.dominant.as_deref().unwrap_or("several variables")
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "**Unexplained structure** remains in the held-out cable-length residuals of \"{}\": {}. The catalogue's chosen effects do not explain it; this names where the model is wrong, not a physical cause (family-wise level {}).\n",
            st.model,
            where_.join("; "),
            st.alpha
        );
    }
    s.push_str("| cable | samples | residual RMS (mm) | structured part RMS (mm) | F | F crit | dominant variable (share) | verdict |\n|---|---|---|---|---|---|---|---|\n");
    for c in &st.cables {
        let verdict = match (c.f_stat, c.significant) {
            (None, _) => "not tested (too few samples or a residual could not be evaluated)",
            (Some(_), true) => "unexplained structure",
            (Some(_), false) => "noise",
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {} | {} | {} | {} | {verdict} |",
            c.cable,
            c.n,
            c.residual_rms_mm,
            if c.f_stat.is_some() {
                format!("{:.2}", c.structured_rms_mm)
            } else {
                "–".into()
            },
            fmt_opt(c.f_stat, 2),
            fmt_opt(c.f_critical, 2),
            match (&c.dominant, c.dominant_share) {
                (Some(d), Some(sh)) => format!("{d} ({:.0} %)", sh * 100.0),
                _ => "–".into(),
            }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn says_no_data(svg: &str) -> bool {
        let doc = roxmltree::Document::parse(svg).expect("well-formed SVG");
        doc.descendants()
            .filter_map(|n| n.text())
            .any(|t| t.trim().ends_with("no data"))
    }

    #[test]
    fn empty_charts_say_no_data() {
        assert!(says_no_data(&bar_chart("steps", "mm", &[], &[])));
        let nan = vec![("x".to_string(), BLUE, vec![f64::NAN])];
        assert!(says_no_data(&bar_chart("steps", "mm", &["a".into()], &nan)));
        assert!(says_no_data(&scatter("error", "m", "mm", &[])));
        let empty = vec![("first".to_string(), RED, Vec::new())];
        assert!(says_no_data(&scatter("error", "m", "mm", &empty)));
    }

    #[test]
    fn a_scatter_draws_each_point_and_a_legend_per_series() {
        let s = vec![
            (
                "|Δp|".to_string(),
                BLUE,
                vec![(0.0, 1.0), (1.0, 2.0), (2.0, 0.5)],
            ),
            ("1σ".to_string(), ORANGE, vec![(0.0, 0.1)]),
        ];
        let svg = scatter("changes", "parameter index (a, b)", "mm", &s);
        let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
        let dots = |c: &str| {
            doc.descendants()
                .filter(|n| n.tag_name().name() == "circle" && n.attribute("fill") == Some(c))
                .count()
        };
        assert_eq!((dots("#1F77B4"), dots("#FF7F0E")), (3 + 1, 1 + 1));
        assert!(svg.contains("parameter index (a, b)") && svg.contains("|Δp|"));
    }
}
