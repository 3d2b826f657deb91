//! The binary: real runs, and bad input giving one clear line, a non-zero exit and no panic.

use crate::common;
use common::wb;
use std::path::Path;

fn assert_clean_failure(args: &[&str], needle: &str) {
    let (code, _, err) = wb(args);
    assert_ne!(code, 0, "{args:?}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert!(lines.len() == 1 || err.contains("Usage"), "{args:?}: {err}");
    assert!(
        err.contains(needle),
        "{args:?}: expected {needle:?} in {err}"
    );
}

/// A synthetic 640×480 photo of two spheres (20 and 12 mm) in a row, in `<tempdir>/s`.
fn two_sphere_row() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let (code, _, err) = wb(&[
        "--quiet",
        "synth",
        "session",
        "--out",
        out.to_str().unwrap(),
        "--size",
        "640x480",
        "--fx",
        "700",
        "--radii",
        "20,12",
        "--layout",
        "row",
    ]);
    assert_eq!(code, 0, "{err}");
    (dir, out)
}

#[test]
fn synth_then_check_a_session() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let o = out.to_str().unwrap();
    let (code, stdout, err) = wb(&[
        "--quiet", "synth", "session", "--out", o, "--size", "320x240", "--fx", "350", "--radii",
        "20,10", "--layout", "row",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("wrote 1 image(s)"));
    let (code, stdout, err) = wb(&["check", o]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("row.png")
            && stdout.contains("16-bit RGB linear")
            && stdout.contains("spheres 20 10 mm"),
        "{stdout}"
    );
    assert!(
        stdout.contains("exposure 1.2000 (session.json)"),
        "{stdout}"
    );

    // The same session with a missing image: the error names the image file.
    std::fs::remove_file(out.join("row.png")).unwrap();
    assert_clean_failure(&["check", o], "row.png: No such file");
    // A corrupt image.
    std::fs::write(out.join("row.png"), b"\x89PNG\r\n\x1a\n truncated").unwrap();
    assert_clean_failure(&["check", o], "row.png");
}

#[test]
fn jpeg_session_uses_exif_exposure() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("j");
    let o = o.to_str().unwrap();
    let (code, _, err) = wb(&[
        "--quiet",
        "synth",
        "session",
        "--out",
        o,
        "--size",
        "320x240",
        "--fx",
        "350",
        "--radii",
        "20",
        "--format",
        "jpeg",
        "--exposure",
        "0.5",
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, stdout, err) = wb(&["check", o]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("8-bit RGB sRGB, exposure 0.5000 (EXIF)"),
        "{stdout}"
    );
}

#[test]
fn checkerboard_writes_views_and_truth() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("c");
    let (code, stdout, err) = wb(&[
        "--quiet",
        "synth",
        "checkerboard",
        "--out",
        o.to_str().unwrap(),
        "--size",
        "320x240",
        "--fx",
        "350",
        "--views",
        "12",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("wrote 12 view(s)"));
    assert!(
        Path::new(&o).join("view12.png").is_file() && Path::new(&o).join("truth.json").is_file()
    );
}

#[test]
fn bad_input_is_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("x");
    let o = o.to_str().unwrap();
    assert_clean_failure(
        &["synth", "session", "--out", o, "--radii", "10,-2"],
        "radius -2 mm is not positive",
    );
    assert_clean_failure(
        &["synth", "session", "--out", o, "--radii", "10,abc"],
        "\"abc\" is not a number",
    );
    assert_clean_failure(
        &["synth", "session", "--out", o, "--size", "10by10"],
        "expected WIDTHxHEIGHT",
    );
    assert_clean_failure(
        &["synth", "session", "--out", o, "--distance", "20"],
        "do not fit",
    );
    assert_clean_failure(
        &["synth", "checkerboard", "--out", o, "--pattern", "1x6"],
        "at least 2×2",
    );
    assert_clean_failure(
        &["synth", "checkerboard", "--out", o, "--format", "gif"],
        "expected png or jpeg",
    );
    assert!(!Path::new(o).exists(), "nothing written for refused input");

    let s = dir.path().join("session.json");
    std::fs::write(&s, r#"{"schema":"workbench.session/1","images":[{"file":"a.png","spheres":[{"radius_mm":-3}]}]}"#).unwrap();
    assert_clean_failure(
        &["check", s.to_str().unwrap()],
        "radius_mm must be a positive number",
    );
    std::fs::write(&s, r#"{"schema":"workbench.session/9","images":[]}"#).unwrap();
    assert_clean_failure(
        &["check", s.to_str().unwrap()],
        "expected \"workbench.session/1\"",
    );
    std::fs::write(&s, "{ not json").unwrap();
    assert_clean_failure(
        &["check", s.to_str().unwrap()],
        "session.json: invalid JSON",
    );
    assert_clean_failure(
        &["check", dir.path().join("nope").to_str().unwrap()],
        "nope: No such file",
    );
}

#[cfg(feature = "opencv")]
#[test]
fn calibrate_a_synthetic_folder_and_refuse_an_empty_one() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c");
    let c = c.to_str().unwrap();
    let (code, _, err) = wb(&[
        "--quiet",
        "synth",
        "checkerboard",
        "--out",
        c,
        "--size",
        "640x480",
        "--fx",
        "700",
        "--views",
        "12",
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, stdout, err) = wb(&[
        "--quiet",
        "calibrate",
        c,
        "--square",
        "25mm",
        "--export",
        "ros,colmap",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("pattern  9x6 inner corners") && stdout.contains("12 used"),
        "{stdout}"
    );
    for f in [
        "intrinsics.json",
        "intrinsics.yml",
        "plots/calibration-views.png",
        "plots/calibration-coverage.svg",
    ] {
        assert!(Path::new(c).join(f).is_file(), "{f}");
    }
    // The session check reads the calibration it wrote.
    let j: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(c).join("intrinsics.json")).unwrap(),
    )
    .unwrap();
    assert!((j["fx"].as_f64().unwrap() / 700.0 - 1.0).abs() < 2e-3);
    // The exports describe the camera intrinsics.json holds (tests/it/export.rs reads them back).
    let cam =
        workbench::formats::intrinsics::IntrinsicsFile::load(&Path::new(c).join("intrinsics.json"))
            .unwrap()
            .camera();
    let read = |f: &str| std::fs::read_to_string(Path::new(c).join(f)).unwrap();
    assert!(crate::export::check_ros(&read("camera_info.yaml"), &cam) < 1e-12);
    let (_, e) = crate::export::check_colmap(&read("cameras.txt"), &cam);
    assert!(e < 1e-12, "{e}");
    assert!(
        stdout.contains("camera_info.yaml (ROS CameraInfo")
            && stdout.contains("cameras.txt (COLMAP"),
        "{stdout}"
    );

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert_clean_failure(
        &["calibrate", empty.to_str().unwrap()],
        "no JPEG, PNG or TIFF images",
    );
    assert_clean_failure(&["calibrate", c, "--pattern", "9by6"], "expected COLSxROWS");
    assert_clean_failure(
        &["calibrate", c, "--square=-3mm"],
        "expected a positive size",
    );
    assert_clean_failure(
        &["calibrate", c, "--square", "0mm"],
        "expected a positive size",
    );
}

