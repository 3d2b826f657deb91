//! `workbench synth session`: render a photo session of translucent spheres with known truth.
//!
//! Interior pixels are the model evaluated at the pixel centre's ray (the detector and solver
//! sample there too); pixels within a few pixels of a silhouette are supersampled n×n so edges are
//! anti-aliased. A constant ambient floor is added everywhere (stray light of a dark room), then
//! shot and read noise, then clipping at full scale.

use crate::camera::sphere::{EllipseJson, Sphere};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::formats::intrinsics::IntrinsicsFile;
use crate::formats::output::write_json;
use crate::formats::photo::{self, ExifInfo};
use crate::formats::session::{self, Session, SessionImage, SessionSphere};
use crate::model::cdrf::Convolution;
use crate::model::{Geometry, LightAngles, Material, Model, Params, SpecularParams};
use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(crate) const TRUTH_SCHEMA: &str = "workbench.truth/1";

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// One photo per sphere, every sphere at the same place (the camera and light stay put while
    /// spheres are swapped).
    Separate,
    /// All spheres in one photo, left to right in the order given.
    Row,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// 16-bit linear RGB PNG (exposure written into session.json: PNG carries no EXIF here).
    Png16,
    /// 8-bit sRGB JPEG with EXIF exposure settings.
    Jpeg,
}

/// What lies behind and under the spheres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backdrop {
    /// A black void (only the ambient floor).
    #[default]
    Black,
    /// A grey card behind the spheres: 8% of full scale at the top-left corner rising to 22% at
    /// the bottom-right (a gentle gradient; the session's noise on top).
    Grey,
    /// The spheres rest on a lit matte table (albedo 0.3, in the photos' radiance units) with
    /// their cast shadows, in front of a grey wall at 10% of full scale.
    Table,
}

/// The table's diffuse albedo (π·radiance / irradiance) and the wall's level behind it.
pub(crate) const TABLE_ALBEDO: f64 = 0.3;
pub(crate) const WALL_LEVEL: f64 = 0.10;
/// The stand's default pin radius (mm).
pub const PIN_RADIUS_MM: f64 = 1.5;

/// The pins that hold the spheres up (`--stand`): each a vertical cylinder under its sphere, from
/// inside the sphere's bottom down three sphere radii; it casts no shadow.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stand {
    /// The pin's radius (mm).
    pub radius_mm: f64,
    /// A constant pixel value (fraction of full scale), as a pin lit from
    /// its own lamp or painted bright would show; without it the pin is matte (albedo 0.5) under
    /// the session's light.
    pub level: Option<f64>,
    /// A pin under every n-th sphere of the radii list (1: every sphere, 2: every other one,
    /// starting with the first).
    pub every: usize,
    /// How far (mm) the pin reaches up in front of the sphere's lower rim, hiding it: 0 for a pin
    /// under the sphere's middle, behind its rim; above 0 the pin stands a sphere radius nearer
    /// the camera (a prong holding the sphere from the front) and its top is this far above the
    /// sphere's lowest point.
    #[serde(default)]
    pub contact_mm: f64,
}

impl Default for Stand {
    fn default() -> Self {
        Stand {
            radius_mm: PIN_RADIUS_MM,
            level: None,
            every: 1,
            contact_mm: 0.0,
        }
    }
}

/// The nearest hit of a camera ray `d` on a sphere's pin (a vertical cylinder under it, see
/// [`Stand`]): the distance and the pin's outward normal there.
fn pin_hit(r: f64, s: &Sphere, stand: &Stand, d: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
    let pin = stand.radius_mm;
    let front = stand.contact_mm > 0.0;
    let mut c = s.center;
    if front {
        // The axis a sphere radius nearer the camera, along the horizontal line of sight.
        let toward = Vector3::new(c.x, 0.0, c.z).normalize();
        c -= toward * r;
    }
    let top = if front {
        s.center.y + r - stand.contact_mm
    } else {
        s.center.y + 0.9 * r
    };
    let a = d.x * d.x + d.z * d.z;
    let b = -2.0 * (d.x * c.x + d.z * c.z);
    let cc = c.x * c.x + c.z * c.z - pin * pin;
    let disc = b * b - 4.0 * a * cc;
    if a <= 0.0 || disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / (2.0 * a);
    let p = d * t;
    // From its top (inside the sphere's bottom, or in front of its rim) down three radii.
    (t > 0.0 && p.y > top && p.y < s.center.y + r + 3.0 * r)
        .then(|| (t, Vector3::new(p.x - c.x, 0.0, p.z - c.z).normalize()))
}

