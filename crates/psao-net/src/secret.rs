//! Secrets kept in files (access tokens, NATS passwords and credentials): read only from
//! regular files of bounded size, so a path naming a device or a huge file is an error.

use std::path::Path;

use crate::NetError;

/// Checks that `path` is a regular file of at most `max` bytes.
pub fn check(path: &Path, max: u64) -> Result<(), NetError> {
    let meta =
        std::fs::metadata(path).map_err(NetError::io(format!("cannot read {}", path.display())))?;
    if !meta.is_file() || meta.len() > max {
        return Err(NetError::Config(format!(
            "{} is no regular file of at most {max} bytes",
            path.display()
        )));
    }
    Ok(())
}

/// The whole of the secret file `path` (at most `max` bytes).
pub fn read(path: &Path, max: u64) -> Result<String, NetError> {
    check(path, max)?;
    std::fs::read_to_string(path).map_err(NetError::io(format!("cannot read {}", path.display())))
}

/// The first line of the secret file `path` (at most `max` bytes), trimmed; an empty one is
/// an error.
pub fn first_line(path: &Path, max: u64) -> Result<String, NetError> {
    let text = read(path, max)?;
    let line = text.lines().next().unwrap_or("").trim();
    if line.is_empty() {
        return Err(NetError::Config(format!(
            "{} has an empty first line",
            path.display()
        )));
    }
    Ok(line.to_owned())
}
