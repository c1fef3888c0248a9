//! CSV tables of numbers under a fixed header: pilot tracks (ride-physics), vehicle tracks
//! (motion-cueing), waypoint files (motion-core). One reader, on the `csv` crate, so that
//! comments, blank lines, CRLF line ends and field positions mean the same in every such file;
//! each format checks its own values and words its own errors.
//!
//! The layout: lines whose first non-blank character is `#`, and blank lines, are comments
//! anywhere; the first other line is the header, which must equal the format's column names
//! (blanks around a name are ignored); every later line is a row with exactly as many fields.
//! No quoting: every field is a number.

/// One field of a row.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// The field's text without the blanks around it.
    pub text: String,
    /// 1-based character column of the field's first non-blank character in its line.
    pub column: usize,
}

/// One row of the table.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// 1-based line in the file.
    pub line: usize,
    /// As many fields as the header has columns.
    pub fields: Vec<Field>,
}

/// The table's rows and where its header was.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// 1-based line of the header.
    pub header_line: usize,
    pub rows: Vec<Row>,
}

/// Why a text is not a table of the expected shape.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TableError {
    /// Only comments and blank lines; `lines` is the number of lines in the text.
    #[error("no header line")]
    NoHeader { lines: usize },
    /// The header differs from the expected column names; `found` is the header line as read.
    #[error("line {line}: header must be `{expected}`, got `{found}`")]
    Header {
        line: usize,
        expected: String,
        found: String,
    },
    /// A row with another number of fields than the header.
    #[error("line {line}: has {found} columns, expected {expected}")]
    Columns {
        line: usize,
        found: usize,
        expected: usize,
    },
    /// The csv reader failed (not reachable on valid UTF-8 text; kept so nothing panics).
    #[error("line {line}: {message}")]
    Csv { line: usize, message: String },
}

impl TableError {
    /// The line the error is on (1 for a text without a header) and what is wrong, in words
    /// without the line: for formats whose errors read `file:line: message`.
    pub fn line_and_message(&self) -> (usize, String) {
        match self {
            TableError::NoHeader { .. } => (1, "empty: no header line".into()),
            TableError::Header {
                line,
                expected,
                found,
            } => (*line, format!("header must be `{expected}`, got `{found}`")),
            TableError::Columns {
                line,
                found,
                expected,
            } => (*line, format!("has {found} columns, expected {expected}")),
            TableError::Csv { line, message } => (*line, message.clone()),
        }
    }
}

/// 1-based line of the first character at or after a byte offset that is not a line end.
#[derive(Default)]
struct LineCounter {
    byte: usize,
    newlines: usize,
}

impl LineCounter {
    fn line_at(&mut self, text: &str, byte: usize) -> usize {
        let bytes = text.as_bytes();
        let mut start = byte.min(bytes.len());
        while start < bytes.len() && bytes[start] == b'\n' {
            start += 1;
        }
        if start >= self.byte {
            self.newlines += bytes[self.byte..start]
                .iter()
                .filter(|b| **b == b'\n')
                .count();
            self.byte = start;
        }
        self.newlines + 1
    }
}

/// Calls `each` with the 1-based line and the fields of every record of `text` that is not a
/// blank line, and `comment` with the line and text after the `#` of every comment line.
pub(crate) fn for_each_record<E>(
    text: &str,
    mut each: impl FnMut(usize, &csv::StringRecord) -> Result<(), E>,
    mut comment: impl FnMut(usize, &str),
    csv_error: impl Fn(usize, String) -> E,
) -> Result<(), E> {
    // `\n` alone ends a record: a `\r` before it stays in the last field and is trimmed with
    // the blanks. csv skips empty lines and reports a record's position from where it started
    // reading, so the line is counted here from the record's byte offset.
    let mut csv = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .quoting(false)
        .terminator(csv::Terminator::Any(b'\n'))
        .from_reader(text.as_bytes());
    let mut lines = LineCounter::default();
    let mut record = csv::StringRecord::new();
    loop {
        let more = csv.read_record(&mut record).map_err(|e| {
            let at = e.position().map_or(0, |p| p.byte() as usize);
            csv_error(lines.line_at(text, at), e.to_string())
        })?;
        if !more {
            return Ok(());
        }
        let line = lines.line_at(text, record.position().map_or(0, |p| p.byte() as usize));
        let first = record.get(0).unwrap_or("").trim_start();
        if let Some(c) = first.strip_prefix('#') {
            // No quoting: the line's text is its pieces joined by the commas that split them.
            let mut text = c.to_string();
            for piece in record.iter().skip(1) {
                text.push(',');
                text.push_str(piece);
            }
            comment(line, text.trim_end_matches('\r'));
        } else if !(record.len() == 1 && first.trim().is_empty()) {
            each(line, &record)?;
        }
    }
}

/// Reads `text` as a table with the columns `header`.
pub fn read_table(text: &str, header: &[&str]) -> Result<Table, TableError> {
    let mut header_line = None;
    let mut rows = Vec::new();
    for_each_record(
        text,
        |line, record| {
            let Some(_) = header_line else {
                if !record.iter().map(str::trim).eq(header.iter().copied()) {
                    return Err(TableError::Header {
                        line,
                        expected: header.join(","),
                        found: record
                            .iter()
                            .collect::<Vec<_>>()
                            .join(",")
                            .trim()
                            .to_string(),
                    });
                }
                header_line = Some(line);
                return Ok(());
            };
            if record.len() != header.len() {
                return Err(TableError::Columns {
                    line,
                    found: record.len(),
                    expected: header.len(),
                });
            }
            let mut column = 1;
            let fields = record
                .iter()
                .map(|raw| {
                    let blanks = raw.chars().count() - raw.trim_start().chars().count();
                    let f = Field {
                        text: raw.trim().to_string(),
                        column: column + blanks,
                    };
                    column += raw.chars().count() + 1;
                    f
                })
                .collect();
            rows.push(Row { line, fields });
            Ok(())
        },
        |_, _| {},
        |line, message| TableError::Csv { line, message },
    )?;
    match header_line {
        Some(header_line) => Ok(Table { header_line, rows }),
        None => Err(TableError::NoHeader {
            lines: text.lines().count(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: [&str; 3] = ["t_s", "a", "b"];

    #[test]
    fn comments_blank_lines_and_crlf_are_skipped_and_lines_counted() {
        let t = "# a comment, with a comma\r\n\r\n  t_s , a,b\r\n0, 1.5,2\r\n  # another\r\n   \r\n1,2,3\r\n";
        let tab = read_table(t, &H).unwrap();
        assert_eq!(tab.header_line, 3);
        assert_eq!(tab.rows.len(), 2);
        assert_eq!((tab.rows[0].line, tab.rows[1].line), (4, 7));
        let f = &tab.rows[0].fields[1];
        assert_eq!((f.text.as_str(), f.column), ("1.5", 4));
        assert_eq!(tab.rows[1].fields[2].column, 5);
    }

    #[test]
    fn a_wrong_header_a_short_row_and_no_header_are_named() {
        assert_eq!(
            read_table("t_s,a,c\n0,1,2\n", &H).unwrap_err(),
            TableError::Header {
                line: 1,
                expected: "t_s,a,b".into(),
                found: "t_s,a,c".into()
            }
        );
        assert_eq!(
            read_table("# x\nt_s,a,b\n0,1\n", &H).unwrap_err(),
            TableError::Columns {
                line: 3,
                found: 2,
                expected: 3
            }
        );
        assert_eq!(
            read_table("# only\n\n", &H).unwrap_err(),
            TableError::NoHeader { lines: 2 }
        );
    }
}