/// Everything that defines a synthetic session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionConfig {
    pub radii_mm: Vec<f64>,
    pub layout: Layout,
    pub camera: Camera,
    pub light: LightAngles,
    pub material: Material,
    pub material_name: String,
    pub convolution: Convolution,
    /// Render with the entry-side Fresnel transmission (off by default, like the model: the bare
    /// clamped cosine, which the paper's procedure assumes).
    pub entry_transmission: bool,
    /// Relative exposure (see [`crate::formats::exif`]).
    pub exposure: f64,
    /// Shot-noise standard deviation at full scale (relative; variance ∝ signal).
    pub noise: f64,
    /// Read-noise standard deviation (relative to full scale).
    pub read_noise: f64,
    /// Constant stray-light floor added to every pixel (relative to full scale).
    pub ambient: f64,
    /// What lies behind and under the spheres.
    #[serde(default)]
    pub backdrop: Backdrop,
    /// Spheres held up by thin pins under them ([`Stand`]).
    #[serde(default)]
    pub stand: Option<Stand>,
    /// Edge supersampling: n×n samples per silhouette pixel.
    pub supersample: u32,
    pub format: Format,
    pub jpeg_quality: u8,
    pub seed: u64,
    /// Camera-to-sphere distance (mm); chosen to frame the spheres when absent.
    pub distance_mm: Option<f64>,
    /// What session.json's "intrinsics" says; absent: the true camera is written as
    /// `intrinsics.json` beside it.
    pub intrinsics_ref: Option<String>,
    /// Sensor width (mm), for the EXIF focal length.
    pub sensor_width_mm: f64,
}

/// The default camera of synthetic data: [`Camera::example`].
pub fn default_camera() -> Camera {
    Camera::example()
}

impl Default for SessionConfig {
    fn default() -> Self {
        SessionConfig {
            radii_mm: vec![35.0, 30.0, 25.0, 20.0, 15.0],
            layout: Layout::Separate,
            camera: default_camera(),
            light: LightAngles {
                azimuth: 70f64.to_radians(),
                elevation: 20f64.to_radians(),
            },
            material: Material {
                sigma0_mm: [4.0, 3.0, 2.2],
                albedo: [0.80, 0.62, 0.45],
                eta: 1.44,
                specular: SpecularParams {
                    ks: 1.0,
                    alpha: 0.1,
                },
                sigma_exponent: 0.0,
                albedo_curvature: 0.0,
                kernel_weight: 0.0,
                kernel_ratio: 0.0,
            },
            material_name: "synthetic wax".into(),
            convolution: Convolution::Wrapped,
            entry_transmission: false,
            exposure: 1.2,
            noise: 0.01,
            read_noise: 5e-4,
            ambient: 2e-3,
            backdrop: Backdrop::Black,
            stand: None,
            supersample: 4,
            format: Format::Png16,
            jpeg_quality: 95,
            seed: 1,
            distance_mm: None,
            intrinsics_ref: None,
            sensor_width_mm: 23.5,
        }
    }
}

