//! `workbench lut` and `workbench render`: the table against the closed form, the renderer against
//! the solver's own prediction of a sphere, mesh formats, and the command line.

use crate::common;
use common::wb;
use nalgebra::Vector3;
use std::path::Path;
use workbench::camera::Camera;
use workbench::model::{LightAngles, Model};
use workbench::render::check::{compare, predict};
use workbench::render::job::{shader, table, TableSize};
use workbench::render::lut::{FitMaterial, Lut};
use workbench::render::mesh::{shapes, Mesh, Unit};
use workbench::render::raster::{render, Samples, Scene, Shading};
use workbench::synth::session::SessionConfig;

fn wax() -> FitMaterial {
    FitMaterial {
        model: Model::default(),
        material: SessionConfig::default().material,
        light: LightAngles {
            azimuth: 70f64.to_radians(),
            elevation: 20f64.to_radians(),
        },
        measured_kappa: [1.0 / 35.0, 1.0 / 15.0],
    }
}

/// An ideal sphere mesh rendered through the table reproduces the radiance model on the exact
/// sphere: the check `workbench render --check` runs on a fit, here on known parameters.
#[test]
fn ideal_sphere_reproduces_the_models_image() {
    let fm = wax();
    let t = table(&fm, TableSize::default(), None).unwrap();
    let cam = Camera::from_fov(640, 480, 40.0);
    for (r, z) in [(35.0, 400.0), (15.0, 200.0), (5.0, 90.0)] {
        let (c, _, _) = compare(&fm, &t.lut, &cam, Vector3::new(8.0, -5.0, z), r);
        println!(
            "r {r} mm: {} px, silhouette {} px, rel RMS {:.2e}, largest {:.2e}",
            c.pixels, c.silhouette_px, c.rel_rmse, c.max_rel
        );
        assert!(c.pixels > 5_000, "{c:?}");
        assert!(c.rel_rmse < 2e-3, "{c:?}");
        assert!(c.max_rel < 0.05, "{c:?}");
        assert!((c.silhouette_px as f64) < 0.002 * c.pixels as f64, "{c:?}");
    }
}

/// Lambert shading is the CDRF's flat limit: the model with σ0 = 0 on the same sphere.
#[test]
fn lambert_is_the_zero_blur_model() {
    let mut fm = wax();
    let t = table(&fm, TableSize::default(), None).unwrap();
    let cam = Camera::from_fov(320, 240, 40.0);
    let centre = Vector3::new(0.0, 0.0, 150.0);
    let mesh = shapes::icosphere(centre, 20.0, 5);
    let k = mesh.curvature();
    let img = render(
        &Scene::new(&mesh, &k),
        &cam,
        &shader(&fm, &t.lut, fm.light, Shading::Lambert),
        Samples::One,
    );
    fm.material.sigma0_mm = [0.0; 3];
    let params = workbench::model::Params {
        material: fm.material,
        light: fm.light,
    };
    let want = predict(
        &fm,
        &params,
        &cam,
        &workbench::camera::sphere::Sphere::new(centre, 20.0),
    );
    let (mut sq, mut rsq, mut dark_past_terminator) = (0.0, 0.0, 0);
    for (k, (a, b)) in img.rgb.iter().zip(&want.rgb).enumerate() {
        if img.coverage[k] == 0.0 || want.coverage[k] == 0.0 {
            continue;
        }
        for c in 0..3 {
            sq += ((a[c] - b[c]) as f64).powi(2);
            rsq += (b[c] as f64).powi(2);
        }
        if b[0] == 0.0 && a[0] == 0.0 {
            dark_past_terminator += 1;
        }
    }
    let rel = (sq / rsq).sqrt();
    println!("lambert vs σ0 = 0: rel RMS {rel:.2e}; {dark_past_terminator} unlit pixels");
    assert!(rel < 2e-3, "{rel}");
    assert!(dark_past_terminator > 1000);
}

