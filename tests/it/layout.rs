//! The library's import direction (docs/architecture.md): each top-level module uses only those
//! below it, and no file or folder reaches itself through the imports between files. Read from
//! the source: every `crate::<module>` path outside comments, and every `use`, `crate::`,
//! `super::` and `self::` path resolved to the file that defines what it names (through
//! re-exports).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

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

// ---- file-level import graph ----

/// A source file's module path (`src/fit/joint/mod.rs` → ["fit", "joint"]).
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// Code without comments, one string (line comments dropped, string contents kept).
fn code_of(text: &str) -> String {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `use` trees expanded into paths (`a::{b, c::{self, d}}` → a::b, a::c, a::c::d).
fn expand_use(tree: &str) -> Vec<String> {
    let tree: String = tree.chars().filter(|c| !c.is_whitespace()).collect();
    fn go(prefix: &str, t: &str, out: &mut Vec<String>) {
        if let Some(open) = t.find('{') {
            let head = &t[..open];
            let inner = &t[open + 1..t.rfind('}').unwrap_or(t.len())];
            let mut depth = 0;
            let mut start = 0;
            let mut items = vec![];
            for (i, ch) in inner.char_indices() {
                match ch {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        items.push(&inner[start..i]);
                        start = i + 1;
                    }
                    _ => {}
                }
            }
            items.push(&inner[start..]);
            for it in items.into_iter().filter(|s| !s.is_empty()) {
                go(&format!("{prefix}{head}"), it, out);
            }
        } else {
            let t = t.split(" as ").next().unwrap_or(t);
            let t = t.split("as").next().filter(|_| false).unwrap_or(t);
            let full = format!("{prefix}{t}");
            let full = full.trim_end_matches("::self").to_string();
            out.push(full);
        }
    }
    let mut out = vec![];
    go("", &tree, &mut out);
    out
}

/// A module's `use` trees (whether each is a re-export) and its code without them.
type Split = (Vec<(bool, String)>, String);

/// The `use` statements of some code (their trees) and the code without them.
fn split_uses(code: &str) -> Split {
    let mut uses = vec![];
    let mut rest = String::new();
    let mut i = 0;
    let b = code.as_bytes();
    while i < code.len() {
        let at_word = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if at_word && code[i..].starts_with("use ") {
            let end = code[i..].find(';').map_or(code.len(), |e| i + e);
            let before = rest.trim_end();
            let public =
                before.ends_with("pub") || before.ends_with(')') && before.contains("pub(");
            // ` as name` renames only the last segment: drop it.
            let tree = code[i + 4..end].replace(" as ", " AS ");
            let tree: String = tree
                .split(',')
                .map(|p| p.split(" AS ").next().unwrap_or(p))
                .collect::<Vec<_>>()
                .join(",");
            uses.push((public, tree));
            i = end + 1;
        } else {
            let ch = code[i..].chars().next().unwrap();
            rest.push(ch);
            i += ch.len_utf8();
        }
    }
    (uses, rest)
}

/// Paths in code that start at `crate`, `super` or `self`.
fn bare_paths(code: &str) -> Vec<String> {
    let b = code.as_bytes();
    let mut out = vec![];
    for root in ["crate::", "super::", "self::"] {
        for (i, _) in code.match_indices(root) {
            if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b':') {
                continue;
            }
            let p: String = code[i..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            out.push(p.trim_end_matches(':').to_string());
        }
    }
    out
}

/// Where the first inline module (`mod name {`) of some code starts, and its name.
fn inline_module(code: &str) -> Option<(usize, String)> {
    code.match_indices("mod ").find_map(|(i, _)| {
        let b = code.as_bytes();
        if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_') {
            return None;
        }
        let name: String = code[i + 4..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let after = code[i + 4 + name.len()..].trim_start();
        (!name.is_empty() && after.starts_with('{')).then_some((i, name))
    })
}

struct Graph {
    /// Module path → file (relative to src/).
    files: BTreeMap<Vec<String>, PathBuf>,
    /// Per module, the names it re-exports → the module they come from.
    reexports: BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>>,
}

