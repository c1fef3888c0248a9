//! Vehicle motion: what an IMU at the rider's head in the vehicle records, the input of the
//! motion cueing. A drive is a CSV file (one header line, then one row per sample; blank lines
//! and `#` lines are comments):
//!
//! | column | unit | meaning |
//! |---|---|---|
//! | `t_s` | s | time of the sample, ≥ 0, strictly increasing, at most [`MAX_GAP_S`] apart |
//! | `f_x_m_per_s2` | m/s² | specific force f = a − g along the vehicle's x axis (forward) |
//! | `f_y_m_per_s2` | m/s² | … along y (left) |
//! | `f_z_m_per_s2` | m/s² | … along z (up): +9.81 standing on level ground |
//! | `omega_x_rad_per_s` | rad/s | angular velocity about x (roll rate, right side down > 0) |
//! | `omega_y_rad_per_s` | rad/s | … about y (pitch rate, nose down > 0) |
//! | `omega_z_rad_per_s` | rad/s | … about z (yaw rate, to the left > 0) |
//!
//! Body axes of the vehicle (ISO 8855: x forward, y left, z up), the quantities an
//! accelerometer and a gyroscope measure (a recorded drive's IMU rotated into these axes).
//! Between samples the signals are interpolated linearly. Bounds: |f| ≤ [`MAX_SPECIFIC_FORCE`]
//! and |ω| ≤ [`MAX_ANGULAR_VELOCITY`] per component (a car or train never comes near; a row
//! beyond is a unit or column mix-up). Every error names the file, the line, the column and
//! what is wrong.

use nalgebra::Vector3;
use std::path::Path;

/// The columns of a vehicle CSV, in order.
pub const COLUMNS: [&str; 7] = [
    "t_s",
    "f_x_m_per_s2",
    "f_y_m_per_s2",
    "f_z_m_per_s2",
    "omega_x_rad_per_s",
    "omega_y_rad_per_s",
    "omega_z_rad_per_s",
];

/// Largest |specific force| per component, m/s² (5 g).
pub const MAX_SPECIFIC_FORCE: f64 = 49.05;
/// Largest |angular velocity| per component, rad/s.
pub const MAX_ANGULAR_VELOCITY: f64 = 10.0;
/// Largest time between two samples, s (a longer gap cannot be interpolated honestly).
pub const MAX_GAP_S: f64 = 0.5;

/// One sample of the vehicle's motion (body axes, SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleSample {
    pub specific_force: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
}

impl VehicleSample {
    /// Standing still on level ground: f = [0, 0, g], ω = 0.
    pub fn at_rest(g: f64) -> Self {
        Self {
            specific_force: Vector3::new(0.0, 0.0, g),
            angular_velocity: Vector3::zeros(),
        }
    }

    /// `self + s (other − self)`.
    pub fn lerp(&self, other: &VehicleSample, s: f64) -> VehicleSample {
        VehicleSample {
            specific_force: self.specific_force + (other.specific_force - self.specific_force) * s,
            angular_velocity: self.angular_velocity
                + (other.angular_velocity - self.angular_velocity) * s,
        }
    }
}

/// A vehicle CSV that cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VehicleError {
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
    #[error("{file}: cannot write: {message}")]
    Write { file: String, message: String },
    #[error("formatting the vehicle CSV: {0}")]
    Csv(String),
}

/// A vehicle's motion over time.
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleTrack {
    samples: Vec<(f64, VehicleSample)>,
}

impl VehicleTrack {
    /// From samples (times strictly increasing; the readers check it).
    pub fn from_samples(samples: Vec<(f64, VehicleSample)>) -> Self {
        Self { samples }
    }

    pub fn samples(&self) -> &[(f64, VehicleSample)] {
        &self.samples
    }