/// Anti-aliasing: a silhouette pixel is partly covered, and the 4- and 16-sample images agree
/// away from the edges.
#[test]
fn silhouettes_are_antialiased() {
    let fm = wax();
    let t = table(&fm, TableSize::Fixed(129, 65), None).unwrap();
    let cam = Camera::from_fov(320, 240, 40.0);
    let mesh = shapes::icosphere(Vector3::new(3.0, 2.0, 150.0), 20.0, 5);
    let k = mesh.curvature();
    let scene = Scene::new(&mesh, &k);
    let sh = shader(&fm, &t.lut, fm.light, Shading::Cdrf);
    let a = render(&scene, &cam, &sh, Samples::Four);
    let b = render(&scene, &cam, &sh, Samples::Sixteen);
    let partial = a.coverage.iter().filter(|&&c| c > 0.0 && c < 1.0).count();
    // The silhouette is a circle of radius ≈ 20/150 · f: a ring of about 2π r partly covered pixels.
    let r_px = cam.fx * (20.0f64 / 150.0).tan();
    let ring = 2.0 * std::f64::consts::PI * r_px;
    println!("partly covered pixels: {partial} (ring {ring:.0})");
    assert!(
        partial as f64 > 0.5 * ring && (partial as f64) < 2.5 * ring,
        "{partial}"
    );
    // Total coverage equals the disc's area to within the ring's quantisation.
    let area: f64 = b.coverage.iter().map(|&c| c as f64).sum();
    let disc = std::f64::consts::PI * r_px * r_px;
    assert!((area - disc).abs() < 0.01 * disc, "{area} vs {disc}");
    let mut worst = 0.0f32;
    for kpx in 0..a.rgb.len() {
        if a.coverage[kpx] == 1.0 && b.coverage[kpx] == 1.0 {
            for c in 0..3 {
                worst = worst.max((a.rgb[kpx][c] - b.rgb[kpx][c]).abs());
            }
        }
    }
    // Fully covered pixels are shaded once at their centre either way, on the triangle of the
    // pixel's first sample (extrapolated when the centre lies on a neighbour): only the sharp
    // highlight (α 0.1) shows that.
    assert!(worst < 0.03, "{worst}");
}

/// OBJ and PLY (ASCII, with polygons and without normals) give the same mesh; units scale it.
#[test]
fn obj_and_ply_load_the_same_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let m = shapes::icosphere(Vector3::zeros(), 0.02, 2);
    let mut obj = String::from("# icosphere\n");
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len()
    );
    for p in &m.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
        ply += &format!("{} {} {}\n", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        ply += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    std::fs::write(dir.path().join("s.obj"), obj).unwrap();
    std::fs::write(dir.path().join("s.ply"), ply).unwrap();
    let a = Mesh::load(&dir.path().join("s.obj"), Unit::M).unwrap();
    let b = Mesh::load(&dir.path().join("s.ply"), Unit::M).unwrap();
    // tobj renumbers vertices in the order faces use them: compare the faces' corners.
    assert_eq!(a.triangles.len(), m.triangles.len());
    assert_eq!(b.triangles, m.triangles);
    for (ta, tb) in a.triangles.iter().zip(&b.triangles) {
        for k in 0..3 {
            let (p, q) = (a.positions[ta[k] as usize], b.positions[tb[k] as usize]);
            assert!((p - q).norm() < 1e-6);
        }
    }
    // 0.02 m = 20 mm: curvature 1/20 per mm.
    let k = b.curvature();
    assert!(
        k.iter().all(|&x| (x - 0.05).abs() < 0.05 * 0.02),
        "{:?}",
        &k[..4]
    );
    // Wound inside out, the computed normals still point outward.
    let flipped: Vec<[u32; 3]> = m.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
    let f = Mesh::new(m.positions.clone(), flipped, None, Path::new("flipped")).unwrap();
    for (p, n) in f.positions.iter().zip(&f.normals) {
        assert!(p.normalize().dot(n) > 0.99);
    }
    // A quad face is split in two.
    std::fs::write(
        dir.path().join("q.ply"),
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
    )
    .unwrap();
    assert_eq!(
        Mesh::load(&dir.path().join("q.ply"), Unit::Mm)
            .unwrap()
            .triangles
            .len(),
        2
    );
}

