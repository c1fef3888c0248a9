//! # crs-dataset: the measurement data-set format
//!
//! Measurement data sets (docs/data-format.md): CSV with `#` metadata lines, one header row and
//! one row per sample. Units are fixed (SI: m, rad, N) and declared in the file; a reader
//! rejects a file that does not declare them, never guesses. Every error names the line.

pub mod table;

use cdpr_model::Pose;
use std::fmt;
use std::io::{BufRead, BufReader, Write};

use std::path::Path;

/// Value of the mandatory `# format:` line.
pub const FORMAT: &str = "crs-dataset 1";
/// Value of the mandatory `# units:` line.
pub const UNITS: &str = "SI (q_cmd m; x y z m; phi rad, R = Rx Ry Rz eq. 2.2; f N)";

/// What a row was recorded for (campaign step).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// The platform commanded to the reference pose.
    Pose = 0,
    /// Tension test: all cables shortened (Fig. 6.15).
    Tensioned = 1,
    /// Tension test: cables returned to the pose command.
    Returned = 2,
}

impl Phase {
    fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(Phase::Pose),
            1 => Some(Phase::Tensioned),
            2 => Some(Phase::Returned),
            _ => None,
        }
    }
}

/// One sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Running sample number.
    pub sample: u64,
    /// Index of the reference pose in the campaign.
    pub pose_index: u64,
    pub phase: Phase,
    /// Commanded (controlled) cable lengths, m.
    pub q_cmd: Vec<f64>,
    /// Measured pose (m, rad).
    pub pose: Pose,
    /// Measured cable forces, N (when the data set has force columns).
    pub forces: Option<Vec<f64>>,
    /// Commanded reference pose (when the data set has reference columns).
    pub pose_ref: Option<Pose>,
}

/// A data set: metadata, column layout, samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// `# key: value` lines other than `format` and `units`, in file order.
    pub metadata: Vec<(String, String)>,
    /// Number of cables m.
    pub m: usize,
    pub has_forces: bool,
    pub has_reference: bool,
    pub samples: Vec<Sample>,
}

impl Dataset {
    pub fn new(m: usize, has_forces: bool, has_reference: bool) -> Self {
        Self {
            metadata: Vec::new(),
            m,
            has_forces,
            has_reference,
            samples: Vec::new(),
        }
    }

    /// First metadata value of `key`.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// Column names of the header row.
    pub fn columns(&self) -> Vec<String> {
        let mut c = vec!["sample".to_string(), "pose_index".into(), "phase".into()];
        c.extend((1..=self.m).map(|i| format!("q_cmd_{i}")));
        c.extend(POSE_COLS.iter().map(|s| s.to_string()));
        if self.has_forces {
            c.extend((1..=self.m).map(|i| format!("f_{i}")));
        }
        if self.has_reference {
            c.extend(POSE_COLS.iter().map(|s| format!("{s}_ref")));
        }
        c
    }
}

const POSE_COLS: [&str; 6] = ["x", "y", "z", "phi_x", "phi_y", "phi_z"];

/// A malformed data set.
#[derive(Debug)]
pub struct DatasetError {
    pub file: String,
    /// 1-based line, when the problem is on one line.
    pub line: Option<usize>,
    pub problem: Problem,
}

impl fmt::Display for DatasetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{l}: {}", self.file, self.problem),
            None => write!(f, "{}: {}", self.file, self.problem),
        }
    }
}

impl std::error::Error for DatasetError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.problem)
    }
}