impl Graph {
    /// The module a path names from module `at`: as deep as modules go, then through re-exports.
    fn resolve(&self, at: &[String], path: &str) -> Option<Vec<String>> {
        let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
        let (mut m, rest): (Vec<String>, &[&str]) = match segs.first().copied() {
            Some("crate") => (vec![], &segs[1..]),
            Some("self") => (at.to_vec(), &segs[1..]),
            Some("super") => {
                let mut m = at.to_vec();
                let mut k = 0;
                while segs.get(k) == Some(&"super") {
                    m.pop();
                    k += 1;
                }
                (m, &segs[k..])
            }
            Some(first) => {
                // A child module of this one (2018 paths), else an outside crate or a local name.
                let mut child = at.to_vec();
                child.push(first.to_string());
                if !self.files.contains_key(&child) {
                    return None;
                }
                (at.to_vec(), &segs[..])
            }
            None => return None,
        };
        for s in rest {
            if *s == "*" {
                break;
            }
            let mut next = m.clone();
            next.push(s.to_string());
            if self.files.contains_key(&next) {
                m = next;
                continue;
            }
            // An item: through this module's re-exports to where it is defined.
            let mut seen = 0;
            while let Some(to) = self.reexports.get(&m).and_then(|r| r.get(*s)) {
                if *to == m || seen > 8 {
                    break;
                }
                m = to.clone();
                seen += 1;
            }
            break;
        }
        Some(m)
    }
}

/// Files that reach themselves through the imports between files (strongly connected sets).
type Edges = BTreeMap<Vec<String>, BTreeSet<Vec<String>>>;

/// The import graph between the files under `src` (modules, by path), with the number of paths
/// resolved; files under the top-level names in `skip_top` are left out.
fn import_graph(src: &Path, skip_top: &[&str]) -> (Edges, usize) {
    let mut paths = vec![];
    rust_files(src, &mut paths);
    let mut files = BTreeMap::new();
    let mut texts = BTreeMap::new();
    for f in &paths {
        let rel = f.strip_prefix(src).unwrap().to_path_buf();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let top = top.trim_end_matches(".rs");
        if skip_top.contains(&top) {
            continue;
        }
        let m = module_of(&rel);
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        // An inline module (`mod tests {`, at a file's end) resolves its paths from itself.
        match inline_module(&code) {
            Some((at, name)) => {
                let mut inner = m.clone();
                inner.push(name);
                texts.insert(m.clone(), code[..at].to_string());
                texts.insert(inner, code[at..].to_string());
            }
            None => {
                texts.insert(m.clone(), code);
            }
        }
        files.insert(m, rel);
    }
    let mut g = Graph {
        files,
        reexports: BTreeMap::new(),
    };
    // Re-exports first (they may chain), then every reference.
    let split: BTreeMap<Vec<String>, Split> = texts
        .iter()
        .map(|(m, t)| (m.clone(), split_uses(t)))
        .collect();
    for (m, (uses, _)) in &split {
        let mut r = BTreeMap::new();
        for (public, tree) in uses {
            if !public {
                continue;
            }
            for p in expand_use(tree) {
                let last = p.rsplit("::").next().unwrap_or("").to_string();
                if let Some(to) = g.resolve(m, &p) {
                    if to != *m && last != "*" {
                        r.insert(last, to);
                    }
                }
            }
        }
        g.reexports.insert(m.clone(), r);
    }
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    let mut count = 0;
    for (inner, (uses, rest)) in &split {
        // An inline module's imports are its file's.
        let m = if g.files.contains_key(inner) {
            inner
        } else {
            &inner[..inner.len() - 1].to_vec()
        };
        let m = &m.clone();
        let all = uses
            .iter()
            .flat_map(|(_, t)| expand_use(t))
            .chain(bare_paths(rest));
        for p in all {
            if let Some(to) = g.resolve(inner, &p) {
                count += 1;
                if to != *m && !to.is_empty() {
                    edges.entry(m.clone()).or_default().insert(to);
                }
            }
        }
    }
    (edges, count)
}

