//! Pilot inputs: a recorded pilot CSV, a scripted manoeuvre, or (in `sim-runs`) a live game
//! controller, all as a track of [`PilotInput`] over time.
//!
//! Pilot CSV (one header line, then one row per sample; `#` lines are comments):
//!
//! | column | unit | range | meaning |
//! |---|---|---|---|
//! | `t_s` | s | ≥ 0, strictly increasing | time of the sample |
//! | `collective` | – | [0, 1] | thrust lever; 0.5 hovers, 1 is the maximum thrust |
//! | `roll` | – | [−1, 1] | cyclic left/right: +1 tilts towards −y at full roll command |
//! | `pitch` | – | [−1, 1] | cyclic fore/aft: +1 tilts the thrust towards +x |
//! | `yaw` | – | [−1, 1] | pedals: commanded yaw |
//!
//! Between samples the input is interpolated linearly; after the last one the track ends.
//! Every error names the file, the line, the column and what is wrong.

use std::path::Path;

/// One pilot input: collective ∈ [0, 1], roll/pitch/yaw ∈ [−1, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PilotInput {
    pub collective: f64,
    pub roll: f64,
    pub pitch: f64,
    pub yaw: f64,
}

impl PilotInput {
    /// Hands off: hover collective, centred stick and pedals.
    pub const HOVER: PilotInput = PilotInput {
        collective: 0.5,
        roll: 0.0,
        pitch: 0.0,
        yaw: 0.0,
    };

    fn lerp(&self, o: &PilotInput, s: f64) -> PilotInput {
        let l = |a: f64, b: f64| a + (b - a) * s;
        PilotInput {
            collective: l(self.collective, o.collective),
            roll: l(self.roll, o.roll),
            pitch: l(self.pitch, o.pitch),
            yaw: l(self.yaw, o.yaw),
        }
    }
}

/// A pilot CSV or a script that cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PilotError {
    #[error("{file}: cannot read: {message}")]
    Read { file: String, message: String },
    #[error("{file}:{line}:{column}: column `{name}`: {message}")]
    Field {
        file: String,
        line: usize,
        column: usize,
        name: String,
        message: String,
    },
    #[error("{file}:{line}: {message}")]
    Line {
        file: String,
        line: usize,
        message: String,
    },
    #[error("unknown pilot script `{0}` (known: {known})", known = SCRIPTS.join(", "))]
    UnknownScript(String),
}

/// The columns of a pilot CSV, in order.
pub const COLUMNS: [&str; 5] = ["t_s", "collective", "roll", "pitch", "yaw"];

/// Built-in manoeuvres ([`PilotTrack::script`]).
pub const SCRIPTS: [&str; 2] = ["walls", "corners"];

/// Pilot inputs over time.
#[derive(Clone, Debug, PartialEq)]
pub struct PilotTrack {
    samples: Vec<(f64, PilotInput)>,
}

impl PilotTrack {
    /// From samples (times strictly increasing, values in range: checked by the readers).
    pub fn from_samples(samples: Vec<(f64, PilotInput)>) -> Self {
        Self { samples }
    }

    pub fn samples(&self) -> &[(f64, PilotInput)] {
        &self.samples
    }

    /// Time of the last sample, s.
    pub fn duration_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.0)
    }

    /// The input at time `t` (linear between samples; the first before it, `None` after the
    /// last sample).
    pub fn at(&self, t: f64) -> Option<PilotInput> {
        let first = self.samples.first()?;
        if t > self.duration_s() {
            return None;
        }
        if t <= first.0 {
            return Some(first.1);
        }
        let k = self.samples.partition_point(|s| s.0 <= t);
        let (t0, a) = self.samples[k - 1];
        match self.samples.get(k) {
            Some((t1, b)) => Some(a.lerp(b, (t - t0) / (t1 - t0))),
            None => Some(a),
        }
    }

    /// Reads a pilot CSV (module docs).
    pub fn read_csv(path: &Path) -> Result<Self, PilotError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| PilotError::Read {
            file: file.clone(),
            message: e.to_string(),
        })?;
        Self::parse_csv(&text, &file)
    }

    /// Parses pilot CSV text; `file` names it in errors.
    pub fn parse_csv(text: &str, file: &str) -> Result<Self, PilotError> {
        let line_err = |line: usize, message: String| PilotError::Line {
            file: file.to_string(),
            line,
            message,
        };
        let table = crs_dataset::table::read_table(text, &COLUMNS).map_err(|e| {
            let (line, message) = e.line_and_message();
            line_err(line, message)
        })?;
        let hl = table.header_line;
        let mut samples: Vec<(f64, PilotInput)> = Vec::new();
        for row in &table.rows {
            let mut v = [0.0; 5];
            for (k, cell) in row.fields.iter().enumerate() {
                let field = |message: String| PilotError::Field {
                    file: file.to_string(),
                    line: row.line,
                    column: cell.column,
                    name: COLUMNS[k].to_string(),
                    message,
                };
                let x: f64 = cell
                    .text
                    .parse()
                    .map_err(|_| field(format!("`{}` is not a number", cell.text)))?;
                let (lo, hi) = match k {
                    0 => (0.0, f64::MAX),
                    1 => (0.0, 1.0),
                    _ => (-1.0, 1.0),
                };
                if !(x.is_finite() && x >= lo && x <= hi) {
                    return Err(field(if k == 0 {
                        format!("{x} must be a finite time >= 0")
                    } else {
                        format!("{x} outside [{lo}, {hi}]")
                    }));
                }
                if k == 0 && samples.last().is_some_and(|s| x <= s.0) {
                    return Err(field(format!(
                        "{x} s is not after the previous sample ({} s)",
                        samples.last().map_or(0.0, |s| s.0)
                    )));
                }
                v[k] = x;
            }
            samples.push((
                v[0],
                PilotInput {
                    collective: v[1],
                    roll: v[2],
                    pitch: v[3],
                    yaw: v[4],
                },
            ));
        }
        if samples.is_empty() {
            return Err(line_err(hl, "no samples after the header".into()));
        }
        Ok(Self { samples })
    }

    /// A scripted manoeuvre:
    /// - `walls`: from hover, full stick towards each of the 26 faces, edges and corners of the
    ///   wall box in turn (pitch ±1 for ±x, roll ∓1 for ±y, collective 1 or 0 for ±z; yaw
    ///   alternating ±1), `push_s` seconds each, then `release_s` hands off;
    /// - `corners`: only the 8 corners, the same way.
    pub fn script(name: &str, push_s: f64, release_s: f64) -> Result<Self, PilotError> {
        let dirs: Vec<[i32; 3]> = match name {
            "walls" => directions().collect(),
            "corners" => directions().filter(|d| d.iter().all(|c| *c != 0)).collect(),
            _ => return Err(PilotError::UnknownScript(name.to_string())),
        };
        let mut samples = vec![(0.0, PilotInput::HOVER)];
        let mut t = 0.5;
        // A 50 ms ramp onto the stick and back, as a hand moves.
        let ramp = 0.05;
        for (k, d) in dirs.iter().enumerate() {
            let full = full_stick(*d, if k % 2 == 0 { 1.0 } else { -1.0 });
            samples.push((t, PilotInput::HOVER));
            samples.push((t + ramp, full));
            samples.push((t + push_s, full));
            samples.push((t + push_s + ramp, PilotInput::HOVER));
            t += push_s + release_s;
        }
        samples.push((t, PilotInput::HOVER));
        Ok(Self { samples })
    }
}

