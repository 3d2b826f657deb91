//! `workbench synth pbr`: physically based photos of translucent spheres, rendered by volumetric
//! path tracing rather than by the CDRF the solver inverts (docs/pbr.md).
//!
//! Each sphere is a homogeneous medium (extinction σt and single-scattering albedo per channel,
//! isotropic phase function) inside a rough dielectric boundary ([`super::dielectric`]), lit by
//! one directional light in a black void, seen by the distorted camera (every sample's ray goes
//! through the lens model, so no image is resampled). A camera path enters through the boundary
//! (sampled from its BSDF), random-walks the medium by free-flight sampling (when the channels'
//! σt differ, one channel's drawn per path and the path weighted by the balance heuristic over
//! the three: one-sample MIS, docs/pbr.md), reflects off the
//! inside of the boundary when its BSDF says so, and leaves the sphere or is ended by Russian
//! roulette. The light is a delta in direction, so it is reached only by next-event estimation:
//! at the first surface hit (the specular reflection) and at every scattering point, where a
//! direction toward the boundary is drawn from a mixture of a GGX lobe around the direction that
//! light refracted at the exit point would travel back along, and the uniform sphere; the
//! boundary's BTDF is then evaluated for that direction and the light.
//!
//! Omitted: light reaching the last scattering point after an internal reflection with no
//! scattering in between (a chord of the sphere, attenuated by exp(−σt·chord); docs/pbr.md), and
//! the ballistic path straight through the sphere.
//!
//! Every photo is the mean of two half renders with independent seeds; half their difference is
//! the noise of the mean per pixel, reported in truth.json.

use super::dielectric::{self, Boundary};
use super::row_rng;
use crate::camera::sphere::Sphere;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::formats::intrinsics::IntrinsicsFile;
use crate::formats::output::write_json;
use crate::formats::photo;
use crate::formats::session::{self, Session, SessionImage, SessionSphere};
use crate::model::specular::ggx_d;
use crate::model::LightAngles;
use crate::stats::percentile;
use nalgebra::{Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

pub(crate) const TRUTH_SCHEMA: &str = "workbench.pbr-truth/1";

/// The scattering medium: extinction (1/mm) and single-scattering albedo, per channel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    pub sigma_t: [f64; 3],
    pub albedo: [f64; 3],
}

impl Medium {
    /// One extinction for all channels.
    pub fn grey(sigma_t: f64, albedo: [f64; 3]) -> Medium {
        Medium {
            sigma_t: [sigma_t; 3],
            albedo,
        }
    }

    /// Whether every channel has the same extinction (free flights need no channel drawn).
    fn is_grey(&self) -> bool {
        self.sigma_t.iter().all(|s| *s == self.sigma_t[0])
    }

    /// Diffusion length 1/√(3 σa σt) per channel (isotropic phase: σt′ = σt), in mm.
    pub(crate) fn diffusion_length_mm(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            let (a, t) = (self.albedo[c], self.sigma_t[c]);
            1.0 / (3.0 * (1.0 - a) * t * t).sqrt()
        })
    }
}

/// One sphere under one directional light (irradiance 1 on a surface facing the light).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scene {
    pub sphere: Sphere,
    /// Unit vector toward the light, camera frame.
    pub light: Vector3<f64>,
    pub medium: Medium,
    pub boundary: Boundary,
}

/// Probability of the GGX lobe in the next-event direction mixture (the rest is uniform).
const LOBE_PROBABILITY: f64 = 0.75;
/// Scattering events before Russian roulette starts.
const ROULETTE_AFTER: u32 = 8;
/// A path that has not ended after this many events is dropped (never reached in practice).
const MAX_EVENTS: u32 = 100_000;

/// One camera sample's radiance: the direct specular reflection and the subsurface part.
#[derive(Clone, Copy, Debug, Default)]
struct PathValue {
    specular: f64,
    subsurface: [f64; 3],
    scatterings: u32,
}

