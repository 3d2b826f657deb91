//! Hostile input through the binary: broken and cut image files, broken EXIF (loaded with a
//! note), empty and unrelated folders, images too large or too small, bad session.json values,
//! paths leaving the session folder, a symlink loop. Each must give one line on stderr naming the
//! file at fault, a non-zero exit, no panic, and no fit.json or detections.json.

use crate::common;
use std::path::{Path, PathBuf};
use std::process::Command;
use workbench::synth::session::{self, Format, SessionConfig};

fn wb(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_workbench"))
        .arg("--quiet")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Run `workbench <cmd> <dir>` and check the failure: one line, naming `needle`.
fn refused(cmd: &str, dir: &Path, needle: &str) -> String {
    let (code, err) = wb(&[cmd, dir.to_str().unwrap()]);
    assert_ne!(code, 0, "{cmd} {}: exit 0", dir.display());
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{cmd} {}: {err}", dir.display());
    assert!(err.contains(needle), "expected {needle:?} in {err}");
    for f in ["fit.json", "detections.json"] {
        assert!(
            !dir.join(f).exists(),
            "{cmd} {}: {f} written",
            dir.display()
        );
    }
    println!("{cmd} {}: {}", dir.display(), lines[0]);
    err
}

/// A one-sphere 320×240 session in `<tmp>/<name>`.
fn session_in(tmp: &Path, name: &str, format: Format) -> PathBuf {
    let cfg = SessionConfig {
        camera: common::camera_320x240(),
        radii_mm: vec![20.0],
        format,
        ..SessionConfig::default()
    };
    let dir = tmp.join(name);
    session::generate(&cfg, &dir, None, true).unwrap();
    dir
}

/// [`session_in`], solved with the defaults: the folder and its fit.json.
fn solved_in(tmp: &Path, name: &str) -> (PathBuf, PathBuf) {
    let d = session_in(tmp, name, Format::Png16);
    let (code, err) = wb(&["solve", d.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let fit = d.join("fit.json");
    (d, fit)
}

fn photo(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| {
            p.extension()
                .is_some_and(|e| e == "png" || e == "jpg" || e == "tif")
        })
        .unwrap()
}

fn edit_session(dir: &Path, f: impl FnOnce(String) -> String) {
    let p = dir.join("session.json");
    let s = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, f(s)).unwrap();
}

/// Make the session orthographic (no intrinsics), so that any image size is accepted by the check
/// against the camera and reaches the size limits.
fn drop_intrinsics(dir: &Path) {
    edit_session(dir, |s| {
        s.replace("\"intrinsics\": \"intrinsics.json\",", "")
    });
}

#[test]
fn broken_image_files() {
    let tmp = tempfile::tempdir().unwrap();
    // A PNG cut after 3000 bytes, and one of random bytes.
    let d = session_in(tmp.path(), "cut-png", Format::Png16);
    let p = photo(&d);
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..3000]).unwrap();
    refused("solve", &d, "r20.png");
    refused("check", &d, "r20.png");
    let d = session_in(tmp.path(), "garbage-png", Format::Png16);
    let p = photo(&d);
    std::fs::write(
        &p,
        (0..5000u32)
            .map(|i| (i * 7919 % 251) as u8)
            .collect::<Vec<_>>(),
    )
    .unwrap();
    refused("solve", &d, "r20.png");
    refused("check", &d, "r20.png");
    // A JPEG cut short (it would decode, its missing rows grey) and one with broken EXIF.
    let d = session_in(tmp.path(), "cut-jpeg", Format::Jpeg);
    let p = photo(&d);
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = refused("solve", &d, "r20.jpg");
    assert!(e.contains("truncated JPEG"), "{e}");
    refused("check", &d, "r20.jpg");
    let d = session_in(tmp.path(), "bad-exif", Format::Jpeg);
    let p = photo(&d);
    let mut bytes = std::fs::read(&p).unwrap();
    let at = bytes
        .windows(6)
        .position(|w| w == b"Exif\0\0")
        .expect("the synthetic JPEG carries EXIF");
    bytes[at + 6..at + 46].fill(0xFF);
    std::fs::write(&p, &bytes).unwrap();
    // A photo whose EXIF block does not parse loads without its settings, and says so.
    let (code, out, err) = common::wb(&["check", d.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.lines()
            .any(|l| l.starts_with("exif") && l.contains("r20.jpg") && l.contains("unreadable")),
        "{out}"
    );
    // A TIFF cut short.
    let d = session_in(tmp.path(), "cut-tiff", Format::Png16);
    let png = photo(&d);
    let tif = d.join("r20.tif");
    image::open(&png).unwrap().save(&tif).unwrap();
    std::fs::remove_file(&png).unwrap();
    edit_session(&d, |s| s.replace("r20.png", "r20.tif"));
    let bytes = std::fs::read(&tif).unwrap();
    std::fs::write(&tif, &bytes[..bytes.len() / 3]).unwrap();
    refused("solve", &d, "r20.tif");
}