    /// Time of the first and the last sample, s.
    pub fn start_s(&self) -> f64 {
        self.samples.first().map_or(0.0, |s| s.0)
    }
    pub fn end_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.0)
    }
    pub fn duration_s(&self) -> f64 {
        self.end_s() - self.start_s()
    }

    /// The motion at time `t` (linear between samples, held before the first; None after the
    /// last).
    pub fn at(&self, t: f64) -> Option<VehicleSample> {
        let first = self.samples.first()?;
        if t > self.end_s() {
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

    /// Reads a vehicle CSV (module docs).
    pub fn read_csv(path: &Path) -> Result<Self, VehicleError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| VehicleError::Read {
            file: file.clone(),
            message: e.to_string(),
        })?;
        Self::parse_csv(&text, &file)
    }

    /// Parses vehicle CSV text; `file` names it in errors.
    pub fn parse_csv(text: &str, file: &str) -> Result<Self, VehicleError> {
        let line_err = |line: usize, message: String| VehicleError::Line {
            file: file.to_string(),
            line,
            message,
        };
        let table = crs_dataset::table::read_table(text, &COLUMNS).map_err(|e| {
            let (line, message) = e.line_and_message();
            line_err(line, message)
        })?;
        let mut samples: Vec<(f64, VehicleSample)> = Vec::new();
        for row in &table.rows {
            let mut v = [0.0; 7];
            for (c, cell) in row.fields.iter().enumerate() {
                let field = |message: String| VehicleError::Field {
                    file: file.to_string(),
                    line: row.line,
                    column: c + 1,
                    name: COLUMNS[c].to_string(),
                    message,
                };
                let x: f64 = cell
                    .text
                    .parse()
                    .map_err(|_| field(format!("not a number: `{}`", cell.text)))?;
                if !x.is_finite() {
                    return Err(field(format!("not finite: {x}")));
                }
                let bound = match c {
                    0 => None,
                    1..=3 => Some(MAX_SPECIFIC_FORCE),
                    _ => Some(MAX_ANGULAR_VELOCITY),
                };
                if let Some(b) = bound
                    && x.abs() > b
                {
                    return Err(field(format!("{x} outside [-{b}, {b}]")));
                }
                if c == 0 {
                    if x < 0.0 {
                        return Err(field(format!("{x} < 0")));
                    }
                    if let Some((t_prev, _)) = samples.last() {
                        if x <= *t_prev {
                            return Err(field(format!(
                                "{x} not after the previous sample's {t_prev}"
                            )));
                        }
                        if x - t_prev > MAX_GAP_S {
                            return Err(field(format!(
                                "{:.3} s after the previous sample (at most {MAX_GAP_S} s)",
                                x - t_prev
                            )));
                        }
                    }
                }
                v[c] = x;
            }
            samples.push((
                v[0],
                VehicleSample {
                    specific_force: Vector3::new(v[1], v[2], v[3]),
                    angular_velocity: Vector3::new(v[4], v[5], v[6]),
                },
            ));
        }
        if samples.len() < 2 {
            return Err(line_err(
                text.lines().count().max(1),
                format!("{} samples: a drive needs at least 2", samples.len()),
            ));
        }
        Ok(Self { samples })
    }

    /// The CSV text of the track, `comment` lines first (prefixed with `# `); the numbers in
    /// fixed decimals (ms, 10 µm/s², µrad/s), as the shipped profiles in config/vehicle/ hold them.
    pub fn to_csv(&self, comment: &[String]) -> Result<String, VehicleError> {
        let mut text = Vec::new();
        for c in comment {
            text.extend_from_slice(format!("# {c}\n").as_bytes());
        }
        let mut w = csv::Writer::from_writer(text);
        for (t, v) in &self.samples {
            let f = v.specific_force;
            let o = v.angular_velocity;
            w.serialize(VehicleRow {
                t_s: format!("{t:.3}"),
                f_x_m_per_s2: format!("{:.5}", f.x),
                f_y_m_per_s2: format!("{:.5}", f.y),
                f_z_m_per_s2: format!("{:.5}", f.z),
                omega_x_rad_per_s: format!("{:.6}", o.x),
                omega_y_rad_per_s: format!("{:.6}", o.y),
                omega_z_rad_per_s: format!("{:.6}", o.z),
            })
            .map_err(|e| VehicleError::Csv(e.to_string()))?;
        }
        let text = w
            .into_inner()
            .map_err(|e| VehicleError::Csv(e.error().to_string()))?;
        // Every piece written is a `String`: the bytes are UTF-8.
        String::from_utf8(text).map_err(|e| VehicleError::Csv(e.to_string()))
    }

    /// Writes [`Self::to_csv`] to `path`.
    pub fn write_csv(&self, path: &Path, comment: &[String]) -> Result<(), VehicleError> {
        std::fs::write(path, self.to_csv(comment)?).map_err(|e| VehicleError::Write {
            file: path.display().to_string(),
            message: e.to_string(),
        })
    }
}

