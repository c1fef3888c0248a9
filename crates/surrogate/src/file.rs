//! Versioned, self-describing, checksummed JSON file of a surrogate.
//!
//! Layout (pretty-printed JSON, fields in this order):
//!
//! ```text
//! { "format": "crs-surrogate", "format_version": 1, "checksum_sha256": "<64 hex>",
//!   "payload": { platform_id, description, coordinates, region, normalisation, basis, degree,
//!                n_cables, exponents, coefficients_m, fit_options, validation } }
//! ```
//!
//! The checksum is SHA-256 over the canonical serialisation
//! `"crs-surrogate\n" + format_version + "\n" + compact_json(payload)` (serde field order, `f64`
//! in shortest round-trip form). `f64` values parse back bit-exactly (`serde_json` with
//! `float_roundtrip`), so re-serialising the loaded payload reproduces the hashed bytes; any edit
//! that changes a value, string or count changes the checksum.
//!
//! Loading checks, in order: JSON syntax, format name, format version, schema (unknown or missing
//! fields are refused), checksum, platform identity, internal consistency (shapes, exponent list,
//! normalisation, options), and finally re-proves the bound of eq. (5.27) by evaluating the
//! coefficients on the regenerated validation poses. Every failure is an error naming what
//! mismatched; loading never panics on file content.

use crate::basis::{Basis, MAX_DEGREE, exponents, n_basis};
use crate::certificate::{FitOptions, FitReport};
use crate::design::{DEFAULT_OVERSAMPLING, MAX_SAMPLES, N_GRID, validation_poses};
use crate::model::{MAX_CABLES, Surrogate};
use crate::region::{COORD_NAMES, N_COORDS, Normalisation, Region, pose_string};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// Value of the `format` field.
pub const FORMAT_NAME: &str = "crs-surrogate";
/// Version of the file layout this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

const DESCRIPTION: &str = "Polynomial surrogate phi_sg of the joint-space offset q_off = phi_sg(x) \
(thesis eq. 5.23), added to the standard kinematics. Pose x = [x_m, y_m, z_m, phi_x_rad, \
phi_y_rad, phi_z_rad]. Normalised u_i = clamp((x_i - centre_i) / half_width_i, -1, 1). \
q_off_j(x) = sum_k coefficients_m[j][k] * prod_i p_{exponents[k][i]}(u_i), p_n = Legendre P_n or \
u^n per `basis`; offsets in m. Validation figures in mm.";

const NORMALISATION_RULE: &str = "u_i = clamp((x_i - centre_i) / half_width_i, -1, 1); \
centre = (lower + upper) / 2, half_width = (upper - lower) / 2";

