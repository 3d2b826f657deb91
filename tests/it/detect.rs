//! `workbench detect` against ground truth: synthetic sessions rendered by the project's forward
//! model (truth.json) and DiLiGenT's calibrated light directions (real photos).

use crate::common;
use nalgebra::{Vector2, Vector3};
use std::path::Path;
use workbench::detect::{self, Options};
use workbench::formats::detections::{Detections, OutlineJson};
use workbench::synth::session::{self, Layout, SessionConfig, SessionTruth};

fn run(dir: &Path) -> workbench::Result<Detections> {
    detect::run(&Options {
        session: dir.to_path_buf(),
        out: None,
        overlays: true,
        quiet: true,
        medium_outlines: false,
    })
}

fn truth(dir: &Path) -> SessionTruth {
    serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap()
}

/// How far a detected outline's centre lies from the true one (px).
fn centre_off(detected: [f64; 2], truth: [f64; 2]) -> f64 {
    (Vector2::from(detected) - Vector2::from(truth)).norm()
}

fn angle_deg(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    Vector3::from(*a).angle(&Vector3::from(*b)).to_degrees()
}

fn edit_session(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let p = dir.join("session.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&p, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

#[test]
fn synthetic_session_silhouettes_light_and_samples() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SessionConfig {
        radii_mm: vec![35.0, 25.0, 15.0],
        noise: 0.003,
        ..SessionConfig::default()
    };
    session::generate(&cfg, dir.path(), None, true).unwrap();
    let d = run(dir.path()).unwrap();
    let t = truth(dir.path());
    assert_eq!(d.schema, "workbench.detections/2");
    assert_eq!(d.projection, "perspective");
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for (im, ti) in d.images.iter().zip(&t.images) {
        let (s, ts) = (&im.spheres[0], &ti.spheres[0]);
        let dc = (Vector2::from(s.ellipse.center_px) - Vector2::from(ts.ellipse.center_px)).norm();
        let da = (s.ellipse.axes_px[0] - ts.ellipse.axes_px[0]).abs();
        let dl = angle_deg(s.light_direction.as_ref().unwrap(), &t.light_direction);
        println!(
            "{}: centre {dc:.3} px, axis {da:.3} px, light {dl:.4}°",
            im.file
        );
        worst = (worst.0.max(dc), worst.1.max(da), worst.2.max(dl));
        let cm = Vector3::from(s.center_mm.unwrap());
        let rel = (cm - Vector3::from(ts.center_mm)).norm() / Vector3::from(ts.center_mm).norm();
        assert!(
            rel < 1e-3,
            "{}: centre {cm:?} vs {:?}",
            im.file,
            ts.center_mm
        );
        // Every pixel centre inside the silhouette is a sample: about the ellipse's area.
        let area = std::f64::consts::PI * ts.ellipse.axes_px[0] * ts.ellipse.axes_px[1];
        let n = s.samples.total as f64;
        assert!(
            (n - area).abs() < 0.01 * area + 10.0,
            "{}: {n} samples, area {area}",
            im.file
        );
        assert!(s.samples.highlight > 0 && s.samples.edge > 0);
        assert!(Path::new(dir.path())
            .join(im.overlay.as_ref().unwrap())
            .is_file());
    }
    // Goals: sub-0.1 px silhouettes, light within 0.1° (per sphere and combined).
    assert!(worst.0 < 0.1 && worst.1 < 0.1, "{worst:?}");
    assert!(worst.2 < 0.1, "{worst:?}");
    let dl = angle_deg(d.light_direction.as_ref().unwrap(), &t.light_direction);
    println!("combined light {dl:.4}° ± {:.4}°", d.light_std_deg.unwrap());
    assert!(dl < 0.05, "{dl}");
    let az = d.light_azimuth_deg.unwrap();
    assert!((az - t.light_azimuth_deg).abs() < 0.1, "{az}");
    // Overlay: a PNG of the photo's size.
    let ov = image::open(dir.path().join("overlays/r35.png")).unwrap();
    assert_eq!((ov.width(), ov.height()), (1280, 960));
    // The JSON on disk is what was returned.
    let back: Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("detections.json")).unwrap())
            .unwrap();
    assert_eq!(back.images.len(), 3);
}

