//! The documents against the suite: every test that README.md or docs/ names as the evidence
//! for a figure (`module::test_name`, or a `cargo test` filter such as `uncertainty::stated_errors`)
//! exists in `tests/it/<module>.rs`, so a renamed or deleted test cannot leave a claim pointing
//! nowhere.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The `#[test]` functions of each integration-test module, by module name.
fn tests_by_module(dir: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut out = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&p).unwrap();
        let mut names = BTreeSet::new();
        let mut after_test = false;
        for line in text.lines().map(str::trim) {
            if line == "#[test]" {
                after_test = true;
            } else if after_test {
                if let Some(rest) = line.strip_prefix("fn ") {
                    names.insert(rest.split('(').next().unwrap().to_string());
                    after_test = false;
                } else if !line.starts_with("#[") {
                    after_test = false;
                }
            }
        }
        out.insert(p.file_stem().unwrap().to_string_lossy().into_owned(), names);
    }
    out
}

/// Every `module::name` inside a code span of `text` whose module is a test module: exactly two
/// segments, not preceded by another `::` segment, the name in lower snake case.
fn named_tests(text: &str, modules: &BTreeSet<&str>) -> Vec<(String, String)> {
    let mut out = vec![];
    for (i, span) in text.split('`').enumerate() {
        if i % 2 == 0 {
            continue;
        }
        for (at, _) in span.match_indices("::") {
            let before = &span[..at];
            let module_start = before
                .char_indices()
                .rev()
                .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_'))
                .map_or(0, |(k, c)| k + c.len_utf8());
            let module = &before[module_start..];
            if !modules.contains(module) || before[..module_start].ends_with(':') {
                continue;
            }
            let after = &span[at + 2..];
            let end = after
                .find(|c: char| !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..end];
            if name.is_empty() || after[end..].starts_with("::") {
                continue;
            }
            out.push((module.to_string(), name.to_string()));
        }
    }
    out
}

/// README.md and every Markdown file under docs/.
fn documents(root: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    let mut out = vec![root.join("README.md")];
    walk(&root.join("docs"), &mut out);
    out
}

/// The names in `text` that match no test: a full name must exist, a filter must match one
/// test's name from its start (cargo's filter is a substring of `module::name`).
fn missing(
    text: &str,
    tests: &BTreeMap<String, BTreeSet<String>>,
    src_modules: &dyn Fn(&str, &str) -> bool,
) -> Vec<String> {
    let modules: BTreeSet<&str> = tests.keys().map(String::as_str).collect();
    named_tests(text, &modules)
        .into_iter()
        .filter(|(m, n)| !src_modules(m, n))
        .filter(|(m, n)| !tests[m].iter().any(|t| t.starts_with(n.as_str())))
        .map(|(m, n)| format!("{m}::{n}"))
        .collect()
}

/// `model::lanes`, `solve::run` and `solver::fit_robust` name a source module (src/model/lanes.rs)
/// or a function of one (`fn run` in src/solve/mod.rs, `fn fit_robust` in src/fit/solver.rs), not
/// tests: the module is a folder or file of that name at any depth under src/.
fn is_source_item(root: &Path) -> impl Fn(&str, &str) -> bool + '_ {
    fn places(dir: &Path, m: &str, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                if p.file_name().is_some_and(|f| f == m) {
                    out.push(p.clone());
                }
                places(&p, m, out);
            } else if p.file_name().is_some_and(|f| *f == *format!("{m}.rs")) {
                out.push(p);
            }
        }
    }
    move |m, n| {
        let defines =
            |p: PathBuf| std::fs::read_to_string(p).is_ok_and(|t| t.contains(&format!("fn {n}(")));
        let mut found = vec![];
        places(&root.join("src"), m, &mut found);
        found.into_iter().any(|p| {
            if p.is_dir() {
                p.join(format!("{n}.rs")).exists()
                    || p.join(n).is_dir()
                    || defines(p.join("mod.rs"))
            } else {
                defines(p)
            }
        })
    }
}

#[test]
fn tests_named_in_the_docs_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tests = tests_by_module(&root.join("tests/it"));
    let src = is_source_item(root);
    let mut bad = vec![];
    let mut named = 0;
    for doc in documents(root) {
        let text = std::fs::read_to_string(&doc).unwrap();
        let modules: BTreeSet<&str> = tests.keys().map(String::as_str).collect();
        named += named_tests(&text, &modules).len();
        for m in missing(&text, &tests, &src) {
            bad.push(format!(
                "{}: {m}",
                doc.strip_prefix(root).unwrap().display()
            ));
        }
    }
    println!("{named} test names in README.md and docs/");
    assert!(
        bad.is_empty(),
        "named in the docs, no such test:\n{}",
        bad.join("\n")
    );
    // The documents do name tests: a parser that found none would pass the check above.
    assert!(named > 40, "{named}");
}

#[test]
fn the_name_finder_sees_names_filters_and_skips_paths() {
    let tests: BTreeMap<String, BTreeSet<String>> = [(
        "solve".to_string(),
        ["one_light_per_photo".to_string()].into(),
    )]
    .into();
    let text = "`solve::one_light_per_photo`, `cargo test --test it solve::one_light -- \
                --nocapture`, `workbench::solve::Options`, `solve::observe::light_frames`, \
                `solve::` and `solve::two_lights`, solve::not_in_a_code_span";
    let none = |_: &str, _: &str| false;
    assert_eq!(missing(text, &tests, &none), ["solve::two_lights"]);
    let found = named_tests(text, &["solve"].into());
    assert_eq!(found.len(), 3, "{found:?}");
    // A source module of that name is not a test.
    let src = |m: &str, n: &str| m == "solve" && n == "two_lights";
    assert!(missing(text, &tests, &src).is_empty());
}

#[test]
fn source_items_are_found_at_any_depth() {
    let src = is_source_item(Path::new(env!("CARGO_MANIFEST_DIR")));
    // src/fit/solver.rs's `fn fit_robust(`, src/model/sphere_atlas.rs, src/solve/mod.rs's `fn run(`.
    assert!(src("solver", "fit_robust"));
    assert!(src("model", "sphere_atlas"));
    assert!(src("solve", "run"));
    assert!(!src("solver", "no_such_function"));
    assert!(!src("medium", "the_medium_of_the_soap_renders"));
}
