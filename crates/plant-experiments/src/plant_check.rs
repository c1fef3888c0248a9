//! `crs plant check`: a plant TOML validated, its effects listed, the plant settled at the
//! home pose with the platform's set-up tension (when the platform configures one), and its
//! equilibrium checked against the independent oracle (`sim_plant::oracle_check`).

use cdpr_model::config::ConfigError;
use sim_plant::oracle_check::{OracleAgreement, OracleCheckError, check_against_oracle};
use sim_plant::{Plant, PlantError, load_plant};
use std::fmt;
use std::path::Path;

/// The plant settled at home.
pub struct HomeSettle {
    /// Position and rotation distance of the settled pose from home, m and rad.
    pub dr_m: f64,
    pub dphi_rad: f64,
    /// Cable forces there, N.
    pub forces: Vec<f64>,
}

/// What a plant TOML describes and how it settles at home.
pub struct PlantCheck {
    pub name: String,
    pub platform_path: String,
    pub cables: usize,
    pub effects: Vec<&'static str>,
    /// The plant built and settled at home; None when the platform has no `f_ini` (no set-up
    /// tension to settle with). An error here is printed after the description.
    pub home: Result<Option<HomeSettle>, PlantError>,
    /// The plant's conservative twin against the minimum-energy oracle (a second formulation sharing no code with the model library).
    pub oracle: Result<OracleAgreement, OracleCheckError>,
}

impl PlantCheck {
    /// Why the check fails, if it does: the home settle's error, the oracle check's error or
    /// a disagreement beyond its tolerances.
    pub fn failure(&self) -> Option<String> {
        if let Err(e) = &self.home {
            return Some(format!("the plant does not settle at home: {e}"));
        }
        match &self.oracle {
            Err(e) => Some(format!("the oracle check could not run: {e}")),
            Ok(a) if !a.within_tolerance() => Some(format!(
                "the plant's equilibrium DISAGREES with the independent oracle: {a}"
            )),
            Ok(_) => None,
        }
    }
}

/// Loads the plant TOML `path`, builds the plant and, when its platform has a set-up tension,
/// settles it at home.
pub fn check(path: &Path) -> Result<PlantCheck, ConfigError> {
    let cfg = load_plant(path)?;
    let mut out = PlantCheck {
        name: cfg.name.clone(),
        platform_path: cfg.platform_path.display().to_string(),
        cables: cfg.platform.model.m(),
        effects: cfg.effects.enabled_names(),
        home: Ok(None),
        oracle: check_against_oracle(&cfg),
    };
    out.home = settle_home(cfg);
    Ok(out)
}

fn settle_home(cfg: sim_plant::PlantConfig) -> Result<Option<HomeSettle>, PlantError> {
    let home = cfg.platform.home;
    let f_ini = cfg.platform.f_ini.clone();
    let mut p = Plant::new(cfg)?;
    let Some(f) = f_ini else {
        return Ok(None);
    };
    let setup = p.setup_tension(&home, &f)?;
    let eq = p.step(&setup.q_cmd)?;
    let (dr_m, dphi_rad) = eq.pose.error_to(&home);
    Ok(Some(HomeSettle {
        dr_m,
        dphi_rad,
        forces: eq.forces.clone(),
    }))
}

impl fmt::Display for PlantCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "plant `{}` on platform {} ({} cables)",
            self.name, self.platform_path, self.cables
        )?;
        writeln!(f, "effects on: {}", self.effects.join(", "))?;
        if let Ok(Some(h)) = &self.home {
            writeln!(
                f,
                "home settled: |Δr| = {:.3e} m, |Δφ| = {:.3e} rad",
                h.dr_m, h.dphi_rad
            )?;
            let forces: Vec<String> = h.forces.iter().map(|x| format!("{x:.1}")).collect();
            writeln!(f, "forces at home, N: {}", forces.join(" "))?;
        }
        match &self.oracle {
            Ok(a) if a.within_tolerance() => writeln!(
                f,
                "independent oracle (minimum potential energy) agrees: {a}"
            )?,
            Ok(a) => writeln!(
                f,
                "independent oracle (minimum potential energy) DISAGREES: {a}"
            )?,
            Err(e) => writeln!(f, "independent oracle: not run: {e}")?,
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/plant")
            .join(name)
    }

    #[test]
    fn a_plant_with_set_up_tension_settles_at_home_and_says_so() {
        let c = check(&plant("crs-ideal.toml")).unwrap();
        let h = c
            .home
            .as_ref()
            .unwrap()
            .as_ref()
            .expect("crs-nominal has f_ini");
        assert_eq!(h.forces.len(), c.cables);
        // The ideal plant holds the set-up pose it was tensioned at (eq. 3.14).
        assert!(h.dr_m < 1e-6 && h.dphi_rad < 1e-6, "{}", c);
        let text = c.to_string();
        assert!(
            text.contains("home settled") && text.contains("forces at home"),
            "{text}"
        );
        assert!(
            text.contains("independent oracle (minimum potential energy) agrees: 7 poses"),
            "{text}"
        );
        assert!(c.failure().is_none(), "{text}");
    }

    #[test]
    fn a_plant_without_set_up_tension_is_described_only() {
        let c = check(&plant("icosahedron.toml")).unwrap();
        assert!(matches!(c.home, Ok(None)));
        let text = c.to_string();
        assert_eq!(text.lines().count(), 3, "{text}");
        assert!(
            text.contains("oracle (minimum potential energy) agrees"),
            "{text}"
        );
    }
}
