//! The cueing tunings side by side and the trade-off of the washout parameters, every drive
//! through motion-core's own cueing tracker and per-cycle checks (tests/common: the nominal
//! icosahedron, 1 ms loop):
//!
//!   cargo run --release -p motion-cueing --example tunings -- docs/img
//!
//! prints (markdown) the per-profile perception table of the two shipped tunings
//! (config/cueing.toml, config/cueing-onset.toml) and a sweep of the specific-force gain K
//! (x, y) and the translational high-pass ω_n against the relative perceived specific-force
//! error and the workspace use, and writes the figures into the directory given:
//! `cueing-tradeoff.svg`, `cueing-perception-<profile>.svg`, `cueing-motion-braking.svg`.
#[path = "../tests/common/mod.rs"]
mod common;
use common::*;
use motion_cueing::CueingSettings;
use motion_cueing::perception::PerceptionReport;
use motion_cueing::plot::{motion_svg, perception_svg, scatter_svg};
use motion_cueing::profiles::PROFILES;
use std::path::PathBuf;

/// Relative perceived error of the horizontal specific force: √Σ err² / √Σ rms_vehicle² over
/// x and y.
fn rel_error(r: &PerceptionReport) -> f64 {
    let (mut e, mut v) = (0.0, 0.0);
    for a in &r.specific_force[..2] {
        e += a.perceived.rms_error.powi(2);
        v += a.perceived.rms_reference.powi(2);
    }
    (e / v).sqrt()
}

/// Perceived correlation on the profile's main axis (f_x braking/accelerating, f_y otherwise).
fn main_corr(name: &str, r: &PerceptionReport) -> f64 {
    let k = if name == "braking" || name == "accelerating" {
        0
    } else {
        1
    };
    r.specific_force[k]
        .perceived
        .correlation
        .unwrap_or(f64::NAN)
}

struct Outcome {
    rel_error: Vec<f64>,
    main_corr: Vec<f64>,
    reports: Vec<PerceptionReport>,
    /// Largest workspace use per profile: translation (x, y, z) and rotation.
    use_translation: Vec<f64>,
    use_rotation: Vec<f64>,
    refused: usize,
    f_lo: f64,
    f_hi: f64,
}

fn evaluate(st: &CueingSettings, keep: bool, dir: Option<&PathBuf>, label: &str) -> Outcome {
    let (pf, lim) = platform_and_limits("motion-core.toml");
    let neutral = motion_cueing::Washout::new(st.washout, pf.home, 1e-3).unwrap();
    let mut o = Outcome {
        rel_error: vec![],
        main_corr: vec![],
        reports: vec![],
        use_translation: vec![],
        use_rotation: vec![],
        refused: 0,
        f_lo: f64::INFINITY,
        f_hi: f64::NEG_INFINITY,
    };
    for p in &PROFILES {
        let track = motion_cueing::VehicleTrack::read_csv(&cfg(&format!("vehicle/{}.csv", p.name)))
            .unwrap();
        let f = fly(&pf, lim, st, track, 1e-3);
        if f.refused.is_some() {
            o.refused += 1;
        }
        o.f_lo = o.f_lo.min(f.f_lo);
        o.f_hi = o.f_hi.max(f.f_hi);
        let (rep, series) = f.perception(st, 1e-3);
        let u = motion_cueing::washout::workspace_use(&neutral, &f.reference);
        o.use_translation
            .push(u[..3].iter().copied().fold(0.0, f64::max));
        o.use_rotation
            .push(u[3..].iter().copied().fold(0.0, f64::max));
        o.rel_error.push(rel_error(&rep));
        o.main_corr.push(main_corr(p.name, &rep));
        if let (true, Some(d)) = (keep, dir) {
            let svg = perception_svg(
                &format!(
                    "{} ({label}): vehicle vs cabin (motion-core's reference) vs perceived",
                    p.name
                ),
                &series,
                &rep,
            );
            std::fs::write(d.join(format!("cueing-perception-{}.svg", p.name)), svg).unwrap();
            if p.name == "braking" {
                let svg = motion_svg(
                    &format!(
                        "braking ({label}): washout demand, motion-core's reference, tilt, cueing box"
                    ),
                    &f.t,
                    &f.desired,
                    &f.reference,
                    &f.tilt,
                    &f.box_min,
                    &f.box_max,
                );
                std::fs::write(d.join("cueing-motion-braking.svg"), svg).unwrap();
            }
        }
        o.reports.push(rep);
    }
    o
}

