//! Outputs as a set: a command killed at any point leaves the previous outputs exactly as they
//! were, and the next complete run leaves a complete new set (src/formats/output.rs). The kill is
//! the test hook `WORKBENCH_ABORT_AFTER_WRITES=n`: the process aborts right after its n-th output
//! file is written.

use crate::common::wb;
use std::collections::BTreeMap;
use std::path::Path;

/// Run the binary with the abort hook at `n` writes: its exit code (-1 when killed by a signal).
fn wb_killed_after(n: usize, args: &[&str]) -> i32 {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_workbench"))
        .args(args)
        .env("WORKBENCH_ABORT_AFTER_WRITES", n.to_string())
        .output()
        .unwrap();
    out.status.code().unwrap_or(-1)
}

/// Every visible file under `dir` (the hidden temporaries of a killed run left out) with its
/// contents.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if name.starts_with(".workbench-") {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Kill `args` after 1, 2, 4, … writes until a run completes: every killed run must leave the
/// snapshot of `dir` as `before`; the run that completes must change `changed` and leave no
/// temporaries. Returns the number of kills.
fn kill_everywhere(dir: &Path, args: &[&str], changed: &str) -> usize {
    let before = snapshot(dir);
    assert!(before.contains_key(changed), "{changed} missing before");
    let mut kills = 0;
    let mut n = 1;
    loop {
        let code = wb_killed_after(n, args);
        if code == 0 {
            break;
        }
        assert_eq!(
            code, -1,
            "{args:?} after {n} writes: not killed, exit {code}"
        );
        kills += 1;
        let now = snapshot(dir);
        assert_eq!(
            now.keys().collect::<Vec<_>>(),
            before.keys().collect::<Vec<_>>(),
            "{args:?} killed after {n} writes: the files differ"
        );
        for (k, v) in &now {
            assert!(
                *v == before[k],
                "{args:?} killed after {n} writes: {k} is not the previous one"
            );
        }
        n *= 2;
        assert!(n < 4096, "{args:?} never completed");
    }
    let after = snapshot(dir);
    assert!(
        after[changed] != before[changed],
        "{changed} was not rewritten"
    );
    kills
}

/// A synthetic 480×320 row of three spheres (20, 15, 12 mm) drawn with `seed`, in `<tmp>/<name>`.
fn row_session(tmp: &Path, name: &str, seed: &str) -> std::path::PathBuf {
    let s = tmp.join(name);
    crate::common::synth_session(
        &s,
        &[
            "--size", "480x320", "--fx", "520", "--radii", "20,15,12", "--layout", "row", "--seed",
            seed,
        ],
    );
    s
}

/// solve with figures: fit.json and every figure, killed at 1, 2, 4, … written files.
#[test]
fn solve_killed_anywhere_keeps_the_previous_set() {
    let tmp = tempfile::tempdir().unwrap();
    let s = row_session(tmp.path(), "s", "1");
    let so = s.to_str().unwrap();
    let plots = s.join("plots");
    let po = plots.to_str().unwrap();
    let (code, _, err) = wb(&["--quiet", "solve", "--joint", so, "--plots", po]);
    assert!(code == 0 || code == 3, "{err}");
    // Another option: a different fit.json and figures.
    let kills = kill_everywhere(
        &s,
        &[
            "--quiet",
            "solve",
            "--joint",
            so,
            "--plots",
            po,
            "--no-jackknife",
        ],
        "fit.json",
    );
    // fit.json and at least the index and a dozen figures (PNG + SVG each) were written.
    assert!(kills >= 4, "only {kills} kills");
    let after = snapshot(&s);
    let fit: serde_json::Value = serde_json::from_slice(&after["fit.json"]).unwrap();
    assert!(
        fit["skipped"]
            .as_array()
            .unwrap()
            .iter()
            .any(|v| v.as_str().unwrap().contains("--no-jackknife")),
        "the new fit.json is the --no-jackknife run's"
    );
}