/// The 26 directions {−1, 0, 1}³ \ {0}.
pub fn directions() -> impl Iterator<Item = [i32; 3]> {
    (0..27)
        .map(|k| [k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1])
        .filter(|d| *d != [0, 0, 0])
}

/// Full stick towards direction `d` (x, y, z ∈ {−1, 0, 1}) with pedals `yaw`.
pub fn full_stick(d: [i32; 3], yaw: f64) -> PilotInput {
    PilotInput {
        collective: match d[2] {
            1 => 1.0,
            -1 => 0.0,
            _ => 0.5,
        },
        roll: -d[1] as f64,
        pitch: d[0] as f64,
        yaw,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_interpolates_and_ends() {
        let t = PilotTrack::parse_csv(
            "# demo\nt_s,collective,roll,pitch,yaw\n0,0.5,0,0,0\n2.0,1.0,-1,0.5,0\n",
            "p.csv",
        )
        .unwrap();
        assert_eq!(t.duration_s(), 2.0);
        let m = t.at(1.0).unwrap();
        assert!((m.collective - 0.75).abs() < 1e-12 && (m.roll + 0.5).abs() < 1e-12);
        assert!(t.at(2.01).is_none());
    }

    #[test]
    fn errors_name_line_column_and_field() {
        let h = "t_s,collective,roll,pitch,yaw\n";
        let e = PilotTrack::parse_csv(&format!("{h}0,0.5,0,0,0\n1,0.5,0,1.5,0\n"), "p.csv")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "p.csv:3:9: column `pitch`: 1.5 outside [-1, 1]");
        let e = PilotTrack::parse_csv(&format!("{h}0,0.5,0,0,0\n0,0.5,0,0,0\n"), "p.csv")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("p.csv:3:1: column `t_s`: 0 s is not after"),
            "{e}"
        );
        let e = PilotTrack::parse_csv(&format!("{h}0,half,0,0,0\n"), "p.csv")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "p.csv:2:3: column `collective`: `half` is not a number");
        let e = PilotTrack::parse_csv(&format!("{h}0,0.5,0,0\n"), "p.csv")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "p.csv:2: has 4 columns, expected 5");
        let e = PilotTrack::parse_csv("t,collective\n", "p.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("p.csv:1: header must be"), "{e}");
        let e = PilotTrack::read_csv(Path::new("/nonexistent/p.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/nonexistent/p.csv: cannot read"), "{e}");
        assert!(
            PilotTrack::script("loop", 1.0, 1.0)
                .unwrap_err()
                .to_string()
                .contains("walls, corners")
        );
    }

    #[test]
    fn the_walls_script_pushes_towards_all_26_directions() {
        let t = PilotTrack::script("walls", 2.0, 1.0).unwrap();
        assert_eq!(directions().count(), 26);
        let held: Vec<PilotInput> = t.samples().iter().skip(2).step_by(4).map(|s| s.1).collect();
        for d in directions() {
            assert!(
                held.iter()
                    .any(|u| u.pitch == d[0] as f64 && u.roll == -d[1] as f64),
                "{d:?}"
            );
        }
        assert!((t.duration_s() - (0.5 + 26.0 * 3.0)).abs() < 1e-9);
    }
}
