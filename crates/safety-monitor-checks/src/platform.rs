//! The monitor's OWN reading of the platform TOML (`config/icosahedron.toml`; the format's
//! owner is `cdpr_model::config`). Only the parameters the monitor needs are read (geometry for
//! the standard kinematics, the workspace box, the force range and motion limits it checks) plus
//! those the platform identity hashes (stiffness, load, pulleys).
//!
//! Diverse redundancy: the motion core reads this file through serde-derived structs
//! and the model library's validation (`cdpr_model::config`, `Model::new`). The monitor shares
//! none of that: it lets the `toml` crate build the spanned document tree
//! ([`toml::de::DeTable`]) and walks it by hand with the small typed accessors of [`Walker`];
//! its checks are its own ([`check`]). The one piece both readers share is the TOML tokenizer.
//! A fault in a derive, a struct or a validation rule on one side cannot reach the other side the
//! same way; the two readings meet only in the platform identity (`identity.rs`), which must
//! agree bit for bit, and the golden vector in `crs_ipc::identity_golden` pins that identity for
//! both.
//!
//! Every error names the file, the line and column of the offending value (or key) and its full
//! path down to the element, e.g. `geometry.frame_anchors_m[3][1]`.

use glam::DVec3;
use std::fmt;
use std::ops::Range;
use std::path::Path;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// A platform file the monitor cannot use.
#[derive(Debug, Clone, PartialEq)]
pub struct PlatformError {
    pub file: String,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// 1-based column (in characters), when known.
    pub column: Option<usize>,
    /// Path of the value, e.g. `geometry.platform_anchors_m[3][0]`; empty for a syntax error.
    pub key: String,
    pub message: String,
}

impl fmt::Display for PlatformError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        if self.key.is_empty() {
            write!(f, ": {}", self.message)
        } else {
            write!(f, ": `{}`: {}", self.key, self.message)
        }
    }
}

impl std::error::Error for PlatformError {}

/// Operating box of the pose the monitor enforces (`[workspace]`), SI (m, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkspaceBox {
    pub position_min_m: DVec3,
    pub position_max_m: DVec3,
    pub rotation_min_rad: DVec3,
    pub rotation_max_rad: DVec3,
}

impl WorkspaceBox {
    /// The box widened by `margin_m` / `margin_rad` on every side.
    pub fn widened(&self, margin_m: f64, margin_rad: f64) -> Self {
        Self {
            position_min_m: self.position_min_m - DVec3::splat(margin_m),
            position_max_m: self.position_max_m + DVec3::splat(margin_m),
            rotation_min_rad: self.rotation_min_rad - DVec3::splat(margin_rad),
            rotation_max_rad: self.rotation_max_rad + DVec3::splat(margin_rad),
        }
    }

    /// True if every coordinate of `pose` = [x, y, z, φx, φy, φz] lies inside (NaN never does).
    pub fn contains(&self, pose: &[f64; 6]) -> bool {
        let lo = [self.position_min_m, self.rotation_min_rad];
        let hi = [self.position_max_m, self.rotation_max_rad];
        (0..6).all(|k| {
            let (l, h) = (lo[k / 3][k % 3], hi[k / 3][k % 3]);
            pose[k] >= l && pose[k] <= h
        })
    }
}

/// Pulley parameters (only hashed into the identity; the monitor checks against the standard
/// kinematics, sec. 5.6).
#[derive(Debug, Clone, PartialEq)]
pub struct PulleyParams {
    pub radius_m: Vec<f64>,
    /// Unit swivel axes (normalised here, as the motion core normalises them).
    pub axis: Vec<DVec3>,
}

/// The parameters the monitor read from the platform TOML.
#[derive(Debug, Clone, PartialEq)]
pub struct PlatformParams {
    pub name: String,
    /// Frame-side cable exit points a_i (world frame), m (eq. 2.4).
    pub frame_anchors_m: Vec<DVec3>,
    /// Platform anchor points b_i^(P) (platform frame), m (eq. 2.4, 2.6).
    pub platform_anchors_m: Vec<DVec3>,
    pub pulleys: Option<PulleyParams>,
    /// k_F per cable, N.
    pub k_f_n: Vec<f64>,
    /// External wrench [f; τ], N and N·m.
    pub wrench_n_nm: [f64; 6],
    pub f_min_n: f64,
    pub f_max_n: f64,
    pub workspace: WorkspaceBox,
    /// Table 5.1 motion limits (the `[limits]` table), SI: m/s, rad/s, m/s², rad/s².
    pub limits: MotionLimits,
}