/// truth.json of a session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionTruth {
    pub schema: String,
    pub kind: String,
    pub sigma0_mm: [f64; 3],
    pub albedo: [f64; 3],
    pub eta: f64,
    pub specular: SpecularParams,
    /// Model extensions (see [`crate::model`]); absent: 0.
    #[serde(default)]
    pub sigma_exponent: f64,
    #[serde(default)]
    pub albedo_curvature: f64,
    /// The kernel's tail weight and width ratio (0: one Gaussian; see `model`).
    #[serde(default)]
    pub kernel_weight: f64,
    #[serde(default)]
    pub kernel_ratio: f64,
    /// Unit vector toward the light, camera frame (x right, y down, z forward).
    pub light_direction: [f64; 3],
    pub light_azimuth_deg: f64,
    pub light_elevation_deg: f64,
    pub cdrf_convolution: Convolution,
    /// Whether the diffuse term blurs the entry-transmitted irradiance (false in older files).
    #[serde(default)]
    pub entry_transmission: bool,
    pub intrinsics: IntrinsicsFile,
    pub images: Vec<TruthImage>,
    pub render: RenderTruth,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthImage {
    pub file: String,
    pub exposure: f64,
    pub spheres: Vec<TruthSphere>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthSphere {
    pub radius_mm: f64,
    pub center_mm: [f64; 3],
    /// Silhouette ellipse in ideal (undistorted) pinhole pixel coordinates.
    pub ellipse: EllipseJson,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderTruth {
    pub noise: f64,
    pub read_noise: f64,
    pub ambient: f64,
    pub supersample: u32,
    pub format: Format,
    pub seed: u64,
    pub layout: Layout,
    #[serde(default)]
    pub backdrop: Backdrop,
    #[serde(default)]
    pub stand: bool,
    /// The pins' size, level and spacing, where there are pins.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stand_pins: Option<Stand>,
}

/// One image of the session: its file name and spheres (left to right).
#[derive(Clone, Debug)]
pub struct ScenePlan {
    pub file: String,
    pub spheres: Vec<(f64, Sphere)>,
}

fn check(cfg: &SessionConfig) -> Result<()> {
    let arg = |m: String| Err(Error::Argument(m));
    if cfg.radii_mm.is_empty() {
        return arg("at least one radius is needed".into());
    }
    if let Some(r) = cfg.radii_mm.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
        return arg(format!("radius {r} mm is not positive"));
    }
    let m = &cfg.material;
    let all_pos = m
        .sigma0_mm
        .iter()
        .chain(&m.albedo)
        .all(|v| v.is_finite() && *v >= 0.0);
    if !all_pos || !(m.eta >= 1.0) || !(m.specular.ks >= 0.0) || !(m.specular.alpha > 0.0) {
        return arg("material: σ0 and albedo must be ≥ 0, η ≥ 1, ks ≥ 0 and α > 0".into());
    }
    let nums = [cfg.exposure, cfg.noise, cfg.read_noise, cfg.ambient];
    if !nums.iter().all(|v| v.is_finite() && *v >= 0.0) || cfg.exposure <= 0.0 {
        return arg("exposure must be positive and noise, read noise and ambient ≥ 0".into());
    }
    if cfg.supersample == 0 || cfg.supersample > 16 {
        return arg("supersample must be between 1 and 16".into());
    }
    let c = &cfg.camera;
    if !(c.fx > 0.0 && c.fy > 0.0) || c.image_size.contains(&0) {
        return arg("camera: focal lengths and image size must be positive".into());
    }
    if let Some(why) = photo::size_problem(c.image_size[0], c.image_size[1]) {
        return arg(why);
    }
    Ok(())
}

/// Whether every sphere's silhouette lies inside the frame with a margin (pixels).
fn fits_in_frame(cam: &Camera, spheres: &[(f64, Sphere)], margin: f64) -> bool {
    let (w, h) = (cam.width() as f64, cam.height() as f64);
    spheres.iter().all(|(_, s)| {
        let Some(half) = s.cone_half_angle() else {
            return false;
        };
        let axis = s.center.normalize();
        let e1 = axis.cross(&Vector3::y()).normalize();
        let e2 = axis.cross(&e1);
        (0..72).all(|k| {
            let t = k as f64 * std::f64::consts::TAU / 72.0;
            let d = axis * half.cos() + (e1 * t.cos() + e2 * t.sin()) * half.sin();
            match cam.pixel_for_ray(&d) {
                Some(p) => p.x > margin && p.y > margin && p.x < w - margin && p.y < h - margin,
                None => false,
            }
        })
    })
}

/// Where the spheres go: a fixed camera-to-sphere distance, chosen (unless given) so that the
/// largest sphere fills about a third of the frame height (separate photos) or the row fills
/// about 85% of the width; then pushed back until every silhouette clears the frame edge.
pub fn plan(cfg: &SessionConfig) -> Result<Vec<ScenePlan>> {
    check(cfg)?;
    let cam = &cfg.camera;
    let r_max = cfg.radii_mm.iter().cloned().fold(0.0, f64::max);
    let r_min = cfg.radii_mm.iter().cloned().fold(f64::INFINITY, f64::min);
    let gap = 0.5 * r_min;
    let row_width: f64 =
        cfg.radii_mm.iter().map(|r| 2.0 * r).sum::<f64>() + gap * (cfg.radii_mm.len() as f64 - 1.0);
    let mut z = cfg.distance_mm.unwrap_or(match cfg.layout {
        Layout::Separate => r_max * cam.fy / (0.17 * cam.height() as f64),
        Layout::Row => row_width * cam.fx / (0.85 * cam.width() as f64),
    });
    let name = |r: f64, i: usize| {
        let dup = cfg.radii_mm.iter().filter(|&&q| q == r).count() > 1;
        let base = if r.fract() == 0.0 {
            format!("r{r:.0}")
        } else {
            format!("r{r}")
        };
        if dup {
            format!("{base}-{}", i + 1)
        } else {
            base
        }
    };
    let ext = match cfg.format {
        Format::Png16 => "png",
        Format::Jpeg => "jpg",
    };
    for _ in 0..60 {
        let plans: Vec<ScenePlan> = match cfg.layout {
            Layout::Separate => cfg
                .radii_mm
                .iter()
                .enumerate()
                .map(|(i, &r)| ScenePlan {
                    file: format!("{}.{ext}", name(r, i)),
                    spheres: vec![(r, Sphere::new(Vector3::new(0.04 * z, -0.03 * z, z), r))],
                })
                .collect(),
            Layout::Row => {
                let mut x = -0.5 * row_width;
                let spheres = cfg
                    .radii_mm
                    .iter()
                    .map(|&r| {
                        let s = Sphere::new(Vector3::new(x + r, 0.0, z), r);
                        x += 2.0 * r + gap;
                        (r, s)
                    })
                    .collect();
                vec![ScenePlan {
                    file: format!("row.{ext}"),
                    spheres,
                }]
            }
        };
        let mut plans = plans;
        if cfg.backdrop == Backdrop::Table {
            // Every sphere rests on the table, which stays put between photos: its plane lies
            // under the largest sphere's place.
            for p in plans.iter_mut() {
                let table_y = p.spheres[0].1.center.y + r_max;
                for (r, s) in p.spheres.iter_mut() {
                    *s = Sphere::new(Vector3::new(s.center.x, table_y - *r, s.center.z), *r);
                }
            }
        }
        let all_fit = plans.iter().all(|p| fits_in_frame(cam, &p.spheres, 6.0));
        if all_fit {
            return Ok(plans);
        }
        if cfg.distance_mm.is_some() {
            return Err(Error::Argument(format!(
                "at a distance of {z} mm the spheres do not fit in the {}×{} frame",
                cam.width(),
                cam.height()
            )));
        }
        z *= 1.05;
    }
    Err(Error::Argument(
        "cannot frame the spheres: check the camera".into(),
    ))
}

/// Pixel bounding box [x0, y0, x1, y1] of a sphere's silhouette (through the lens distortion),
/// padded by `pad` pixels; `None` when the sphere is not wholly in front of the camera.
pub(crate) fn silhouette_box(cam: &Camera, s: &Sphere, pad: f64) -> Option<[f64; 4]> {
    let half = s.cone_half_angle()?;
    let axis = s.center.normalize();
    let e1 = axis
        .cross(&Vector3::y())
        .try_normalize(1e-12)
        .unwrap_or_else(|| axis.cross(&Vector3::x()).normalize());
    let e2 = axis.cross(&e1);
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for k in 0..360 {
        let t = k as f64 * std::f64::consts::TAU / 360.0;
        let d = axis * half.cos() + (e1 * t.cos() + e2 * t.sin()) * half.sin();
        let p = cam.pixel_for_ray(&d)?;
        b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
    }
    // 360 outline samples: the chord sagitta is below 1e-4 of the radius; the pad covers it.
    Some([b[0] - pad, b[1] - pad, b[2] + pad, b[3] + pad])
}

/// Linear radiance-times-exposure (plus ambient) along one ray: the nearest sphere hit, or the
/// ambient floor.
fn shade(
    cfg: &SessionConfig,
    model: &Model,
    params: &Params,
    spheres: &[(f64, Sphere)],
    d: &Vector3<f64>,
) -> [f64; 3] {
    let mut best: Option<(f64, usize)> = None;
    for (i, (_, s)) in spheres.iter().enumerate() {
        if let Some(t) = s.intersect(d) {
            if best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, i));
            }
        }
    }
    if let Some(stand) = cfg.stand {
        let held = |r: f64| {
            let k = cfg.radii_mm.iter().position(|&x| x == r).unwrap_or(0);
            k % stand.every.max(1) == 0
        };
        let pin = spheres
            .iter()
            .filter(|(r, _)| held(*r))
            .filter_map(|(r, s)| pin_hit(*r, s, &stand, d))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((t, n)) = pin {
            if best.is_none_or(|(bt, _)| t < bt) {
                let value = stand
                    .level
                    .unwrap_or_else(|| cfg.exposure * 0.5 * n.dot(&cfg.light.direction()).max(0.0));
                return [value + cfg.ambient; 3];
            }
        }
    }
    let Some((_, i)) = best else {
        return backdrop(cfg, spheres, d);
    };
    let (r, s) = &spheres[i];
    let Some(sp) = s.surface_at(d) else {
        return [cfg.ambient; 3];
    };
    let g = Geometry {
        normal: sp.normal,
        view: sp.view,
        radius_mm: *r,
    };
    let l = model.radiance(params, &g);
    [0, 1, 2].map(|c| cfg.exposure * l[c] + cfg.ambient)
}