#[test]
fn samples_carry_exposure_normalised_radiance_and_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SessionConfig {
        radii_mm: vec![20.0],
        noise: 0.0,
        read_noise: 0.0,
        ..SessionConfig::default()
    };
    session::generate(&cfg, dir.path(), None, true).unwrap();
    let d = run(dir.path()).unwrap();
    let t = truth(dir.path());
    let s = &d.images[0].spheres[0];
    let img =
        workbench::formats::photo::load_linear_rgb(&dir.path().join("r20.png"), None).unwrap();
    let cam = t.intrinsics.camera();
    let proj = workbench::camera::outline::Projection::Perspective(cam);
    // θ and the highlight flags come from the detected light.
    let l = Vector3::from(d.light_direction.unwrap());
    let smp = workbench::detect::samples::sphere_samples(
        &img,
        t.images[0].exposure,
        &proj,
        &s.outline.outline(),
        20.0,
        Some(&l),
        Some(s.highlight.as_ref().unwrap().radius_deg.to_radians()),
    );
    assert_eq!(workbench::detect::samples::counts(&smp), s.samples);
    let sphere = workbench::camera::sphere::Sphere::new(
        Vector3::from(t.images[0].spheres[0].center_mm),
        20.0,
    );
    let mut worst_theta: f64 = 0.0;
    for x in smp
        .iter()
        .filter(|x| x.flags & workbench::detect::samples::EDGE == 0)
    {
        let i = (x.px[1] * img.width + x.px[0]) as usize;
        for c in 0..3 {
            let expect = img.data[3 * i + c] as f64 / t.images[0].exposure;
            assert!((x.radiance[c] - expect).abs() < 1e-12);
        }
        let ray = cam
            .ray_for_pixel(Vector2::new(x.px[0] as f64, x.px[1] as f64))
            .unwrap();
        let sp = sphere.surface_at(&ray).unwrap();
        worst_theta = worst_theta.max((sp.normal.dot(&l).acos() - x.theta).abs());
        assert!((sp.normal.dot(&sp.view).acos() - x.phi).abs() < 0.02);
    }
    println!("worst θ error {:.4}°", worst_theta.to_degrees());
    // Measured 0.10°: the detected outline against the true sphere.
    assert!(worst_theta.to_degrees() < 0.3);
}

#[test]
fn row_of_spheres_left_to_right_and_count_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SessionConfig {
        radii_mm: vec![30.0, 15.0, 22.0],
        layout: Layout::Row,
        noise: 0.003,
        ..SessionConfig::default()
    };
    session::generate(&cfg, dir.path(), None, true).unwrap();
    let d = run(dir.path()).unwrap();
    let t = truth(dir.path());
    let found: Vec<f64> = d.images[0].spheres.iter().map(|s| s.radius_mm).collect();
    assert_eq!(found, [30.0, 15.0, 22.0]);
    for (s, ts) in d.images[0].spheres.iter().zip(&t.images[0].spheres) {
        let dc = (Vector2::from(s.ellipse.center_px) - Vector2::from(ts.ellipse.center_px)).norm();
        assert!(dc < 0.15, "r {}: {dc}", s.radius_mm);
    }
    assert!(angle_deg(d.light_direction.as_ref().unwrap(), &t.light_direction) < 0.1);
    edit_session(dir.path(), |v| {
        v["images"][0]["spheres"].as_array_mut().unwrap().pop();
    });
    let e = workbench::error::one_line(&run(dir.path()).unwrap_err().to_string());
    assert!(
        e.contains("row.png") && e.contains("found 3 sphere(s), session.json lists 2"),
        "{e}"
    );
    // Told where to look (rough hints: 3 px and 10% of the radius off), the two listed spheres
    // are found and the third is ignored; the outlines as good as without hints.
    edit_session(dir.path(), |v| {
        for (k, ts) in t.images[0].spheres.iter().take(2).enumerate() {
            let c = ts.ellipse.center_px;
            v["images"][0]["spheres"][k]["center_px"] = serde_json::json!([c[0] + 3.0, c[1] - 2.0]);
            v["images"][0]["spheres"][k]["radius_px"] =
                serde_json::json!(1.1 * ts.ellipse.axes_px[0]);
        }
    });
    let d = run(dir.path()).unwrap();
    assert_eq!(d.images[0].spheres.len(), 2);
    for (s, ts) in d.images[0].spheres.iter().zip(&t.images[0].spheres) {
        let dc = (Vector2::from(s.ellipse.center_px) - Vector2::from(ts.ellipse.center_px)).norm();
        println!("hinted r {}: centre {dc:.3} px", s.radius_mm);
        assert!(dc < 0.15, "hinted r {}: {dc}", s.radius_mm);
    }
    // A hint for one sphere of two is refused, naming the photo.
    edit_session(dir.path(), |v| {
        let s = &mut v["images"][0]["spheres"][1];
        s.as_object_mut().unwrap().remove("center_px");
        s.as_object_mut().unwrap().remove("radius_px");
    });
    let e = run(dir.path()).unwrap_err().to_string();
    assert!(e.contains("row.png") && e.contains("all or none"), "{e}");
}

