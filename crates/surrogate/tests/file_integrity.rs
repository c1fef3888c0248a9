//! Surrogate file: exact round trip, and refusal of corrupted / mismatched files with messages
//! naming what mismatched.

mod common;

use common::{crs_region, smooth_target};
use std::path::PathBuf;
use surrogate::{FileError, FitOptions, Surrogate, fit};

const PLATFORM: &str = "crs-8cable-sha256:0f3a";

fn fitted() -> Surrogate {
    let opts = FitOptions {
        validation_samples: 1000,
        ..FitOptions::default()
    };
    fit(&crs_region(), &opts, 8, PLATFORM, |x: &[f64; 6]| {
        Ok::<_, String>(smooth_target::<8>(x))
    })
    .unwrap()
    .0
}

fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("surrogate-{name}.json"))
}

#[test]
fn save_load_round_trip_is_bit_exact() {
    let s = fitted();
    let p = tmp("roundtrip");
    s.save(&p).unwrap();
    let l = Surrogate::load(&p, PLATFORM).unwrap();
    for j in 0..8 {
        let (a, b) = (s.coefficients(j).unwrap(), l.coefficients(j).unwrap());
        assert!(
            a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
            "cable {j}"
        );
    }
    assert_eq!(s.report(), l.report());
    assert_eq!(s.region(), l.region());
    assert_eq!(s.options(), l.options());
    assert_eq!(l.platform_id(), PLATFORM);
    let x = [0.3, -1.0, 2.0, 0.1, -0.05, 0.2];
    let (mut a, mut b) = ([0.0; 8], [0.0; 8]);
    s.eval(&x, &mut a).unwrap();
    l.eval(&x, &mut b).unwrap();
    assert_eq!(a, b);
    let text = std::fs::read_to_string(&p).unwrap();
    for key in [
        "\"format\": \"crs-surrogate\"",
        "\"format_version\": 1",
        "\"checksum_sha256\"",
        "\"platform_id\"",
        "\"normalisation\"",
        "\"exponents\"",
        "\"coefficients_m\"",
        "\"max_abs_offset_mm\"",
        "\"condition_number\"",
    ] {
        assert!(text.contains(key), "file lacks {key}");
    }
}

/// Flips one non-zero digit of the text after `key` (the `skip`-th such digit).
fn flip_digit_after(text: &str, key: &str, skip: usize) -> String {
    let start = text.find(key).unwrap() + key.len();
    let off = text[start..]
        .char_indices()
        .filter(|(_, c)| c.is_ascii_digit() && *c != '0')
        .nth(skip)
        .unwrap()
        .0;
    let i = start + off;
    let c = text.as_bytes()[i];
    let flipped = if c == b'9' { b'8' } else { c + 1 };
    let mut bytes = text.as_bytes().to_vec();
    bytes[i] = flipped;
    String::from_utf8(bytes).unwrap()
}

#[test]
fn flipped_digit_is_refused_by_checksum() {
    let s = fitted();
    let p = tmp("flip");
    s.save(&p).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    // A coefficient (first cable, and deep inside the array), a region bound, a validation
    // figure, and the checksum itself.
    for (key, skip) in [
        ("\"coefficients_m\"", 3),
        ("\"coefficients_m\"", 5000),
        ("\"upper\"", 0),
        ("\"max_abs_offset_mm\"", 4),
        ("\"checksum_sha256\"", 10),
    ] {
        let bad = flip_digit_after(&text, key, skip);
        assert_ne!(bad, text);
        std::fs::write(&p, bad).unwrap();
        let e = Surrogate::load(&p, PLATFORM).unwrap_err();
        assert!(matches!(e, FileError::Checksum { .. }), "{key}: {e}");
        let msg = e.to_string();
        assert!(
            msg.contains("checksum mismatch") && msg.contains("surrogate-flip.json"),
            "{msg}"
        );
    }
    // The untouched file still loads: the refusals above are due to the flips.
    std::fs::write(&p, &text).unwrap();
    assert!(Surrogate::load(&p, PLATFORM).is_ok());
}

#[test]
fn platform_mismatch_is_refused_naming_both_identities() {
    let p = tmp("platform");
    fitted().save(&p).unwrap();
    let e = Surrogate::load(&p, "other-platform").unwrap_err();
    assert!(matches!(e, FileError::Platform { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains(PLATFORM) && msg.contains("other-platform"),
        "{msg}"
    );
}

#[test]
fn version_and_format_mismatch_are_refused() {
    let p = tmp("version");
    fitted().save(&p).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(
        &p,
        text.replacen("\"format_version\": 1", "\"format_version\": 2", 1),
    )
    .unwrap();
    let e = Surrogate::load(&p, PLATFORM).unwrap_err();
    assert!(matches!(e, FileError::Version { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("format_version is 2, this build reads version 1"),
        "{e}"
    );

    std::fs::write(
        &p,
        text.replacen("\"crs-surrogate\"", "\"something-else\"", 1),
    )
    .unwrap();
    let e = Surrogate::load(&p, PLATFORM).unwrap_err();
    assert!(matches!(e, FileError::Format { .. }), "{e}");
    assert!(e.to_string().contains("something-else"), "{e}");
}

#[test]
fn truncated_unknown_field_and_missing_file_are_refused_without_panic() {
    let p = tmp("truncated");
    fitted().save(&p).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, &text[..text.len() / 2]).unwrap();
    let e = Surrogate::load(&p, PLATFORM).unwrap_err();
    assert!(matches!(e, FileError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("line"), "{e}");

    std::fs::write(&p, text.replacen("\"degree\":", "\"degre\":", 1)).unwrap();
    let e = Surrogate::load(&p, PLATFORM).unwrap_err();
    assert!(matches!(e, FileError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("degre"), "{e}");

    std::fs::write(&p, "").unwrap();
    assert!(matches!(
        Surrogate::load(&p, PLATFORM),
        Err(FileError::Parse { .. })
    ));
    let e = Surrogate::load(tmp("does-not-exist"), PLATFORM).unwrap_err();
    assert!(matches!(e, FileError::Io { .. }), "{e}");
}

#[test]
fn fit_and_file_are_deterministic() {
    let (a, b) = (tmp("det-a"), tmp("det-b"));
    fitted().save(&a).unwrap();
    fitted().save(&b).unwrap();
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "two fits of the same target produced different files"
    );
}
