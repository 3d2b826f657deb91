//! The library's import direction (docs/architecture.md): each top-level module uses only those
//! below it, so there are no cycles. Read from the source: every `crate::<module>` path outside
//! comments.

use std::collections::BTreeMap;
use std::path::Path;

/// The layers, lowest first; a module may use the modules of its own layer and of lower ones.
const LAYERS: &[&[&str]] = &[
    &["stats", "error", "progress", "lm"],
    &["model"],
    &["camera"],
    &["formats"],
    &["plot"],
    &["calibrate"],
    &["detect"],
    &["fit"],
    &["figures"],
    &["solve"],
    &["render"],
    &["synth"],
    &["bench"],
];

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `crate::<name>` paths in a line of code (comments dropped).
fn crate_paths(line: &str) -> Vec<String> {
    let code = line.split("//").next().unwrap_or("");
    code.match_indices("crate::")
        .filter(|(i, _)| {
            // Not part of a longer identifier (`workbench_crate::`).
            *i == 0
                || !code.as_bytes()[i - 1].is_ascii_alphanumeric() && code.as_bytes()[i - 1] != b'_'
        })
        .map(|(i, m)| {
            code[i + m.len()..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect()
        })
        .collect()
}

#[test]
fn every_module_imports_only_from_below() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = vec![];
    rust_files(&src, &mut files);
    let mut upward: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut checked = 0;
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string();
        // The binary's shell (main, cli, commands) sits above the library; lib.rs declares it.
        if ["main", "lib", "cli", "commands"].contains(&top.as_str()) {
            continue;
        }
        let own = layer(&top).unwrap_or_else(|| panic!("src/{top}: not in LAYERS"));
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("//") {
                continue;
            }
            for used in crate_paths(line) {
                let Some(l) = layer(&used) else {
                    continue; // an item of lib.rs (`crate::Result`)
                };
                checked += 1;
                if l > own {
                    upward
                        .entry(format!("{top} → {used}"))
                        .or_default()
                        .push(format!("{}:{}", rel.display(), n + 1));
                }
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} crate paths found: is the parser right?"
    );
    assert!(
        upward.is_empty(),
        "imports against the layer order (docs/architecture.md): {upward:#?}"
    );
}

#[test]
fn the_parser_finds_paths_and_skips_comments() {
    assert_eq!(
        crate_paths("use crate::fit::joint::{self, Setup}; let x = crate::model::idx::ETA;"),
        vec!["fit", "model"]
    );
    assert!(crate_paths("// crate::solve in a comment").is_empty());
    assert_eq!(
        crate_paths("f(); // then crate::solve"),
        Vec::<String>::new()
    );
}
