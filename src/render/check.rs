//! The renderer checked against the fit itself: each sphere of a fitted session, as an ideal
//! sphere mesh (an icosphere) where the detector placed it, rendered through the look-up table,
//! against the solver's predicted image of that sphere (the radiance model on the exact sphere
//! geometry, [`crate::model::Model::radiance`]).
//!
//! Both images are taken through the session camera's pinhole part (lens distortion moves pixels,
//! not radiance) with one sample at each pixel centre, so they see the same rays. The difference
//! is the mesh's facets and interpolated normals, the curvature estimate, the table's
//! interpolation and the renderer's f32 arithmetic.

use crate::camera::sphere::Sphere;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::model::{Geometry, Params};
use crate::render::lut::{FitMaterial, Lut};
use crate::render::mesh::shapes;
use crate::render::raster::{render, Image, Samples, Scene, Shader, Shading};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Icosphere subdivision level of the check (81 920 triangles).
pub(crate) const LEVEL: u32 = 6;

/// One sphere's comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereComparison {
    pub image: String,
    pub index: usize,
    pub radius_mm: f64,
    /// Pixels both images see the sphere in.
    pub pixels: usize,
    /// Pixels only one of them does (the facetted silhouette).
    pub silhouette_px: usize,
    /// RMS difference over RMS of the prediction, all channels.
    pub rel_rmse: f64,
    /// Largest difference over the prediction's peak.
    pub max_rel: f64,
}

/// The solver's predicted image of a sphere: the model at every pixel centre whose ray hits it.
pub fn predict(fm: &FitMaterial, params: &Params, cam: &Camera, sphere: &Sphere) -> Image {
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let mut rgb = vec![[0.0f32; 3]; w * h];
    let mut coverage = vec![0.0f32; w * h];
    for j in 0..h {
        for i in 0..w {
            let d = cam.ideal_ray(i as f64, j as f64);
            if let Some(sp) = sphere.surface_at(&d) {
                let g = Geometry {
                    normal: sp.normal,
                    view: sp.view,
                    radius_mm: sphere.radius,
                };
                let l = fm.model.radiance(params, &g);
                rgb[j * w + i] = [l[0] as f32, l[1] as f32, l[2] as f32];
                coverage[j * w + i] = 1.0;
            }
        }
    }
    Image {
        width: cam.width(),
        height: cam.height(),
        rgb,
        coverage,
    }
}

/// Render the ideal sphere mesh and compare it with [`predict`]. Returns the comparison (image
/// name and index left empty) and both images (rendered, predicted).
pub fn compare(
    fm: &FitMaterial,
    lut: &Lut,
    cam: &Camera,
    center: Vector3<f64>,
    radius_mm: f64,
) -> (SphereComparison, Image, Image) {
    let params = Params {
        material: fm.material,
        light: fm.light,
    };
    let mesh = shapes::icosphere(center, radius_mm, LEVEL);
    let kappa = mesh.curvature();
    let scene = Scene::new(&mesh, &kappa);
    let shader = Shader {
        lut,
        eta: fm.material.eta,
        ks: fm.material.specular.ks,
        alpha: fm.material.specular.alpha,
        light: fm.light.direction(),
        shading: Shading::Cdrf,
    };
    let rendered = render(&scene, cam, &shader, Samples::One);
    let predicted = predict(fm, &params, cam, &Sphere::new(center, radius_mm));
    let (mut n, mut only_one, mut sq, mut ref_sq, mut max_d, mut peak) =
        (0, 0, 0.0, 0.0, 0.0f64, 0.0f64);
    for k in 0..rendered.rgb.len() {
        let (a, b) = (rendered.coverage[k] > 0.0, predicted.coverage[k] > 0.0);
        if a != b {
            only_one += 1;
        }
        if !(a && b) {
            continue;
        }
        n += 1;
        for c in 0..3 {
            let (r, p) = (rendered.rgb[k][c] as f64, predicted.rgb[k][c] as f64);
            sq += (r - p) * (r - p);
            ref_sq += p * p;
            max_d = max_d.max((r - p).abs());
            peak = peak.max(p);
        }
    }
    let cmp = SphereComparison {
        image: String::new(),
        index: 0,
        radius_mm,
        pixels: n,
        silhouette_px: only_one,
        rel_rmse: if ref_sq > 0.0 {
            (sq / ref_sq).sqrt()
        } else {
            0.0
        },
        max_rel: if peak > 0.0 { max_d / peak } else { 0.0 },
    };
    (cmp, rendered, predicted)
}

/// Every sphere of the fit's session (`fit`, read from `fit_path`), as the detector placed it
/// (needs a perspective session: intrinsics and detections.json with sphere centres).
pub(crate) fn check_fit(
    fit: &crate::formats::fit::FitFile,
    fit_path: &Path,
    fm: &FitMaterial,
    lut: &Lut,
) -> Result<Vec<(SphereComparison, Image, Image)>> {
    let session = fit.session_path(fit_path)?;
    let report = crate::formats::session::inspect(&session)?;
    let cam = report.camera.ok_or_else(|| {
        Error::invalid(
            &session,
            "no intrinsics: the check needs a perspective session",
        )
    })?;
    let det_path = session.with_file_name("detections.json");
    let det: crate::formats::detections::Detections = crate::formats::output::read_json(&det_path)?;
    let pin = cam.ideal();
    let mut out = Vec::new();
    for im in &det.images {
        for (index, s) in im.spheres.iter().enumerate() {
            let Some(c) = s.center_mm else {
                return Err(Error::invalid(
                    &det_path,
                    format!("{} sphere {index} has no centre", im.file),
                ));
            };
            let (mut cmp, a, b) = compare(fm, lut, &pin, Vector3::from(c), s.radius_mm);
            cmp.image = im.file.clone();
            cmp.index = index;
            out.push((cmp, a, b));
        }
    }
    Ok(out)
}
