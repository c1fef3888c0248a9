//! `crs gen-man DIR` (man pages, clap_mangen) and `crs completions SHELL` (clap_complete): the
//! command line documents itself, so the pages never drift from the flags.

use std::path::Path;

/// Writes `crs.1` and one `crs-<sub>.1` per subcommand (recursively) into `dir`; returns the
/// files. The same page writer as every daemon's `--gen-man` (crs-service).
pub fn gen_man(cmd: clap::Command, dir: &Path) -> Result<Vec<std::path::PathBuf>, std::io::Error> {
    crs_service::write_man("crs", cmd, dir)
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
