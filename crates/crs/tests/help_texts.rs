//! The help texts an operator reads: every command group's one-line description in its
//! parent's help names exactly its subcommands (none missing, none that does not exist), and
//! no help text of any command at any depth shows a Rust module path.

use std::process::Command;

fn help(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_crs"))
        .args(args)
        .arg("--help")
        .output()
        .unwrap();
    assert!(o.status.success(), "crs {args:?} --help failed");
    String::from_utf8(o.stdout).unwrap()
}

/// The `Commands:` section: (name, description) pairs, without `help`.
fn subcommands(text: &str) -> Vec<(String, String)> {
    let Some(sec) = text.split("Commands:\n").nth(1) else {
        return Vec::new();
    };
    sec.lines()
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| {
            let l = l.trim_start();
            let (name, about) = l.split_once(' ').unwrap_or((l, ""));
            (name != "help").then(|| (name.to_string(), about.trim().to_string()))
        })
        .collect()
}

/// Walks every command below `path`, checking its help; returns how many were checked.
fn walk(path: &mut Vec<String>) -> usize {
    let args: Vec<&str> = path.iter().map(String::as_str).collect();
    let text = help(&args);
    for bad in ["crs_", "::"] {
        assert!(
            !text.contains(bad),
            "`crs {} --help` shows a module path (`{bad}`):\n{text}",
            path.join(" ")
        );
    }
    let mut n = 1;
    for (name, about) in subcommands(&text) {
        path.push(name.clone());
        let below = subcommands(&help(&path.iter().map(String::as_str).collect::<Vec<_>>()));
        if !below.is_empty() {
            // A group's description names each of its subcommands, as words of the list.
            let words: Vec<&str> = about
                .split(|c: char| !(c.is_alphanumeric() || c == '-'))
                .collect();
            for (sub, _) in &below {
                assert!(
                    words.contains(&sub.as_str()),
                    "`crs {}` description does not name `{sub}`: {about}",
                    path.join(" ")
                );
            }
        }
        n += walk(path);
        path.pop();
    }
    n
}

#[test]
fn every_group_names_its_subcommands_and_no_help_shows_module_paths() {
    let n = walk(&mut Vec::new());
    assert!(n > 30, "only {n} commands walked");
}

#[test]
fn surrogate_help_names_no_subcommand_that_does_not_exist() {
    let top = subcommands(&help(&[]));
    let about = &top.iter().find(|(n, _)| n == "surrogate").unwrap().1;
    let subs: Vec<String> = subcommands(&help(&["surrogate"]))
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    let listed = about.rsplit(':').next().unwrap();
    for word in listed.trim().trim_end_matches('.').split(", ") {
        assert!(
            subs.iter().any(|s| s == word),
            "`{word}` is no subcommand: {about}"
        );
    }
}