#[test]
fn sphere_cut_by_the_frame_is_an_error_naming_the_photo() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SessionConfig {
        radii_mm: vec![30.0, 20.0],
        layout: Layout::Row,
        noise: 0.003,
        ..SessionConfig::default()
    };
    session::generate(&cfg, dir.path(), None, true).unwrap();
    // Crop the left edge through the first sphere.
    let p = dir.path().join("row.png");
    let img = image::open(&p).unwrap();
    let t = truth(dir.path());
    let cut = (t.images[0].spheres[0].ellipse.center_px[0]) as u32;
    img.crop_imm(cut, 0, img.width() - cut, img.height())
        .save(&p)
        .unwrap();
    edit_session(dir.path(), |v| {
        v.as_object_mut().unwrap().remove("intrinsics");
    });
    let e = workbench::error::one_line(&run(dir.path()).unwrap_err().to_string());
    assert!(
        e.contains("row.png") && e.contains("touches the frame border"),
        "{e}"
    );
}

#[test]
fn orthographic_without_intrinsics_and_no_highlight() {
    let dir = tempfile::tempdir().unwrap();
    // A long lens (narrow field) so that the orthographic model is close; no specular lobe.
    let mut cfg = SessionConfig {
        radii_mm: vec![30.0, 20.0],
        noise: 0.003,
        ..SessionConfig::default()
    };
    cfg.camera.fx = 5000.0;
    cfg.camera.fy = 5000.0;
    cfg.camera.distortion = Default::default();
    session::generate(&cfg, dir.path(), None, true).unwrap();
    edit_session(dir.path(), |v| {
        v.as_object_mut().unwrap().remove("intrinsics");
    });
    let d = run(dir.path()).unwrap();
    let t = truth(dir.path());
    assert_eq!(d.projection, "orthographic");
    for (im, ti) in d.images.iter().zip(&t.images) {
        let s = &im.spheres[0];
        assert!(s.center_mm.is_none());
        assert!(matches!(s.outline, OutlineJson::Circle { .. }));
        let dc = (Vector2::from(s.ellipse.center_px)
            - Vector2::from(ti.spheres[0].ellipse.center_px))
        .norm();
        // A circle fitted to a (slightly elliptic) perspective silhouette.
        assert!(dc < 0.5, "{dc}");
    }
    // Off the optical axis the orthographic view direction is wrong by the field angle, and the
    // light by up to twice that (l = 2(n·v)n − v).
    let field = Vector3::from(t.images[0].spheres[0].center_mm)
        .angle(&Vector3::z())
        .to_degrees();
    let dl = angle_deg(d.light_direction.as_ref().unwrap(), &t.light_direction);
    println!("orthographic light error {dl:.3}° at a field angle of {field:.3}°");
    assert!(dl < 2.0 * field, "{dl}");

    let dir = tempfile::tempdir().unwrap();
    let mut cfg = SessionConfig {
        radii_mm: vec![25.0],
        noise: 0.003,
        ..SessionConfig::default()
    };
    cfg.material.specular.ks = 0.0;
    session::generate(&cfg, dir.path(), None, true).unwrap();
    let d = run(dir.path()).unwrap();
    let s = &d.images[0].spheres[0];
    assert!(s.light_direction.is_none() && s.highlight.is_none());
    assert!(s
        .no_highlight
        .as_ref()
        .unwrap()
        .contains("no significant specular peak"));
    assert!(d.light_direction.is_none());
    assert_eq!(s.samples.highlight, 0);
}