/// Table 5.1: largest platform velocities and accelerations, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    pub linear_velocity_m_per_s: f64,
    pub angular_velocity_rad_per_s: f64,
    pub linear_acceleration_m_per_s2: f64,
    pub angular_acceleration_rad_per_s2: f64,
}

impl PlatformParams {
    /// Number of cables m.
    pub fn cables(&self) -> usize {
        self.frame_anchors_m.len()
    }
}

/// Degrees to radians: the factor `f64::to_radians` multiplies by, so that the monitor's
/// radians are bit-identical to the motion core's (the identity hashes exact bits).
const RAD_PER_DEG: f64 = std::f64::consts::PI / 180.0;

/// Two anchor points closer than this are the same point (the Jacobian would be singular).
const DISTINCT_ANCHOR_M: f64 = 1e-9;

/// Reads and validates the platform TOML at `path`.
pub fn load_platform(path: &Path) -> Result<PlatformParams, PlatformError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| PlatformError {
        file: file.clone(),
        line: None,
        column: None,
        key: String::new(),
        message: format!("cannot read: {e}"),
    })?;
    parse_platform(&text, &file)
}

/// Parses and validates platform TOML text (`file` names it in errors).
pub fn parse_platform(text: &str, file: &str) -> Result<PlatformParams, PlatformError> {
    let w = Walker { text, file };
    let doc = DeTable::parse(text).map_err(|e| w.syntax_error(&e))?;
    let root = Table {
        at: Place::root(),
        entries: doc.get_ref(),
    };
    let read = read_document(&w, &root)?;
    check::all(&w, &read)?;
    Ok(read.into_params())
}

/// Where a value sits: its path from the document root and its byte range in the text
/// (`None` for something that is absent, e.g. a missing table).
#[derive(Clone, Debug)]
struct Place {
    path: String,
    span: Option<Range<usize>>,
}

impl Place {
    fn root() -> Self {
        Self {
            path: String::new(),
            span: None,
        }
    }

    fn child(&self, key: &str, span: Range<usize>) -> Self {
        let path = if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.path)
        };
        Self {
            path,
            span: Some(span),
        }
    }

    /// The place of an absent `key` of this table: its path, located at the table (header).
    fn missing(&self, key: &str) -> Self {
        let mut at = self.child(key, 0..0);
        at.span = self.span.clone();
        at
    }

    fn element(&self, i: usize, span: Range<usize>) -> Self {
        Self {
            path: format!("{}[{i}]", self.path),
            span: Some(span),
        }
    }
}

/// A finite number read from the file, kept with its place so that a later check can point
/// at exactly this value.
#[derive(Clone, Debug)]
struct Num {
    x: f64,
    at: Place,
}

/// A 3-vector read from the file (a row such as `[-5.380, 7.677, 6.524]`).
#[derive(Clone, Debug)]
struct Row {
    xyz: [Num; 3],
    at: Place,
}

impl Row {
    fn vec(&self) -> DVec3 {
        DVec3::new(self.xyz[0].x, self.xyz[1].x, self.xyz[2].x)
    }
}

/// An array of rows (anchor points, pulley axes) with the array's own place.
#[derive(Clone, Debug)]
struct Rows {
    rows: Vec<Row>,
    at: Place,
}

/// A table of the document being walked.
struct Table<'d, 'i> {
    at: Place,
    entries: &'d DeTable<'i>,
}

/// A value of the document being walked.
struct Item<'d, 'i> {
    at: Place,
    value: &'d DeValue<'i>,
}

/// The monitor's typed accessors over the spanned TOML tree of one file; every failure becomes
/// a [`PlatformError`] at the value's line and column.
struct Walker<'t> {
    text: &'t str,
    file: &'t str,
}