/// Relative/absolute tolerance for comparing recomputed validation figures with stored ones.
const FIGURE_TOL_MM: f64 = 1e-6;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct NormalisationOnDisk {
    rule: String,
    centre: [f64; N_COORDS],
    half_width: [f64; N_COORDS],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Payload {
    platform_id: String,
    description: String,
    coordinates: Vec<String>,
    region: Region,
    normalisation: NormalisationOnDisk,
    basis: Basis,
    degree: usize,
    n_cables: usize,
    exponents: Vec<[u8; N_COORDS]>,
    coefficients_m: Vec<Vec<f64>>,
    fit_options: FitOptions,
    validation: FitReport,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileOnDisk {
    format: String,
    format_version: u32,
    checksum_sha256: String,
    payload: Payload,
}

/// Just enough to check format and version before the full (version-specific) schema.
#[derive(Deserialize)]
struct Header {
    format: Option<serde_json::Value>,
    format_version: Option<serde_json::Value>,
}

/// Why a surrogate file could not be written or was refused on load.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// Reading or writing failed.
    #[error("surrogate file {}: {source}", path.display())]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Not valid JSON or does not match the schema (message names line, column and field).
    #[error("surrogate file {}: {source}", path.display())]
    Parse {
        /// File path.
        path: PathBuf,
        /// Parser error (line/column).
        source: serde_json::Error,
    },
    /// The `format` field is missing or not `crs-surrogate`.
    #[error("surrogate file {}: format is {found}, expected \"{FORMAT_NAME}\"", path.display())]
    Format {
        /// File path.
        path: PathBuf,
        /// What the file says.
        found: String,
    },
    /// The `format_version` is missing or not the one this build reads.
    #[error(
        "surrogate file {}: format_version is {found}, this build reads version {expected}",
        path.display()
    )]
    Version {
        /// File path.
        path: PathBuf,
        /// What the file says.
        found: String,
        /// [`FORMAT_VERSION`].
        expected: u32,
    },
    /// Content does not match its checksum (corrupted or edited).
    #[error(
        "surrogate file {}: checksum mismatch: file says {stored}, content hashes to {computed} \
         (file corrupted or edited)",
        path.display()
    )]
    Checksum {
        /// File path.
        path: PathBuf,
        /// `checksum_sha256` as stored.
        stored: String,
        /// SHA-256 of the canonical payload.
        computed: String,
    },
    /// The surrogate was fitted for another platform.
    #[error(
        "surrogate file {}: platform identity mismatch: file is for \"{found}\", expected \"{expected}\"",
        path.display()
    )]
    Platform {
        /// File path.
        path: PathBuf,
        /// `platform_id` in the file.
        found: String,
        /// The identity the caller expected.
        expected: String,
    },
    /// A field is inconsistent with the rest of the file.
    #[error("surrogate file {}: field `{field}`: {reason}", path.display())]
    Inconsistent {
        /// File path.
        path: PathBuf,
        /// Field name (dotted path inside `payload`).
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// Re-evaluating the coefficients on the validation poses violates eq. (5.27) with margin.
    #[error(
        "surrogate file {}: bound violated: |phi_sg| = {offset_mm:.3} mm for cable {cable} at \
         pose {pose} reaches the limit {limit_mm:.3} mm",
        path.display()
    )]
    BoundViolated {
        /// File path.
        path: PathBuf,
        /// Pose (formatted).
        pose: String,
        /// Cable index.
        cable: usize,
        /// Offset there (mm).
        offset_mm: f64,
        /// bound - margin (mm).
        limit_mm: f64,
    },
}