#[test]
fn per_image_lights_and_a_sphere_that_stayed_put() {
    let dir = tempfile::tempdir().unwrap();
    let mut lights = vec![];
    for (k, (az, el)) in [(60.0f64, 25.0f64), (-40.0, 10.0), (20.0, -30.0)]
        .iter()
        .enumerate()
    {
        let mut cfg = SessionConfig {
            radii_mm: vec![25.0],
            noise: 0.003,
            seed: k as u64 + 1,
            ..SessionConfig::default()
        };
        cfg.light.azimuth = az.to_radians();
        cfg.light.elevation = el.to_radians();
        let sub = dir.path().join(format!("l{k}"));
        let out = session::generate(&cfg, &sub, None, true).unwrap();
        lights.push(out.truth.light_direction);
    }
    let session = serde_json::json!({
        "schema": "workbench.session/1",
        "intrinsics": "l0/intrinsics.json",
        "light": "per-image",
        "images": (0..3).map(|k| serde_json::json!({
            "file": format!("l{k}/r25.png"), "exposure": 1.2, "spheres": [{"radius_mm": 25.0}]
        })).collect::<Vec<_>>()
    });
    std::fs::write(dir.path().join("session.json"), session.to_string()).unwrap();
    let d = run(dir.path()).unwrap();
    assert!(d.light_direction.is_none());
    for (im, l) in d.images.iter().zip(&lights) {
        let e = angle_deg(im.light_direction.as_ref().unwrap(), l);
        println!("{}: light error {e:.4}°", im.file);
        assert!(e < 0.1, "{}: {e}", im.file);
        // Same sphere, same place: one outline fitted over the three photos.
        assert_eq!(im.spheres[0].silhouette_photos, 3);
    }
}

/// DiLiGenT's glossy ball (16-bit, 48 lights) with no mask, normals, light file or intrinsics:
/// every photo's estimate in `d` against the calibrated directions `truth` (x right, y up, z toward
/// the camera). Checked on the detections the whole solve writes
/// (`solve::diligent_ball_whole_solve`: the detection of 48 photos runs once for both).
pub fn diligent_ball_lights(d: &Detections, truth: &[[f64; 3]]) {
    let mut errs: Vec<f64> = d
        .images
        .iter()
        .zip(truth)
        .map(|(im, t)| {
            angle_deg(
                im.light_direction
                    .as_ref()
                    .expect("a highlight in every photo"),
                t,
            )
        })
        .collect();
    errs.sort_by(|a, b| a.total_cmp(b));
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let median = errs[errs.len() / 2];
    let max = errs[errs.len() - 1];
    println!(
        "DiLiGenT ball, {} photos: mean {mean:.3}°, median {median:.3}°, max {max:.3}°",
        errs.len()
    );
    // Measured 0.61° / 0.63° / 1.27°; a plain saturated-blob centroid on the same outline 0.73°.
    assert!(mean < 0.7 && max < 1.4, "mean {mean} max {max}");
    // Most of it is one rotation shared by every photo (the frame: a sub-pixel bias of the ball's
    // outline, or of the chrome sphere DiLiGenT calibrated with, turns every light alike). After
    // the rotation that best aligns the 48 lights with the calibrated ones (Kabsch: 3 of 96
    // numbers), they agree to 0.354° mean (measured), a rotation of 0.557°.
    let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = d
        .images
        .iter()
        .zip(truth)
        .map(|(im, t)| {
            (
                Vector3::from(im.light_direction.unwrap()).normalize(),
                Vector3::from(*t).normalize(),
            )
        })
        .collect();
    let h: nalgebra::Matrix3<f64> = pairs.iter().map(|(a, b)| a * b.transpose()).sum();
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let sign = (vt.transpose() * u.transpose()).determinant().signum();
    let r = vt.transpose()
        * nalgebra::Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign))
        * u.transpose();
    let aligned = pairs
        .iter()
        .map(|(a, b)| (r * a).angle(b).to_degrees())
        .sum::<f64>()
        / pairs.len() as f64;
    let turn = nalgebra::Rotation3::from_matrix(&r).angle().to_degrees();
    println!("after one shared rotation of {turn:.3}°: mean {aligned:.3}°");
    assert!(
        aligned < 0.45 && turn > 0.3,
        "aligned {aligned}°, rotation {turn}°"
    );
}