fn uniform_sphere(u1: f64, u2: f64) -> Vector3<f64> {
    let z = 1.0 - 2.0 * u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

impl Scene {
    /// Distance from a point inside (or on) the sphere to the boundary along a unit direction.
    fn exit(&self, p: &Vector3<f64>, d: &Vector3<f64>) -> f64 {
        let oc = p - self.sphere.center;
        let b = oc.dot(d);
        let c = oc.norm_squared() - self.sphere.radius * self.sphere.radius;
        (-b + (b * b - c).max(0.0).sqrt()).max(0.0)
    }

    fn normal_at(&self, y: &Vector3<f64>) -> Vector3<f64> {
        (y - self.sphere.center).normalize()
    }

    /// The direction from x toward the boundary along which light refracted at a smooth exit
    /// point would arrive (two fixed-point steps from the straight line to the light).
    fn guide(&self, x: &Vector3<f64>) -> Vector3<f64> {
        let l = self.light;
        let e = 1.0 / self.boundary.eta;
        let mut d = l;
        for _ in 0..2 {
            let y = x + d * self.exit(x, &d);
            let n = self.normal_at(&y);
            let ci = n.dot(&l);
            if ci <= 0.0 {
                break;
            }
            let ct = (1.0 - e * e * (1.0 - ci * ci)).sqrt();
            // Light travelling along −l refracts to t = −e l + (e ci − ct) n; back along −t.
            d = (l * e - n * (e * ci - ct)).normalize();
        }
        d
    }

    /// Next-event estimate at a scattering point x per channel: the light reaching x through
    /// the boundary, times the isotropic phase function, for irradiance 1.
    fn next_event(&self, x: &Vector3<f64>, rng: &mut ChaCha8Rng) -> [f64; 3] {
        let g = self.guide(x);
        let beta = self.boundary.alpha;
        let (u0, u1, u2): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
        let w = if u0 < LOBE_PROBABILITY {
            let tan2 = beta * beta * u1 / (1.0 - u1).max(1e-300);
            let c = 1.0 / (1.0 + tan2).sqrt();
            let s = (1.0 - c * c).max(0.0).sqrt();
            let (t, b) = dielectric::frame(&g);
            let phi = 2.0 * PI * u2;
            t * (s * phi.cos()) + b * (s * phi.sin()) + g * c
        } else {
            uniform_sphere(u1, u2)
        };
        let c = w.dot(&g);
        let lobe = if c > 0.0 { ggx_d(c, beta).0 * c } else { 0.0 };
        let pdf = LOBE_PROBABILITY * lobe + (1.0 - LOBE_PROBABILITY) / (4.0 * PI);
        let s = self.exit(x, &w);
        let y = x + w * s;
        let n = self.normal_at(&y);
        let nl = n.dot(&self.light);
        if nl <= 0.0 {
            return [0.0; 3];
        }
        let f = self.boundary.eval(&self.light, &-w, &n) * nl / (4.0 * PI * pdf);
        self.medium.sigma_t.map(|t| f * (-t * s).exp())
    }

    /// One camera path along the unit ray d from the camera centre. `lamp`: instead of
    /// next-event estimation, light only paths that leave the sphere toward a distant lamp of
    /// this angular radius and the same irradiance (stock volumetric path tracing; the tests'
    /// independent check).
    fn path(&self, d: &Vector3<f64>, rng: &mut ChaCha8Rng, lamp: Option<f64>) -> PathValue {
        let mut out = PathValue::default();
        let Some(t0) = self.sphere.intersect(d) else {
            return out;
        };
        let y0 = d * t0;
        let n0 = self.normal_at(&y0);
        let wo = -d;
        let l = self.light;
        let nl = n0.dot(&l);
        // Radiance of the lamp for irradiance 1: E = L·π·sin²δ.
        let lamp = lamp.map(|delta: f64| (delta.cos(), 1.0 / (PI * delta.sin().powi(2))));
        let sees_lamp = |w: &Vector3<f64>| lamp.filter(|(c, _)| w.dot(&l) >= *c).map(|v| v.1);
        if nl > 0.0 && lamp.is_none() {
            out.specular = self.boundary.eval(&l, &wo, &n0) * nl;
        }
        let s = self
            .boundary
            .sample(&wo, &n0, [rng.random(), rng.random(), rng.random()]);
        if !s.transmitted || s.weight == 0.0 {
            if let Some(le) = sees_lamp(&s.wi) {
                out.specular = s.weight * le;
            }
            return out;
        }
        // thr[c]: the path's value in channel c over its density under the drawing channel j;
        // q[k]: its density under channel k's σt over that under j. Channel c's estimate is
        // thr[c] / mean(q): the balance heuristic over the three channels' samplings of the
        // whole path (one-sample MIS; docs/pbr.md). A grey medium keeps q = 1.
        let mut thr = [s.weight; 3];
        let mut q = [1.0; 3];
        let (mut p, mut dir) = (y0, s.wi);
        let Medium { sigma_t, albedo } = self.medium;
        let grey = self.medium.is_grey();
        let j = if grey {
            0
        } else {
            ((3.0 * rng.random::<f64>()) as usize).min(2)
        };
        let weights = |thr: &[f64; 3], q: &[f64; 3]| {
            let m = (q[0] + q[1] + q[2]) / 3.0;
            thr.map(|v| v / m)
        };
        for _ in 0..MAX_EVENTS {
            let t_exit = self.exit(&p, &dir);
            let u: f64 = rng.random();
            let t = -(1.0 - u).ln() / sigma_t[j];
            if t < t_exit {
                p += dir * t;
                if grey {
                    (0..3).for_each(|c| thr[c] *= albedo[c]);
                } else {
                    // Value σs_c e^{−σt_c t}; densities σt_k e^{−σt_k t}.
                    let d = sigma_t.map(|k| k * (-k * t).exp());
                    (0..3).for_each(|c| {
                        thr[c] *= albedo[c] * d[c] / d[j];
                        q[c] *= d[c] / d[j];
                    });
                }
                let w = weights(&thr, &q);
                if lamp.is_none() {
                    let e = self.next_event(&p, rng);
                    (0..3).for_each(|c| out.subsurface[c] += w[c] * e[c]);
                }
                out.scatterings += 1;
                if out.scatterings > ROULETTE_AFTER {
                    // Survival at most 1: a roulette never lifts the largest weight above 1.
                    // Capped lower, long paths' weights grew without bound and past albedo
                    // 0.975 the estimator's variance was infinite (docs/pbr.md, "Russian
                    // roulette at high albedo").
                    let survive = w.iter().cloned().fold(0.0, f64::max).min(1.0);
                    if rng.random::<f64>() >= survive {
                        break;
                    }
                    thr.iter_mut().for_each(|v| *v /= survive);
                }
                dir = uniform_sphere(rng.random(), rng.random());
            } else {
                if !grey {
                    // Value and densities alike: the probability e^{−σt t_exit} of no event.
                    let tr = sigma_t.map(|k| (-k * t_exit).exp());
                    (0..3).for_each(|c| {
                        thr[c] *= tr[c] / tr[j];
                        q[c] *= tr[c] / tr[j];
                    });
                }
                let y = p + dir * t_exit;
                let n = self.normal_at(&y);
                let s = self
                    .boundary
                    .sample(&-dir, &n, [rng.random(), rng.random(), rng.random()]);
                if s.transmitted || s.weight == 0.0 {
                    if let Some(le) = sees_lamp(&s.wi).filter(|_| s.transmitted) {
                        let w = weights(&thr, &q);
                        (0..3).for_each(|c| out.subsurface[c] += w[c] * s.weight * le);
                    }
                    break; // left the sphere into the black void
                }
                thr.iter_mut().for_each(|v| *v *= s.weight);
                p = y;
                dir = s.wi;
            }
        }
        out
    }
}

/// A rendered photo, linear radiance for irradiance 1, full frame, row-major.
#[derive(Clone, Debug)]
pub struct Rendered {
    pub width: usize,
    pub height: usize,
    /// The two independent half renders (each the mean of spp/2 samples), RGB.
    pub halves: [Vec<[f64; 3]>; 2],
    /// The direct specular reflection (mean over both halves; white).
    pub specular: Vec<f64>,
    /// Pixels whose box was traced.
    pub pixels_traced: usize,
    /// Mean number of scattering events per camera path that entered the medium.
    pub mean_scatterings: f64,
}

impl Rendered {
    /// The photo: the mean of the halves.
    pub fn mean(&self) -> Vec<[f64; 3]> {
        self.halves[0]
            .iter()
            .zip(&self.halves[1])
            .map(|(a, b)| [0, 1, 2].map(|c| 0.5 * (a[c] + b[c])))
            .collect()
    }
}

/// One pixel's mean over `n` samples (uniform inside the pixel box).
#[derive(Clone, Copy, Debug, Default)]
struct PixelMean {
    radiance: [f64; 3],
    specular: f64,
    /// Scattering events, and the paths that scattered.
    scatterings: u64,
    paths: u64,
}

fn pixel(
    cam: &Camera,
    scene: &Scene,
    [x, y]: [usize; 2],
    n: u32,
    rng: &mut ChaCha8Rng,
    lamp: Option<f64>,
) -> PixelMean {
    let mut out = PixelMean::default();
    for _ in 0..n {
        let px = Vector2::new(
            x as f64 + rng.random::<f64>() - 0.5,
            y as f64 + rng.random::<f64>() - 0.5,
        );
        let Some(d) = cam.ray_for_pixel(px) else {
            continue;
        };
        let v = scene.path(&d, rng, lamp);
        (0..3).for_each(|c| out.radiance[c] += v.specular + v.subsurface[c]);
        out.specular += v.specular;
        if v.scatterings > 0 {
            out.scatterings += v.scatterings as u64;
            out.paths += 1;
        }
    }
    out.radiance = out.radiance.map(|a| a / n as f64);
    out.specular /= n as f64;
    out
}

/// Chosen pixels of one sphere, each the mean of `spp` samples split into two halves seeded
/// from (seed, image, pixel's place in `pixels`) and (seed + 1, …): per pixel, the halves.
pub fn render_pixels(
    cam: &Camera,
    scene: &Scene,
    pixels: &[[u32; 2]],
    spp: u32,
    seed: u64,
    image: u64,
) -> Vec<[[f64; 3]; 2]> {
    let half = (spp / 2).max(1);
    pixels
        .par_iter()
        .enumerate()
        .map(|(i, &[x, y])| {
            let at = [x as usize, y as usize];
            [0, 1].map(|k| {
                let mut rng = row_rng(seed + k, image, i as u64);
                pixel(cam, scene, at, half, &mut rng, None).radiance
            })
        })
        .collect()
}

/// Render one sphere: `spp` samples per pixel (box filter: uniform inside each pixel), split
/// into two halves seeded from (seed, image) and (seed + 1, image).
pub fn render(cam: &Camera, scene: &Scene, spp: u32, seed: u64, image: u64) -> Rendered {
    render_with(cam, scene, spp, seed, image, None)
}

/// [`render`], optionally lit by a lamp of angular radius `lamp` (radians) that paths must hit
/// instead of next-event estimation (see [`Scene::path`]).
pub fn render_with(
    cam: &Camera,
    scene: &Scene,
    spp: u32,
    seed: u64,
    image: u64,
    lamp: Option<f64>,
) -> Rendered {
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let half = (spp / 2).max(1);
    let bx = super::session::silhouette_box(cam, &scene.sphere, 2.0)
        .map(|b| {
            [
                b[0].floor().max(0.0) as usize,
                b[1].floor().max(0.0) as usize,
                (b[2].ceil().max(0.0) as usize).min(w - 1),
                (b[3].ceil().max(0.0) as usize).min(h - 1),
            ]
        })
        .unwrap_or([1, 1, 0, 0]);
    type Row = (Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<f64>, u64, u64);
    let rows: Vec<(usize, Row)> = (bx[1]..=bx[3])
        .into_par_iter()
        .map(|y| {
            let n = bx[2] + 1 - bx[0];
            let mut r: Row = (vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![0.0; n], 0, 0);
            for k in 0..2u64 {
                let mut rng = row_rng(seed + k, image, y as u64);
                for i in 0..n {
                    let v = pixel(cam, scene, [bx[0] + i, y], half, &mut rng, lamp);
                    r.3 += v.scatterings;
                    r.4 += v.paths;
                    let dst = if k == 0 { &mut r.0 } else { &mut r.1 };
                    dst[i] = v.radiance;
                    r.2[i] += 0.5 * v.specular;
                }
            }
            (y, r)
        })
        .collect();
    let mut out = Rendered {
        width: w,
        height: h,
        halves: [vec![[0.0; 3]; w * h], vec![[0.0; 3]; w * h]],
        specular: vec![0.0; w * h],
        pixels_traced: 0,
        mean_scatterings: 0.0,
    };
    let (mut events, mut paths) = (0u64, 0u64);
    for (y, r) in rows {
        let at = y * w + bx[0];
        let n = r.0.len();
        out.halves[0][at..at + n].copy_from_slice(&r.0);
        out.halves[1][at..at + n].copy_from_slice(&r.1);
        out.specular[at..at + n].copy_from_slice(&r.2);
        out.pixels_traced += n;
        events += r.3;
        paths += r.4;
    }
    out.mean_scatterings = events as f64 / paths.max(1) as f64;
    out
}

/// Everything that defines a physically based session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PbrConfig {
    pub radii_mm: Vec<f64>,
    pub camera: Camera,
    pub light: LightAngles,
    pub medium: Medium,
    pub eta: f64,
    pub alpha: f64,
    /// Samples per pixel (both halves together).
    pub spp: u32,
    pub seed: u64,
    /// Camera to sphere centre (mm); every sphere sits at the same place, (0.04, −0.03, 1)·d.
    pub distance_mm: f64,
    pub material_name: String,
}