fn canonical_bytes(format_version: u32, payload: &Payload) -> Result<Vec<u8>, serde_json::Error> {
    let mut bytes = format!("{FORMAT_NAME}\n{format_version}\n").into_bytes();
    serde_json::to_writer(&mut bytes, payload)?;
    Ok(bytes)
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl Surrogate {
    fn payload(&self) -> Payload {
        let norm = Normalisation::new(&self.region);
        let (degree, basis) = self.degree_basis();
        Payload {
            platform_id: self.platform_id.clone(),
            description: DESCRIPTION.to_owned(),
            coordinates: COORD_NAMES.iter().map(|s| s.to_string()).collect(),
            region: self.region,
            normalisation: NormalisationOnDisk {
                rule: NORMALISATION_RULE.to_owned(),
                centre: norm.centre,
                half_width: norm.half_width,
            },
            basis,
            degree,
            n_cables: self.n_cables,
            exponents: exponents(degree),
            coefficients_m: self.coefficients.clone(),
            fit_options: self.options.clone(),
            validation: self.report.clone(),
        }
    }

    /// Serialises to the file text (pretty JSON with checksum).
    fn to_file_text(&self) -> Result<String, serde_json::Error> {
        let payload = self.payload();
        let checksum = sha256_hex(&canonical_bytes(FORMAT_VERSION, &payload)?);
        let file = FileOnDisk {
            format: FORMAT_NAME.to_owned(),
            format_version: FORMAT_VERSION,
            checksum_sha256: checksum,
            payload,
        };
        let mut text = crate::json_layout::to_string(&file)?;
        text.push('\n');
        Ok(text)
    }

    /// Writes the surrogate file (see the module docs of `file` for the layout). The file is
    /// written to `<path>.tmp`, synced, then renamed over `path`, so a reader never sees a
    /// half-written file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), FileError> {
        let path = path.as_ref();
        let text = self.to_file_text().map_err(|e| FileError::Io {
            path: path.to_owned(),
            source: std::io::Error::other(e),
        })?;
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let io = |source| FileError::Io {
            path: path.to_owned(),
            source,
        };
        {
            use std::io::Write;
            let mut f = std::fs::File::create(&tmp).map_err(io)?;
            f.write_all(text.as_bytes()).map_err(io)?;
            f.sync_all().map_err(io)?;
        }
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Loads and verifies a surrogate file written by [`Surrogate::save`].
    ///
    /// Refused (with an error naming what mismatched) if the JSON or schema is invalid, the
    /// format or `format_version` differs, the checksum does not match the content, the
    /// `platform_id` differs from `expected_platform_id`, the content is inconsistent, or the
    /// coefficients re-evaluated on the validation poses violate `bound - margin`.
    pub fn load(path: impl AsRef<Path>, expected_platform_id: &str) -> Result<Self, FileError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| FileError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_file_text(&text, path, expected_platform_id)
    }

    fn from_file_text(
        text: &str,
        path: &Path,
        expected_platform_id: &str,
    ) -> Result<Self, FileError> {
        let p = || path.to_owned();
        let parse = |source| FileError::Parse { path: p(), source };
        let header: Header = serde_json::from_str(text).map_err(parse)?;
        match &header.format {
            Some(serde_json::Value::String(s)) if s == FORMAT_NAME => {}
            other => {
                return Err(FileError::Format {
                    path: p(),
                    found: other
                        .as_ref()
                        .map_or("missing".to_owned(), |v| v.to_string()),
                });
            }
        }
        match &header.format_version {
            Some(v) if v.as_u64() == Some(u64::from(FORMAT_VERSION)) => {}
            other => {
                return Err(FileError::Version {
                    path: p(),
                    found: other
                        .as_ref()
                        .map_or("missing".to_owned(), |v| v.to_string()),
                    expected: FORMAT_VERSION,
                });
            }
        }
        let file: FileOnDisk = serde_json::from_str(text).map_err(parse)?;
        let computed = canonical_bytes(file.format_version, &file.payload)
            .map(|b| sha256_hex(&b))
            .map_err(parse)?;
        if computed != file.checksum_sha256 {
            return Err(FileError::Checksum {
                path: p(),
                stored: file.checksum_sha256,
                computed,
            });
        }
        let pl = file.payload;
        if pl.platform_id != expected_platform_id {
            return Err(FileError::Platform {
                path: p(),
                found: pl.platform_id,
                expected: expected_platform_id.to_owned(),
            });
        }
        check_consistency(&pl).map_err(|(field, reason)| FileError::Inconsistent {
            path: p(),
            field,
            reason,
        })?;
        let surrogate = Surrogate::from_parts(
            pl.platform_id,
            pl.region,
            pl.fit_options,
            pl.validation,
            pl.coefficients_m,
        );
        reprove_bound(&surrogate, path)?;
        Ok(surrogate)
    }
}

