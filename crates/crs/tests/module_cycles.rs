//! No two source files of a crate import each other: a file that needs another and is needed
//! by it is one unit split in two, or a third file's content living in one of them. Read from
//! the sources (`crate::a::…` and `super::a` paths in code, comments left out), tests included.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file under `src` (`a/b.rs` and `a/b/mod.rs` → `a::b`; the crate root
/// and binaries' roots → "").
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts.join("::")
}

/// The code of a file without its comments (line comments and doc comments).
fn code(text: &str) -> String {
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Identifier paths following `prefix` in `code` (`crate::a::b` → `a::b`).
fn paths_after<'a>(code: &'a str, prefix: &'a str) -> impl Iterator<Item = String> + 'a {
    code.match_indices(prefix).map(move |(i, _)| {
        code[i + prefix.len()..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':')
            .collect::<String>()
            .trim_end_matches(':')
            .to_string()
    })
}

/// Pairs of modules of the crate at `src` that import each other.
fn mutual_imports(src: &Path) -> Vec<(String, String)> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeMap<String, PathBuf> = files
        .iter()
        .map(|f| (module_of(src, f), f.clone()))
        .collect();
    let mut uses: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (m, f) in &modules {
        let text = code(&std::fs::read_to_string(f).unwrap());
        let mut found = BTreeSet::new();
        for p in paths_after(&text, "crate::") {
            // The longest prefix of the path that is a file of the crate.
            let segs: Vec<&str> = p.split("::").collect();
            if let Some(target) = (1..=segs.len())
                .rev()
                .map(|k| segs[..k].join("::"))
                .find(|c| modules.contains_key(c))
            {
                found.insert(target);
            }
        }
        let parent: Vec<&str> = m.split("::").filter(|s| !s.is_empty()).collect();
        if !parent.is_empty() {
            for p in paths_after(&text, "super::") {
                let first = p.split("::").next().unwrap_or("");
                let mut c = parent[..parent.len() - 1].to_vec();
                c.push(first);
                let c = c.join("::");
                if modules.contains_key(&c) {
                    found.insert(c);
                }
            }
        }
        found.remove(m);
        let (key, _) = modules.get_key_value(m).unwrap();
        uses.entry(key.as_str()).or_default().extend(
            found
                .iter()
                .map(|t| modules.get_key_value(t).unwrap().0.as_str()),
        );
    }
    let mut pairs = Vec::new();
    for (a, targets) in &uses {
        for b in targets {
            if a < b && uses.get(b).is_some_and(|t| t.contains(a)) {
                pairs.push((a.to_string(), b.to_string()));
            }
        }
    }
    pairs
}

/// Pairs allowed to import each other: none is left. The list only shrinks (a pair that is
/// gone must be struck from it, so the check cannot go stale).
const KNOWN: &[&str] = &[];

#[test]
fn no_two_files_of_a_crate_import_each_other() {
    let crates = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut found = Vec::new();
    for e in std::fs::read_dir(&crates).unwrap().flatten() {
        let src = e.path().join("src");
        if src.is_dir() {
            for (a, b) in mutual_imports(&src) {
                found.push(format!("{}: {a} <-> {b}", e.file_name().to_string_lossy()));
            }
        }
    }
    found.sort();
    let new: Vec<&String> = found
        .iter()
        .filter(|f| !KNOWN.contains(&f.as_str()))
        .collect();
    assert!(new.is_empty(), "files importing each other: {new:#?}");
    let gone: Vec<&&str> = KNOWN
        .iter()
        .filter(|k| !found.iter().any(|f| f == *k))
        .collect();
    assert!(
        gone.is_empty(),
        "strike these from KNOWN, they no longer import each other: {gone:?}"
    );
}

/// The check sees a pair: two files of a scratch crate importing each other, one by
/// `crate::` and one by `super::`.
#[test]
fn a_pair_is_seen() {
    let dir = std::env::temp_dir().join(format!("module-cycles-{}", std::process::id()));
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("a")).unwrap();
    std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\n").unwrap();
    std::fs::write(src.join("a/mod.rs"), "use crate::b::B; // crate::c\n").unwrap();
    std::fs::write(src.join("b.rs"), "fn f() { super::a::g() }\n").unwrap();
    assert_eq!(mutual_imports(&src), vec![("a".into(), "b".into())]);
    std::fs::write(src.join("b.rs"), "// super::a::g()\n").unwrap();
    assert!(mutual_imports(&src).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}