fn check(cfg: &PbrConfig) -> Result<()> {
    let bad = |m: &str| Err(Error::Argument(m.into()));
    if cfg.radii_mm.is_empty() || !cfg.radii_mm.iter().all(|r| r.is_finite() && *r > 0.0) {
        return bad("give at least one radius, every one positive");
    }
    let m = &cfg.medium;
    let valid = m.sigma_t.iter().all(|t| *t > 0.0 && t.is_finite())
        && m.albedo.iter().all(|a| (0.0..1.0).contains(a));
    if !valid {
        return bad("medium: σt must be positive and every albedo in [0, 1)");
    }
    if !m.is_grey() {
        // truth.json (workbench.pbr-truth/1) states one σt.
        return bad("medium: a session takes one σt for all channels");
    }
    if !(cfg.eta > 1.0 && cfg.eta < 4.0 && cfg.alpha >= 0.001 && cfg.alpha <= 1.0) {
        return bad("boundary: η must lie in (1, 4) and α in [0.001, 1]");
    }
    if cfg.spp < 2 {
        return bad("spp must be at least 2 (two half renders)");
    }
    let size = cfg.camera.image_size;
    if let Some(why) = photo::size_problem(size[0], size[1]) {
        return Err(Error::Argument(why));
    }
    let r_max = cfg.radii_mm.iter().cloned().fold(0.0, f64::max);
    if !(cfg.distance_mm > 1.5 * r_max) {
        return bad("the distance must exceed 1.5 × the largest radius");
    }
    Ok(())
}