impl Walker<'_> {
    /// 1-based line and column (characters) of byte `offset`.
    fn line_column(&self, offset: usize) -> (usize, usize) {
        let mut end = offset.min(self.text.len());
        while !self.text.is_char_boundary(end) {
            end -= 1;
        }
        let before = &self.text[..end];
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        (
            before.matches('\n').count() + 1,
            before[line_start..].chars().count() + 1,
        )
    }

    fn error(&self, at: &Place, message: impl Into<String>) -> PlatformError {
        let (line, column) = at.span.as_ref().map(|s| self.line_column(s.start)).unzip();
        PlatformError {
            file: self.file.to_string(),
            line,
            column,
            key: at.path.clone(),
            message: message.into(),
        }
    }

    fn syntax_error(&self, e: &toml::de::Error) -> PlatformError {
        let (line, column) = e.span().map(|s| self.line_column(s.start)).unzip();
        PlatformError {
            file: self.file.to_string(),
            line,
            column,
            key: String::new(),
            message: e.message().trim().to_string(),
        }
    }

    /// The entry `key` of `table`, if present.
    fn get<'d, 'i>(&self, table: &Table<'d, 'i>, key: &str) -> Option<Item<'d, 'i>> {
        table
            .entries
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == key)
            .map(|(_, v)| Item {
                at: table.at.child(key, v.span()),
                value: v.get_ref(),
            })
    }

    /// The entry `key` of `table`; its absence is an error at the table.
    fn require<'d, 'i>(
        &self,
        table: &Table<'d, 'i>,
        key: &str,
    ) -> Result<Item<'d, 'i>, PlatformError> {
        self.get(table, key).ok_or_else(|| {
            let what = if table.at.path.is_empty() {
                format!("the file has no [{key}] table")
            } else {
                format!("[{}] has no key `{key}`", table.at.path)
            };
            self.error(&table.at.missing(key), what)
        })
    }

    fn table<'d, 'i>(&self, item: Item<'d, 'i>) -> Result<Table<'d, 'i>, PlatformError> {
        match item.value {
            DeValue::Table(entries) => Ok(Table {
                at: item.at,
                entries,
            }),
            other => Err(self.error(
                &item.at,
                format!("expected a table, found {}", a_type(other)),
            )),
        }
    }

    /// A table the monitor reads: every key in it must be one the monitor knows (`known`), so
    /// that a key it does not understand cannot silently change what the motion core does.
    fn known_table<'d, 'i>(
        &self,
        parent: &Table<'d, 'i>,
        key: &str,
        known: &[&str],
    ) -> Result<Table<'d, 'i>, PlatformError> {
        let t = self.table(self.require(parent, key)?)?;
        self.only_keys(&t, known)?;
        Ok(t)
    }

    /// Like [`Walker::known_table`], for a table that may be absent.
    fn optional_known_table<'d, 'i>(
        &self,
        parent: &Table<'d, 'i>,
        key: &str,
        known: &[&str],
    ) -> Result<Option<Table<'d, 'i>>, PlatformError> {
        let Some(item) = self.get(parent, key) else {
            return Ok(None);
        };
        let t = self.table(item)?;
        self.only_keys(&t, known)?;
        Ok(Some(t))
    }

    fn only_keys(&self, t: &Table, known: &[&str]) -> Result<(), PlatformError> {
        match t
            .entries
            .iter()
            .find(|(k, _)| !known.contains(&k.get_ref().as_ref()))
        {
            Some((k, _)) => Err(self.error(
                &t.at.child(k.get_ref(), k.span()),
                format!(
                    "unknown key (the keys of [{}] are: {})",
                    t.at.path,
                    known.join(", ")
                ),
            )),
            None => Ok(()),
        }
    }

    /// A number: TOML float or integer (integers as `i64 as f64`, as serde reads them), and
    /// finite (nan and ±inf are refused for every number the monitor reads).
    fn number(&self, item: &Item) -> Result<Num, PlatformError> {
        let x = match item.value {
            DeValue::Float(f) => f
                .as_str()
                .parse::<f64>()
                .map_err(|_| self.error(&item.at, format!("`{}` is not a number", f.as_str())))?,
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix())
                .map(|i| i as f64)
                .map_err(|_| self.error(&item.at, format!("integer {i} is out of range")))?,
            other => {
                return Err(self.error(
                    &item.at,
                    format!("expected a number, found {}", a_type(other)),
                ));
            }
        };
        if !x.is_finite() {
            return Err(self.error(&item.at, format!("must be a finite number, got {x}")));
        }
        Ok(Num {
            x,
            at: item.at.clone(),
        })
    }

    /// The elements of an array, each with its own path (`key[i]`) and place.
    fn elements<'d, 'i>(&self, item: &Item<'d, 'i>) -> Result<Vec<Item<'d, 'i>>, PlatformError> {
        match item.value {
            DeValue::Array(xs) => Ok(xs
                .iter()
                .enumerate()
                .map(|(i, v): (usize, &'d Spanned<DeValue<'i>>)| Item {
                    at: item.at.element(i, v.span()),
                    value: v.get_ref(),
                })
                .collect()),
            other => Err(self.error(
                &item.at,
                format!("expected an array, found {}", a_type(other)),
            )),
        }
    }

    /// An array of exactly `n` numbers.
    fn numbers(&self, item: &Item, n: usize) -> Result<Vec<Num>, PlatformError> {
        let xs = self.elements(item)?;
        if xs.len() != n {
            return Err(self.error(
                &item.at,
                format!("expected {n} numbers, found {}", xs.len()),
            ));
        }
        xs.iter().map(|x| self.number(x)).collect()
    }

    fn row(&self, item: &Item) -> Result<Row, PlatformError> {
        let v = self.numbers(item, 3)?;
        Ok(Row {
            xyz: [v[0].clone(), v[1].clone(), v[2].clone()],
            at: item.at.clone(),
        })
    }

    fn rows(&self, item: &Item) -> Result<Rows, PlatformError> {
        Ok(Rows {
            rows: self
                .elements(item)?
                .iter()
                .map(|r| self.row(r))
                .collect::<Result<_, _>>()?,
            at: item.at.clone(),
        })
    }

    /// One value per cable: a single number for all `m` cables, or an array of exactly `m`.
    fn per_cable(&self, item: &Item, m: usize) -> Result<Vec<Num>, PlatformError> {
        match item.value {
            DeValue::Array(xs) if xs.len() != m => Err(self.error(
                &item.at,
                format!("has {} entries but there are {m} cables", xs.len()),
            )),
            DeValue::Array(_) => self.numbers(item, m),
            _ => Ok(vec![self.number(item)?; m]),
        }
    }

    fn string(&self, item: &Item) -> Result<String, PlatformError> {
        match item.value {
            DeValue::String(s) => Ok(s.to_string()),
            other => Err(self.error(
                &item.at,
                format!("expected a string, found {}", a_type(other)),
            )),
        }
    }
}

