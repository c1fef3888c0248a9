//! Data-set reader/writer: exact round trip, malformed files rejected with the line number.

#![allow(clippy::needless_range_loop)] // per-cable index loops read like the equations

use cdpr_model::Pose;
use crs_dataset::{Dataset, Phase, Sample, read_dataset, write_dataset};
use crs_dataset::{FORMAT, UNITS};

fn sample_set(forces: bool) -> Dataset {
    let mut ds = Dataset::new(8, forces, true);
    ds.metadata
        .push(("platform".into(), "crs-nominal-ch6".into()));
    ds.metadata.push(("seed".into(), "7".into()));
    for k in 0..3u64 {
        ds.samples.push(Sample {
            sample: k,
            pose_index: k / 2,
            phase: if k == 1 {
                Phase::Tensioned
            } else {
                Phase::Pose
            },
            q_cmd: (0..8)
                .map(|i| 8.0 + 0.1 * i as f64 + 1e-13 * k as f64)
                .collect(),
            pose: Pose::from_array([0.1 / 3.0, -1.2, 1.5, 0.01, -0.02, 1e-17]),
            forces: forces.then(|| {
                (0..8)
                    .map(|i| 1000.0 + std::f64::consts::PI * i as f64)
                    .collect()
            }),
            pose_ref: Some(Pose::from_array([0.0, -1.2, 1.5, 0.0, 0.0, 0.0])),
        });
    }
    ds
}

fn text(ds: &Dataset) -> String {
    let mut buf = Vec::new();
    write_dataset(&mut buf, ds).unwrap();
    String::from_utf8(buf).unwrap()
}

#[test]
fn round_trip_is_exact_with_and_without_forces() {
    for forces in [true, false] {
        let ds = sample_set(forces);
        let t = text(&ds);
        assert!(t.starts_with(&format!("# format: {FORMAT}\n# units: {UNITS}\n")));
        let back = read_dataset(t.as_bytes(), "mem").unwrap();
        assert_eq!(back, ds);
        assert_eq!(back.meta("seed"), Some("7"));
        let header = t.lines().find(|l| !l.starts_with('#')).unwrap();
        assert_eq!(header.contains("f_1"), forces);
        assert!(header.starts_with("sample,pose_index,phase,q_cmd_1,"));
        assert!(header.ends_with("x_ref,y_ref,z_ref,phi_x_ref,phi_y_ref,phi_z_ref"));
    }
}

#[test]
fn minimal_file_without_optional_columns_reads() {
    let mut t = format!("# format: {FORMAT}\n# units: {UNITS}\nsample");
    for i in 1..=8 {
        t += &format!(",q_cmd_{i}");
    }
    t += ",x,y,z,phi_x,phi_y,phi_z\n0,1,2,3,4,5,6,7,8,0.1,0.2,1.5,0,0,0\n";
    let ds = read_dataset(t.as_bytes(), "min").unwrap();
    assert_eq!((ds.m, ds.has_forces, ds.has_reference), (8, false, false));
    assert_eq!(ds.samples[0].phase, Phase::Pose);
    assert_eq!(ds.samples[0].q_cmd[7], 8.0);
}

#[test]
fn comments_after_the_header_crlf_and_blank_lines_read_as_written() {
    let ds = sample_set(true);
    let t = text(&ds);
    let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
    let hdr = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    // A comment with commas and spaces after the header keeps its text exactly.
    let note = "# unreachable: pose_index 39 phase 0 x_ref [-1.5000, 0.0000, 1.5000]: cable 4";
    lines.insert(hdr + 2, note.to_string());
    lines.insert(hdr + 3, "   ".to_string());
    lines.insert(hdr + 4, String::new());
    let crlf = lines.join("\r\n") + "\r\n";
    let back = read_dataset(crlf.as_bytes(), "crlf").unwrap();
    assert_eq!(back.samples, ds.samples);
    assert_eq!(
        back.meta("unreachable"),
        Some("pose_index 39 phase 0 x_ref [-1.5000, 0.0000, 1.5000]: cable 4")
    );
    // A bad row after the comment and the blank line is named by its line in the file.
    let mut bad = lines.clone();
    let last = bad.len() - 1;
    bad[last] = bad[last].replacen(',', ",x", 1);
    for end in ["\n", "\r\n"] {
        let e = read_dataset(bad.join(end).as_bytes(), "bad.csv").unwrap_err();
        assert_eq!(e.line, Some(last + 1), "{e}");
    }
}