fn main() {
    let dir = std::env::args().nth(1).map(PathBuf::from);
    if let Some(d) = &dir {
        std::fs::create_dir_all(d).unwrap();
    }
    let corr = |c: Option<f64>| c.map_or("–".to_string(), |c| format!("{c:.2}"));
    let deg = 180.0 / std::f64::consts::PI;
    println!(
        "## Two tunings side by side (nominal icosahedron, motion-core's tracker and checks, 1 ms)\n"
    );
    println!(
        "| tuning | profile | perceived f_x RMS error / corr. | perceived f_y RMS error / corr. | perceived ω_z RMS error (°/s) / corr. | relative f error | workspace use translation / rotation | refused |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut shipped = Vec::new();
    for (file, label) in [("cueing.toml", "default"), ("cueing-onset.toml", "onset")] {
        let st = CueingSettings::load(&cfg(file)).unwrap();
        let o = evaluate(&st, file == "cueing.toml", dir.as_ref(), label);
        for (k, p) in PROFILES.iter().enumerate() {
            let r = &o.reports[k];
            let (fx, fy, wz) = (
                &r.specific_force[0].perceived,
                &r.specific_force[1].perceived,
                &r.angular_velocity[2].perceived,
            );
            println!(
                "| `{file}` | {} | {:.3} / {} | {:.3} / {} | {:.2} / {} | {:.2} | {:.0} % / {:.0} % | {} |",
                p.name,
                fx.rms_error,
                corr(fx.correlation),
                fy.rms_error,
                corr(fy.correlation),
                wz.rms_error * deg,
                corr(wz.correlation),
                o.rel_error[k],
                o.use_translation[k] * 100.0,
                o.use_rotation[k] * 100.0,
                if o.refused > 0 { "yes" } else { "0" }
            );
        }
        let mean = o.rel_error.iter().sum::<f64>() / o.rel_error.len() as f64;
        let used = o.use_translation.iter().copied().fold(0.0, f64::max);
        println!(
            "| `{file}` | **mean / max** | | | | **{mean:.3}** | {:.0} % / {:.0} % | forces {:.0} … {:.0} N |",
            used * 100.0,
            o.use_rotation.iter().copied().fold(0.0, f64::max) * 100.0,
            o.f_lo,
            o.f_hi
        );
        shipped.push((used, mean, label.to_string()));
    }
    // The sweep: K (x, y) × translational ω_n, from the default tuning.
    println!("\n## Sweep: specific-force gain K (x, y) × translational high-pass ω_n\n");
    println!(
        "| K | ω_n (rad/s) | mean relative perceived f error | mean perceived corr. (main axis) | largest translational workspace use | refused |"
    );
    println!("|---|---|---|---|---|---|");
    let base = std::fs::read_to_string(cfg("cueing.toml")).unwrap();
    let mut pts = Vec::new();
    for k in [0.2, 0.3, 0.5, 0.7, 1.0] {
        for w in [0.8, 1.2, 2.0, 3.0] {
            let text = base
                .replace(
                    "specific_force_gain = [0.3, 0.3, 0.3]",
                    &format!("specific_force_gain = [{k}, {k}, 0.3]"),
                )
                .replace(
                    "specific_force_limit_m_per_s2 = [0.45, 0.45, 1.0]",
                    "specific_force_limit_m_per_s2 = [2.0, 2.0, 1.0]",
                )
                .replace(
                    "omega_n_rad_per_s = [2.0, 2.0, 2.5]",
                    &format!("omega_n_rad_per_s = [{w}, {w}, 2.5]"),
                );
            let st = CueingSettings::parse(&text, "sweep.toml").unwrap();
            assert_eq!(
                st.washout.translation[0].omega_n, w,
                "sweep edit not applied"
            );
            assert_eq!(
                st.washout.specific_force_gain.x, k,
                "sweep edit not applied"
            );
            let o = evaluate(&st, false, None, "");
            let mean = o.rel_error.iter().sum::<f64>() / o.rel_error.len() as f64;
            let used = o.use_translation.iter().copied().fold(0.0, f64::max);
            let corr = o.main_corr.iter().sum::<f64>() / o.main_corr.len() as f64;
            println!(
                "| {k} | {w} | {mean:.3} | {corr:.2} | {:.0} % | {} |",
                used * 100.0,
                o.refused
            );
            pts.push((used, mean, format!("K {k}, ω_n {w}"), false));
        }
    }
    // Pareto front (lower error at lower workspace use).
    let mut front: Vec<&(f64, f64, String, bool)> = pts
        .iter()
        .filter(|p| {
            !pts.iter()
                .any(|q| q.0 <= p.0 && q.1 < p.1 || q.0 < p.0 && q.1 <= p.1)
        })
        .collect();
    front.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    println!(
        "\nPareto front (workspace use → error): {}",
        front
            .iter()
            .map(|p| format!("{} ({:.0} %, {:.3})", p.2, p.0 * 100.0, p.1))
            .collect::<Vec<_>>()
            .join("; ")
    );
    if let Some(d) = &dir {
        let mut all: Vec<(f64, f64, String, bool)> = pts
            .iter()
            .map(|p| {
                (
                    p.0 * 100.0,
                    p.1,
                    if front.iter().any(|f| f.2 == p.2) {
                        p.2.clone()
                    } else {
                        String::new()
                    },
                    false,
                )
            })
            .collect();
        for s in &shipped {
            all.push((s.0 * 100.0, s.1, format!("shipped: {}", s.2), true));
        }
        let svg = scatter_svg(
            "Washout trade-off, nominal icosahedron: 4 profiles through motion-core's tracker and checks (sweep blue, shipped red)",
            "largest translational workspace use (% of the cueing box half-width)",
            "mean relative perceived specific-force error (x, y)",
            &all,
        );
        std::fs::write(d.join("cueing-tradeoff.svg"), svg).unwrap();
        println!("figures written to {}", d.display());
    }
}