fn a_type(v: &DeValue) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

/// Everything read from the file, still with places, before the cross-field checks.
struct Read {
    name: String,
    name_at: Place,
    frame_anchors: Rows,
    platform_anchors: Rows,
    /// Radii and swivel axes.
    pulleys: Option<(Vec<Num>, Rows)>,
    k_f: Vec<Num>,
    wrench: Vec<Num>,
    f_min: Num,
    f_max: Num,
    position_min: Row,
    position_max: Row,
    rotation_min_deg: Row,
    rotation_max_deg: Row,
    /// Linear velocity, angular velocity (deg/s), linear acceleration, angular acceleration
    /// (deg/s²), in the file's units.
    limits: [Num; 4],
}

/// Walks the tables the monitor uses. `[winch]`, `[home]`, `[dynamics]` and `[sections]` are
/// the motion core's alone and are not read.
fn read_document(w: &Walker, root: &Table) -> Result<Read, PlatformError> {
    let platform = w.table(w.require(root, "platform")?)?;
    let name_item = w.require(&platform, "name")?;
    let name = w.string(&name_item)?;
    let name_at = name_item.at;

    let geometry = w.known_table(root, "geometry", &["frame_anchors_m", "platform_anchors_m"])?;
    let a_item = w.require(&geometry, "frame_anchors_m")?;
    let frame_anchors = w.rows(&a_item)?;
    // m comes from the frame anchors; it must be settled before any per-cable value is read.
    check::cable_count(w, &frame_anchors)?;
    let m = frame_anchors.rows.len();
    let platform_anchors = w.rows(&w.require(&geometry, "platform_anchors_m")?)?;

    let pulleys = match w.optional_known_table(root, "pulleys", &["radius_m", "swivel_axes"])? {
        None => None,
        Some(t) => {
            let radius = w.per_cable(&w.require(&t, "radius_m")?, m)?;
            let axes = w.rows(&w.require(&t, "swivel_axes")?)?;
            Some((radius, axes))
        }
    };

    let elasticity = w.known_table(root, "elasticity", &["k_f_n"])?;
    let k_f = w.per_cable(&w.require(&elasticity, "k_f_n")?, m)?;
    let load = w.known_table(root, "load", &["wrench_n_nm"])?;
    let wrench = w.numbers(&w.require(&load, "wrench_n_nm")?, 6)?;
    // f_abs_max_n is the motion core's (winch dimensioning); the monitor checks the operating
    // range f_min..f_max.
    let forces = w.known_table(root, "forces", &["f_min_n", "f_max_n", "f_abs_max_n"])?;
    let f_min = w.number(&w.require(&forces, "f_min_n")?)?;
    let f_max = w.number(&w.require(&forces, "f_max_n")?)?;

    let ws_keys = [
        "position_min_m",
        "position_max_m",
        "rotation_min_deg",
        "rotation_max_deg",
    ];
    let ws = w.known_table(root, "workspace", &ws_keys)?;
    let [
        position_min,
        position_max,
        rotation_min_deg,
        rotation_max_deg,
    ] = ws_keys.map(|k| w.require(&ws, k).and_then(|item| w.row(&item)));

    let limit_keys = [
        "linear_velocity_max_m_per_s",
        "angular_velocity_max_deg_per_s",
        "linear_acceleration_max_m_per_s2",
        "angular_acceleration_max_deg_per_s2",
    ];
    let lt = w.known_table(root, "limits", &limit_keys)?;
    let [v, om, a, al] = limit_keys.map(|k| w.require(&lt, k).and_then(|item| w.number(&item)));

    Ok(Read {
        name,
        name_at,
        frame_anchors,
        platform_anchors,
        pulleys,
        k_f,
        wrench,
        f_min,
        f_max,
        position_min: position_min?,
        position_max: position_max?,
        rotation_min_deg: rotation_min_deg?,
        rotation_max_deg: rotation_max_deg?,
        limits: [v?, om?, a?, al?],
    })
}

