//! Independent numerical tools for the tests (adaptive quadrature, finite differences), shared
//! data, and running the binary.
#![allow(dead_code)]

/// Gauss–Kronrod 7/15 on [a, b]: (Kronrod estimate, |Kronrod − Gauss|).
fn gk15(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> (f64, f64) {
    const XK: [f64; 8] = [
        0.991_455_371_120_812_6,
        0.949_107_912_342_758_5,
        0.864_864_423_359_769_1,
        0.741_531_185_599_394_4,
        0.586_087_235_467_691_1,
        0.405_845_151_377_397_2,
        0.207_784_955_007_898_5,
        0.0,
    ];
    const WK: [f64; 8] = [
        0.022_935_322_010_529_22,
        0.063_092_092_629_978_55,
        0.104_790_010_322_250_2,
        0.140_653_259_715_525_9,
        0.169_004_726_639_267_9,
        0.190_350_578_064_785_4,
        0.204_432_940_075_298_9,
        0.209_482_141_084_727_8,
    ];
    const WG: [f64; 4] = [
        0.129_484_966_168_869_7,
        0.279_705_391_489_276_7,
        0.381_830_050_505_118_9,
        0.417_959_183_673_469_4,
    ];
    let c = 0.5 * (a + b);
    let h = 0.5 * (b - a);
    let fc = f(c);
    let mut k = WK[7] * fc;
    let mut g = WG[3] * fc;
    for i in 0..7 {
        let x = h * XK[i];
        let (f1, f2) = (f(c - x), f(c + x));
        k += WK[i] * (f1 + f2);
        if i % 2 == 1 {
            g += WG[i / 2] * (f1 + f2);
        }
    }
    (k * h, ((k - g) * h).abs())
}

/// Adaptive Gauss–Kronrod quadrature to an absolute tolerance.
pub fn integrate(f: &dyn Fn(f64) -> f64, a: f64, b: f64, tol: f64) -> f64 {
    fn rec(f: &dyn Fn(f64) -> f64, a: f64, b: f64, tol: f64, depth: u32) -> f64 {
        let (v, err) = gk15(f, a, b);
        if err <= tol || depth > 60 || (b - a).abs() < 1e-15 {
            return v;
        }
        let m = 0.5 * (a + b);
        rec(f, a, m, 0.5 * tol, depth + 1) + rec(f, m, b, 0.5 * tol, depth + 1)
    }
    rec(f, a, b, tol, 0)
}

/// Central difference with one Richardson step (error O(h⁴)).
pub fn derivative(f: &dyn Fn(f64) -> f64, x: f64, h: f64) -> f64 {
    let d = |h: f64| (f(x + h) - f(x - h)) / (2.0 * h);
    (4.0 * d(0.5 * h) - d(h)) / 3.0
}

/// |a − b| ≤ rel·|b| + abs.
pub fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * b.abs() + abs
}

/// `workbench --quiet synth session --out <out> <args>`, which must succeed.
pub fn synth_session(out: &std::path::Path, args: &[&str]) {
    let (code, _, err) = wb(&[
        &[
            "--quiet",
            "synth",
            "session",
            "--out",
            out.to_str().unwrap(),
        ][..],
        args,
    ]
    .concat());
    assert_eq!(code, 0, "{err}");
}

/// A small synthetic session solved (two spheres, 25 and 12 mm, in one 640×480 photo); `solve`
/// gets `extra` arguments. Returns the temporary folder and the session folder inside it.
pub fn solved_row(extra: &[&str]) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    synth_session(
        &s,
        &[
            "--size", "640x480", "--fx", "700", "--radii", "25,12", "--layout", "row",
        ],
    );
    let (code, _, err) = wb(&[&["--quiet", "solve"][..], extra, &[s.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    (dir, s)
}

/// A system program the setup script installs (`package`), or None with the reason recorded
/// ([`skipped`]); its absence fails the test under `CI=true`.
pub fn system_tool(program: &'static str, package: &str) -> Option<&'static str> {
    let ok = std::process::Command::new(program)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(program);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{program} missing under CI=true: scripts/setup-system.sh installs {package}"
    );
    skipped(&format!(
        "{program} not installed (scripts/setup-system.sh installs {package})"
    ));
    None
}

/// Mitsuba 3 as `scripts/setup-system.sh` installs it (into the build folder's `python/`): the
/// Python program and the `PYTHONPATH` that imports it, or None with the reason recorded
/// ([`skipped`]); its absence fails the test under `CI=true`.
pub fn mitsuba() -> Option<(&'static str, std::path::PathBuf)> {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .expect("the build folder")
        .join("python");
    let ok = std::process::Command::new("python3")
        .args(["-c", "import mitsuba"])
        .env("PYTHONPATH", &path)
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(("python3", path));
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "Mitsuba 3 missing under CI=true: scripts/setup-system.sh installs it into {}",
        path.display()
    );
    skipped(&format!(
        "Mitsuba 3 not installed in {} (scripts/setup-system.sh installs it)",
        path.display()
    ));
    None
}

/// Where the tests that skipped list themselves: `scripts/test.sh` prints it at the end of a run
/// (the harness hides a passing test's output).
pub const SKIPPED_LIST: &str = concat!(env!("CARGO_TARGET_TMPDIR"), "/skipped-tests.txt");

/// Record that the running test passes without checking what it is for, and why: printed, and
/// appended to [`SKIPPED_LIST`] as "test name: reason".
pub fn skipped(reason: &str) {
    use std::io::Write;
    let name = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    println!("skipped: {reason}");
    let line = format!("{name}: {reason}\n");
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(SKIPPED_LIST);
    if let Err(e) = file.and_then(|mut f| f.write_all(line.as_bytes())) {
        eprintln!("cannot record the skip in {SKIPPED_LIST}: {e}");
    }
}

/// ../shared/data, or None with the reason recorded ([`skipped`]); under `CI=true` its absence
/// fails the test.
pub fn shared_data() -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if p.is_dir() {
        Some(p)
    } else if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{} is absent, and CI=true needs it", p.display());
    } else {
        skipped(&format!("{} is absent", p.display()));
        None
    }
}