/// Clipped highlights are data: a rough-ish lobe (α 0.1–0.15) exposed so that 5–30% of every disc
/// clips is fitted on its unclipped ring (clipped pixels censored: "at least this bright"); its
/// stated error covers the light's, and the solve, given that honest prior, refines the light.
#[test]
fn clipped_highlights_are_fitted_and_refined() {
    // 6%, 7%, 22% and 29% of each disc clipped; the last is the rough sphere (α 0.25) that was
    // refused on every sphere before the fit's patch held the ring around the clipped core.
    let mut z = vec![];
    for (alpha, ks) in [(0.1, 40.0), (0.15, 30.0), (0.15, 300.0), (0.25, 300.0)] {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SessionConfig {
            radii_mm: vec![35.0, 25.0, 15.0],
            camera: common::camera_640x480(),
            material: workbench::model::Material {
                specular: workbench::model::SpecularParams { ks, alpha },
                ..SessionConfig::default().material
            },
            noise: 0.003,
            ..SessionConfig::default()
        };
        session::generate(&cfg, dir.path(), None, true).unwrap();
        let d = run(dir.path()).unwrap();
        let t = truth(dir.path());
        for im in &d.images {
            let s = &im.spheres[0];
            let h = s
                .highlight
                .as_ref()
                .unwrap_or_else(|| panic!("{}: {:?}", im.file, s.no_highlight));
            let disc = std::f64::consts::PI * s.ellipse.axes_px[0] * s.ellipse.axes_px[1];
            let clipped = h.saturated_px as f64 / disc;
            let dl = angle_deg(s.light_direction.as_ref().unwrap(), &t.light_direction);
            let std = s.light_std_deg.unwrap();
            println!(
                "α {alpha} ks {ks} {}: {:.1}% clipped, {:?}, α {:.3}, light {dl:.3}° ± {std:.3}°",
                im.file,
                100.0 * clipped,
                h.method,
                h.alpha.unwrap_or(f64::NAN)
            );
            assert!((0.05..0.30).contains(&clipped), "{clipped}");
            assert_eq!(h.method, workbench::formats::detections::Method::LobeFit);
            // The roughness from the ring alone: measured within 15% up to 10% clipped, within
            // 45% at 22% and 31% at 29%.
            let tol = if clipped < 0.1 { 0.25 } else { 0.6 };
            assert!(
                (h.alpha.unwrap() / alpha - 1.0).abs() < tol,
                "{:?}",
                h.alpha
            );
            assert!(dl < 3.0 * std, "{}: {dl}° ± {std}°", im.file);
            z.push(dl / std);
        }
        let dl = angle_deg(d.light_direction.as_ref().unwrap(), &t.light_direction);
        let std = d.light_std_deg.unwrap();
        println!("α {alpha} ks {ks}: session light {dl:.3}° ± {std:.3}°");
        assert!(dl < 3.0 * std, "{dl}° ± {std}°");
        // The solve: the light within 0.1° of the truth (the goal).
        let mut o = workbench::solve::Options::new(dir.path());
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
        o.quiet = true;
        let f = workbench::solve::run(&o).unwrap();
        let dl = Vector3::from(f.light_direction)
            .angle(&Vector3::from(t.light_direction))
            .to_degrees();
        println!("α {alpha} ks {ks}: solved light {dl:.4}°, {}", f.light_fit);
        assert!(dl < 0.1, "{dl}");
    }
    // Each photo's stated light std, neither too small (each error within 3 of it, above) nor
    // many times too large: the errors' RMS in units of their std over the twelve photos.
    // Measured 0.54 (the std about twice the typical error, never smaller than it).
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    println!(
        "per-photo light error / stated std: RMS {rms:.2} over {}",
        z.len()
    );
    assert!(z.len() == 12 && rms > 0.18 && rms < 1.6, "{rms}: {z:?}");
}