/// What is wrong with a data set being read ([`DatasetError`] adds the file and line).
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    #[error("cannot open: {0}")]
    Open(#[source] std::io::Error),
    #[error("cannot read: {0}")]
    Read(#[source] std::io::Error),
    #[error("metadata line must read `# key: value`")]
    MetadataLine,
    #[error("unsupported format `{found}` (expected `{expected}`)", expected = FORMAT)]
    Format { found: String },
    #[error("unsupported units `{found}` (expected `{expected}`)", expected = UNITS)]
    Units { found: String },
    #[error("missing `# format: {expected}` before the header", expected = FORMAT)]
    MissingFormat,
    #[error("missing `# units:` declaration before the header (units are never guessed)")]
    MissingUnits,
    #[error("end of file before the header row")]
    NoHeader,
    #[error("duplicate column `{0}`")]
    DuplicateColumn(String),
    #[error("unknown column `{0}`")]
    UnknownColumn(String),
    #[error("no `q_cmd_1..q_cmd_m` columns")]
    NoCableColumns,
    #[error("`q_cmd_i` columns must be numbered 1..m without gaps")]
    CableColumnGaps,
    /// Force columns present but not one per cable, numbered 1..m.
    #[error("force columns must be `f_1..f_{m}` (one per cable)")]
    ForceColumns { m: usize },
    #[error("missing column `{0}`")]
    MissingColumn(&'static str),
    #[error("reference pose columns must be all of `x_ref..phi_z_ref` or none")]
    PartialReference,
    #[error("expected {expected} fields, got {got}")]
    FieldCount { expected: usize, got: usize },
    /// `field` is 1-based, `text` as in the file.
    #[error("field {field} `{text}` is not a number")]
    NotANumber { field: usize, text: String },
    #[error("field {field} `{text}` is not finite")]
    NotFinite { field: usize, text: String },
    #[error("field {field} `{text}` is not a non-negative integer")]
    NotAnInteger { field: usize, text: String },
    #[error("phase `{0}` is not 0, 1 or 2")]
    Phase(u64),
}

/// Why [`write_dataset`] refuses a data set (as the InvalidInput error's payload).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WriteProblem {
    /// Sample `sample` does not match the column layout or holds a non-finite number.
    #[error("sample {sample}: {what}")]
    Sample { sample: u64, what: &'static str },
    #[error("invalid metadata key `{0}`")]
    MetadataKey(String),
}

/// Writes a data set. Numbers use Rust's shortest round-trip form, so a file read back gives
/// the identical values. Refuses (InvalidInput, nothing written) a data set whose samples do
/// not match its column layout or hold non-finite numbers.
pub fn write_dataset(mut w: impl Write, ds: &Dataset) -> std::io::Result<()> {
    check(ds).map_err(|m| std::io::Error::new(std::io::ErrorKind::InvalidInput, m))?;
    writeln!(w, "# format: {FORMAT}")?;
    writeln!(w, "# units: {UNITS}")?;
    for (k, v) in &ds.metadata {
        writeln!(w, "# {k}: {}", v.replace('\n', " "))?;
    }
    // The rows through the `csv` crate; every field is a number, so nothing is ever quoted.
    let mut out = csv::WriterBuilder::new()
        .quote_style(csv::QuoteStyle::Never)
        .from_writer(&mut w);
    out.write_record(ds.columns())
        .map_err(std::io::Error::other)?;
    let mut fields: Vec<String> = Vec::new();
    for s in &ds.samples {
        fields.clear();
        fields.extend([
            s.sample.to_string(),
            s.pose_index.to_string(),
            (s.phase as u8).to_string(),
        ]);
        // `{}` of an f64 is Rust's shortest round-trip form.
        let numbers = s
            .q_cmd
            .iter()
            .copied()
            .chain(s.pose.to_array())
            .chain(s.forces.iter().flatten().copied())
            .chain(s.pose_ref.map(|p| p.to_array()).into_iter().flatten());
        fields.extend(numbers.map(|v| v.to_string()));
        out.write_record(&fields).map_err(std::io::Error::other)?;
    }
    out.flush()?;
    Ok(())
}

fn check(ds: &Dataset) -> Result<(), WriteProblem> {
    for s in &ds.samples {
        let bad = |what: &'static str| {
            Err(WriteProblem::Sample {
                sample: s.sample,
                what,
            })
        };
        if s.q_cmd.len() != ds.m {
            return bad("q_cmd has the wrong length");
        }
        if ds.has_forces != s.forces.is_some() || s.forces.as_ref().is_some_and(|f| f.len() != ds.m)
        {
            return bad("forces do not match the force columns");
        }
        if ds.has_reference != s.pose_ref.is_some() {
            return bad("reference pose does not match the reference columns");
        }
        let all = s
            .q_cmd
            .iter()
            .chain(s.forces.iter().flatten())
            .chain(s.pose.to_array().iter())
            .chain(s.pose_ref.map(|p| p.to_array()).iter().flatten())
            .all(|v| v.is_finite());
        if !all {
            return bad("non-finite value");
        }
    }
    for (k, v) in &ds.metadata {
        if k.is_empty() || k.contains(':') || k.contains('\n') || k == "format" || k == "units" {
            return Err(WriteProblem::MetadataKey(k.clone()));
        }
        let _ = v;
    }
    Ok(())
}

/// Writes a data set to a file.
pub fn save_dataset(path: impl AsRef<Path>, ds: &Dataset) -> std::io::Result<()> {
    let f = std::fs::File::create(path)?;
    let mut w = std::io::BufWriter::new(f);
    write_dataset(&mut w, ds)?;
    w.flush()
}

/// Reads a data set from a file.
pub fn load_dataset(path: impl AsRef<Path>) -> Result<Dataset, DatasetError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| DatasetError {
        file: name.clone(),
        line: None,
        problem: Problem::Open(e),
    })?;
    read_dataset(BufReader::new(f), &name)
}