/// Where a ray `d` from the camera hits nothing but the backdrop: its pixel value (plus ambient).
fn backdrop(cfg: &SessionConfig, spheres: &[(f64, Sphere)], d: &Vector3<f64>) -> [f64; 3] {
    let cam = &cfg.camera;
    match cfg.backdrop {
        Backdrop::Black => [cfg.ambient; 3],
        Backdrop::Grey => {
            // The gradient over the (pinhole) image position of the ray.
            let u = ((cam.fx * d.x / d.z + cam.cx) / cam.width() as f64).clamp(0.0, 1.0);
            let v = ((cam.fy * d.y / d.z + cam.cy) / cam.height() as f64).clamp(0.0, 1.0);
            [0.08 + 0.14 * (0.5 * u + 0.5 * v) + cfg.ambient; 3]
        }
        Backdrop::Table => {
            let r_max = spheres.iter().map(|(r, _)| *r).fold(0.0, f64::max);
            let table_y = spheres
                .iter()
                .map(|(r, s)| s.center.y + r)
                .fold(f64::NEG_INFINITY, f64::max);
            let far = spheres.iter().map(|(_, s)| s.center.z).fold(0.0, f64::max) + 4.0 * r_max;
            let wall = [WALL_LEVEL + cfg.ambient; 3];
            if d.y <= 0.0 {
                return wall;
            }
            let p = d * (table_y / d.y);
            if p.z > far {
                return wall;
            }
            let l = cfg.light.direction();
            // Lit from above (l.y < 0: the light direction points up, toward −y), and not in a
            // sphere's shadow.
            let lit = (-l.y).max(0.0);
            let shadowed = spheres.iter().any(|(r, s)| {
                let oc = p - s.center;
                let b = oc.dot(&l);
                let disc = b * b - (oc.norm_squared() - r * r);
                disc > 0.0 && -b + disc.sqrt() > 0.0
            });
            let e = if shadowed { 0.0 } else { lit };
            [cfg.exposure * TABLE_ALBEDO * e + cfg.ambient; 3]
        }
    }
}

