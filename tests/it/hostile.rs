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
            "escape",
            Box::new(|s: String| s.replace("\"r20.png\"", "\"../other/r20.png\"")),
            "outside the session folder",
        ),
        (
            "absolute",
            Box::new(|s: String| s.replace("\"r20.png\"", "\"/etc/r20.png\"")),
            "outside the session folder",
        ),
    ] {
        let d = session_in(tmp.path(), name, Format::Png16);
        edit_session(&d, edit);
        let e = refused("solve", &d, "session.json");
        assert!(e.contains(needle), "{name}: {e}");
    }
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
