//! The platform TOML writer, next to its reader ([`crate::config::parse_platform`]): what
//! `crs calibrate` writes as `calibrated.toml` must load with the daemon's loader, so both
//! live in the model crate and a round-trip test keeps them in step.
//!
//! Numbers are written with `{:?}` (the shortest text that parses back to the same f64), so
//! a written platform loads to the identical model and the identical identity hash.

use crate::config::Platform;
use nalgebra::Vector3;
use std::fmt::Write as _;

/// Why a platform cannot be written as platform TOML.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum WriteError {
    /// The schema's `[dynamics] inertia_kg_m2` holds principal moments along the platform axes;
    /// an inertia with products of inertia (e.g. a payload combined off-axis) cannot be written
    /// without losing them.
    #[error(
        "[dynamics]: the inertia has products of inertia (largest {0:.3e} kg·m²), which the platform TOML cannot express"
    )]
    InertiaNotDiagonal(f64),
}

/// The platform as platform-TOML text. `header` is written first as `#` comment lines (e.g.
/// where the platform came from).
pub fn platform_toml(p: &Platform, header: &[&str]) -> Result<String, WriteError> {
    let mut s = String::new();
    for line in header {
        let _ = writeln!(s, "# {line}");
    }
    if !header.is_empty() {
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "[platform]\nname = {:?}\ndescription = {:?}\n",
        p.name, p.description
    );
    let params = p.model.params();
    let v3 = |v: &Vector3<f64>| format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z);
    let list = |v: &mut dyn Iterator<Item = f64>| {
        v.map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", ")
    };
    s.push_str("[geometry]\nframe_anchors_m = [\n");
    for a in &params.a {
        let _ = writeln!(s, "  {},", v3(a));
    }
    s.push_str("]\nplatform_anchors_m = [\n");
    for b in &params.b {
        let _ = writeln!(s, "  {},", v3(b));
    }
    s.push_str("]\n\n");
    if let Some(pl) = &params.pulleys {
        // One radius for all cables is written as a scalar (the reader accepts both).
        let radius = match pl.radius.split_first() {
            Some((r0, rest)) if rest.iter().all(|r| r == r0) => format!("{r0:?}"),
            _ => format!("[{}]", list(&mut pl.radius.iter().copied())),
        };
        let _ = writeln!(s, "[pulleys]\nradius_m = {radius}\nswivel_axes = [");
        for ax in &pl.axis {
            let _ = writeln!(s, "  {},", v3(ax));
        }
        s.push_str("]\n\n");
    }
    let _ = writeln!(
        s,
        "[elasticity]\nk_f_n = [{}]\n",
        list(&mut params.k_f.iter().copied())
    );
    let _ = writeln!(
        s,
        "[load]\nwrench_n_nm = [{}]\n",
        list(&mut params.w_e.iter().copied())
    );
    if let Some(d) = &p.dynamics {
        let i = &d.inertia_kg_m2;
        let off = [
            i[(0, 1)],
            i[(0, 2)],
            i[(1, 2)],
            i[(1, 0)],
            i[(2, 0)],
            i[(2, 1)],
        ]
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
        if off > 1e-12 * i.diagonal().amax().max(1.0) {
            return Err(WriteError::InertiaNotDiagonal(off));
        }
        let _ = writeln!(
            s,
            "[dynamics]\nmass_kg = {:?}\ncenter_of_gravity_m = {}\ninertia_kg_m2 = [{:?}, {:?}, {:?}]\n",
            d.mass_kg,
            v3(&d.cog_m),
            i[(0, 0)],
            i[(1, 1)],
            i[(2, 2)]
        );
    }
    let _ = writeln!(
        s,
        "[forces]\nf_min_n = {:?}\nf_max_n = {:?}\nf_abs_max_n = {:?}\n",
        params.f_min, params.f_max, p.f_abs_max
    );
    let l = &p.limits;
    let _ = writeln!(
        s,
        "[limits]\nlinear_velocity_max_m_per_s = {:?}\nangular_velocity_max_deg_per_s = {:?}\nlinear_acceleration_max_m_per_s2 = {:?}\nangular_acceleration_max_deg_per_s2 = {:?}\n",
        l.linear_velocity_max,
        l.angular_velocity_max.to_degrees(),
        l.linear_acceleration_max,
        l.angular_acceleration_max.to_degrees()
    );
    let _ = writeln!(
        s,
        "[winch]\ndrum_diameter_m = {:?}\nrope_diameter_m = {:?}\n",
        p.winch.drum_diameter, p.winch.rope_diameter
    );
    let r = &p.region;
    let deg = |v: &Vector3<f64>| {
        format!(
            "[{:?}, {:?}, {:?}]",
            v.x.to_degrees(),
            v.y.to_degrees(),
            v.z.to_degrees()
        )
    };
    let _ = writeln!(
        s,
        "[workspace]\nposition_min_m = {}\nposition_max_m = {}\nrotation_min_deg = {}\nrotation_max_deg = {}\n",
        v3(&r.position.min),
        v3(&r.position.max),
        deg(&r.rotation_min),
        deg(&r.rotation_max)
    );
    let _ = writeln!(
        s,
        "[home]\nposition_m = {}\nrotation_deg = {}",
        v3(&p.home.r),
        deg(&p.home.phi)
    );
    if let Some(f) = &p.f_ini {
        let _ = writeln!(s, "f_ini_n = [{}]", list(&mut f.iter().copied()));
    }
    if !p.sections.is_empty() {
        s.push_str("\n[sections]\n");
        for sec in &p.sections {
            let c: Vec<String> = sec.cables.iter().map(|c| (c + 1).to_string()).collect();
            let _ = writeln!(s, "{} = [{}]", sec.name, c.join(", "));
        }
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{load_platform, parse_platform};

    /// Every shipped platform written and read back is the same platform (the reader and the
    /// writer agree on every field), with the same identity hash.
    #[test]
    fn every_shipped_platform_round_trips() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config");
        let mut n = 0;
        for entry in std::fs::read_dir(dir).expect("config dir") {
            let path = entry.expect("entry").path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let Ok(p) = load_platform(&path) else {
                continue; // not a platform file (daemon, monitor, drives configs)
            };
            let text = platform_toml(&p, &["written by the round-trip test"]).expect("writable");
            let back = parse_platform(&text, "written")
                .unwrap_or_else(|e| panic!("{}: written text does not load: {e}", path.display()));
            assert_eq!(back, p, "{}", path.display());
            assert_eq!(back.model.identity_hex(), p.model.identity_hex());
            n += 1;
        }
        assert!(
            n >= 2,
            "expected the shipped platforms in config/, found {n}"
        );
    }

    /// Per-cable pulley radii that differ are written as a list (not collapsed).
    #[test]
    fn differing_pulley_radii_stay_per_cable() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/crs-nominal.toml");
        let mut p = load_platform(dir).expect("nominal platform");
        let mut params = p.model.params().clone();
        let m = params.a.len();
        params.pulleys = Some(crate::model::Pulleys {
            radius: (0..m).map(|i| 0.1 + 0.01 * i as f64).collect(),
            axis: vec![Vector3::z(); m],
        });
        p.model = crate::model::Model::new(params).expect("model");
        let back = parse_platform(&platform_toml(&p, &[]).unwrap(), "written").expect("loads");
        assert_eq!(back.model.params().pulleys, p.model.params().pulleys);
    }
}
