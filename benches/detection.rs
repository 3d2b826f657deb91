//! Detection benchmark, run by hand (`cargo bench --bench detection [-- --quick]`):
//! 1. synthetic sessions (5 radii, 1280×960) against their truth: silhouette centre and radius
//!    error (px), light error per sphere and combined (°), at several noise levels, exposures
//!    (clipped highlights), roughnesses and as 8-bit JPEG;
//! 2. DiLiGenT's ball (../shared/data/diligent-ball): light error against the calibrated
//!    directions, with the plain saturated-blob centroid on the same outline as the baseline;
//! 3. time per 24 MP photo (3 photos in parallel on this machine's cores).
//!
//! Prints Markdown tables.

#[path = "../tests/it/common/mod.rs"]
mod common;

use nalgebra::{Vector2, Vector3};
use std::path::Path;
use std::time::Instant;
use workbench::detect::{self, Options};
use workbench::formats::detections::Detections;
use workbench::synth::session::{self, Format, SessionConfig, SessionTruth};

fn detect(dir: &Path) -> Detections {
    detect::run(&Options {
        session: dir.to_path_buf(),
        out: None,
        overlays: false,
        quiet: true,
        medium_outlines: false,
    })
    .unwrap()
}

fn deg(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    Vector3::from(*a).angle(&Vector3::from(*b)).to_degrees()
}

/// Baseline for detection times: decoding the same photos to linear RGB (in parallel, as
/// detection does), seconds.
fn decode_time(files: &[std::path::PathBuf]) -> f64 {
    use rayon::prelude::*;
    let t0 = Instant::now();
    files.par_iter().for_each(|f| {
        workbench::formats::photo::load_linear_rgb(f, None).unwrap();
    });
    t0.elapsed().as_secs_f64()
}

fn synthetic(label: &str, cfg: &SessionConfig) {
    let dir = tempfile::tempdir().unwrap();
    let out = session::generate(cfg, dir.path(), None, true).unwrap();
    let t: &SessionTruth = &out.truth;
    let t0 = Instant::now();
    let d = detect(dir.path());
    let secs = t0.elapsed().as_secs_f64();
    let (mut dc, mut dr, mut dl) = (0.0f64, 0.0f64, 0.0f64);
    let mut methods = vec![];
    for (im, ti) in d.images.iter().zip(&t.images) {
        for (s, ts) in im.spheres.iter().zip(&ti.spheres) {
            let c =
                (Vector2::from(s.ellipse.center_px) - Vector2::from(ts.ellipse.center_px)).norm();
            dc = dc.max(c);
            dr = dr.max((s.ellipse.axes_px[0] - ts.ellipse.axes_px[0]).abs());
            if let Some(l) = &s.light_direction {
                dl = dl.max(deg(l, &t.light_direction));
            }
            methods.push(match &s.highlight {
                Some(h) => format!("{:?}", h.method),
                None => "none".into(),
            });
        }
    }
    methods.dedup();
    let comb = d
        .light_direction
        .map(|l| format!("{:.3}", deg(&l, &t.light_direction)))
        .unwrap_or_else(|| "—".into());
    let std = d
        .light_std_deg
        .map(|s| format!("{s:.3}"))
        .unwrap_or_else(|| "—".into());
    println!(
        "| {label} | {dc:.3} | {dr:.3} | {dl:.3} | {comb} | {std} | {} | {secs:.1} |",
        methods.join(", ")
    );
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    println!("## Synthetic sessions (5 radii 35–15 mm, 1280×960, light az 70° el 20°)\n");
    println!("| case | max centre err (px) | max radius err (px) | max light err per sphere (°) | combined light err (°) | combined std (°) | highlight method | detect (s) |");
    println!("|---|---|---|---|---|---|---|---|");
    let base = SessionConfig::default();
    let noises: &[f64] = if quick { &[0.01] } else { &[0.0, 0.01, 0.03] };
    for &n in noises {
        synthetic(
            &format!("noise {n}, exposure 1.2, α 0.1"),
            &SessionConfig {
                noise: n,
                read_noise: if n == 0.0 { 0.0 } else { base.read_noise },
                ..base.clone()
            },
        );
    }
    if !quick {
        for e in [0.3, 3.0] {
            synthetic(
                &format!("noise 0.01, exposure {e}"),
                &SessionConfig {
                    exposure: e,
                    ..base.clone()
                },
            );
        }
        for a in [0.05, 0.2, 0.3] {
            let mut cfg = base.clone();
            cfg.material.specular.alpha = a;
            synthetic(&format!("noise 0.01, α {a}"), &cfg);
        }
        synthetic(
            "8-bit JPEG q95, noise 0.01",
            &SessionConfig {
                format: Format::Jpeg,
                ..base.clone()
            },
        );
    }

    diligent();
    if !quick {
        large();
    }
}