fn err_of(t: &str) -> (Option<usize>, String) {
    let e = read_dataset(t.as_bytes(), "bad.csv").unwrap_err();
    assert!(e.to_string().starts_with("bad.csv"));
    (e.line, e.problem.to_string())
}

#[test]
fn malformed_files_are_rejected_with_line_numbers() {
    let good = text(&sample_set(true));
    let lines: Vec<&str> = good.lines().collect();
    let hdr = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    let with = |n: usize, new: &str| {
        let mut l = lines.clone();
        l[n] = new;
        l.join("\n")
    };
    // units never guessed
    let (line, msg) = err_of(&good.replacen(&format!("# units: {UNITS}\n"), "", 1));
    assert_eq!(line, Some(hdr));
    assert!(msg.contains("units"), "{msg}");
    let (line, msg) = err_of(&good.replacen(UNITS, "mm deg N", 1));
    assert_eq!(line, Some(2));
    assert!(msg.contains("units"));
    let (_, msg) = err_of(&good.replacen(FORMAT, "crs-dataset 9", 1));
    assert!(msg.contains("format"));
    // a bad number on the second data row
    let row = hdr + 2;
    let mut fields: Vec<&str> = lines[row].split(',').collect();
    fields[5] = "1.2.3";
    let bad_num = fields.join(",");
    let (line, msg) = err_of(&with(row, &bad_num));
    assert_eq!(line, Some(row + 1));
    assert!(msg.contains("field 6") && msg.contains("1.2.3"), "{msg}");
    fields[5] = "NaN";
    let (line, msg) = err_of(&with(row, &fields.join(",")));
    assert_eq!(line, Some(row + 1));
    assert!(msg.contains("not finite"));
    // wrong field count
    let (line, msg) = err_of(&with(row, "0,1,2"));
    assert_eq!(line, Some(row + 1));
    assert!(msg.contains("expected"));
    // unknown / duplicate / missing columns
    let (line, msg) = err_of(&with(hdr, &lines[hdr].replace("phi_z,", "psi,")));
    assert_eq!(line, Some(hdr + 1));
    assert!(msg.contains("psi"));
    let (_, msg) = err_of(&with(hdr, &lines[hdr].replace("q_cmd_2,", "q_cmd_1,")));
    assert!(msg.contains("duplicate"));
    let (_, msg) = err_of(&with(hdr, &lines[hdr].replace("f_8,", "f_9,")));
    assert!(msg.contains("f_1..f_8"), "{msg}");
    let (_, msg) = err_of(&with(hdr, &lines[hdr].replace("x_ref,", "x_rof,")));
    assert!(msg.contains("x_rof") || msg.contains("reference"), "{msg}");
    // bad phase
    let mut fields: Vec<&str> = lines[row].split(',').collect();
    fields[2] = "7";
    let (_, msg) = err_of(&with(row, &fields.join(",")));
    assert!(msg.contains("phase"));
    // no header at all: the error points at the end of the file
    let (line, msg) = err_of(&format!("# format: {FORMAT}\n# units: {UNITS}\n"));
    assert_eq!(line, Some(2));
    assert!(msg.contains("header"), "{msg}");
}

#[test]
fn writer_refuses_inconsistent_samples() {
    let mut ds = sample_set(true);
    ds.samples[1].forces = None;
    assert!(write_dataset(Vec::new(), &ds).is_err());
    let mut ds = sample_set(false);
    ds.samples[0].q_cmd[3] = f64::INFINITY;
    assert!(write_dataset(Vec::new(), &ds).is_err());
}