/// Spheres before a grey card (8–22% of full scale, a gradient), resting on a lit table with
/// their shadows, and held up on a pin before the card: outlines and light as on black; the dark
/// floor, which a lit backdrop leaves unmeasured, fitted with the material (and said), σ0 as on
/// black with it fitted and with it given.
#[test]
fn grey_backdrop_and_table() {
    use workbench::synth::session::{Backdrop, Stand};
    let make = |backdrop, stand: bool| {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SessionConfig {
            radii_mm: vec![35.0, 25.0, 15.0],
            camera: common::camera_640x480(),
            backdrop,
            stand: stand.then(Stand::default),
            noise: 0.003,
            ..SessionConfig::default()
        };
        session::generate(&cfg, dir.path(), None, true).unwrap();
        dir
    };
    let solve = |dir: &Path| {
        let mut o = workbench::solve::Options::new(dir);
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
        o.quiet = true;
        workbench::solve::run(&o).unwrap()
    };
    let black = make(Backdrop::Black, false);
    run(black.path()).unwrap();
    let f_black = solve(black.path());
    for (backdrop, stand) in [
        (Backdrop::Grey, false),
        (Backdrop::Table, false),
        (Backdrop::Grey, true),
    ] {
        let dir = make(backdrop, stand);
        let backdrop = format!("{backdrop:?}{}", if stand { " + pin" } else { "" });
        let d = run(dir.path()).unwrap();
        let t = truth(dir.path());
        for (im, ti) in d.images.iter().zip(&t.images) {
            let (s, ts) = (&im.spheres[0], &ti.spheres[0]);
            let dc = centre_off(s.ellipse.center_px, ts.ellipse.center_px);
            let da = (s.ellipse.axes_px[0] - ts.ellipse.axes_px[0]).abs();
            println!("{backdrop} {}: centre {dc:.3} px, axis {da:.3} px", im.file);
            // Measured ≤ 0.043 px.
            assert!(dc < 0.1 && da < 0.1, "{backdrop} {}: {dc} {da}", im.file);
        }
        let dl = angle_deg(d.light_direction.as_ref().unwrap(), &t.light_direction);
        let std = d.light_std_deg.unwrap();
        println!("{backdrop}: detector's light {dl:.4}° ± {std:.4}°");
        // Measured 0.032° ± 0.034° (grey), 0.054° ± 0.034° (table). The solve's light below
        // meets the 0.05° goal on both.
        assert!(dl < 3.0 * std, "{backdrop}: {dl}° ± {std}°");
        // Without the floor: fitted with the material, and said.
        let f = solve(dir.path());
        assert!(
            f.notes.iter().any(|n| n.contains("no dark floor measured")),
            "{:?}",
            f.notes
        );
        let fl = f.dark_floor.expect("the floor is fitted");
        // σ0 against the truth, with black's beside it (the sessions share the material).
        let sigma0_off = |f: &workbench::formats::fit::FitFile| {
            (0..3)
                .map(|c| (f.sigma0_mm[c] / t.sigma0_mm[c] - 1.0).abs())
                .fold(0.0, f64::max)
        };
        println!(
            "black: σ0 {:.2}% from the truth",
            100.0 * sigma0_off(&f_black)
        );
        let dl = Vector3::from(f.light_direction)
            .angle(&Vector3::from(t.light_direction))
            .to_degrees();
        println!(
            "{backdrop}, floor fitted: {:?} ± {:?} (truth {}), light {dl:.4}°, σ0 {:?}: {:.2}% from the truth",
            fl.value,
            fl.std,
            t.render.ambient,
            f.sigma0_mm,
            100.0 * sigma0_off(&f)
        );
        for c in 0..3 {
            // Measured ≤ 6.8e-6 (2.3 of its std) for the truth's 2e-3.
            let e = fl.value[c] - t.render.ambient;
            println!(
                "{backdrop} channel {c}: floor off by {e:.2e}, {:.1} std",
                e / fl.std[c]
            );
            assert!(e.abs() < 2e-5, "{backdrop} channel {c}: floor off by {e}");
        }
        // Measured: light 0.003–0.006°, σ0 0.32/0.41/0.28% from black's; since the lights are
        // combined (2026-12-04) light 0.006° (grey), 0.030° (table: its detector's is 0.054° off
        // and the combination leans on it), σ0 0.10–0.29% from the truth (black's 0.52%). The
        // goals: 0.5% for σ0, 0.05° for the light (its std here is the formal one alone: the
        // jackknife is off).
        assert!(dl < 0.05, "{backdrop}: {dl}°");
        assert!(sigma0_off(&f) < 0.005, "{backdrop}: {}", sigma0_off(&f));
        // With it given (truth's ambient), σ0 as on black.
        let p = dir.path().join("session.json");
        let mut s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        s["floor"] = serde_json::json!(t.render.ambient);
        std::fs::write(&p, s.to_string()).unwrap();
        let f = solve(dir.path());
        let dl = Vector3::from(f.light_direction)
            .angle(&Vector3::from(t.light_direction))
            .to_degrees();
        println!(
            "{backdrop}: solved light {dl:.4}° ± {:.4}°",
            f.std.light_deg
        );
        assert!(dl < 0.05, "{backdrop}: {dl}°");
        assert!(f.dark_floor.is_none());
        let worst = sigma0_off(&f);
        println!(
            "{backdrop}: σ0 {:?} (black {:?}): {:.2}% from the truth",
            f.sigma0_mm,
            f_black.sigma0_mm,
            100.0 * worst
        );
        // Measured 0.21% (grey), 0.37% (table), 0.21% (pin) from black's; from the truth since the
        // lights are combined (black's own is printed); the goal 0.5%.
        assert!(worst < 0.005, "{backdrop}: {worst}");
    }
}