/// Render one image to linear RGB (noise-free), row-major, 3 values a pixel.
pub fn render_linear(cfg: &SessionConfig, spheres: &[(f64, Sphere)]) -> Vec<f64> {
    let cam = &cfg.camera;
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let model = Model {
        convolution: cfg.convolution,
        entry_fresnel: cfg.entry_transmission,
        // Ground truth: the closed form, not the fit's table.
        tabulated: false,
        ..Model::default()
    };
    let params = Params {
        material: cfg.material,
        light: cfg.light,
    };
    // A pixel is an edge pixel when its centre ray is within this angle of a silhouette.
    let margin = 2.5 * cam.pixel_angle();
    let n = cfg.supersample as usize;
    // Only pixels inside the spheres' padded bounding boxes can see a sphere: the rest is the
    // ambient floor, with no ray to trace.
    let boxes: Vec<[f64; 4]> = spheres
        .iter()
        .filter_map(|(_, s)| silhouette_box(cam, s, 3.0))
        .collect();
    let mut img = vec![cfg.ambient; w * h * 3];
    img.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let yf = y as f64;
        let everywhere = [[0.0, yf, (w - 1) as f64, yf]];
        let boxes: &[[f64; 4]] = if cfg.backdrop == Backdrop::Black && cfg.stand.is_none() {
            &boxes
        } else {
            &everywhere
        };
        let spans: Vec<(usize, usize)> = boxes
            .iter()
            .filter(|b| yf >= b[1] && yf <= b[3])
            .map(|b| {
                (
                    b[0].max(0.0) as usize,
                    (b[2].ceil().max(0.0) as usize).min(w - 1),
                )
            })
            .collect();
        for x in (0..w).filter(|&x| spans.iter().any(|&(a, b)| x >= a && x <= b)) {
            let px = Vector2::new(x as f64, y as f64);
            let Some(d) = cam.ray_for_pixel(px) else {
                continue;
            };
            let near_edge = n > 1
                && spheres
                    .iter()
                    .any(|(_, s)| s.angle_outside(&d).is_some_and(|a| a.abs() < margin));
            let v = if near_edge {
                let mut acc = [0.0; 3];
                for j in 0..n {
                    for i in 0..n {
                        let sub = px
                            + Vector2::new(
                                (i as f64 + 0.5) / n as f64 - 0.5,
                                (j as f64 + 0.5) / n as f64 - 0.5,
                            );
                        let v = match cam.ray_for_pixel(sub) {
                            Some(ds) => shade(cfg, &model, &params, spheres, &ds),
                            None => [cfg.ambient; 3],
                        };
                        (0..3).for_each(|c| acc[c] += v[c]);
                    }
                }
                acc.map(|a| a / (n * n) as f64)
            } else {
                shade(cfg, &model, &params, spheres, &d)
            };
            row[3 * x..3 * x + 3].copy_from_slice(&v);
        }
    });
    img
}

