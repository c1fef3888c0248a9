//! `crs gen-man DIR` (man pages, clap_mangen) and `crs completions SHELL` (clap_complete): the
//! command line documents itself, so the pages never drift from the flags.

use std::path::Path;

/// Writes `crs.1` and one `crs-<sub>.1` per subcommand (recursively) into `dir`; returns the files.
pub fn gen_man(cmd: clap::Command, dir: &Path) -> Result<Vec<std::path::PathBuf>, std::io::Error> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    fn walk(
        cmd: &clap::Command,
        name: &str,
        dir: &Path,
        written: &mut Vec<std::path::PathBuf>,
    ) -> Result<(), std::io::Error> {
        let cmd = cmd.clone().name(name.to_string());
        let path = dir.join(format!("{name}.1"));
        let mut buf = Vec::new();
        clap_mangen::Man::new(cmd.clone()).render(&mut buf)?;
        std::fs::write(&path, buf)?;
        written.push(path);
        for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
            walk(sub, &format!("{name}-{}", sub.get_name()), dir, written)?;
        }
        Ok(())
    }
    let mut cmd = cmd;
    cmd.build();
    walk(&cmd, "crs", dir, &mut written)?;
    Ok(written)
}

/// Prints the completion script for `shell` to stdout. A reader that closes the pipe early
/// (`crs completions zsh | grep -q …`) is not an error: the script is rendered into memory first
/// (clap_complete panics on a failed write) and a broken pipe ends the output quietly.
pub fn completions(mut cmd: clap::Command, shell: clap_complete::Shell) -> std::io::Result<()> {
    use std::io::Write;
    let mut buf = Vec::new();
    clap_complete::generate(shell, &mut cmd, "crs", &mut buf);
    let mut out = std::io::stdout().lock();
    match out.write_all(&buf).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}
