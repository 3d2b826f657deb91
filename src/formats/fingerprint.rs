//! What an output was made from, by content: each input file's size and a 64-bit hash of its
//! bytes, recorded in the output (`"inputs"` in detections.json and fit.json) and compared on the
//! next run. An output is reused only when every input still has the recorded size and hash —
//! whatever the files' modification times say (a copy with `cp -p` or `rsync -a` keeps old
//! times on new contents).

use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::hash::Hasher;
use std::io::Read;
use std::path::{Path, PathBuf};

/// This build of workbench: a hash of its sources, manifest, lock file, features and profile
/// (build.rs). detections.json and fit.json record it (`"build"`) and are reused only by the
/// same build, since a changed detector or model gives other results from the same inputs.
pub const BUILD: &str = env!("WORKBENCH_BUILD");

/// Why an output recording `recorded` as its build cannot be reused by this one (`None`: it can).
pub fn other_build(recorded: &str) -> Option<String> {
    match recorded {
        "" => Some("it records no build (written by an older workbench)".into()),
        b if b != BUILD => Some(format!(
            "it was made by another workbench build ({b}; this one {BUILD})"
        )),
        _ => None,
    }
}

/// Input file (as named by the session) → `"<size>:<hash>"`.
pub type Inputs = BTreeMap<String, String>;

/// A file's size and hash: `"<bytes>:<16 hex digits>"`. The hash is std's `DefaultHasher` with
/// its fixed keys (SipHash-1-3 today): not a cryptographic digest, a change detector; a Rust
/// release that changed it would only make the next run redo its work.
pub fn of_file(path: &Path) -> Result<String> {
    crate::formats::input::regular_file(path)?;
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut h = std::hash::DefaultHasher::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut size: u64 = 0;
    loop {
        let n = f.read(&mut buf).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        h.write(&buf[..n]);
        size += n as u64;
    }
    Ok(format!("{size}:{:016x}", h.finish()))
}

/// Every file's [`of_file`], keyed by its path as given.
pub fn of_files(paths: &[PathBuf]) -> Result<Inputs> {
    use rayon::prelude::*;
    paths
        .par_iter()
        .map(|p| Ok((p.display().to_string(), of_file(p)?)))
        .collect()
}

/// Why a recorded set of inputs does not describe the current one (`None`: it does).
pub fn differs(recorded: &Inputs, now: &Inputs) -> Option<String> {
    if recorded.is_empty() {
        return Some("it records no inputs (written by an older workbench)".into());
    }
    for (name, v) in now {
        match recorded.get(name) {
            None => return Some(format!("{name} is not among its inputs")),
            Some(r) if r != v => return Some(format!("{name} has changed")),
            _ => {}
        }
    }
    recorded
        .keys()
        .find(|k| !now.contains_key(*k))
        .map(|k| format!("{k} is no longer an input"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Same bytes, same fingerprint; one byte changed (same size, same time), another.
    #[test]
    fn content_decides_not_time() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::write(&a, b"0123456789").unwrap();
        std::fs::write(&b, b"0123456789").unwrap();
        assert_eq!(of_file(&a).unwrap(), of_file(&b).unwrap());
        assert!(of_file(&a).unwrap().starts_with("10:"));
        std::fs::write(&b, b"0123456788").unwrap();
        assert_ne!(of_file(&a).unwrap(), of_file(&b).unwrap());
        let now = of_files(std::slice::from_ref(&a)).unwrap();
        assert_eq!(differs(&now, &now), None);
        let other = of_files(std::slice::from_ref(&b)).unwrap();
        assert!(differs(&now, &other).unwrap().contains("is not among"));
        let mut changed = now.clone();
        changed.insert(a.display().to_string(), "10:0".into());
        assert!(differs(&changed, &now).unwrap().contains("has changed"));
        assert!(differs(&Inputs::new(), &now).unwrap().contains("no inputs"));
    }

    /// This build's outputs are its own; another's, or one that records none, are not.
    #[test]
    fn only_this_build_is_reused() {
        assert_eq!(BUILD.len(), 16);
        assert_eq!(other_build(BUILD), None);
        assert!(other_build("0123456789abcdef")
            .unwrap()
            .contains("another workbench build"));
        assert!(other_build("").unwrap().contains("no build"));
    }
}