/// What `synth session` wrote.
#[derive(Debug)]
pub struct SessionOutput {
    pub session_file: PathBuf,
    pub truth_file: PathBuf,
    pub images: Vec<PathBuf>,
    pub truth: SessionTruth,
}

/// Render the session into `out` (created if needed): the images, `session.json`, `truth.json`,
/// and `intrinsics.json` when no intrinsics reference is given. `preview`: also write the first
/// image as an 8-bit sRGB PNG there (for looking at, not for measuring).
pub fn generate(
    cfg: &SessionConfig,
    out: &Path,
    preview: Option<&Path>,
    quiet: bool,
) -> Result<SessionOutput> {
    let plans = plan(cfg)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The photos, session.json and truth.json are one set: a run cut short leaves the folder's
    // previous session whole, never new photos beside an old truth.
    let set = crate::formats::output::OutputSet::begin(&[out])?;
    let cam = &cfg.camera;
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let pb = crate::progress::bar(plans.len() as u64, "rendering", quiet);
    let focal_mm = cam.fx * cfg.sensor_width_mm / cam.width() as f64;
    let f35 =
        photo::focal_35mm_equivalent(focal_mm, cfg.sensor_width_mm, cam.image_size).round() as u32;
    let exif = ExifInfo::for_exposure(cfg.exposure, "workbench", "synthetic camera", focal_mm, f35);
    let mut images = Vec::new();
    let mut truth_images = Vec::new();
    let mut session_images = Vec::new();
    for (k, p) in plans.iter().enumerate() {
        let lin = render_linear(cfg, &p.spheres);
        let path = out.join(&p.file);
        let noisy = sensor_noise(cfg, &lin, k as u64);
        if let (0, Some(pv)) = (k, preview) {
            let q: Vec<u8> = noisy
                .iter()
                .map(|v| (photo::srgb_encode(*v) * 255.0).round() as u8)
                .collect();
            photo::write_8bit(pv, w as u32, h as u32, 3, &q, 0, None)?;
        }
        write_photo(cfg, &path, &noisy, &exif)?;
        images.push(path);
        truth_images.push(truth_image(cfg, p));
        session_images.push(SessionImage {
            light_intensity: None,
            file: p.file.clone(),
            spheres: p
                .spheres
                .iter()
                .map(|(r, _)| SessionSphere::new(*r))
                .collect(),
            exposure: (cfg.format == Format::Png16).then_some(cfg.exposure),
            linear: None,
        });
        pb.inc(1);
    }
    pb.finish_and_clear();

    let intrinsics_ref = match &cfg.intrinsics_ref {
        Some(r) => r.clone(),
        None => {
            crate::formats::output::write_json(
                &out.join("intrinsics.json"),
                &IntrinsicsFile::from_truth(cam),
            )?;
            "intrinsics.json".into()
        }
    };
    let session = Session {
        schema: session::SCHEMA.into(),
        material: Some(cfg.material_name.clone()),
        intrinsics: Some(intrinsics_ref),
        light: Default::default(),
        floor: None,
        images: session_images,
        reference: None,
    };
    let truth = session_truth(cfg, truth_images);
    let session_file = out.join("session.json");
    let truth_file = out.join("truth.json");
    write_json(&session_file, &session)?;
    write_json(&truth_file, &truth)?;
    set.commit()?;
    Ok(SessionOutput {
        session_file,
        truth_file,
        images,
        truth,
    })
}