/// A `session.json` in `dir` for DiLiGenT's ball photos in `ball` (one light per photo, no
/// intrinsics, nothing else given), and the calibrated light directions converted to the camera
/// frame (theirs: x right, y up, z toward the camera). Also the photos' file names.
pub fn diligent_session(
    ball: &std::path::Path,
    dir: &std::path::Path,
) -> (Vec<String>, Vec<[f64; 3]>) {
    diligent_session_with(ball, dir, false)
}

/// [`diligent_session`], with each photo's `light_intensity` from the dataset's
/// `light_intensities.txt` where `intensities`.
pub fn diligent_session_with(
    ball: &std::path::Path,
    dir: &std::path::Path,
    intensities: bool,
) -> (Vec<String>, Vec<[f64; 3]>) {
    let lines = |f: &str| -> Vec<String> {
        std::fs::read_to_string(ball.join(f))
            .unwrap()
            .lines()
            .map(|l| l.trim().to_string())
            .filter(|l| !l.is_empty())
            .collect()
    };
    let names = lines("filenames.txt");
    let truth = lines("light_directions.txt")
        .iter()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [v[0], -v[1], -v[2]]
        })
        .collect();
    // Photos must lie in the session folder: links to the shared files, not copies.
    for n in &names {
        let from = std::fs::canonicalize(ball.join(n)).unwrap();
        std::os::unix::fs::symlink(from, dir.join(n)).unwrap();
    }
    let numbers =
        |l: &String| -> Vec<f64> { l.split_whitespace().map(|t| t.parse().unwrap()).collect() };
    let lamps: Vec<Vec<f64>> = lines("light_intensities.txt").iter().map(numbers).collect();
    let session = serde_json::json!({
        "schema": "workbench.session/1",
        "light": "per-image",
        "images": names.iter().zip(&lamps).map(|(n, i)| {
            let mut im = serde_json::json!({"file": n, "spheres": [{"radius_mm": 20.0}]});
            if intensities {
                im["light_intensity"] = serde_json::json!(i);
            }
            im
        }).collect::<Vec<_>>()
    });
    std::fs::write(dir.join("session.json"), session.to_string()).unwrap();
    (names, truth)
}

/// The synthetic camera (its distortion) at another size, focal length and principal point.
fn camera(size: [u32; 2], f: f64, cx: f64, cy: f64) -> workbench::camera::Camera {
    workbench::camera::Camera {
        fx: f,
        fy: f,
        cx,
        cy,
        image_size: size,
        ..workbench::synth::session::default_camera()
    }
}

/// A 640×480 version of the synthetic camera (fx 700): a quarter of the default's pixels.
pub fn camera_640x480() -> workbench::camera::Camera {
    camera([640, 480], 700.0, 321.6, 239.3)
}

/// A 320×240 version of the synthetic camera (fx 350): small sessions for fast tests.
pub fn camera_320x240() -> workbench::camera::Camera {
    camera([320, 240], 350.0, 160.8, 119.6)
}

/// Run the workbench binary: (exit code, stdout, stderr).
pub fn wb(args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_workbench"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A copy of a session folder's files in a temporary folder, as the repository or ../shared holds
/// it: what an earlier run wrote beside it (detections.json, fit.json, overlays) is left behind.
pub fn session_copy(src: &std::path::Path) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        if p.is_file() && name != "detections.json" && name != "fit.json" {
            std::fs::copy(&p, dir.path().join(&name)).unwrap();
        }
    }
    dir
}
