//! Structure-aware mutation of seed inputs (the project's own config files, data sets and
//! frames): the cases a coverage-guided fuzzer reaches first on text formats — a byte flipped,
//! a line dropped or doubled, a number replaced by an extreme (NaN, ±inf, −0, 1e308, i64 edges),
//! a key renamed, a table header broken, the file cut short — stacked a few at a time so deeper
//! combinations appear too. Deterministic for a seed, so every failure is reproducible.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// Numbers a parser and the checks after it must survive.
const EXTREMES: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "+inf",
    "-0",
    "-0.0",
    "0",
    "1e308",
    "-1e308",
    "1e-320",
    "9223372036854775807",
    "-9223372036854775808",
    "18446744073709551616",
    "4294967296",
    "-1",
    "0x7FF",
    "1_000",
    "1e",
    ".",
    "-",
    "1.7976931348623157e308",
    "2.2250738585072014e-308",
    "99999999999999999999999999999",
    "\"1.0\"",
    "[]",
    "{}",
    "true",
];

/// Tokens that break TOML/CSV/JSON structure.
const BREAKERS: &[&str] = &[
    "[",
    "]",
    "[[",
    "]]",
    "=",
    ",",
    "\"",
    "'",
    "{",
    "}",
    "#",
    "\n",
    "\r\n",
    "\t",
    "\\",
    "\u{0}",
    "\u{FEFF}",
    "é",
    "\u{202E}",
    ",,",
    "[[x]]",
    "[x]\n",
    "a.b.c = 1\n",
    ":",
    "null",
];

/// A mutator over one seed set.
pub struct Mutator {
    rng: SmallRng,
    seeds: Vec<Vec<u8>>,
}

impl Mutator {
    pub fn new(seed: u64, seeds: Vec<Vec<u8>>) -> Self {
        assert!(!seeds.is_empty(), "a mutator needs at least one seed input");
        Self {
            rng: SmallRng::seed_from_u64(seed),
            seeds,
        }
    }

    pub fn rng(&mut self) -> &mut SmallRng {
        &mut self.rng
    }

    /// The next case: a seed with 1–6 stacked mutations (now and then the seed itself, or
    /// random bytes).
    pub fn next_case(&mut self) -> Vec<u8> {
        let pick = self.rng.random_range(0..self.seeds.len());
        let mut v = self.seeds[pick].clone();
        match self.rng.random_range(0..100) {
            0 => return v,
            1 => {
                let n = self.rng.random_range(0..512);
                return (0..n).map(|_| self.rng.random()).collect();
            }
            _ => {}
        }
        let rounds = self.rng.random_range(1..=6);
        for _ in 0..rounds {
            self.mutate(&mut v);
        }
        v
    }

    fn mutate(&mut self, v: &mut Vec<u8>) {
        let r = &mut self.rng;
        match r.random_range(0..11) {
            // Replace a number token by an extreme.
            0..=2 => {
                if let Some((s, e)) = number_span(v, r) {
                    let x = EXTREMES[r.random_range(0..EXTREMES.len())].as_bytes();
                    v.splice(s..e, x.iter().copied());
                }
            }
            // Flip a bit.
            3 => {
                if !v.is_empty() {
                    let i = r.random_range(0..v.len());
                    v[i] ^= 1 << r.random_range(0..8);
                }
            }
            // Insert a structure breaker.
            4 => {
                let i = r.random_range(0..=v.len());
                let b = BREAKERS[r.random_range(0..BREAKERS.len())].as_bytes();
                v.splice(i..i, b.iter().copied());
            }
            // Drop, double or swap lines.
            5..=7 => {
                let lines = line_spans(v);
                if lines.len() > 1 {
                    let a = lines[r.random_range(0..lines.len())];
                    let b = lines[r.random_range(0..lines.len())];
                    match r.random_range(0..3) {
                        0 => {
                            v.drain(a.0..a.1);
                        }
                        1 => {
                            let copy = v[a.0..a.1].to_vec();
                            v.splice(b.0..b.0, copy);
                        }
                        _ => {
                            let (x, y) = if a.0 < b.0 { (a, b) } else { (b, a) };
                            if x.1 <= y.0 {
                                let lx = v[x.0..x.1].to_vec();
                                let ly = v[y.0..y.1].to_vec();
                                v.splice(y.0..y.1, lx);
                                v.splice(x.0..x.1, ly);
                            }
                        }
                    }
                }
            }
            // Cut the input short.
            8 => {
                if !v.is_empty() {
                    let n = r.random_range(0..v.len());
                    v.truncate(n);
                }
            }
            // Copy a chunk of the input somewhere else (duplicate keys, tables, rows).
            9 => {
                if v.len() > 2 {
                    let s = r.random_range(0..v.len() - 1);
                    let e = (s + r.random_range(1..64)).min(v.len());
                    let chunk = v[s..e].to_vec();
                    let at = r.random_range(0..=v.len());
                    v.splice(at..at, chunk);
                }
            }
            // Rename an identifier (unknown key / missing key).
            _ => {
                if let Some((s, e)) = ident_span(v, r) {
                    let suffix = [b"_x".as_slice(), b"", b"Z", b"_m_deg"][r.random_range(0..4)];
                    let keep = r.random_range(0..=(e - s));
                    v.splice(s + keep..e, suffix.iter().copied());
                }
            }
        }
    }
}

fn line_spans(v: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut s = 0;
    for (i, b) in v.iter().enumerate() {
        if *b == b'\n' {
            out.push((s, i + 1));
            s = i + 1;
        }
    }
    if s < v.len() {
        out.push((s, v.len()));
    }
    out
}

fn spans_where(
    v: &[u8],
    start: impl Fn(u8) -> bool,
    cont: impl Fn(u8) -> bool,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < v.len() {
        if start(v[i]) {
            let s = i;
            while i < v.len() && cont(v[i]) {
                i += 1;
            }
            out.push((s, i.max(s + 1).min(v.len())));
        } else {
            i += 1;
        }
    }
    out
}

fn number_span(v: &[u8], r: &mut SmallRng) -> Option<(usize, usize)> {
    let spans = spans_where(
        v,
        |b| b.is_ascii_digit() || b == b'-',
        |b| b.is_ascii_digit() || matches!(b, b'.' | b'-' | b'e' | b'E' | b'+' | b'_'),
    );
    (!spans.is_empty()).then(|| spans[r.random_range(0..spans.len())])
}

fn ident_span(v: &[u8], r: &mut SmallRng) -> Option<(usize, usize)> {
    let spans = spans_where(
        v,
        |b| b.is_ascii_alphabetic(),
        |b| b.is_ascii_alphanumeric() || b == b'_',
    );
    (!spans.is_empty()).then(|| spans[r.random_range(0..spans.len())])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_for_a_seed_and_actually_mutates() {
        let seeds = vec![b"[a]\nx = 1.5\ny = [1, 2, 3]\n".to_vec()];
        let mut a = Mutator::new(7, seeds.clone());
        let mut b = Mutator::new(7, seeds.clone());
        let xs: Vec<_> = (0..200).map(|_| a.next_case()).collect();
        let ys: Vec<_> = (0..200).map(|_| b.next_case()).collect();
        assert_eq!(xs, ys);
        let changed = xs.iter().filter(|x| **x != seeds[0]).count();
        assert!(
            changed > 150,
            "only {changed} of 200 cases differ from the seed"
        );
    }
}