/// The monitor's own rules over what was read; each failure points at the offending value.
mod check {
    use super::{DISTINCT_ANCHOR_M, Num, PlatformError, Read, Row, Rows, Walker};
    use crs_ipc::MAX_CABLES;

    pub(super) fn all(w: &Walker, r: &Read) -> Result<(), PlatformError> {
        let m = r.frame_anchors.rows.len();
        same_count(w, &r.platform_anchors, m)?;
        distinct(w, &r.frame_anchors.rows)?;
        distinct(w, &r.platform_anchors.rows)?;
        if let Some((radius, axes)) = &r.pulleys {
            for x in radius {
                at_least_zero(w, x)?;
            }
            same_count(w, axes, m)?;
            for a in &axes.rows {
                if super::unit(a).is_none() {
                    return Err(w.error(&a.at, "must be a non-zero vector"));
                }
            }
        }
        for k in &r.k_f {
            if k.x <= 0.0 {
                return Err(w.error(&k.at, format!("must be > 0, got {} N", k.x)));
            }
        }
        at_least_zero(w, &r.f_min)?;
        if r.f_max.x <= r.f_min.x {
            return Err(w.error(
                &r.f_max.at,
                format!(
                    "must be greater than forces.f_min_n ({} N <= {} N)",
                    r.f_max.x, r.f_min.x
                ),
            ));
        }
        for k in 0..3 {
            let (lo, hi) = (&r.position_min.xyz[k], &r.position_max.xyz[k]);
            if hi.x <= lo.x {
                return Err(w.error(
                    &hi.at,
                    format!("must be greater than {} ({})", lo.at.path, lo.x),
                ));
            }
            let (lo, hi) = (&r.rotation_min_deg.xyz[k], &r.rotation_max_deg.xyz[k]);
            if hi.x < lo.x {
                return Err(w.error(&hi.at, format!("must be >= {} ({})", lo.at.path, lo.x)));
            }
        }
        for l in &r.limits {
            if l.x <= 0.0 {
                return Err(w.error(&l.at, format!("must be > 0, got {}", l.x)));
            }
        }
        if r.name.trim().is_empty() {
            return Err(w.error(&r.name_at, "must not be empty"));
        }
        Ok(())
    }

