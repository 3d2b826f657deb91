//! `workbench view` in a real browser: headless Chromium (Debian's package, installed by
//! scripts/setup-system.sh) opens the page from disk, with WebGL2 on its software rasterizer; a
//! screenshot of a fixed view is compared with `workbench render` of the same view, and pages with
//! a broken fit show an error, not a blank canvas.

use crate::common::wb;
use std::path::{Path, PathBuf};
use std::process::Command;

fn chromium() -> Option<&'static str> {
    crate::common::system_tool("chromium", "chromium")
}

/// Headless Chromium on `page` (with `hash`): a screenshot of `size` into `png`, or the DOM after
/// the scripts ran (returned) when `png` is None.
fn browse(tool: &str, page: &Path, hash: &str, size: (u32, u32), png: Option<&Path>) -> String {
    let profile = tempfile::tempdir().unwrap();
    let mut c = Command::new(tool);
    c.args([
        "--headless",
        "--no-sandbox",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--hide-scrollbars",
        "--virtual-time-budget=10000",
    ])
    .arg(format!("--user-data-dir={}", profile.path().display()))
    .arg(format!("--window-size={},{}", size.0, size.1));
    match png {
        Some(p) => c.arg(format!("--screenshot={}", p.display())),
        None => c.arg("--dump-dom"),
    };
    let out = c
        .arg(format!(
            "file://{}#{hash}",
            page.canonicalize().unwrap().display()
        ))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "chromium: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A torus (major radius 30 mm, tube 12 mm) as an OBJ file: curvature from 1/12 to 1/42 … −1/18 /mm.
pub(crate) fn torus_obj(dir: &Path) -> PathBuf {
    let m = workbench::render::mesh::shapes::torus(30.0, 12.0, 96, 48);
    let mut s = String::new();
    for p in &m.positions {
        s += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let path = dir.join("torus.obj");
    std::fs::write(&path, s).unwrap();
    path
}

fn rgb8(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

#[test]
fn the_page_shows_what_render_draws() {
    let Some(tool) = chromium() else { return };
    let (dir, fit) = crate::engine::solved();
    let fit = fit.to_str().unwrap();
    let obj = torus_obj(dir.path());
    let obj = obj.to_str().unwrap();
    let page = dir.path().join("page");
    let view = ["--view", "30,35", "--light", "-40,25"];
    let (code, out, err) = wb(&[
        &["view", fit, "--mesh", obj, "--out", page.to_str().unwrap()][..],
        &view[..],
    ]
    .concat());
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("a mesh of 4608 vertices"), "{out}");
    let (w, h) = (480, 360);
    let shot = dir.path().join("shot.png");
    browse(
        tool,
        &page.join("index.html"),
        &format!("shot={w}x{h}&mesh"),
        (w, h),
        Some(&shot),
    );
    let rendered = dir.path().join("render.png");
    let (code, _, err) = wb(&[
        &[
            "render",
            obj,
            "--fit",
            fit,
            "--out",
            rendered.to_str().unwrap(),
            "--resolution",
            "480x360",
        ][..],
        &view[..],
    ]
    .concat());
    assert_eq!(code, 0, "{err}");
    let (a, b) = (rgb8(&shot), rgb8(&rendered));
    assert_eq!(a.dimensions(), b.dimensions());
    let (mut d2, mut b2, mut lit) = (0.0f64, 0.0f64, 0);
    for (p, q) in a.pixels().zip(b.pixels()) {
        for c in 0..3 {
            let (x, y) = (p[c] as f64, q[c] as f64);
            d2 += (x - y) * (x - y);
            b2 += y * y;
        }
        lit += (q[0] > 20) as usize;
    }
    let rel = (d2 / b2).sqrt();
    println!("screenshot against render: relative RMS {rel:.4} over {lit} lit pixels");
    // Something was drawn (not a blank canvas), and it is render's picture: measured 1.24%
    // (0.33% away from the silhouettes, where the two sample patterns differ); the goal is 2%.
    assert!(lit > 10_000, "{lit} lit pixels");
    assert!(rel <= 0.02, "relative RMS {rel}");
}

/// `workbench view <fit> --out <dir>/page`, which must succeed: the page's folder.
fn page_of(dir: &Path, fit: &Path) -> PathBuf {
    let page = dir.join("page");
    let (code, _, err) = wb(&[
        "view",
        fit.to_str().unwrap(),
        "--out",
        page.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    page
}

#[test]
fn a_broken_fit_shows_an_error_on_the_page() {
    let Some(tool) = chromium() else { return };
    let (dir, fit) = crate::engine::solved();
    let page = page_of(dir.path(), &fit);
    let data = std::fs::read_to_string(page.join("data.js")).unwrap();
    let index = page.join("index.html");
    // The fit's η not a number, then data.js cut short (fit.json truncated: not JSON at all).
    assert!(data.contains("\"eta\":"));
    let eta = data.replacen("\"eta\":", "\"eta\": \"broken\", \"was\":", 1);
    for (broken, says) in [
        (eta, "fit.json: eta must be a number"),
        (data[..data.len() / 2].to_string(), "data.js did not load"),
    ] {
        std::fs::write(page.join("data.js"), broken).unwrap();
        let dom = browse(tool, &index, "", (640, 480), None);
        assert!(dom.contains(says), "{says}: {dom}");
        // The error is on screen: red pixels, not a blank canvas.
        let shot = dir.path().join("error.png");
        browse(tool, &index, "", (640, 480), Some(&shot));
        let red = rgb8(&shot)
            .pixels()
            .filter(|p| p[0] > 150 && p[1] < 60 && p[2] < 80)
            .count();
        assert!(red > 5_000, "{says}: {red} red pixels");
    }
    // workbench view itself refuses a broken fit.json in one line, writing nothing.
    std::fs::write(&fit, "{ \"schema\": ").unwrap();
    let empty = dir.path().join("none");
    let (code, _, err) = wb(&[
        "view",
        fit.to_str().unwrap(),
        "--out",
        empty.to_str().unwrap(),
    ]);
    assert!(
        code != 0 && err.lines().count() == 1 && err.contains("fit.json"),
        "{err}"
    );
    assert!(!empty.join("index.html").exists());
}

/// The page copies the fit's own figures from plots/ beside fit.json, as regular files, and
/// nothing else the folder holds (issue 33: calibration plots, and a link to a system file
/// copied in as a .png).
#[cfg(unix)]
#[test]
fn the_page_copies_only_the_fits_figures() {
    let (dir, fit) = crate::engine::solved();
    let plots = fit.parent().unwrap().join("plots");
    std::fs::create_dir_all(&plots).unwrap();
    let png = image::RgbImage::from_pixel(4, 4, image::Rgb([200, 10, 10]));
    png.save(plots.join("radiance-theta.png")).unwrap();
    png.save(plots.join("calibration-rms.png")).unwrap();
    let outside = dir.path().join("outside.txt");
    std::fs::write(&outside, "not a figure").unwrap();
    std::os::unix::fs::symlink(&outside, plots.join("residual-theta.png")).unwrap();
    let page = page_of(dir.path(), &fit);
    let mut copied: Vec<String> = std::fs::read_dir(page.join("figures"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    copied.sort();
    assert_eq!(copied, ["radiance-theta.png"]);
}