/// The strongly connected sets of more than one node (Tarjan), each sorted.
fn cycles_of(edges: &Edges) -> Vec<Vec<Vec<String>>> {
    let mut all: BTreeSet<Vec<String>> = edges.keys().cloned().collect();
    all.extend(edges.values().flatten().cloned());
    let nodes: Vec<Vec<String>> = all.into_iter().collect();
    let index_of: BTreeMap<&Vec<String>, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n, i)).collect();
    let adj: Vec<Vec<usize>> = nodes
        .iter()
        .map(|n| {
            edges
                .get(n)
                .map(|s| s.iter().filter_map(|t| index_of.get(t).copied()).collect())
                .unwrap_or_default()
        })
        .collect();
    struct T {
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        sccs: Vec<Vec<usize>>,
    }
    fn visit(v: usize, adj: &[Vec<usize>], t: &mut T) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for &w in &adj[v] {
            match t.index[w] {
                None => {
                    visit(w, adj, t);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(iw) if t.on[w] => t.low[v] = t.low[v].min(iw),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut scc = vec![];
            while let Some(w) = t.stack.pop() {
                t.on[w] = false;
                scc.push(w);
                if w == v {
                    break;
                }
            }
            t.sccs.push(scc);
        }
    }
    let n = nodes.len();
    let mut t = T {
        index: vec![None; n],
        low: vec![0; n],
        on: vec![false; n],
        stack: vec![],
        next: 0,
        sccs: vec![],
    };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(v, &adj, &mut t);
        }
    }
    t.sccs
        .into_iter()
        .filter(|s| s.len() > 1)
        .map(|s| {
            let mut names: Vec<Vec<String>> = s.iter().map(|&i| nodes[i].clone()).collect();
            names.sort();
            names
        })
        .collect()
}

/// The edges between siblings that the file edges make: an import from `a::x::…` of
/// `a::y::…` is one from `x` to `y`, children of folder `a` (a file or a folder each).
fn sibling_edges(edges: &Edges) -> Edges {
    let mut out: Edges = BTreeMap::new();
    for (from, tos) in edges {
        for to in tos {
            let k = from.iter().zip(to).take_while(|(a, b)| a == b).count();
            if k < from.len() && k < to.len() {
                out.entry(from[..=k].to_vec())
                    .or_default()
                    .insert(to[..=k].to_vec());
            }
        }
    }
    out
}

#[test]
fn no_file_or_folder_reaches_itself() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    // The binary's shell (main, cli, commands) only dispatches into the library.
    let (edges, resolved) = import_graph(&src, &["main", "cli", "commands"]);
    assert!(
        resolved > 500,
        "only {resolved} paths resolved: is the resolver right?"
    );
    let show = |c: Vec<Vec<Vec<String>>>| -> Vec<String> {
        c.into_iter()
            .map(|s| {
                s.iter()
                    .map(|m| m.join("::"))
                    .collect::<Vec<_>>()
                    .join(" ⇄ ")
            })
            .collect()
    };
    let files = show(cycles_of(&edges));
    assert!(files.is_empty(), "files importing each other: {files:#?}");
    let folders = show(cycles_of(&sibling_edges(&edges)));
    assert!(
        folders.is_empty(),
        "files or folders of one folder importing each other: {folders:#?}"
    );
}