/// The table's files: PNG (16-bit, scaled) and EXR (float) hold the table; the sidecar says how.
#[test]
fn lut_files_round_trip() {
    let fm = wax();
    let t = table(&fm, TableSize::Fixed(65, 33), None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let paths = workbench::render::lut::write(
        &dir.path().join("wax"),
        &t.lut,
        &fm,
        Path::new("fit.json"),
        &t.error,
        None,
    )
    .unwrap();
    let side: workbench::render::lut::LutJson =
        serde_json::from_str(&std::fs::read_to_string(&paths[2]).unwrap()).unwrap();
    assert_eq!(side.schema, "workbench.lut/1");
    assert_eq!((side.n_cos, side.n_kappa), (65, 33));
    let exr = image::open(&paths[1]).unwrap().to_rgb32f();
    let png = image::open(&paths[0]).unwrap().to_rgb16();
    assert_eq!(exr.dimensions(), (65, 33));
    assert_eq!(png.dimensions(), (65, 33));
    let check = |lut: &Lut, i: usize, j: usize| {
        let v = lut.values[j * lut.n_cos + i];
        let e = exr.get_pixel(i as u32, j as u32);
        let p = png.get_pixel(i as u32, j as u32);
        for c in 0..3 {
            assert_eq!(e[c], v[c]);
            let from_png = p[c] as f64 / 65535.0 * side.png_scale;
            assert!((from_png - v[c] as f64).abs() <= 0.5 / 65535.0 * side.png_scale + 1e-9);
        }
        // The sidecar's mapping: node (i, j) is at N·L = −1 + 2i/(n−1), κ = κmax j/(m−1).
        let cos = side.cos_range[0] + 2.0 * i as f64 / (side.n_cos - 1) as f64;
        let kappa = side.kappa_range_per_mm[1] * j as f64 / (side.n_kappa - 1) as f64;
        let want = fm.diffuse(cos, kappa);
        for c in 0..3 {
            assert!((want[c] - e[c] as f64).abs() < 1e-6, "{i},{j}");
        }
    };
    for (i, j) in [(0, 0), (32, 0), (48, 10), (64, 32), (40, 20)] {
        check(&t.lut, i, j);
    }
}

/// End to end on a solved synthetic session: `lut`, `render --check`, `render` of a PLY mesh in
/// both shadings and bit depths, and bad input as one line.
#[test]
fn command_line_lut_render_and_check() {
    let (dir, s) = common::solved_row(&[]);
    let fit = s.join("fit.json");
    let fit = fit.to_str().unwrap();
    let (code, out, err) = wb(&["lut", fit]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("largest") && s.join("lut.exr").is_file() && s.join("lut.json").is_file(),
        "{out}"
    );
    let (code, out, err) = wb(&["render", "--check", "--fit", fit]);
    assert_eq!(code, 0, "{err}");
    let check: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(s.join("render-check/sphere-check.json")).unwrap(),
    )
    .unwrap();
    let spheres = check["spheres"].as_array().unwrap();
    assert_eq!(spheres.len(), 2, "{out}");
    for sp in spheres {
        assert!(sp["rel_rmse"].as_f64().unwrap() < 2e-3, "{sp}");
    }
    // One picture per sphere, named after its photo and index, and the JSON: nothing else.
    for sp in spheres {
        let stem = Path::new(sp["image"].as_str().unwrap())
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let png = s.join(format!("render-check/sphere-{stem}-{}.png", sp["index"]));
        let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
        assert!(
            img.width() > 2 * img.height(),
            "{}: not a strip",
            png.display()
        );
    }
    assert_eq!(
        std::fs::read_dir(s.join("render-check")).unwrap().count(),
        spheres.len() + 1
    );

    // A PLY mesh in metres.
    let m = shapes::torus(0.03, 0.01, 96, 32);
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len()
    );
    for p in &m.positions {
        ply += &format!("{} {} {}\n", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        ply += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    let mesh = dir.path().join("torus.ply");
    std::fs::write(&mesh, ply).unwrap();
    let mesh = mesh.to_str().unwrap();
    let img = dir.path().join("t.png");
    let img_s = img.to_str().unwrap();
    let base = [
        "render",
        mesh,
        "--unit",
        "m",
        "--fit",
        fit,
        "--resolution",
        "320x200",
        "--view",
        "20,40",
    ];
    let (code, out, err) = wb(&[&base[..], &["--out", img_s]].concat());
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("frame"), "{out}");
    let a = image::open(&img).unwrap();
    assert_eq!((a.width(), a.height()), (320, 200));
    let a = a.to_rgb8();
    let lit = a.pixels().filter(|p| p[0] > 30).count();
    assert!(lit > 5000, "{lit} lit pixels");
    let img16 = dir.path().join("t16.png");
    let (code, _, err) = wb(&[
        &base[..],
        &[
            "--out",
            img16.to_str().unwrap(),
            "--bits",
            "16",
            "--shading",
            "lambert",
            "--light=-40,10",
        ],
    ]
    .concat());
    assert_eq!(code, 0, "{err}");
    assert!(matches!(
        image::open(&img16).unwrap(),
        image::DynamicImage::ImageRgb16(_)
    ));

    // Bad input: one line naming the problem (and the file).
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["render", "/nonexistent/m.obj", "--fit", fit, "--out", img_s],
            "m.obj",
        ),
        (
            vec![
                "render",
                bad.to_str().unwrap(),
                "--fit",
                fit,
                "--out",
                img_s,
            ],
            "bad.obj",
        ),
        (
            vec!["render", mesh, "--fit", fit, "--out", "/tmp/x.jpg"],
            ".png",
        ),
        (
            vec![
                "render", mesh, "--fit", fit, "--out", img_s, "--light", "70",
            ],
            "AZIMUTH,ELEVATION",
        ),
        (
            vec!["render", mesh, "--fit", fit, "--out", img_s, "--bits", "12"],
            "8 or 16",
        ),
        (
            vec!["render", mesh, "--fit", mesh, "--out", img_s],
            "torus.ply",
        ),
        (vec!["lut", fit, "--size", "1x5"], "2..2049"),
        (vec!["render", mesh, "--fit", fit], "--out"),
    ];
    for (args, needle) in cases {
        let (code, _, err) = wb(&args);
        assert_ne!(code, 0, "{args:?}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        let lines = err.lines().filter(|l| !l.trim().is_empty()).count();
        assert_eq!(lines, 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}