/// The photo's noisy values: each row's shot and read noise from its own generator.
fn sensor_noise(cfg: &SessionConfig, lin: &[f64], image: u64) -> Vec<f64> {
    let w = cfg.camera.width() as usize;
    let mut v = vec![0.0; lin.len()];
    v.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let mut rng = super::row_rng(cfg.seed, image, y as u64);
        for (o, i) in row.iter_mut().zip(&lin[y * w * 3..(y + 1) * w * 3]) {
            *o = super::sensor(*i, cfg.noise, cfg.read_noise, &mut rng);
        }
    });
    v
}

/// The photo in the session's format: 16-bit linear PNG, or 8-bit sRGB JPEG with EXIF.
fn write_photo(cfg: &SessionConfig, path: &Path, noisy: &[f64], exif: &ExifInfo) -> Result<()> {
    let (w, h) = (cfg.camera.width() as usize, cfg.camera.height() as usize);
    match cfg.format {
        Format::Png16 => {
            let q: Vec<u16> = noisy.iter().map(|v| (v * 65535.0).round() as u16).collect();
            photo::write_png16_rgb(path, w as u32, h as u32, &q)?;
        }
        Format::Jpeg => {
            let q: Vec<u8> = noisy
                .iter()
                .map(|v| (photo::srgb_encode(*v) * 255.0).round() as u8)
                .collect();
            photo::write_8bit(
                path,
                w as u32,
                h as u32,
                3,
                &q,
                cfg.jpeg_quality,
                Some(exif),
            )?;
        }
    }
    Ok(())
}

/// What is true of one photo: its spheres' centres and image ellipses.
fn truth_image(cfg: &SessionConfig, p: &ScenePlan) -> TruthImage {
    let cam = &cfg.camera;
    TruthImage {
        file: p.file.clone(),
        exposure: cfg.exposure,
        spheres: p
            .spheres
            .iter()
            .map(|(r, s)| TruthSphere {
                radius_mm: *r,
                center_mm: [s.center.x, s.center.y, s.center.z],
                ellipse: s
                    .image_ellipse(cam)
                    .expect("sphere in front of the camera")
                    .into(),
            })
            .collect(),
    }
}

/// Everything true of the session.
fn session_truth(cfg: &SessionConfig, images: Vec<TruthImage>) -> SessionTruth {
    let cam = &cfg.camera;
    let l = cfg.light.direction();
    let m = &cfg.material;
    SessionTruth {
        schema: TRUTH_SCHEMA.into(),
        kind: "session".into(),
        sigma0_mm: m.sigma0_mm,
        albedo: m.albedo,
        eta: m.eta,
        specular: m.specular,
        sigma_exponent: m.sigma_exponent,
        albedo_curvature: m.albedo_curvature,
        kernel_weight: m.kernel_weight,
        kernel_ratio: m.kernel_ratio,
        light_direction: [l.x, l.y, l.z],
        light_azimuth_deg: cfg.light.azimuth.to_degrees(),
        light_elevation_deg: cfg.light.elevation.to_degrees(),
        cdrf_convolution: cfg.convolution,
        entry_transmission: cfg.entry_transmission,
        intrinsics: IntrinsicsFile::from_truth(cam),
        images,
        render: RenderTruth {
            noise: cfg.noise,
            read_noise: cfg.read_noise,
            ambient: cfg.ambient,
            supersample: cfg.supersample,
            format: cfg.format,
            seed: cfg.seed,
            layout: cfg.layout,
            backdrop: cfg.backdrop,
            stand: cfg.stand.is_some(),
            stand_pins: cfg.stand,
        },
    }
}