/// A small source tree written out, for the cycle finder's own tests.
fn tree(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (path, text) in files {
        let p = dir.path().join(path);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    dir
}

#[test]
fn the_cycle_finder_sees_globs_reexports_and_folders() {
    // `use super::*` in a child of a folder whose mod.rs uses that child: a file cycle.
    let glob = tree(&[
        ("lib.rs", "pub mod a;"),
        ("a/mod.rs", "mod b; use b::run; pub struct S;"),
        ("a/b.rs", "use super::*; pub fn run(_: S) {}"),
    ]);
    let (e, _) = import_graph(glob.path(), &[]);
    let c = cycles_of(&e);
    assert_eq!(c.len(), 1, "{c:?}");
    assert_eq!(
        c[0],
        vec![vec!["a".to_string()], vec!["a".into(), "b".into()]]
    );
    // An item re-exported by mod.rs resolves to the file defining it: no cycle through mod.rs,
    // but x ⇄ y through the re-export is one.
    let reexport = tree(&[
        ("lib.rs", "pub mod a;"),
        ("a/mod.rs", "mod x; mod y; pub use x::X; pub use y::Y;"),
        ("a/x.rs", "use crate::a::Y; pub struct X(Y);"),
        ("a/y.rs", "// crate::a::X only in a comment\npub struct Y;"),
    ]);
    let (e, _) = import_graph(reexport.path(), &[]);
    assert!(cycles_of(&e).is_empty(), "{:?}", cycles_of(&e));
    let back = tree(&[
        ("lib.rs", "pub mod a;"),
        ("a/mod.rs", "mod x; mod y; pub use x::X; pub use y::Y;"),
        ("a/x.rs", "use crate::a::Y; pub struct X(Y);"),
        ("a/y.rs", "pub struct Y; fn f(_: super::X) {}"),
    ]);
    let (e, _) = import_graph(back.path(), &[]);
    let c = cycles_of(&e);
    assert_eq!(c.len(), 1, "{c:?}");
    assert_eq!(c[0].len(), 2);
    // Files that import each other only across two folders: no file cycle, a folder cycle.
    let folders = tree(&[
        ("lib.rs", "pub mod p; pub mod q;"),
        ("p/mod.rs", "pub mod one; pub mod two;"),
        ("p/one.rs", "use crate::q::three::T; pub struct O;"),
        ("p/two.rs", "pub struct W;"),
        ("q/mod.rs", "pub mod three;"),
        ("q/three.rs", "pub struct T(crate::p::two::W);"),
    ]);
    let (e, _) = import_graph(folders.path(), &[]);
    assert!(cycles_of(&e).is_empty());
    let c = cycles_of(&sibling_edges(&e));
    assert_eq!(c, vec![vec![vec!["p".to_string()], vec!["q".to_string()]]]);
}

/// Functions longer than `max` lines in the Rust files under `dir` (their tests left out: a
/// file is read up to its first `#[cfg(test)]`), as "file:line name (lines)". A function runs
/// from its `fn` line to the first line that closes it at the same indentation.
fn long_functions(dir: &Path, max: usize) -> Vec<String> {
    let mut files = vec![];
    rust_files(dir, &mut files);
    let mut long = vec![];
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let lines: Vec<&str> = text
            .lines()
            .take_while(|l| !l.starts_with("#[cfg(test)]"))
            .collect();
        let mut i = 0;
        while i < lines.len() {
            let l = lines[i];
            let code = l.trim_start();
            let indent = &l[..l.len() - code.len()];
            let rest = ["pub(crate) ", "pub(super) ", "pub "]
                .iter()
                .find_map(|p| code.strip_prefix(p))
                .unwrap_or(code);
            let rest = rest.strip_prefix("const ").unwrap_or(rest);
            let Some(name) = rest.strip_prefix("fn ") else {
                i += 1;
                continue;
            };
            let name: String = name
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            // The signature ends at its body's `{` or, for a declaration, at `;`.
            let mut j = i;
            while j < lines.len() && !lines[j].ends_with('{') && !lines[j].ends_with(';') {
                j += 1;
            }
            if j >= lines.len() || lines[j].ends_with(';') {
                i = j + 1;
                continue;
            }
            let close = format!("{indent}}}");
            let end = (j + 1..lines.len())
                .find(|&k| lines[k] == close)
                .unwrap_or(lines.len() - 1);
            let n = end - i + 1;
            if n > max {
                long.push(format!("{}:{} {name} ({n} lines)", f.display(), i + 1));
            }
            i = end + 1;
        }
    }
    long
}

#[test]
fn no_function_is_longer_than_120_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut long = long_functions(&root.join("src"), 120);
    long.extend(long_functions(&root.join("benches"), 120));
    assert!(
        long.is_empty(),
        "functions over 120 lines (split them into named steps): {long:#?}"
    );
}

#[test]
fn the_length_check_measures_functions() {
    let dir = tree(&[(
        "a.rs",
        "fn short() {\n    1;\n}\n\npub(crate) fn long(\n    x: u32,\n) -> u32 {\n    x\n        + 1\n}\n\n#[cfg(test)]\nfn in_tests() {\n    2;\n    3;\n    4;\n}\n",
    )]);
    // `long` spans 6 lines, `short` 3; what follows #[cfg(test)] is not read.
    assert_eq!(
        long_functions(dir.path(), 2),
        vec![
            format!("{}:1 short (3 lines)", dir.path().join("a.rs").display()),
            format!("{}:5 long (6 lines)", dir.path().join("a.rs").display()),
        ]
    );
    assert_eq!(
        long_functions(dir.path(), 5),
        vec![format!(
            "{}:5 long (6 lines)",
            dir.path().join("a.rs").display()
        )]
    );
    assert!(long_functions(dir.path(), 6).is_empty());
}