/// DiLiGenT's ball: the light per photo against the dataset's, and a plain centroid's.
fn diligent() {
    if let Ok(ball) = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/diligent-ball")
        .canonicalize()
    {
        println!("\n## DiLiGenT ball (48 photos, no mask/normals/lights/intrinsics given)\n");
        let dir = tempfile::tempdir().unwrap();
        let (names, truth) = common::diligent_session(&ball, dir.path());
        let t0 = Instant::now();
        let d = detect(dir.path());
        let secs = t0.elapsed().as_secs_f64();
        // Baseline on the same outline: the plain centroid of the clipped pixels.
        let mut ours = vec![];
        let mut plain = vec![];
        for ((im, t), name) in d.images.iter().zip(&truth).zip(&names) {
            let s = &im.spheres[0];
            ours.push(deg(s.light_direction.as_ref().unwrap(), t));
            let img = workbench::formats::photo::load_linear_rgb(&ball.join(name), None).unwrap();
            let o = s.outline.outline();
            let (mut n, mut c) = (0.0, Vector2::zeros());
            for y in 0..img.height {
                for x in 0..img.width {
                    let p = Vector2::new(x as f64, y as f64);
                    let q = Vector3::new(p.x, p.y, 0.0);
                    if img.saturated[(y * img.width + x) as usize] && o.s(&q) < 1.0 {
                        n += 1.0;
                        c += p;
                    }
                }
            }
            let q = c / n;
            let surf = o.surface(&Vector3::new(q.x, q.y, 0.0)).unwrap();
            let l = workbench::camera::outline::reflect(&surf.normal, &surf.view);
            plain.push(deg(&[l.x, l.y, l.z], t));
        }
        println!("| estimator | mean (°) | median (°) | max (°) |");
        println!("|---|---|---|---|");
        for (name, mut e) in [
            ("workbench detect", ours),
            ("plain saturated centroid, same outline", plain),
        ] {
            e.sort_by(|a, b| a.total_cmp(b));
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            println!(
                "| {name} | {mean:.3} | {:.3} | {:.3} |",
                e[e.len() / 2],
                e[e.len() - 1]
            );
        }
        let files: Vec<_> = names.iter().map(|n| ball.join(n)).collect();
        let dec = decode_time(&files);
        println!(
            "\nDetection of the 48 photos: {secs:.1} s, {:.0}× the time to decode them ({dec:.2} s, same run); silhouette pooled over {} photos.",
            secs / dec,
            d.images[0].spheres[0].silhouette_photos
        );
    }
}

/// Three 24 MP photos: detection against decoding.
fn large() {
    println!("\n## 24 MP photos\n");
    let mut cfg = SessionConfig {
        radii_mm: vec![35.0, 25.0, 15.0],
        ..SessionConfig::default()
    };
    cfg.camera.image_size = [6000, 4000];
    cfg.camera.fx = 6500.0;
    cfg.camera.fy = 6500.0;
    cfg.camera.cx = 3001.5;
    cfg.camera.cy = 1998.0;
    cfg.supersample = 2;
    let dir = tempfile::tempdir().unwrap();
    let out = session::generate(&cfg, dir.path(), None, true).unwrap();
    let t0 = Instant::now();
    let d = detect(dir.path());
    let secs = t0.elapsed().as_secs_f64();
    let dec = decode_time(&out.images);
    let dl = deg(
        d.light_direction.as_ref().unwrap(),
        &out.truth.light_direction,
    );
    println!(
        "3 photos of 6000×4000 (sphere radii {:.0}–{:.0} px), {} cores: {secs:.1} s, {:.1} s per photo, {:.1}× the time to decode them ({dec:.2} s, same run); combined light error {dl:.3}°",
        d.images[2].spheres[0].ellipse.axes_px[0],
        d.images[0].spheres[0].ellipse.axes_px[0],
        rayon::current_num_threads(),
        secs / 3.0,
        secs / dec
    );
}
