//! Inputs are read only from regular files (or links to them). A FIFO, a device or a socket named
//! where a photo, a mesh or a JSON file is expected would block its reader or never end (a mesh
//! at /dev/zero grew to 24 GB), so it is refused in one line before it is opened.

use crate::error::{Error, Result};
use std::path::Path;

/// `Ok` when `path` is a regular file (through links); else the one-line reason.
pub fn regular_file(path: &Path) -> Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) if m.is_dir() => Err(Error::invalid(path, "is a folder, where a file is read")),
        Ok(_) => Err(Error::invalid(
            path,
            "is not a regular file (a device, FIFO or socket): inputs are read from files",
        )),
        Err(e) => Err(Error::io(path, e)),
    }
}
