//! The build's identity: a hash of the sources, the manifest, the lock file, the enabled features
//! and the profile, given to the crate as `WORKBENCH_BUILD`. detections.json and fit.json record
//! it (`"build"`), and a run reuses one only when it was made by the same build: a detector or
//! model changed since would otherwise be served from the old file (docs/formats.md).

use std::hash::Hasher;
use std::path::{Path, PathBuf};

fn main() {
    let mut files = vec![PathBuf::from("Cargo.toml"), PathBuf::from("Cargo.lock")];
    sources(Path::new("src"), &mut files);
    files.sort();
    let mut h = std::hash::DefaultHasher::new();
    for f in &files {
        h.write(f.to_string_lossy().as_bytes());
        h.write(&std::fs::read(f).unwrap_or_default());
    }
    let mut settings: Vec<(String, String)> = std::env::vars()
        .filter(|(k, _)| k.starts_with("CARGO_FEATURE_") || k == "PROFILE" || k == "TARGET")
        .collect();
    settings.sort();
    for (k, v) in settings {
        h.write(k.as_bytes());
        h.write(v.as_bytes());
    }
    println!("cargo:rustc-env=WORKBENCH_BUILD={:016x}", h.finish());
    println!("cargo:rerun-if-changed=src");
    println!("cargo:rerun-if-changed=Cargo.toml");
    println!("cargo:rerun-if-changed=Cargo.lock");
}

/// Every file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, out);
        } else {
            out.push(p);
        }
    }
}