/// The outline's stated error covers its centre's (issue 34): the edge model's noise-only error
/// σ²(JᵀWJ)⁻¹ was 0.005–0.01 px, the centres 0.01–0.06 px off; the stated one is the larger of
/// that and the jackknife over eight arcs of the rim, which sees whatever moves one part of the
/// rim against the rest. Three seeds of the default session (15 spheres, 1280×960).
#[test]
fn outline_centres_are_within_their_stated_errors() {
    let mut z = vec![];
    for seed in 1..=3 {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SessionConfig {
            seed,
            ..SessionConfig::default()
        };
        session::generate(&cfg, dir.path(), None, true).unwrap();
        let d = run(dir.path()).unwrap();
        let t = truth(dir.path());
        for (im, ti) in d.images.iter().zip(&t.images) {
            let (s, ts) = (&im.spheres[0], &ti.spheres[0]);
            let dc = centre_off(s.ellipse.center_px, ts.ellipse.center_px);
            let std = s.silhouette_std_px[0].hypot(s.silhouette_std_px[1]);
            println!(
                "seed {seed} {}: centre {dc:.3} px, stated ± {std:.3} px",
                im.file
            );
            z.push(dc / std);
        }
    }
    let within2 = z.iter().filter(|&&v| v < 2.0).count();
    println!(
        "{within2} of {} within 2 of their stated error, largest {:.2}",
        z.len(),
        z.iter().cloned().fold(0.0, f64::max)
    );
    // Measured: 13 of 15 within 2, the largest 2.96 (the formal error alone: 5–10).
    assert!(z.iter().all(|&v| v < 3.5), "{z:?}");
    assert!(within2 >= 11, "{z:?}");
}

/// The mean errors (px) of a session's detected outlines against truth.json: [radius, centre x].
fn outline_mean_errors(dir: &Path, medium: bool) -> [f64; 2] {
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap()
    };
    let (det, t) = (read("detections.json"), read("truth.json"));
    let fx = read("intrinsics.json")["fx"].as_f64().unwrap();
    let v = |x: &serde_json::Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_f64().unwrap())
            .collect()
    };
    let mut sum = [0.0; 2];
    let images = det["images"].as_array().unwrap();
    for im in images {
        let tr = t["images"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["file"] == im["file"])
            .unwrap();
        let (c, s) = (v(&tr["centre_mm"]), &im["spheres"][0]);
        let outline = if medium {
            &s["medium_outline"]["outline"]
        } else {
            &s["outline"]
        };
        let (axis, half) = (
            v(&outline["axis"]),
            outline["half_angle_deg"].as_f64().unwrap().to_radians(),
        );
        let distance = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let truth_half = (s["radius_mm"].as_f64().unwrap() / distance).asin();
        sum[0] += (half.tan() - truth_half.tan()) * fx;
        sum[1] += (axis[0] / axis[2] - c[0] / c[2]) * fx;
    }
    sum.map(|e| e / images.len() as f64)
}

