//! Where every binary of the stack finds its configuration.
//!
//! The one lookup rule, used by every binary's default paths (`motion-core`, `drive-io`,
//! `safety-monitor`, `sim-plant`, `crs`) and by their `--config`-style arguments:
//!
//! A relative path that starts with `config/` names a file of the configuration directory:
//! 1. `$CRS_CONFIG_DIR/REST` when the environment variable `CRS_CONFIG_DIR` is set;
//! 2. else `config/REST` when the working directory has a `config/` directory (run from the
//!    repository, or from `/etc/crs` as the installed units do);
//! 3. else `/etc/crs/config/REST` (installed: the package's conffiles).
//!
//! Any other path (absolute, or relative without the `config/` prefix) is used as given.
//! docs/install.md documents the rule for administrators.

use std::path::{Path, PathBuf};

/// The environment variable that overrides the configuration directory.
pub const CONFIG_DIR_ENV: &str = "CRS_CONFIG_DIR";

/// The installed configuration directory (the package's conffiles).
pub const INSTALLED_CONFIG_DIR: &str = "/etc/crs/config";

/// The prefix that marks a path as a file of the configuration directory.
pub const CONFIG_PREFIX: &str = "config";

/// The configuration directory of this process under the rule (see the crate docs).
pub fn config_dir() -> PathBuf {
    config_dir_from(
        std::env::var_os(CONFIG_DIR_ENV).map(PathBuf::from),
        Path::new(CONFIG_PREFIX).is_dir(),
    )
}

/// [`config_dir`] from its inputs: the override, and whether `./config` exists.
pub fn config_dir_from(env: Option<PathBuf>, repo_config_here: bool) -> PathBuf {
    match env.filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir,
        None if repo_config_here => PathBuf::from(CONFIG_PREFIX),
        None => PathBuf::from(INSTALLED_CONFIG_DIR),
    }
}

/// `path` under the rule: `config/REST` → the configuration directory's `REST`; anything else
/// unchanged.
pub fn resolve(path: &Path) -> PathBuf {
    resolve_in(path, &config_dir())
}

/// [`resolve`] against a given configuration directory.
pub fn resolve_in(path: &Path, dir: &Path) -> PathBuf {
    match path.strip_prefix(CONFIG_PREFIX) {
        Ok(rest) if path.is_relative() => dir.join(rest),
        _ => path.to_path_buf(),
    }
}

/// A clap value parser for configuration paths (`value_parser = crs_service::paths::parse_config`):
/// the argument, or its default, resolved under the rule.
pub fn parse_config(arg: &str) -> Result<PathBuf, std::convert::Infallible> {
    Ok(resolve(Path::new(arg)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_override_wins_then_the_repository_then_etc() {
        let env = Some(PathBuf::from("/srv/crs-test/config"));
        assert_eq!(config_dir_from(env.clone(), true), env.clone().unwrap());
        assert_eq!(config_dir_from(None, true), PathBuf::from("config"));
        assert_eq!(
            config_dir_from(None, false),
            PathBuf::from("/etc/crs/config")
        );
        assert_eq!(
            config_dir_from(Some(PathBuf::new()), false),
            PathBuf::from("/etc/crs/config"),
            "an empty override is no override"
        );
    }

    #[test]
    fn only_config_relative_paths_are_resolved() {
        let etc = Path::new("/etc/crs/config");
        assert_eq!(
            resolve_in(Path::new("config/plant/icosahedron.toml"), etc),
            PathBuf::from("/etc/crs/config/plant/icosahedron.toml")
        );
        for as_given in [
            "/opt/x/config/drives.toml",
            "my/drives.toml",
            "configs/a.toml",
        ] {
            assert_eq!(
                resolve_in(Path::new(as_given), etc),
                PathBuf::from(as_given)
            );
        }
    }
}