type Inconsistency = (&'static str, String);

fn check_consistency(pl: &Payload) -> Result<(), Inconsistency> {
    let err = |field, reason: String| Err((field, reason));
    if pl.coordinates.len() != N_COORDS
        || pl.coordinates.iter().zip(COORD_NAMES).any(|(a, b)| a != b)
    {
        return err(
            "payload.coordinates",
            format!("{:?}, expected {:?}", pl.coordinates, COORD_NAMES),
        );
    }
    if let Err(e) = pl.region.validate() {
        return err("payload.region", e.to_string());
    }
    let norm = Normalisation::new(&pl.region);
    if pl.normalisation.centre != norm.centre || pl.normalisation.half_width != norm.half_width {
        return err(
            "payload.normalisation",
            "centre/half_width do not match the region".to_owned(),
        );
    }
    if pl.degree > MAX_DEGREE {
        return err(
            "payload.degree",
            format!("{} exceeds the maximum {MAX_DEGREE}", pl.degree),
        );
    }
    if pl.n_cables == 0 || pl.n_cables > MAX_CABLES {
        return err(
            "payload.n_cables",
            format!("{} not in 1..={MAX_CABLES}", pl.n_cables),
        );
    }
    if pl.exponents != exponents(pl.degree) {
        return err(
            "payload.exponents",
            format!(
                "not the canonical total-degree-{} basis order of this build",
                pl.degree
            ),
        );
    }
    let nb = n_basis(pl.degree);
    if pl.coefficients_m.len() != pl.n_cables {
        return err(
            "payload.coefficients_m",
            format!(
                "{} rows, n_cables is {}",
                pl.coefficients_m.len(),
                pl.n_cables
            ),
        );
    }
    for (j, row) in pl.coefficients_m.iter().enumerate() {
        if row.len() != nb {
            return err(
                "payload.coefficients_m",
                format!("cable {j} has {} coefficients, expected {nb}", row.len()),
            );
        }
    }
    let o = &pl.fit_options;
    if o.degree != pl.degree || o.basis != pl.basis {
        return err(
            "payload.fit_options",
            "degree/basis differ from payload.degree/basis".to_owned(),
        );
    }
    let limit_ok = o.bound_m.is_finite()
        && o.bound_m > 0.0
        && o.margin_m.is_finite()
        && o.margin_m >= 0.0
        && o.margin_m < o.bound_m;
    if !limit_ok {
        return err(
            "payload.fit_options",
            format!(
                "bound_m {} / margin_m {} out of range",
                o.bound_m, o.margin_m
            ),
        );
    }
    let v = &pl.validation;
    if v.degree != pl.degree
        || v.basis != pl.basis
        || v.n_cables != pl.n_cables
        || v.n_coeffs_per_cable != nb
    {
        return err(
            "payload.validation",
            "degree/basis/n_cables/n_coeffs_per_cable differ from the payload".to_owned(),
        );
    }
    if v.n_validation_samples != N_GRID.saturating_add(o.validation_samples) {
        return err(
            "payload.validation.n_validation_samples",
            format!(
                "{} != {N_GRID} grid + {} validation_samples",
                v.n_validation_samples, o.validation_samples
            ),
        );
    }
    if v.n_fit_samples != o.fit_samples.unwrap_or(DEFAULT_OVERSAMPLING * nb) || v.n_fit_samples < nb
    {
        return err(
            "payload.validation.n_fit_samples",
            format!(
                "{} does not match fit_options.fit_samples {:?} for {nb} coefficients",
                v.n_fit_samples, o.fit_samples
            ),
        );
    }
    if o.validation_samples > MAX_SAMPLES || v.n_fit_samples > MAX_SAMPLES {
        return err(
            "payload.validation",
            "sample counts implausibly large".to_owned(),
        );
    }
    if (v.bound_mm - o.bound_m * 1e3).abs() > FIGURE_TOL_MM
        || (v.margin_mm - o.margin_m * 1e3).abs() > FIGURE_TOL_MM
    {
        return err(
            "payload.validation",
            "bound_mm/margin_mm differ from fit_options".to_owned(),
        );
    }
    Ok(())
}

/// Re-evaluates the loaded coefficients on the regenerated validation poses (and the certified
/// bound) and compares with the limit and with the stored figures.
fn reprove_bound(s: &Surrogate, path: &Path) -> Result<(), FileError> {
    let o = &s.options;
    let r = &s.report;
    let limit_m = o.bound_m - o.margin_m;
    let mut phi = vec![0.0; s.n_cables];
    let mut max_abs = 0.0_f64;
    for pose in validation_poses(&s.region, r.n_fit_samples, o.validation_samples) {
        // Cannot fail: phi has n_cables entries.
        let _ = s.eval(&pose, &mut phi);
        for (cable, v) in phi.iter().enumerate() {
            // NaN counts as a violation.
            if v.is_nan() || v.abs() >= limit_m {
                return Err(FileError::BoundViolated {
                    path: path.to_owned(),
                    pose: pose_string(&pose),
                    cable,
                    offset_mm: v * 1e3,
                    limit_mm: limit_m * 1e3,
                });
            }
            max_abs = max_abs.max(v.abs());
        }
    }
    let inconsistent = |field, reason| FileError::Inconsistent {
        path: path.to_owned(),
        field,
        reason,
    };
    let close = |a: f64, b: f64| (a - b).abs() <= FIGURE_TOL_MM * (1.0 + b.abs());
    if !close(max_abs * 1e3, r.max_abs_offset_mm) {
        return Err(inconsistent(
            "payload.validation.max_abs_offset_mm",
            format!(
                "file says {} mm, the coefficients give {} mm",
                r.max_abs_offset_mm,
                max_abs * 1e3
            ),
        ));
    }
    let cert = s.certified_bounds_m().into_iter().fold(0.0_f64, f64::max);
    if !close(cert * 1e3, r.certified_bound_mm) {
        return Err(inconsistent(
            "payload.validation.certified_bound_mm",
            format!(
                "file says {} mm, the coefficients give {} mm",
                r.certified_bound_mm,
                cert * 1e3
            ),
        ));
    }
    if o.require_certified_bound && (cert.is_nan() || cert >= limit_m) {
        return Err(inconsistent(
            "payload.validation.certified_bound_mm",
            format!(
                "{} mm reaches the limit {} mm while require_certified_bound is set",
                cert * 1e3,
                limit_m * 1e3
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::fit;

    fn small() -> Surrogate {
        let region = Region {
            lower: [-1.0, -1.0, 0.5, -0.1, -0.1, -0.2],
            upper: [1.0, 1.5, 2.0, 0.1, 0.1, 0.2],
        };
        let opts = FitOptions {
            degree: 2,
            validation_samples: 200,
            ..FitOptions::default()
        };
        fit(&region, &opts, 3, "test-platform", |x: &[f64; 6]| {
            Ok::<_, String>([
                0.01 * x[0] + 0.002 * x[1] * x[2],
                -0.02 * x[3] + 0.001,
                0.005 * (x[0] * x[5]).sin(),
            ])
        })
        .unwrap()
        .0
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let s = small();
        let text = s.to_file_text().unwrap();
        let back = Surrogate::from_file_text(&text, Path::new("mem"), "test-platform").unwrap();
        assert_eq!(back.coefficients, s.coefficients);
        assert_eq!(back.report, s.report);
        assert_eq!(back.to_file_text().unwrap(), text);
    }

    #[test]
    fn rechecksummed_file_with_inflated_coefficients_is_refused_by_bound_reproof() {
        // A writer that bypasses `fit` (or a hand edit with a recomputed checksum) cannot smuggle
        // an over-range surrogate past `load`: the bound is re-proved from the coefficients.
        let s = small();
        let mut pl = s.payload();
        pl.coefficients_m[1][0] += 0.5; // +500 mm constant offset on cable 1
        let checksum = sha256_hex(&canonical_bytes(FORMAT_VERSION, &pl).unwrap());
        let text = serde_json::to_string_pretty(&FileOnDisk {
            format: FORMAT_NAME.into(),
            format_version: FORMAT_VERSION,
            checksum_sha256: checksum,
            payload: pl,
        })
        .unwrap();
        let e = Surrogate::from_file_text(&text, Path::new("mem"), "test-platform").unwrap_err();
        assert!(
            matches!(e, FileError::BoundViolated { cable: 1, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("cable 1"), "{e}");
    }

    #[test]
    fn rechecksummed_file_with_falsified_figures_is_refused() {
        let s = small();
        let mut pl = s.payload();
        pl.validation.max_abs_offset_mm *= 0.5;
        let checksum = sha256_hex(&canonical_bytes(FORMAT_VERSION, &pl).unwrap());
        let text = serde_json::to_string(&FileOnDisk {
            format: FORMAT_NAME.into(),
            format_version: FORMAT_VERSION,
            checksum_sha256: checksum,
            payload: pl,
        })
        .unwrap();
        let e = Surrogate::from_file_text(&text, Path::new("mem"), "test-platform").unwrap_err();
        assert!(e.to_string().contains("max_abs_offset_mm"), "{e}");
    }
}
