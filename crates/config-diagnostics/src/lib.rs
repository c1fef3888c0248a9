//! # config-diagnostics: where in which file a configuration is wrong
//!
//! Every loader of the stack (platform, plant, campaign, daemon, drives, monitor TOML) reports
//! bad input the same way: `file:line:column: `key`: message`, so an operator finds the line
//! and nothing is guessed. This crate holds the one [`ConfigError`] and the one [`Locator`]
//! (byte span → 1-based line and column, safe for any span a parser reports, also inside a
//! multi-byte character). It depends on `toml` only (for [`Locator::toml`]).

use std::fmt;
use std::ops::Range;
use std::path::Path;

/// A configuration error with its location.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError {
    pub file: String,
    /// 1-based line and column, when known.
    pub line: Option<usize>,
    pub column: Option<usize>,
    /// Dotted key path, e.g. `geometry.frame_anchors_m[3]`.
    pub key: String,
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let (Some(l), Some(c)) = (self.line, self.column) {
            write!(f, ":{l}:{c}")?;
        }
        if self.key.is_empty() {
            write!(f, ": {}", self.message)
        } else {
            write!(f, ": `{}`: {}", self.key, self.message)
        }
    }
}

impl std::error::Error for ConfigError {}

impl ConfigError {
    /// An error about the whole file (no line), e.g. it cannot be read.
    pub fn file(file: impl Into<String>, message: impl Into<String>) -> Self {
        ConfigError {
            file: file.into(),
            line: None,
            column: None,
            key: String::new(),
            message: message.into(),
        }
    }
}

/// Reads a configuration file; an unreadable or non-UTF-8 file is a [`ConfigError`] naming it.
pub fn read(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path)
        .map_err(|e| ConfigError::file(path.display().to_string(), format!("cannot read: {e}")))
}

/// 1-based (line, column) of byte `offset` in `text`. An offset past the end is clamped, one
/// inside a multi-byte character moves back to its first byte: never panics.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut o = offset.min(text.len());
    while !text.is_char_boundary(o) {
        o -= 1;
    }
    let before = &text[..o];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |p| p + 1) + 1;
    (line, column)
}

/// Turns byte spans of one file's text into located [`ConfigError`]s.
#[derive(Clone, Copy, Debug)]
pub struct Locator<'a> {
    pub text: &'a str,
    pub file: &'a str,
}

impl<'a> Locator<'a> {
    pub fn new(text: &'a str, file: &'a str) -> Self {
        Locator { text, file }
    }

    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        line_col(self.text, offset)
    }

    /// An error at `span` about `key`.
    pub fn err(
        &self,
        span: Range<usize>,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> ConfigError {
        let (line, column) = self.line_col(span.start);
        ConfigError {
            file: self.file.to_string(),
            line: Some(line),
            column: Some(column),
            key: key.into(),
            message: message.into(),
        }
    }

    /// A TOML syntax or schema error from the `toml` crate, at its span when it has one.
    pub fn toml(&self, e: &toml::de::Error) -> ConfigError {
        let message = e.message().trim().to_string();
        match e.span() {
            Some(span) => self.err(span, "", message),
            None => ConfigError::file(self.file, message),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_and_columns_are_one_based() {
        let t = "a = 1\nbb = 2\n";
        assert_eq!(line_col(t, 0), (1, 1));
        assert_eq!(line_col(t, 6), (2, 1));
        assert_eq!(line_col(t, 9), (2, 4));
        assert_eq!(line_col(t, 1000), (3, 1));
    }

    #[test]
    fn a_span_inside_a_multibyte_character_does_not_panic() {
        let t = "name = \"Δq\"\n";
        // Byte 9 is the second byte of 'Δ'.
        assert_eq!(line_col(t, 9), (1, 9));
    }

    #[test]
    fn errors_name_file_line_column_and_key() {
        let t = "[a]\nx = \"no\"\n";
        let l = Locator::new(t, "f.toml");
        let e = l.err(8..12, "a.x", "expected a number");
        assert_eq!(e.to_string(), "f.toml:2:5: `a.x`: expected a number");
        let te = toml::from_str::<toml::Table>("x = = 1").unwrap_err();
        let e = Locator::new("x = = 1", "g.toml").toml(&te);
        assert!(e.to_string().starts_with("g.toml:1:"), "{e}");
        let e = read(Path::new("/nonexistent/config.toml")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/config.toml: cannot read"),
            "{e}"
        );
    }
}