/// One row of a vehicle CSV, its fields named as [`COLUMNS`], the numbers already formatted.
#[derive(serde::Serialize)]
struct VehicleRow {
    t_s: String,
    f_x_m_per_s2: String,
    f_y_m_per_s2: String,
    f_z_m_per_s2: String,
    omega_x_rad_per_s: String,
    omega_y_rad_per_s: String,
    omega_z_rad_per_s: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "t_s,f_x_m_per_s2,f_y_m_per_s2,f_z_m_per_s2,omega_x_rad_per_s,omega_y_rad_per_s,omega_z_rad_per_s";

    #[test]
    fn reads_interpolates_and_round_trips() {
        let text = format!("# a drive\n{HEAD}\n0,0,0,9.81,0,0,0\n\n0.5,-2,0.5,9.81,0,0.1,0\n");
        let t = VehicleTrack::parse_csv(&text, "d.csv").unwrap();
        assert_eq!(t.samples().len(), 2);
        let m = t.at(0.25).unwrap();
        assert!(
            (m.specific_force.x + 1.0).abs() < 1e-12 && (m.angular_velocity.y - 0.05).abs() < 1e-12
        );
        assert_eq!(t.at(0.6), None);
        let again = VehicleTrack::parse_csv(&t.to_csv(&["x".into()]).unwrap(), "e.csv").unwrap();
        assert_eq!(again, t);
    }

    #[test]
    fn bad_rows_are_refused_by_line_and_column() {
        let e = |body: &str| {
            VehicleTrack::parse_csv(&format!("{HEAD}\n0,0,0,9.81,0,0,0\n{body}\n"), "d.csv")
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            e("0.1,0,abc,9.81,0,0,0"),
            "d.csv:3:3: column `f_y_m_per_s2`: not a number: `abc`"
        );
        assert_eq!(
            e("0.1,0,0,9.81,0,0,20"),
            "d.csv:3:7: column `omega_z_rad_per_s`: 20 outside [-10, 10]"
        );
        assert_eq!(
            e("0.0,0,0,9.81,0,0,0"),
            "d.csv:3:1: column `t_s`: 0 not after the previous sample's 0"
        );
        assert!(e("0.9,0,0,9.81,0,0,0").contains("0.900 s after the previous sample"));
        assert!(e("0.1,0,0,9.81,0,0").contains("d.csv:3: has 6 columns, expected 7"));
        assert!(e("0.1,0,0,inf,0,0,0").contains("column `f_z_m_per_s2`: not finite"));
        let h = VehicleTrack::parse_csv("t,a,b\n", "d.csv")
            .unwrap_err()
            .to_string();
        assert!(h.starts_with("d.csv:1: header must be"), "{h}");
        let one = VehicleTrack::parse_csv(&format!("{HEAD}\n0,0,0,9.81,0,0,0\n"), "d.csv")
            .unwrap_err()
            .to_string();
        assert!(one.contains("at least 2"), "{one}");
    }
}