/// Reads a data set; `name` labels errors. Rejects: missing/unknown `format` or `units`
/// declarations, unknown, duplicate or missing columns, rows with the wrong number of fields,
/// unparsable or non-finite numbers, cable columns not numbered 1..m.
pub fn read_dataset(r: impl BufRead, name: &str) -> Result<Dataset, DatasetError> {
    let err = |line: Option<usize>, problem: Problem| DatasetError {
        file: name.to_string(),
        line,
        problem,
    };
    let mut metadata = Vec::new();
    let mut format_seen = false;
    let mut units_seen = false;
    let mut samples = Vec::new();
    // Up to the header row line by line (the metadata lines are not CSV); the rows after it
    // through the `csv` crate.
    let mut r = r;
    let mut ln = 0;
    let mut buf = String::new();
    let lay = loop {
        buf.clear();
        if r.read_line(&mut buf)
            .map_err(|e| err(Some(ln + 1), Problem::Read(e)))?
            == 0
        {
            return Err(err(Some(ln.max(1)), Problem::NoHeader));
        }
        ln += 1;
        let line = buf.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            let Some((k, v)) = c.split_once(':') else {
                return Err(err(Some(ln), Problem::MetadataLine));
            };
            let (k, v) = (k.trim(), v.trim());
            match k {
                "format" if v != FORMAT => {
                    let found = v.to_string();
                    return Err(err(Some(ln), Problem::Format { found }));
                }
                "format" => format_seen = true,
                "units" if v != UNITS => {
                    let found = v.to_string();
                    return Err(err(Some(ln), Problem::Units { found }));
                }
                "units" => units_seen = true,
                _ => metadata.push((k.to_string(), v.to_string())),
            }
            continue;
        }
        if !format_seen {
            return Err(err(Some(ln), Problem::MissingFormat));
        }
        if !units_seen {
            return Err(err(Some(ln), Problem::MissingUnits));
        }
        break Layout::parse(line).map_err(|m| err(Some(ln), m))?;
    };
    let header_line = ln;
    // The rows through the `csv` crate (crate::table).
    let mut body = String::new();
    r.read_to_string(&mut body)
        .map_err(|e| err(Some(header_line + 1), Problem::Read(e)))?;
    table::for_each_record(
        &body,
        |line, record| {
            let ln = header_line + line;
            samples.push(lay.row(record).map_err(|m| err(Some(ln), m))?);
            Ok(())
        },
        // Comment lines after the header are allowed; `# key: value` ones (e.g.
        // `# unreachable: …`) are kept as metadata.
        |_, c| {
            if let Some((k, v)) = c.split_once(':') {
                metadata.push((k.trim().to_string(), v.trim().to_string()));
            }
        },
        |line, message| {
            let e = std::io::Error::new(std::io::ErrorKind::InvalidData, message);
            err(Some(header_line + line), Problem::Read(e))
        },
    )?;
    Ok(Dataset {
        metadata,
        m: lay.m,
        has_forces: lay.f.is_some(),
        has_reference: lay.r.is_some(),
        samples,
    })
}

struct Layout {
    n_cols: usize,
    m: usize,
    sample: usize,
    pose_index: Option<usize>,
    phase: Option<usize>,
    q: Vec<usize>,
    x: [usize; 6],
    f: Option<Vec<usize>>,
    r: Option<[usize; 6]>,
}

fn numbered(col: &str, prefix: &str) -> Option<usize> {
    col.strip_prefix(prefix)
        .and_then(|s| s.parse::<usize>().ok())
        .filter(|i| *i >= 1)
}