/// truth.json of a physically based session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PbrTruth {
    pub schema: String,
    pub what: String,
    pub light: TruthLight,
    pub material: TruthMaterial,
    /// The light's irradiance in the photos' own units (PNG value / 65535): pass it to `solve
    /// --irradiance`.
    pub irradiance_in_png_units: f64,
    pub intrinsics: IntrinsicsFile,
    pub images: Vec<TruthPhoto>,
    pub renderer: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthLight {
    pub direction_to_light_camera_frame: [f64; 3],
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthMaterial {
    pub name: String,
    pub eta: f64,
    pub alpha: f64,
    pub sigma_t_per_mm: f64,
    pub albedo_rgb: [f64; 3],
    pub diffusion_length_mm_rgb: [f64; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthPhoto {
    pub file: String,
    pub radius_mm: f64,
    pub centre_mm: [f64; 3],
    /// Median over lit pixels (subsurface above a tenth of the photo's 99th percentile) of the
    /// noise of the mean relative to the value, from the two half renders.
    pub noise_rel_median_lit: f64,
    pub saturated_pixels: usize,
    pub spp: u32,
    pub pixels_traced: usize,
    pub mean_scatterings_per_path: f64,
    pub render_time_s: f64,
}

/// What `synth pbr` wrote.
#[derive(Debug)]
pub struct PbrOutput {
    pub images: Vec<PathBuf>,
    pub truth: PbrTruth,
}

/// Render the session into `out`: one photo per radius (`r35.png` …, 16-bit linear RGB), scaled
/// so that the 99.97th percentile of the subsurface radiance over all photos is 0.6 of full
/// scale; `session.json`, `intrinsics.json` (the rendering camera) and `truth.json`.
pub fn generate(cfg: &PbrConfig, out: &Path, quiet: bool) -> Result<PbrOutput> {
    check(cfg)?;
    let cam = &cfg.camera;
    let z = cfg.distance_mm;
    let centre = Vector3::new(0.04 * z, -0.03 * z, z);
    let renders = render_all(cfg, centre, quiet);
    let scale = exposure_scale(&renders)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // One set: the photos with their session.json and truth.json, or the folder as it was.
    let set = crate::formats::output::OutputSet::begin(&[out])?;
    let mut images = Vec::new();
    let mut photos = Vec::new();
    for (r, img, mean, secs) in &renders {
        let (path, photo) = write_photo(cfg, out, centre, scale, (*r, img, mean, *secs))?;
        images.push(path);
        photos.push(photo);
    }
    write_json(
        &out.join("intrinsics.json"),
        &IntrinsicsFile::from_truth(cam),
    )?;
    let session = Session {
        schema: session::SCHEMA.into(),
        material: Some(format!("{} (physically based render)", cfg.material_name)),
        intrinsics: Some("intrinsics.json".into()),
        light: Default::default(),
        floor: None,
        images: photos
            .iter()
            .map(|p| SessionImage {
                light_intensity: None,
                file: p.file.clone(),
                spheres: vec![SessionSphere::new(p.radius_mm)],
                exposure: None,
                linear: None,
            })
            .collect(),
        reference: None,
    };
    write_json(&out.join("session.json"), &session)?;
    let truth = pbr_truth(cfg, scale, photos);
    write_json(&out.join("truth.json"), &truth)?;
    set.commit()?;
    Ok(PbrOutput { images, truth })
}

/// One render per radius: the radius, the render, its mean photo and the seconds it took.
type Renders = Vec<(f64, Rendered, Vec<[f64; 3]>, f64)>;

/// Every radius path-traced, the spheres at `centre`.
fn render_all(cfg: &PbrConfig, centre: Vector3<f64>, quiet: bool) -> Renders {
    let cam = &cfg.camera;
    let l = cfg.light.direction();
    let pb = crate::progress::bar(cfg.radii_mm.len() as u64, "path tracing", quiet);
    let mut renders = Vec::new();
    for (k, &r) in cfg.radii_mm.iter().enumerate() {
        let scene = Scene {
            sphere: Sphere::new(centre, r),
            light: l,
            medium: cfg.medium,
            boundary: Boundary {
                eta: cfg.eta,
                alpha: cfg.alpha,
            },
        };
        let t0 = std::time::Instant::now();
        let img = render(cam, &scene, cfg.spp, cfg.seed, k as u64);
        let mean = img.mean();
        renders.push((r, img, mean, t0.elapsed().as_secs_f64()));
        pb.inc(1);
    }
    pb.finish_and_clear();
    renders
}

/// Radiance → pixel values: the 99.97th percentile of the subsurface radiance over all photos
/// at 0.6 of full scale.
fn exposure_scale(renders: &Renders) -> Result<f64> {
    let subsurface: Vec<f64> = renders
        .iter()
        .flat_map(|(_, img, mean, _)| {
            mean.iter()
                .zip(&img.specular)
                .filter(|(v, _)| v.iter().any(|c| *c > 0.0))
                .flat_map(|(v, s)| v.map(|c| c - s))
        })
        .collect();
    let reference = percentile(subsurface, 0.9997);
    if !(reference > 0.0) {
        return Err(Error::Argument(
            "the render is black: is the light behind the spheres?".into(),
        ));
    }
    Ok(0.6 / reference)
}

/// One photo written (16-bit linear), with what is true of it: its noise (from the two half
/// renders), its clipped pixels, the render's statistics.
fn write_photo(
    cfg: &PbrConfig,
    out: &Path,
    centre: Vector3<f64>,
    scale: f64,
    (r, img, mean, secs): (f64, &Rendered, &[[f64; 3]], f64),
) -> Result<(PathBuf, TruthPhoto)> {
    let file = if r.fract() == 0.0 {
        format!("r{r:.0}.png")
    } else {
        format!("r{r}.png")
    };
    let q: Vec<u16> = mean
        .iter()
        .flat_map(|v| v.map(|c| ((c * scale).clamp(0.0, 1.0) * 65535.0).round() as u16))
        .collect();
    let saturated = mean
        .iter()
        .filter(|v| v.iter().any(|c| c * scale >= 1.0))
        .count();
    let lum: Vec<f64> = mean
        .iter()
        .zip(&img.specular)
        .map(|(v, s)| (v[0] + v[1] + v[2]) / 3.0 - s)
        .collect();
    let p99 = percentile(lum.iter().cloned().filter(|v| *v > 0.0).collect(), 0.99);
    let rel: Vec<f64> = (0..mean.len())
        .filter(|&i| lum[i] > 0.1 * p99)
        .map(|i| {
            let (a, b) = (&img.halves[0][i], &img.halves[1][i]);
            let m = (0..3).map(|c| 0.5 * (a[c] + b[c])).sum::<f64>();
            let d = 0.5 * (0..3).map(|c| a[c] - b[c]).sum::<f64>().abs();
            d / m
        })
        .collect();
    // (a − b)/2 has the standard deviation of the mean (a + b)/2; the median of |N(0, s²)|
    // is 0.6745 s.
    let noise = (percentile(rel, 0.5) / 0.6745).max(0.0); // no lit pixel: 0
    let path = out.join(&file);
    photo::write_png16_rgb(&path, img.width as u32, img.height as u32, &q)?;
    let photo = TruthPhoto {
        file,
        radius_mm: r,
        centre_mm: [centre.x, centre.y, centre.z],
        noise_rel_median_lit: noise,
        saturated_pixels: saturated,
        spp: cfg.spp,
        pixels_traced: img.pixels_traced,
        mean_scatterings_per_path: img.mean_scatterings,
        render_time_s: secs,
    };
    Ok((path, photo))
}

/// Everything true of the session: the light, the material, the irradiance in the photos'
/// units, the camera, each photo, the renderer.
fn pbr_truth(cfg: &PbrConfig, scale: f64, photos: Vec<TruthPhoto>) -> PbrTruth {
    let l = cfg.light.direction();
    PbrTruth {
        schema: TRUTH_SCHEMA.into(),
        what: "volumetric path tracing of a homogeneous medium in a rough dielectric sphere under \
               one directional light (workbench synth pbr); there is no true σ0"
            .into(),
        light: TruthLight {
            direction_to_light_camera_frame: [l.x, l.y, l.z],
            azimuth_deg: cfg.light.azimuth.to_degrees(),
            elevation_deg: cfg.light.elevation.to_degrees(),
        },
        material: TruthMaterial {
            name: cfg.material_name.clone(),
            eta: cfg.eta,
            alpha: cfg.alpha,
            sigma_t_per_mm: cfg.medium.sigma_t[0],
            albedo_rgb: cfg.medium.albedo,
            diffusion_length_mm_rgb: cfg.medium.diffusion_length_mm(),
        },
        irradiance_in_png_units: scale,
        intrinsics: IntrinsicsFile::from_truth(&cfg.camera),
        images: photos,
        renderer: format!(
            "workbench {} synth pbr: NEE through the rough boundary (GGX lobe {LOBE_PROBABILITY} + \
             uniform), Russian roulette after {ROULETTE_AFTER} scatterings",
            env!("CARGO_PKG_VERSION")
        ),
    }
}