/// A PNG whose header says 10000×10000 (100 MP) with a few rows of data: refused from the header,
/// before anything is decoded.
fn huge_png(path: &Path) {
    fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend(kind);
        out.extend(data);
        let crc = crc32(&out[start..]);
        out.extend(crc.to_be_bytes());
    }
    fn crc32(b: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &x in b {
            c ^= x as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = vec![];
    ihdr.extend(10000u32.to_be_bytes());
    ihdr.extend(10000u32.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    // Stored (uncompressed) zlib data of one empty row: enough for a well-formed IDAT.
    chunk(
        &mut png,
        b"IDAT",
        &[
            0x78, 0x01, 0x01, 0x01, 0x00, 0xFE, 0xFF, 0x00, 0x00, 0x01, 0x00, 0x01,
        ],
    );
    chunk(&mut png, b"IEND", &[]);
    std::fs::write(path, png).unwrap();
}

#[test]
fn images_too_large_or_too_small() {
    let tmp = tempfile::tempdir().unwrap();
    let d = session_in(tmp.path(), "huge", Format::Png16);
    drop_intrinsics(&d);
    huge_png(&photo(&d));
    let e = refused("solve", &d, "r20.png");
    assert!(e.contains("100.0 MP"), "{e}");
    refused("check", &d, "r20.png");
    let d = session_in(tmp.path(), "tiny", Format::Png16);
    drop_intrinsics(&d);
    image::RgbImage::from_pixel(8, 8, image::Rgb([120, 100, 80]))
        .save(photo(&d))
        .unwrap();
    let e = refused("solve", &d, "r20.png");
    assert!(e.contains("8×8"), "{e}");
}

#[test]
fn empty_and_unrelated_folders() {
    let tmp = tempfile::tempdir().unwrap();
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    refused("solve", &empty, "session.json");
    refused("check", &empty, "session.json");
    refused("calibrate", &empty, "empty");
    // Photos of noise: no sphere, no chessboard.
    let d = session_in(tmp.path(), "noise", Format::Png16);
    let noise = image::RgbImage::from_fn(320, 240, |x, y| {
        let v = ((x * 7919 + y * 104729) % 251) as u8;
        image::Rgb([v, v / 2, 255 - v])
    });
    noise.save(photo(&d)).unwrap();
    let e = refused("solve", &d, "r20.png");
    assert!(e.contains("found 0 sphere"), "{e}");
    let cal = tmp.path().join("unrelated");
    std::fs::create_dir(&cal).unwrap();
    for k in 0..3 {
        noise.save(cal.join(format!("view{k}.png"))).unwrap();
    }
    refused("calibrate", &cal, "unrelated");
}

#[test]
fn bad_session_json() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, edit, needle) in [
        (
            "missing",
            Box::new(|s: String| s.replace("\"schema\": \"workbench.session/1\",", ""))
                as Box<dyn Fn(String) -> String>,
            "missing field `schema`",
        ),
        (
            "extra",
            Box::new(|s: String| s.replacen("\"schema\"", "\"colour\": \"red\", \"schema\"", 1)),
            "unknown field `colour`",
        ),
        (
            "negative",
            Box::new(|s: String| s.replace("\"radius_mm\": 20.0", "\"radius_mm\": -20.0")),
            "radius_mm must be a positive",
        ),
        (
            "nan",
            Box::new(|s: String| s.replace("\"radius_mm\": 20.0", "\"radius_mm\": NaN")),
            "invalid JSON",
        ),
        (
            "absurd-radius",
            Box::new(|s: String| s.replace("\"radius_mm\": 20.0", "\"radius_mm\": 1e12")),
            "radius_mm must be a positive",
        ),
        (
            "absurd-exposure",
            Box::new(|s: String| {
                let i = s.find("\"exposure\"").unwrap();
                let j = i + s[i..].find(['\n', '}']).unwrap();
                format!("{}\"exposure\": 1e300{}", &s[..i], &s[j..])
            }),
            "exposure must lie between",
        ),
        (
            "zero-lamp",
            Box::new(|s: String| {
                let mut v: serde_json::Value = serde_json::from_str(&s).unwrap();
                v["images"][0]["light_intensity"] = serde_json::json!([1.0, 0.0, 1.0]);
                v.to_string()
            }),
            "light_intensity must lie between",
        ),
        (
            "some-lamps",
            Box::new(|s: String| {
                let mut v: serde_json::Value = serde_json::from_str(&s).unwrap();
                v["light"] = "per-image".into();
                let mut other = v["images"][0].clone();
                other["file"] = "r20-again.png".into();
                v["images"].as_array_mut().unwrap().push(other);
                v["images"][0]["light_intensity"] = serde_json::json!([1.0, 0.9, 0.8]);
                v.to_string()
            }),
            "give it for all or none",
        ),
        (
            "escape",
            Box::new(|s: String| s.replace("\"r20.png\"", "\"../other/r20.png\"")),
            "outside the session folder",
        ),
        (
            "absolute",
            Box::new(|s: String| s.replace("\"r20.png\"", "\"/etc/r20.png\"")),
            "outside the session folder",
        ),
        (
            "twice",
            Box::new(|s: String| {
                let v: serde_json::Value = serde_json::from_str(&s).unwrap();
                let mut again = v["images"][0].clone();
                again["file"] = "./r20.png".into();
                let mut v = v;
                v["images"].as_array_mut().unwrap().push(again);
                v.to_string()
            }),
            "images[1] (./r20.png) is images[0] again",
        ),
        (
            "huge-field",
            Box::new(|s: String| {
                s.replacen(
                    "\"schema\"",
                    &format!("\"{}\": 1, \"schema\"", "x".repeat(10_000_000)),
                    1,
                )
            }),
            "characters left out",
        ),
    ] {
        let d = session_in(tmp.path(), name, Format::Png16);
        edit_session(&d, edit);
        let e = refused("solve", &d, "session.json");
        assert!(e.contains(needle), "{name}: {e}");
        // One line, however long the field it quotes.
        assert!(e.len() < 5000, "{name}: {} bytes on stderr", e.len());
    }
}