impl Layout {
    fn parse(header: &str) -> Result<Self, Problem> {
        let cols: Vec<&str> = header.split(',').map(|c| c.trim()).collect();
        let mut seen = std::collections::HashSet::new();
        for c in &cols {
            if !seen.insert(*c) {
                return Err(Problem::DuplicateColumn(c.to_string()));
            }
        }
        let find = |name: &str| cols.iter().position(|c| *c == name);
        let mut q = Vec::new();
        let mut f = Vec::new();
        for (k, c) in cols.iter().enumerate() {
            let known = ["sample", "pose_index", "phase"].contains(c)
                || POSE_COLS.contains(c)
                || POSE_COLS.iter().any(|p| c.strip_suffix("_ref") == Some(p));
            if known {
                continue;
            }
            if let Some(i) = numbered(c, "q_cmd_") {
                q.push((i, k));
            } else if let Some(i) = numbered(c, "f_") {
                f.push((i, k));
            } else {
                return Err(Problem::UnknownColumn(c.to_string()));
            }
        }
        q.sort();
        f.sort();
        let m = q.len();
        if m == 0 {
            return Err(Problem::NoCableColumns);
        }
        if q.iter().enumerate().any(|(j, (i, _))| *i != j + 1) {
            return Err(Problem::CableColumnGaps);
        }
        let f = if f.is_empty() {
            None
        } else {
            if f.len() != m || f.iter().enumerate().any(|(j, (i, _))| *i != j + 1) {
                return Err(Problem::ForceColumns { m });
            }
            Some(f.into_iter().map(|(_, k)| k).collect())
        };
        let sample = find("sample").ok_or(Problem::MissingColumn("sample"))?;
        let mut x = [0; 6];
        for (j, p) in POSE_COLS.iter().enumerate() {
            x[j] = find(p).ok_or(Problem::MissingColumn(p))?;
        }
        let refs: Vec<Option<usize>> = POSE_COLS
            .iter()
            .map(|p| find(&format!("{p}_ref")))
            .collect();
        let r = if refs.iter().all(|r| r.is_none()) {
            None
        } else if refs.iter().all(|r| r.is_some()) {
            let mut r = [0; 6];
            for (j, v) in refs.iter().enumerate() {
                r[j] = v.unwrap_or(0);
            }
            Some(r)
        } else {
            return Err(Problem::PartialReference);
        };
        Ok(Layout {
            n_cols: cols.len(),
            m,
            sample,
            pose_index: find("pose_index"),
            phase: find("phase"),
            q: q.into_iter().map(|(_, k)| k).collect(),
            x,
            f,
            r,
        })
    }

    fn row(&self, record: &csv::StringRecord) -> Result<Sample, Problem> {
        let fields: Vec<&str> = record.iter().map(|c| c.trim()).collect();
        if fields.len() != self.n_cols {
            return Err(Problem::FieldCount {
                expected: self.n_cols,
                got: fields.len(),
            });
        }
        let num = |k: usize| -> Result<f64, Problem> {
            let v: f64 = fields[k].parse().map_err(|_| Problem::NotANumber {
                field: k + 1,
                text: fields[k].to_string(),
            })?;
            if !v.is_finite() {
                return Err(Problem::NotFinite {
                    field: k + 1,
                    text: fields[k].to_string(),
                });
            }
            Ok(v)
        };
        let int = |k: usize| -> Result<u64, Problem> {
            fields[k].parse().map_err(|_| Problem::NotAnInteger {
                field: k + 1,
                text: fields[k].to_string(),
            })
        };
        let pose = |ix: &[usize; 6]| -> Result<Pose, Problem> {
            let mut a = [0.0; 6];
            for (j, k) in ix.iter().enumerate() {
                a[j] = num(*k)?;
            }
            Ok(Pose::from_array(a))
        };
        let sample = int(self.sample)?;
        let phase = match self.phase {
            None => Phase::Pose,
            Some(k) => {
                let c = int(k)?;
                u8::try_from(c)
                    .ok()
                    .and_then(Phase::from_code)
                    .ok_or(Problem::Phase(c))?
            }
        };
        Ok(Sample {
            sample,
            pose_index: match self.pose_index {
                Some(k) => int(k)?,
                None => sample,
            },
            phase,
            q_cmd: self.q.iter().map(|k| num(*k)).collect::<Result<_, _>>()?,
            pose: pose(&self.x)?,
            forces: match &self.f {
                Some(ix) => Some(ix.iter().map(|k| num(*k)).collect::<Result<_, _>>()?),
                None => None,
            },
            pose_ref: match &self.r {
                Some(ix) => Some(pose(ix)?),
                None => None,
            },
        })
    }
}
