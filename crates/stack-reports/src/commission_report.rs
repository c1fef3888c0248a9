//! What `crs commission` prints of a [`Commission`]: the set-up wrench, the payload against the
//! configured one, the cable offsets, the initial tension and the pre-ride verdict.

use calibration_campaigns::commission::{Commission, Verdict};
use std::fmt;
use std::path::Path;

/// A commissioning and the file it was written to, as the operator reads it.
pub struct CommissionReport<'a> {
    pub commission: &'a Commission,
    /// Where `commission.toml` was written.
    pub written: &'a Path,
}

impl fmt::Display for CommissionReport<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.commission;
        let p = &c.payload;
        writeln!(
            f,
            "commissioning `{}`: {} rest points",
            c.platform, c.rest_points
        )?;
        writeln!(
            f,
            "  w_e at the set-up pose (eq. 6.23): [{}] N, N·m",
            c.w_e_setup.map(|v| format!("{v:.1}")).join(", ")
        )?;
        let cog = |k: usize| match (p.cog_m[k], p.cog_std_m[k]) {
            (Some(v), Some(s)) => format!("{v:.3} ± {s:.3} m"),
            _ => "not observable".into(),
        };
        writeln!(
            f,
            "  payload: {:.1} ± {:.1} kg, COG x {}, y {}, z {} (configured {:.1} kg, COG x {:.3} m, y {:.3} m)",
            p.mass_kg,
            p.mass_std_kg,
            cog(0),
            cog(1),
            cog(2),
            c.configured.0,
            c.configured.1[0],
            c.configured.1[1]
        )?;
        if let Some((m, t)) = c.truth {
            writeln!(
                f,
                "  plant truth: {m:.1} kg, COG ({:.3}, {:.3}, {:.3}) m",
                t[0], t[1], t[2]
            )?;
        }
        writeln!(
            f,
            "  q_off (eq. 6.24): [{}] mm",
            c.q_off_m
                .iter()
                .map(|v| format!("{:.1}", v * 1e3))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        match &c.f_ini {
            Ok(t) => writeln!(
                f,
                "  f_ini (eq. 3.42 along the daemon's tour): [{}] N; RMS to f_ref {:.0} N (start {:.0} N)",
                t.f_ini
                    .iter()
                    .map(|v| format!("{v:.0}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                t.rms_chosen_n,
                t.rms_start_n
            )?,
            Err(e) => writeln!(f, "  f_ini (eq. 3.42): not chosen: {e}")?,
        }
        writeln!(
            f,
            "wrote {} (review it; config/ is unchanged)",
            self.written.display()
        )?;
        match &c.verdict {
            Verdict::Ready => writeln!(f, "PRE-RIDE CHECK: READY"),
            Verdict::Refused(why) => {
                writeln!(f, "PRE-RIDE CHECK: REFUSED — do not arm for rides:")?;
                for w in why {
                    writeln!(f, "  - {w}")?;
                }
                Ok(())
            }
        }
    }
}