/// The outlines drawn for the medium (`detect --model medium`, what `solve --model medium`
/// uses) on the medium's edge model: the rim weighed by its contrast as well, the limb's
/// T(φ)·cos φ term left out. On a path-traced jade-like session lit from the left
/// (`datasets/pbr-seeds/jade-6`) the dim stretches of the translucent rim draw the shared
/// outlines 0.13 px small and 0.16 px off-centre on average; the medium's 0.020 and 0.015 px
/// (with the contrast weights alone 0.05 and 0.04 px; docs/measurements/detection.md, "Each
/// sector weighted by its rim's contrast" and "The medium's outlines without the limb's
/// T(φ)·cos φ term"). Asserted against truth.json: the medium's outlines' mean radius and centre
/// errors within 0.06 px, the shared ones' beyond 0.1 px; those (what the highlights, the light
/// and the CDRF use) the same whichever model asked, to the bit; only the medium's detections
/// hold the medium's outlines (`auto` draws them only with a reference in session.json); and a
/// solve that fits the medium (`auto`, the irradiance given) detects again over the CDRF's
/// detections, then reuses its own.
#[test]
fn the_medium_draws_its_outlines_on_its_own_edge_model() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-seeds/jade-6");
    let dir = common::session_copy(&src);
    let d = dir.path().to_str().unwrap();
    let detect = |model: &str| {
        let (code, _, err) =
            common::wb(&["--quiet", "detect", d, "--no-overlays", "--model", model]);
        assert_eq!(code, 0, "{err}");
        let det: Detections = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join("detections.json")).unwrap(),
        )
        .unwrap();
        let errors = det
            .has_medium_outlines()
            .then(|| outline_mean_errors(dir.path(), true));
        (det, outline_mean_errors(dir.path(), false), errors)
    };
    let (with_medium, noise, contrast) = detect("medium");
    let (cdrf, noise_cdrf, none) = detect("cdrf");
    // `auto` (the default) draws them only where session.json names a reference; this has none.
    let (_, _, auto) = detect("auto");
    assert!(auto.is_none(), "auto without a reference: {auto:?}");
    println!("mean radius, centre x error (px): noise {noise:.3?}, the medium's {contrast:.3?}");
    let contrast = contrast.expect("the medium's outlines");
    assert!(
        none.is_none(),
        "the CDRF's detections draw no medium outlines"
    );
    assert_eq!(noise, noise_cdrf);
    for (a, b) in with_medium.images.iter().zip(&cdrf.images) {
        for (x, y) in a.spheres.iter().zip(&b.spheres) {
            assert_eq!(x.outline, y.outline);
            assert_eq!(x.light_direction, y.light_direction);
        }
    }
    assert!(contrast.iter().all(|e| e.abs() < 0.06), "{contrast:?}");
    assert!(noise.iter().all(|e| e.abs() > 0.1), "{noise:?}");
    let solve = |extra: &[&str]| {
        // `--model auto` (the default): the irradiance given, the medium is fitted.
        let mut args = vec!["solve", d, "--irradiance", "5.392961114328331"];
        args.extend(extra);
        let (code, out, err) = common::wb(&args);
        assert_eq!(code, 0, "{err}");
        format!("{out}{err}")
    };
    let first = solve(&[]);
    assert!(
        first.contains(
            "detection: ran (detections.json has no outlines drawn for the medium, which the medium fit needs)"
        ),
        "{first}"
    );
    // Another fit of the same session (a radius held out) reuses the medium's detections.
    let second = solve(&["--holdout", "15"]);
    assert!(
        second.contains("detection: detections.json reused"),
        "{second}"
    );
}

/// A detections.json from the builds of 2026-12-07 that drew every outline for the medium under
/// `--model medium` (`"edge_weights": "contrast"`): its `outline`s are not the ones the CDRF
/// and the light use, so a solve for either model detects again rather than reuse it, and says
/// why; the file it writes has both outlines and no such field.
#[test]
fn an_earlier_builds_medium_outlines_are_not_reused() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-seeds/soap-2");
    let dir = common::session_copy(&src);
    let d = dir.path().to_str().unwrap();
    let det = dir.path().join("detections.json");
    for model in ["cdrf", "medium"] {
        let (code, _, err) =
            common::wb(&["--quiet", "detect", d, "--no-overlays", "--model", model]);
        assert_eq!(code, 0, "{err}");
        let mut j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&det).unwrap()).unwrap();
        j["edge_weights"] = "contrast".into();
        std::fs::write(&det, serde_json::to_string(&j).unwrap()).unwrap();
        let (code, out, err) = common::wb(&["solve", d, "--model", model]);
        assert_eq!(code, 0, "{err}");
        assert!(
            format!("{out}{err}").contains(
                "detection: ran (detections.json's outlines were drawn for the medium alone"
            ),
            "{model}: {out}{err}"
        );
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&det).unwrap()).unwrap();
        assert!(j.get("edge_weights").is_none());
        let medium = j["images"][0]["spheres"][0].get("medium_outline").is_some();
        assert_eq!(medium, model == "medium");
    }
}