#[test]
fn detect_writes_detections_and_overlays_and_refuses_a_wrong_count() {
    let (_dir, out) = two_sphere_row();
    let o = out.to_str().unwrap();
    let (code, stdout, err) = wb(&["--quiet", "detect", o]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("light    session"), "{stdout}");
    let det: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("detections.json")).unwrap())
            .unwrap();
    assert_eq!(det["schema"], "workbench.detections/2");
    assert_eq!(det["images"][0]["spheres"].as_array().unwrap().len(), 2);
    assert!(out.join("overlays/row.png").is_file());
    // The session lists one sphere too few.
    let p = out.join("session.json");
    let mut s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    s["images"][0]["spheres"].as_array_mut().unwrap().pop();
    std::fs::write(&p, s.to_string()).unwrap();
    assert_clean_failure(&["--quiet", "detect", o], "row.png");
    assert_clean_failure(
        &["--quiet", "detect", o],
        "found 2 sphere(s), session.json lists 1",
    );
    assert_clean_failure(&["detect", "/nonexistent/session"], "/nonexistent/session");
}

#[test]
fn solve_writes_fit_json_and_refuses_bad_options() {
    let (dir, out) = two_sphere_row();
    let o = out.to_str().unwrap();
    let fit = dir.path().join("fit.json");
    let f = fit.to_str().unwrap();
    let (code, stdout, err) = wb(&["--quiet", "solve", "--joint", o, "--out", f]);
    assert_eq!(code, 0, "{err}");
    for key in [
        "sigma0",
        "albedo",
        "eta",
        "specular",
        "light",
        "solver   converged",
        "wrote",
    ] {
        assert!(stdout.contains(key), "{key}: {stdout}");
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit).unwrap()).unwrap();
    assert_eq!(v["schema"], "workbench.fit/1");
    assert_eq!(v["sigma0_mm"].as_array().unwrap().len(), 3);
    // `--model auto` (the default) without the irradiance: the CDRF alone, and the summary says so.
    assert!(v.get("medium").is_none());
    assert!(
        stdout.contains("skipped  medium: the light's irradiance is unknown"),
        "{stdout}"
    );
    // Detection ran once and, --out lying in another folder, wrote detections.json beside the
    // fit, not into the session folder.
    assert!(dir.path().join("detections.json").is_file());
    assert!(!out.join("detections.json").exists());
    assert_clean_failure(&["solve", o, "--reduce", "3"], "cell width");
    assert_clean_failure(&["solve", o, "--prior", "alpha=0.1:0.1"], "eta only");
    assert_clean_failure(&["solve", o, "--prior", "eta=0.9:0.1"], "1 < mean");
    assert_clean_failure(&["solve", o, "--extensions", "wiggle"], "unknown extension");
    assert_clean_failure(&["solve", o, "--irradiance", "-1"], "positive");
    assert_clean_failure(
        &["solve", o, "--joint", "--method", "paper"],
        "cannot be used",
    );
    let nope = dir.path().join("nope.json");
    assert_clean_failure(
        &[
            "--quiet",
            "solve",
            o,
            "--holdout",
            "17",
            "--out",
            nope.to_str().unwrap(),
        ],
        "--holdout 17",
    );
    assert!(!nope.exists());
    assert_clean_failure(&["solve", "/nonexistent/session"], "/nonexistent/session");
    // `workbench plot` redraws the figures from fit.json (default: plots/ beside it).
    let (code, stdout, err) = wb(&["--quiet", "plot", f]);
    assert_eq!(code, 0, "{err}");
    let plots = dir.path().join("plots");
    assert!(stdout.contains("index.html"), "{stdout}");
    for name in [
        "index.html",
        "radiance-theta.png",
        "residual-phi.svg",
        "correlation.png",
        "residual-row-1.png",
        "residual-row-2.svg",
    ] {
        assert!(plots.join(name).is_file(), "{name}");
    }
    assert_clean_failure(&["plot", nope.to_str().unwrap()], "nope.json");
    std::fs::write(&nope, "{ not json").unwrap();
    assert_clean_failure(&["plot", nope.to_str().unwrap()], "nope.json");
}