    /// 1..=MAX_CABLES cables (the IPC payloads carry at most MAX_CABLES).
    pub(super) fn cable_count(w: &Walker, a: &Rows) -> Result<(), PlatformError> {
        let m = a.rows.len();
        if m == 0 || m > MAX_CABLES {
            return Err(w.error(&a.at, format!("needs 1..={MAX_CABLES} rows, got {m}")));
        }
        Ok(())
    }

    fn same_count(w: &Walker, r: &Rows, m: usize) -> Result<(), PlatformError> {
        if r.rows.len() != m {
            return Err(w.error(
                &r.at,
                format!("has {} rows but there are {m} cables", r.rows.len()),
            ));
        }
        Ok(())
    }

    /// No two anchors of one side coincide (the structure matrix would lose rank).
    fn distinct(w: &Walker, rows: &[Row]) -> Result<(), PlatformError> {
        for (j, b) in rows.iter().enumerate() {
            if let Some(i) = rows[..j]
                .iter()
                .position(|a| a.vec().distance(b.vec()) < DISTINCT_ANCHOR_M)
            {
                return Err(w.error(
                    &b.at,
                    format!("coincides with row {i} (anchor points must be distinct)"),
                ));
            }
        }
        Ok(())
    }

    fn at_least_zero(w: &Walker, n: &Num) -> Result<(), PlatformError> {
        if n.x < 0.0 {
            return Err(w.error(&n.at, format!("must be >= 0, got {}", n.x)));
        }
        Ok(())
    }
}

/// The unit vector along `r`, or `None` for a (near) zero vector. Normalised as the motion core
/// normalises pulley axes (Euclidean norm x² + y² + z² summed in that order, then each
/// component divided by it), so the identities agree bit for bit.
fn unit(r: &Row) -> Option<DVec3> {
    let [x, y, z] = [r.xyz[0].x, r.xyz[1].x, r.xyz[2].x];
    let n = (x * x + y * y + z * z).sqrt();
    (n >= 1e-12).then(|| DVec3::new(x / n, y / n, z / n))
}

impl Read {
    /// The checked values in SI (degrees converted here, at the edge).
    fn into_params(self) -> PlatformParams {
        let vecs = |rows: &[Row]| rows.iter().map(Row::vec).collect::<Vec<_>>();
        let xs = |nums: &[Num]| nums.iter().map(|n| n.x).collect::<Vec<_>>();
        let mut wrench_n_nm = [0.0; 6];
        for (dst, n) in wrench_n_nm.iter_mut().zip(&self.wrench) {
            *dst = n.x;
        }
        let [v, om, a, al] = self.limits.map(|n| n.x);
        PlatformParams {
            name: self.name.trim().to_string(),
            frame_anchors_m: vecs(&self.frame_anchors.rows),
            platform_anchors_m: vecs(&self.platform_anchors.rows),
            pulleys: self.pulleys.as_ref().map(|(radius, axes)| PulleyParams {
                radius_m: xs(radius),
                // `check::all` refused zero axes.
                axis: axes.rows.iter().filter_map(unit).collect(),
            }),
            k_f_n: xs(&self.k_f),
            wrench_n_nm,
            f_min_n: self.f_min.x,
            f_max_n: self.f_max.x,
            workspace: WorkspaceBox {
                position_min_m: self.position_min.vec(),
                position_max_m: self.position_max.vec(),
                rotation_min_rad: self.rotation_min_deg.vec() * RAD_PER_DEG,
                rotation_max_rad: self.rotation_max_deg.vec() * RAD_PER_DEG,
            },
            limits: MotionLimits {
                linear_velocity_m_per_s: v,
                angular_velocity_rad_per_s: om * RAD_PER_DEG,
                linear_acceleration_m_per_s2: a,
                angular_acceleration_rad_per_s2: al * RAD_PER_DEG,
            },
        }
    }
}