/// synth session into a folder that holds an earlier session: the photos, session.json and
/// truth.json are one set (issue 33: a run cut short left new photos beside the old truth).
#[test]
fn synth_killed_anywhere_keeps_the_previous_session() {
    let tmp = tempfile::tempdir().unwrap();
    let s = row_session(tmp.path(), "s", "1");
    let kills = kill_everywhere(
        &s,
        &[
            "--quiet",
            "synth",
            "session",
            "--out",
            s.to_str().unwrap(),
            "--size",
            "480x320",
            "--fx",
            "520",
            "--radii",
            "20,15,12",
            "--layout",
            "row",
            "--seed",
            "2",
            "--light-azimuth",
            "40",
        ],
        "truth.json",
    );
    // The photo, the intrinsics, session.json and truth.json: four files, three kills at least.
    assert!(kills >= 2, "only {kills} kills");
}

/// calibrate: intrinsics.json, the OpenCV YAML and the plots.
#[cfg(feature = "opencv")]
#[test]
fn calibrate_killed_anywhere_keeps_the_previous_set() {
    let tmp = tempfile::tempdir().unwrap();
    let c = tmp.path().join("c");
    let co = c.to_str().unwrap();
    let (code, _, err) = wb(&[
        "--quiet",
        "synth",
        "checkerboard",
        "--out",
        co,
        "--views",
        "6",
        "--size",
        "640x480",
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = wb(&["--quiet", "calibrate", co]);
    assert_eq!(code, 0, "{err}");
    let kills = kill_everywhere(
        &c,
        &["--quiet", "calibrate", co, "--detector", "both"],
        "intrinsics.json",
    );
    assert!(kills >= 2, "only {kills} kills");
}

/// bench never deletes a folder it did not make.
#[test]
fn bench_keeps_folders_it_did_not_make() {
    let tmp = tempfile::tempdir().unwrap();
    let mine = tmp.path().join("sessions/640-480-1pc-png");
    std::fs::create_dir_all(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = wb(&[
        "--quiet",
        "bench",
        "--quick",
        "--out",
        tmp.path().to_str().unwrap(),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("was not made by workbench bench"), "{err}");
    assert_eq!(
        std::fs::read_to_string(mine.join("notes.txt")).unwrap(),
        "mine"
    );
}

/// `workbench --quiet solve --joint <session> --no-jackknife`, what it printed (exit 0 or 3).
fn quick_solve(session: &Path) -> String {
    let s = session.to_str().unwrap();
    let (code, out, err) = wb(&["--quiet", "solve", "--joint", s, "--no-jackknife"]);
    assert!(code == 0 || code == 3, "{err}");
    out
}

/// Reuse by content: a photo replaced by another with an old modification time (as `cp -p` or
/// `rsync -a` leave it) makes solve detect and fit again; only touching the files does not.
#[test]
fn stale_results_are_never_reused_whatever_the_times() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (
        row_session(tmp.path(), "a", "1"),
        row_session(tmp.path(), "b", "2"),
    );
    let solve = || quick_solve(&a);
    let first = solve();
    assert!(first.contains("detection: ran"), "{first}");
    // Touched: every file newer, nothing changed: both reused.
    let photo = std::fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "png"))
        .unwrap();
    let old_time = std::fs::metadata(&photo).unwrap().modified().unwrap();
    let now = std::time::SystemTime::now() + std::time::Duration::from_secs(5);
    std::fs::File::options()
        .write(true)
        .open(&photo)
        .unwrap()
        .set_modified(now)
        .unwrap();
    let touched = solve();
    assert!(touched.contains("fit.json reused"), "{touched}");
    // Replaced by session b's photo of the same name, with the old time back.
    let other = b.join(photo.file_name().unwrap());
    std::fs::copy(&other, &photo).unwrap();
    std::fs::File::options()
        .write(true)
        .open(&photo)
        .unwrap()
        .set_modified(old_time)
        .unwrap();
    let replaced = solve();
    assert!(!replaced.contains("fit.json reused"), "{replaced}");
    assert!(
        replaced.contains("detections.json is stale:") && replaced.contains("has changed"),
        "{replaced}"
    );
}

/// Reuse by build: detections.json and fit.json made by another workbench build (a detector or
/// model changed since gives other results from the same inputs), or by one from before builds
/// were recorded, are made again, and the run says why; this build's own are reused.
#[test]
fn another_builds_results_are_not_reused() {
    let tmp = tempfile::tempdir().unwrap();
    let a = row_session(tmp.path(), "a", "1");
    let solve = || quick_solve(&a);
    let first = solve();
    assert!(first.contains("detection: ran"), "{first}");
    assert!(solve().contains("fit.json reused"));
    let rewrite = |name: &str, build: Option<&str>| {
        let path = a.join(name);
        let mut j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(j["build"].as_str().unwrap().len(), 16, "{name}");
        match build {
            Some(b) => j["build"] = b.into(),
            None => {
                j.as_object_mut().unwrap().remove("build");
            }
        }
        std::fs::write(&path, serde_json::to_string(&j).unwrap()).unwrap();
    };
    rewrite("detections.json", Some("0123456789abcdef"));
    rewrite("fit.json", Some("0123456789abcdef"));
    let other = solve();
    assert!(!other.contains("fit.json reused"), "{other}");
    assert!(
        other.contains("detections.json is stale: it was made by another workbench build"),
        "{other}"
    );
    rewrite("detections.json", None);
    let older = solve();
    assert!(!older.contains("fit.json reused"), "{older}");
    assert!(
        older.contains("detections.json is stale: it records no build"),
        "{older}"
    );
    assert!(solve().contains("fit.json reused"));
}

/// SIGINT or SIGTERM in the middle of a set (issue 33: `plot` and `lut` left `.workbench-*.tmp`
/// files): the run deletes its temporaries, exits with 128 + the signal, and the previous
/// outputs stay as they were. The run is paused after its second file (a test hook) and signalled
/// there.
#[cfg(unix)]
#[test]
fn a_signal_leaves_no_temporaries() {
    let tmp = tempfile::tempdir().unwrap();
    let s = row_session(tmp.path(), "s", "1");
    let (code, _, err) = wb(&["--quiet", "solve", s.to_str().unwrap()]);
    assert!(code == 0 || code == 3, "{err}");
    let fit = s.join("fit.json");
    let plots = tmp.path().join("plots");
    let (code, _, err) = wb(&[
        "--quiet",
        "plot",
        fit.to_str().unwrap(),
        "--out",
        plots.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let before = snapshot(&plots);
    for (signal, name) in [(15, "TERM"), (2, "INT")] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_workbench"))
            .args([
                "--quiet",
                "plot",
                fit.to_str().unwrap(),
                "--out",
                plots.to_str().unwrap(),
            ])
            .env("WORKBENCH_PAUSE_AFTER_WRITES", "2")
            .spawn()
            .unwrap();
        let temporaries = || {
            std::fs::read_dir(&plots)
                .unwrap()
                .filter(|e| {
                    e.as_ref()
                        .unwrap()
                        .file_name()
                        .to_string_lossy()
                        .starts_with(".workbench-")
                })
                .count()
        };
        let t = std::time::Instant::now();
        while temporaries() < 2 {
            assert!(
                t.elapsed().as_secs() < 20,
                "SIG{name}: the run never paused"
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let killed = std::process::Command::new("kill")
            .args([format!("-{name}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(128 + signal), "SIG{name}");
        assert_eq!(temporaries(), 0, "SIG{name}: temporaries left");
        assert!(
            snapshot(&plots) == before,
            "SIG{name}: the previous figures changed"
        );
    }
}
