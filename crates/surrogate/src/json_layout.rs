//! The surrogate file's JSON layout: serde_json's pretty layout (two-space indent), except that
//! an array whose first element is a number or literal (a pose, an exponent tuple, a row of
//! coefficients) stays on one line, `[0, 0, 1, 0, 0, 2]`, so the file reads and diffs well.
//! A serde_json [`Formatter`]: only whitespace differs from `to_string_pretty`, the parsed
//! content (and so the checksum) is the same.

use serde_json::ser::{CompactFormatter, Formatter};
use std::io::{self, Write};

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// No element written yet.
    Undecided,
    /// Elements separated by `, ` on the array's line.
    Inline,
    /// One element per line, indented.
    Lines,
}

enum Frame {
    /// `has_key`: a key was written (the closing brace goes on its own line).
    Object { has_key: bool },
    /// `first`: the next element is the first; `pending`: an element was announced
    /// (`begin_array_value`) and its separator not yet written.
    Array {
        mode: Mode,
        first: bool,
        pending: bool,
    },
}

/// Pretty JSON with arrays of scalars on one line.
#[derive(Default)]
pub struct ScalarArraysInline {
    stack: Vec<Frame>,
    /// Containers open (the indent level).
    depth: usize,
    /// A key is being written (its string is not a value).
    in_key: bool,
}

fn indent<W: ?Sized + Write>(w: &mut W, depth: usize) -> io::Result<()> {
    for _ in 0..depth {
        w.write_all(b"  ")?;
    }
    Ok(())
}

impl ScalarArraysInline {
    /// Writes the separator of an element about to start; `scalar`: a number or literal.
    fn open_value<W: ?Sized + Write>(&mut self, w: &mut W, scalar: bool) -> io::Result<()> {
        if self.in_key {
            return Ok(());
        }
        let depth = self.depth;
        if let Some(Frame::Array {
            mode,
            first,
            pending,
        }) = self.stack.last_mut()
            && *pending
        {
            *pending = false;
            if *mode == Mode::Undecided {
                *mode = if scalar { Mode::Inline } else { Mode::Lines };
            }
            match (*mode, *first) {
                (Mode::Inline, true) => {}
                (Mode::Inline, false) => w.write_all(b", ")?,
                (_, true) => {
                    w.write_all(b"\n")?;
                    indent(w, depth)?;
                }
                (_, false) => {
                    w.write_all(b",\n")?;
                    indent(w, depth)?;
                }
            }
        }
        Ok(())
    }
}

macro_rules! scalar {
    ($($name:ident: $t:ty),* $(,)?) => {$(
        fn $name<W: ?Sized + Write>(&mut self, w: &mut W, value: $t) -> io::Result<()> {
            self.open_value(w, true)?;
            CompactFormatter.$name(w, value)
        }
    )*};
}

impl Formatter for ScalarArraysInline {
    scalar!(
        write_bool: bool, write_i8: i8, write_i16: i16, write_i32: i32, write_i64: i64,
        write_i128: i128, write_u8: u8, write_u16: u16, write_u32: u32, write_u64: u64,
        write_u128: u128, write_f32: f32, write_f64: f64, write_number_str: &str,
    );

    fn write_null<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.open_value(w, true)?;
        w.write_all(b"null")
    }

    fn begin_string<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        // An array of strings keeps one element per line, as the pretty layout does.
        self.open_value(w, false)?;
        w.write_all(b"\"")
    }

    fn begin_array<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.open_value(w, false)?;
        self.depth += 1;
        self.stack.push(Frame::Array {
            mode: Mode::Undecided,
            first: true,
            pending: false,
        });
        w.write_all(b"[")
    }

    fn begin_array_value<W: ?Sized + Write>(&mut self, _w: &mut W, first: bool) -> io::Result<()> {
        if let Some(Frame::Array {
            first: f, pending, ..
        }) = self.stack.last_mut()
        {
            *f = first;
            *pending = true;
        }
        Ok(())
    }

    fn end_array_value<W: ?Sized + Write>(&mut self, _w: &mut W) -> io::Result<()> {
        Ok(())
    }

    fn end_array<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.depth -= 1;
        if let Some(Frame::Array {
            mode: Mode::Lines, ..
        }) = self.stack.pop()
        {
            w.write_all(b"\n")?;
            indent(w, self.depth)?;
        }
        w.write_all(b"]")
    }

    fn begin_object<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.open_value(w, false)?;
        self.depth += 1;
        self.stack.push(Frame::Object { has_key: false });
        w.write_all(b"{")
    }

    fn begin_object_key<W: ?Sized + Write>(&mut self, w: &mut W, first: bool) -> io::Result<()> {
        if let Some(Frame::Object { has_key }) = self.stack.last_mut() {
            *has_key = true;
        }
        self.in_key = true;
        w.write_all(if first { b"\n" } else { b",\n" })?;
        indent(w, self.depth)
    }

    fn end_object_key<W: ?Sized + Write>(&mut self, _w: &mut W) -> io::Result<()> {
        self.in_key = false;
        Ok(())
    }

    fn begin_object_value<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        w.write_all(b": ")
    }

    fn end_object_value<W: ?Sized + Write>(&mut self, _w: &mut W) -> io::Result<()> {
        Ok(())
    }

    fn end_object<W: ?Sized + Write>(&mut self, w: &mut W) -> io::Result<()> {
        self.depth -= 1;
        if let Some(Frame::Object { has_key: true }) = self.stack.pop() {
            w.write_all(b"\n")?;
            indent(w, self.depth)?;
        }
        w.write_all(b"}")
    }
}

/// `value` as pretty JSON with arrays of scalars on one line.
pub fn to_string<T: serde::Serialize + ?Sized>(value: &T) -> Result<String, serde_json::Error> {
    let mut out = Vec::new();
    let mut ser = serde_json::Serializer::with_formatter(&mut out, ScalarArraysInline::default());
    value.serialize(&mut ser)?;
    // serde_json writes valid UTF-8.
    String::from_utf8(out).map_err(|e| serde::ser::Error::custom(e.to_string()))
}

#[cfg(test)]
mod tests {
    #[test]
    fn scalar_arrays_on_one_line_strings_and_containers_as_pretty() {
        let v = serde_json::json!({
            "s": "a [1,\n 2] \"q\" [x]",
            "n": [[1, 2], [3.5, -4e-7]],
            "e": [],
            "eo": {},
            "o": [{"a": [true, null]}],
            "ss": ["a", "b"]
        });
        let text = super::to_string(&v).unwrap();
        let expected = r#"{
  "e": [],
  "eo": {},
  "n": [
    [1, 2],
    [3.5, -4e-7]
  ],
  "o": [
    {
      "a": [true, null]
    }
  ],
  "s": "a [1,\n 2] \"q\" [x]",
  "ss": [
    "a",
    "b"
  ]
}"#;
        assert_eq!(text, expected);
        let back: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(back, v);
        // Only whitespace differs from serde_json's own pretty layout.
        let strip = |t: &str| t.split_whitespace().collect::<String>();
        assert_eq!(
            strip(&text),
            strip(&serde_json::to_string_pretty(&v).unwrap())
        );
    }
}
