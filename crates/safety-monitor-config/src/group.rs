//! The operator group of the reset socket, resolved when the configuration is loaded.

/// The gid of `group`: a group name (looked up in the group database) or a numeric gid.
pub fn resolve_group(group: &str) -> Result<u32, String> {
    if let Ok(gid) = group.trim().parse::<u32>() {
        return Ok(gid);
    }
    let name =
        std::ffi::CString::new(group.trim()).map_err(|_| format!("{group:?}: not a group name"))?;
    let mut grp: libc::group = unsafe { std::mem::zeroed() };
    let mut buf = vec![0 as libc::c_char; 16 * 1024];
    let mut out: *mut libc::group = std::ptr::null_mut();
    // SAFETY: every pointer is valid for the call; `buf` outlives it; getgrnam_r writes only
    // into `grp` and `buf`.
    let rc = unsafe {
        libc::getgrnam_r(
            name.as_ptr(),
            &mut grp,
            buf.as_mut_ptr(),
            buf.len(),
            &mut out,
        )
    };
    if rc != 0 || out.is_null() {
        return Err(format!(
            "{group:?}: no such group (create it, or give a numeric gid)"
        ));
    }
    Ok(grp.gr_gid)
}

#[cfg(test)]
mod tests {
    use super::resolve_group;

    #[test]
    fn numeric_gids_and_unknown_names() {
        assert_eq!(resolve_group("0"), Ok(0));
        assert!(resolve_group("no-such-group-crs-test").is_err());
    }
}