/// Outputs replace only regular files (issue 33): `--out` naming a FIFO, a symbolic link or a
/// folder is refused in one line before anything is written, and the special file is left as it
/// was, with no temporary beside it. Made in a temporary folder, never the system's /dev.
#[cfg(unix)]
#[test]
fn outputs_never_replace_special_files() {
    use std::os::unix::fs::FileTypeExt;
    let tmp = tempfile::tempdir().unwrap();
    let (d, fit) = solved_in(tmp.path(), "s");
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let fifo = out.join("fifo.json");
    let made = Command::new("mkfifo").arg(&fifo).status();
    let target = out.join("target.json");
    std::fs::write(&target, "keep").unwrap();
    let link = out.join("link.json");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let folder = out.join("folder.json");
    std::fs::create_dir(&folder).unwrap();
    let fifo_made = made.is_ok_and(|s| s.success());
    if !fifo_made {
        common::skipped("hostile::outputs_never_replace_special_files: the FIFO case: no mkfifo");
    }
    // The table's stem `t` writes t.png, t.exr and t.json: t.json is a link here.
    let lut_json = out.join("t.json");
    std::os::unix::fs::symlink(&target, &lut_json).unwrap();
    let (dir, fit, stem) = (d.to_str().unwrap(), fit.to_str().unwrap(), out.join("t"));
    let (link_s, folder_s, fifo_s) = (
        link.to_str().unwrap(),
        folder.to_str().unwrap(),
        fifo.to_str().unwrap(),
    );
    let mut cases = vec![
        (vec!["solve", dir, "--out", link_s], "symbolic link"),
        (vec!["solve", dir, "--out", folder_s], "a folder"),
        (vec!["plot", fit, "--out", link_s], "symbolic link"),
        (
            vec!["lut", fit, "--out", stem.to_str().unwrap()],
            "symbolic link",
        ),
    ];
    if fifo_made {
        cases.push((vec!["solve", dir, "--out", fifo_s], "not a regular file"));
        cases.push((vec!["plot", fit, "--out", fifo_s], "not a regular file"));
    }
    for (args, needle) in cases {
        let (code, err) = wb(&args);
        assert_ne!(code, 0, "{args:?}: exit 0");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
        println!("{}: {}", args[0], err.trim());
    }
    assert!(!out.join("t.png").exists() && !out.join("t.exr").exists());
    let meta = |p: &Path| std::fs::symlink_metadata(p).unwrap().file_type();
    if fifo.exists() {
        assert!(meta(&fifo).is_fifo(), "the FIFO was replaced");
    }
    assert!(meta(&link).is_symlink(), "the link was replaced");
    assert!(
        meta(&lut_json).is_symlink(),
        "the table's link was replaced"
    );
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
    assert!(meta(&folder).is_dir());
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".workbench-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

/// A stderr that cannot be written (`2>/dev/full`) does not turn an error into a panic: the exit
/// status is still the command's (1), not 101. /dev/full is only written to, never replaced.
#[cfg(unix)]
#[test]
fn an_unwritable_stderr_keeps_the_exit_status() {
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        common::skipped("hostile::an_unwritable_stderr_keeps_the_exit_status: no /dev/full");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_workbench"))
        .args([
            "--quiet",
            "solve",
            tmp.path().join("none").to_str().unwrap(),
        ])
        .stderr(full)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(1));
}

/// Angles out of range are refused when parsed: an elevation beyond ±90° or an azimuth beyond a
/// turn, for the solve's start light and the synthetic session's light.
#[test]
fn light_angles_out_of_range() {
    let tmp = tempfile::tempdir().unwrap();
    let d = session_in(tmp.path(), "s", Format::Png16);
    for (args, needle) in [
        (
            vec!["solve", d.to_str().unwrap(), "--start-light", "0,1000"],
            "elevation must lie",
        ),
        (
            vec!["solve", d.to_str().unwrap(), "--start-light", "-400,10"],
            "azimuth must lie",
        ),
        (
            vec![
                "synth",
                "session",
                "--out",
                tmp.path().join("x").to_str().unwrap(),
                "--light-elevation",
                "91",
            ],
            "elevation must lie",
        ),
    ] {
        let (code, err) = wb(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(
            err.contains(needle) && err.lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    assert!(!d.join("fit.json").exists() && !tmp.path().join("x").exists());
}

#[cfg(unix)]
#[test]
fn symlink_loop() {
    let tmp = tempfile::tempdir().unwrap();
    let d = session_in(tmp.path(), "loop", Format::Png16);
    let p = photo(&d);
    std::fs::remove_file(&p).unwrap();
    std::os::unix::fs::symlink(d.join("r20b.png"), &p).unwrap();
    std::os::unix::fs::symlink(&p, d.join("r20b.png")).unwrap();
    refused("solve", &d, "r20.png");
}

/// Sizes a user controls, each refused with one line: a chessboard pattern of 70000 × 70000
/// corners (it used to exhaust memory), a camera with fx = fy = 10⁻²⁰⁰ (it reached an `expect`)
/// or a 2 GiB image size, and a fit.json whose correlation lists 600 parameters (it overflowed
/// the figure's buffer).
#[test]
fn sizes_out_of_bounds() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = session_in(tmp.path(), "s", Format::Png16);
    if cfg!(feature = "opencv") {
        let (code, err) = wb(&[
            "calibrate",
            dir.to_str().unwrap(),
            "--pattern",
            "70000x70000",
        ]);
        assert_ne!(code, 0);
        assert!(err.contains("2 to 100 a side"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    let intrinsics = dir.join("intrinsics.json");
    let good = std::fs::read_to_string(&intrinsics).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["fx"] = serde_json::json!(1e-200);
    v["fy"] = serde_json::json!(1e-200);
    std::fs::write(&intrinsics, v.to_string()).unwrap();
    let err = refused("detect", &dir, "intrinsics.json");
    assert!(err.contains("fx = 1e-200"), "{err}");
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["image_size"] = serde_json::json!([1u64 << 31, 240]);
    std::fs::write(&intrinsics, v.to_string()).unwrap();
    refused("detect", &dir, "image_size");
    std::fs::write(&intrinsics, &good).unwrap();
    // A real fit, then its correlation blown up to 600 names.
    let (code, err) = wb(&["solve", dir.to_str().unwrap(), "--no-jackknife"]);
    assert!(code == 0 || code == 3, "{err}");
    let fit = dir.join("fit.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit).unwrap()).unwrap();
    let names: Vec<String> = (0..600).map(|k| format!("p{k}")).collect();
    let matrix = vec![vec![0.0; 600]; 600];
    v["correlation"] = serde_json::json!({ "names": names, "matrix": matrix });
    let bad = tmp.path().join("bad-fit.json");
    std::fs::write(&bad, v.to_string()).unwrap();
    let (code, err) = wb(&["plot", bad.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(
        err.contains("bad-fit.json") && err.contains("600 names"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// Run the binary with a deadline: its exit code and stderr, or a failure naming the command when
/// it is still running after `secs` (killed first, so that a hang fails the test, not the suite).
fn wb_within(secs: u64, args: &[&str]) -> (i32, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_workbench"))
        .arg("--quiet")
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            return (status.code().unwrap_or(-1), err);
        }
        if t.elapsed().as_secs() >= secs {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?}: still running after {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// A FIFO where a photo or a mesh is read is refused in one line, not waited on forever
/// (issue 33: `check` and `render` hung), and so is a folder.
#[cfg(unix)]
#[test]
fn special_files_as_inputs_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, fit) = solved_in(tmp.path(), "solved");
    let d = session_in(tmp.path(), "s", Format::Png16);
    let p = photo(&d);
    std::fs::remove_file(&p).unwrap();
    if !Command::new("mkfifo")
        .arg(&p)
        .status()
        .is_ok_and(|s| s.success())
    {
        common::skipped("hostile::special_files_as_inputs_are_refused: no mkfifo");
        return;
    }
    let mesh = tmp.path().join("fifo.obj");
    Command::new("mkfifo").arg(&mesh).status().unwrap();
    let folder_mesh = tmp.path().join("folder.obj");
    std::fs::create_dir(&folder_mesh).unwrap();
    let out = tmp.path().join("r.png");
    let (ds, ms, fs, os, fit) = (
        d.to_str().unwrap(),
        mesh.to_str().unwrap(),
        folder_mesh.to_str().unwrap(),
        out.to_str().unwrap(),
        fit.to_str().unwrap(),
    );
    for (args, needle) in [
        (vec!["check", ds], "not a regular file"),
        (vec!["solve", ds], "not a regular file"),
        (
            vec!["render", ms, "--fit", fit, "--out", os],
            "not a regular file",
        ),
        (vec!["render", fs, "--fit", fit, "--out", os], "is a folder"),
    ] {
        let (code, err) = wb_within(30, &args);
        assert_ne!(code, 0, "{args:?}");
        assert!(
            err.contains(needle) && err.lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    assert!(!out.exists());
}

/// `synth` writes only photos the readers accept (issue 33: a 20000×20000 session aborted on a
/// 9.6 GB allocation, beyond the 64 MP any command reads): refused in one line, nothing written.
#[test]
fn synthetic_photos_larger_than_what_is_read_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    for kind in ["session", "pbr", "checkerboard"] {
        let out = tmp.path().join(kind);
        let (code, err) = wb_within(
            30,
            &[
                "synth",
                kind,
                "--out",
                out.to_str().unwrap(),
                "--size",
                "20000x20000",
            ],
        );
        assert_ne!(code, 0, "{kind}");
        assert!(
            err.contains("more than the 64 MP") && err.lines().count() == 1,
            "{kind}: {err}"
        );
        assert!(
            !out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(),
            "{kind}"
        );
    }
}

/// A session folder whose name is not UTF-8 is refused by `solve` in one line (issue 33: fit.json
/// stored the name lossily, and `plot` then said the session was gone).
#[cfg(target_os = "linux")]
#[test]
fn a_session_path_that_is_not_utf8_is_refused() {
    use std::os::unix::ffi::OsStrExt;
    let tmp = tempfile::tempdir().unwrap();
    let name = std::ffi::OsStr::from_bytes(b"caf\xe9");
    let d = session_in(tmp.path(), "s", Format::Png16);
    let odd = tmp.path().join(name);
    std::fs::rename(&d, &odd).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_workbench"))
        .args(["--quiet", "solve"])
        .arg(&odd)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("not valid UTF-8") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!odd.join("fit.json").exists());
}

/// Table and render options whose result would be `inf` or black are refused in one line, and a
/// tolerance no table size meets is said, not recorded as met (issue 33).
#[test]
fn table_and_render_options_out_of_range() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, fit) = solved_in(tmp.path(), "s");
    let (fit, stem) = (fit.to_str().unwrap(), tmp.path().join("t"));
    let stem = stem.to_str().unwrap();
    let obj = crate::view::torus_obj(tmp.path());
    let out = tmp.path().join("r.png");
    let (obj, out_s) = (obj.to_str().unwrap(), out.to_str().unwrap());
    let render = |size| {
        vec![
            "render",
            obj,
            "--fit",
            fit,
            "--out",
            out_s,
            "--object-size",
            size,
        ]
    };
    for (args, needle) in [
        (
            vec!["lut", fit, "--out", stem, "--kappa-max", "1e300"],
            "--kappa-max must lie",
        ),
        (
            vec!["lut", fit, "--out", stem, "--tolerance", "1e-7"],
            "the largest table",
        ),
        (
            vec![
                "lut",
                fit,
                "--out",
                stem,
                "--preset",
                "unity",
                "--size",
                "8193x8193",
            ],
            "2..2049",
        ),
        (render("1e300"), "--object-size must lie"),
        (render("1e-300"), "--object-size must lie"),
    ] {
        let (code, err) = wb_within(120, &args);
        assert_ne!(code, 0, "{args:?}");
        assert!(
            err.contains(needle) && err.lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    assert!(!out.exists() && !tmp.path().join("t.json").exists());
}

/// fit.json has one reader and one validation (issue 33): a summary value edited without its
/// parameters[] entry, a negative σ0, an absurd albedo curvature (it hung `plot`) or a sphere of
/// 10⁻⁹ mm (an EXR of inf) is refused alike by `plot`, `lut` and `view`, in one line, in seconds.
#[test]
fn edited_fit_json_is_refused_alike_by_every_reader() {
    let tmp = tempfile::tempdir().unwrap();
    let (d, fit_path) = solved_in(tmp.path(), "s");
    let original: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit_path).unwrap()).unwrap();
    let set_param = |v: &mut serde_json::Value, name: &str, x: f64| {
        for p in v["parameters"].as_array_mut().unwrap() {
            if p["name"] == name {
                p["value"] = x.into();
            }
        }
    };
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "summary",
            Box::new(|v| v["sigma0_mm"][0] = 9.0.into()),
            "parameters[] says",
        ),
        (
            "negative",
            Box::new(move |v| {
                v["sigma0_mm"][0] = (-4.0).into();
                set_param(v, "sigma0_r", -4.0);
            }),
            "must be ≥ 0",
        ),
        (
            "curvature",
            Box::new(move |v| {
                v["albedo_curvature"] = 1e4.into();
                set_param(v, "albedo_curvature", 1e4);
            }),
            "within ±20",
        ),
        (
            "radius",
            Box::new(|v| v["rmse"]["spheres"][0]["radius_mm"] = 1e-9.into()),
            "outside",
        ),
    ];
    for (name, edit, needle) in cases {
        let mut v = original.clone();
        edit(&mut v);
        let f = d.join(format!("fit-{name}.json"));
        std::fs::write(&f, v.to_string()).unwrap();
        let (fs, out) = (f.to_str().unwrap(), tmp.path().join(format!("out-{name}")));
        let os = out.to_str().unwrap();
        for args in [
            vec!["plot", fs, "--out", os],
            vec!["lut", fs, "--out", os],
            vec!["view", fs, "--out", os],
        ] {
            let (code, err) = wb_within(30, &args);
            assert_ne!(code, 0, "{name}: {args:?}");
            assert!(
                err.contains(needle) && err.lines().count() == 1,
                "{name}: {args:?}: {err}"
            );
        }
        assert!(!out.exists(), "{name}");
    }
}

/// Every file under `dir` with its bytes.
fn tree_of(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// `solve --out` in another folder writes nothing into the session folder (issue 33: it wrote
/// detections.json and overlays/ there, so a read-only dataset could not be solved): detection's
/// files go beside the fit, a rerun reuses them, and `plot` of that fit finds them there.
#[test]
fn solve_elsewhere_leaves_the_session_folder_as_it_was() {
    let tmp = tempfile::tempdir().unwrap();
    let d = session_in(tmp.path(), "s", Format::Png16);
    let before = tree_of(&d);
    let out = tmp.path().join("results").join("fit.json");
    let (ds, os) = (d.to_str().unwrap(), out.to_str().unwrap());
    let (code, err) = wb(&["solve", ds, "--out", os]);
    assert_eq!(code, 0, "{err}");
    let results = out.parent().unwrap();
    assert!(results.join("detections.json").is_file() && results.join("overlays").is_dir());
    let (code, out2, err) = common::wb(&["solve", ds, "--out", os]);
    assert_eq!(code, 0, "{err}");
    assert!(out2.contains("reused"), "{out2}");
    let plots = tmp.path().join("plots");
    let (code, err) = wb(&["plot", os, "--out", plots.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(tree_of(&d) == before, "the session folder changed");
}

/// A fit whose standard errors are not finite (fit.json holds null for them) opens in every
/// reader (issue 33: `plot`, `view` and `lut` refused their own failed fits with "invalid type:
/// null, expected f64"): `plot` draws it, `view` shows it, and `lut` says why it makes no table.
#[test]
fn failed_fits_open_in_their_readers() {
    let tmp = tempfile::tempdir().unwrap();
    let d = session_in(tmp.path(), "s", Format::Png16);
    let ds = d.to_str().unwrap();
    for (name, extra) in [
        ("sigma", ["--start-sigma0", "1e300"]),
        ("irradiance", ["--irradiance", "1e300"]),
    ] {
        let fit = tmp.path().join(format!("{name}.json"));
        let fs = fit.to_str().unwrap();
        let (code, err) = wb(&[&["solve", ds, "--out", fs][..], &extra[..]].concat());
        assert!(code == 0 || code == 3, "{name}: {err}");
        let text = std::fs::read_to_string(&fit).unwrap();
        println!(
            "{name}: exit {code}, {} nulls in fit.json",
            text.matches("null").count()
        );
        let plots = tmp.path().join(format!("plots-{name}"));
        let (code, err) = wb_within(60, &["plot", fs, "--out", plots.to_str().unwrap()]);
        assert_eq!(code, 0, "{name}: plot: {err}");
        assert!(plots.join("radiance-theta.png").is_file());
        let page = tmp.path().join(format!("view-{name}"));
        let (code, err) = wb_within(60, &["view", fs, "--out", page.to_str().unwrap()]);
        assert_eq!(code, 0, "{name}: view: {err}");
        let (code, err) = wb_within(
            60,
            &["lut", fs, "--out", tmp.path().join(name).to_str().unwrap()],
        );
        assert!(code == 0 || err.lines().count() == 1, "{name}: lut: {err}");
        assert!(!err.contains("invalid type"), "{name}: lut: {err}");
    }
    // Any float of fit.json may be null (not finite): every one nulled, the file still reads.
    fn null_floats(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Number(n) if n.is_f64() => *v = serde_json::Value::Null,
            serde_json::Value::Array(a) => a.iter_mut().for_each(null_floats),
            serde_json::Value::Object(o) => o.values_mut().for_each(null_floats),
            _ => {}
        }
    }
    // Three radii, so that the jackknife, the extensions, the baseline, a held-out radius and
    // the paper's per-radius fits are in the files too.
    let three = tmp.path().join("three");
    common::synth_session(
        &three,
        &["--size", "320x240", "--fx", "350", "--radii", "30,20,12"],
    );
    let t = three.to_str().unwrap();
    let p = tmp.path().join("p");
    for (file, args) in [
        (
            "joint.json",
            vec!["--plots", p.to_str().unwrap(), "--extensions", "auto"],
        ),
        ("holdout.json", vec!["--holdout", "12"]),
        ("paper.json", vec!["--method", "paper"]),
    ] {
        let out = tmp.path().join(file);
        let (code, err) =
            wb(&[&["solve", t, "--out", out.to_str().unwrap()][..], &args[..]].concat());
        assert!(code == 0 || code == 3, "{file}: {err}");
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        null_floats(&mut v);
        std::fs::write(&out, v.to_string()).unwrap();
        let read: Result<workbench::formats::fit::FitFile, _> =
            workbench::formats::output::read_json(&out);
        assert!(read.is_ok(), "{file}: {:?}", read.err());
    }
}

/// An unknown field nested 100 000 deep in fit.json (issue 33: `view` copied it into a data.js
/// that browsers reject, with exit 0) is refused in one line or left out of the page.
#[test]
fn a_deeply_nested_unknown_field_stays_out_of_the_page() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, fit_file) = solved_in(tmp.path(), "s");
    let text = std::fs::read_to_string(&fit_file).unwrap();
    let deep = format!("{}1{}", "[".repeat(100_000), "]".repeat(100_000));
    let edited = text.replacen('{', &format!("{{\"zz_unknown\": {deep},"), 1);
    let fit = tmp.path().join("deep.json");
    std::fs::write(&fit, edited).unwrap();
    let page = tmp.path().join("page");
    let (code, err) = wb_within(
        60,
        &[
            "view",
            fit.to_str().unwrap(),
            "--out",
            page.to_str().unwrap(),
        ],
    );
    if code == 0 {
        let data = std::fs::read_to_string(page.join("data.js")).unwrap();
        assert!(
            !data.contains("zz_unknown") && data.len() < 1_000_000,
            "{} bytes",
            data.len()
        );
    } else {
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(!page.exists());
    }
}
