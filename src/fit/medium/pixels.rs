//! The medium fit's inputs: what it is given besides the pixels ([`Setup`]), and the pixels it
//! fits, pooled by radius ([`pixels`]).

use crate::fit::observe::SphereData;
use nalgebra::Vector3;

/// What the medium fit is given besides the pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setup {
    /// The light, toward it, in the frame of the observations' normals.
    pub light: Vector3<f64>,
    /// η's prior: the joint fit's η and its std.
    pub eta_prior: (f64, f64),
    /// Whether the joint fit's η joins the pixels' in the medium's ([`super::fit`]): false where
    /// the joint fit's model does not describe the photos (its residuals more than twice their
    /// noise), so that its η's error is its model's bias more than its noise.
    pub joint_eta_combined: bool,
    /// How the joint fit's η follows its α: Σ_ηα/Σ_αα of its covariance (0 where it states
    /// none). A clipped highlight's wings hold F(η)·α², so a polished surface's η rests on its
    /// lobe's α, and the medium's measured α moves it ([`super::fit`]).
    pub eta_alpha_slope: f64,
    /// The boundary's GGX roughness: the lobe's α (0: smooth), held, or with `alpha_std` the
    /// prior of the α the fit measures.
    pub alpha: f64,
    /// The std of `alpha` as a prior (the lobe's stated error); None: α is held at `alpha`.
    pub alpha_std: Option<f64>,
    /// The light's irradiance in the photos' units, when known.
    pub irradiance: Option<f64>,
    /// The largest sphere's radius (mm): it bounds σs′ (`MAX_SIGMA_T_RADIUS`).
    pub largest_radius: f64,
}

/// One pixel and channel: where it lies and what it saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Px {
    /// n·l, n·v and l·v.
    pub cos_theta: f64,
    pub cos_phi: f64,
    pub cos_light_view: f64,
    pub radiance: f64,
    /// 1/σ of its noise.
    pub weight: f64,
}

impl Px {
    /// The pixel of normal `n` seen along `v` (toward the camera) under the light `light`.
    pub fn at(
        n: &Vector3<f64>,
        v: &Vector3<f64>,
        light: &Vector3<f64>,
        radiance: f64,
        weight: f64,
    ) -> Px {
        Px {
            cos_theta: n.dot(light),
            cos_phi: n.dot(v),
            cos_light_view: light.dot(v),
            radiance,
            weight,
        }
    }
}

/// Every sphere of one radius: its pixels per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Radius {
    pub radius_mm: f64,
    pub pixels: [Vec<Px>; 3],
}

/// Whether the diffusion model describes a pixel at all: its half vector more than 25° from
/// the normal (out of the lobe) and φ within 75° (off the rim).
pub fn described(n: &Vector3<f64>, v: &Vector3<f64>, light: &Vector3<f64>) -> bool {
    let h = (light + v).normalize();
    n.dot(&h) <= 25f64.to_radians().cos() && n.dot(v) >= 75f64.to_radians().cos()
}

/// Whether a pixel is fitted: [`described`], and θ within [`MAX_THETA_DEG`].
pub fn fitted(n: &Vector3<f64>, v: &Vector3<f64>, light: &Vector3<f64>) -> bool {
    described(n, v, light) && n.dot(light) >= MAX_THETA_DEG.to_radians().cos()
}

/// Whether an observation is one the medium fit uses: every channel weighted, and [`fitted`].
pub fn fitted_obs(o: &crate::fit::solver::Obs, light: &Vector3<f64>) -> bool {
    o.weight.iter().all(|w| *w > 0.0) && fitted(&o.geometry.normal, &o.geometry.view, light)
}

/// The deepest shadow fitted (θ, degrees). Further past the terminator the light has crossed
/// the sphere and leaves it mostly away from the light, where the model's exit law (the first
/// azimuthal harmonic, checked against the photon tally up to 95°) sends too much toward a
/// camera on the light's side: at the truth, 105–110° from the light wax's photos hold
/// 0.70–0.81 of the model's red light on the 20–35 mm spheres (the longest diffusion length;
/// 0.49–0.92 beyond; `medium::the_renders_over_the_model_at_the_truth`), and fitting them
/// pulled red's σa 12–18% high. Chosen among 95°, 100°, 105° and none by the errors
/// against the truth of the eight wax and soap sessions, with Snell's beams and with the beams
/// along the transmitted light's mean direction (docs/medium.md, "The deepest shadow fitted").
pub const MAX_THETA_DEG: f64 = 105.0;

/// The spheres' fitted pixels, pooled by radius (in increasing radius).
pub fn pixels(spheres: &[&SphereData], light: &Vector3<f64>) -> Vec<Radius> {
    pixels_seen(spheres, light, light)
}

/// The pixels [`pixels`] chooses under `light`, their cosines taken under `seen`: the same
/// pixels in the same order under a moved light (the fit's sensitivity to the light).
pub fn pixels_seen(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    seen: &Vector3<f64>,
) -> Vec<Radius> {
    pool(spheres, light, seen, |_, _| None)
}

/// The pixels [`pixels`] chooses under `light`, each with the normal and view `moved` gives it
/// (by sphere and observation; `None`: its own): the same pixels in the same order on a moved
/// sphere (the fit's sensitivity to the spheres' outlines).
pub fn pixels_moved(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    moved: impl Fn(usize, usize) -> Option<(Vector3<f64>, Vector3<f64>)>,
) -> Vec<Radius> {
    pool(spheres, light, light, moved)
}

/// The spheres' pixels fitted under `light`, pooled by radius (in increasing radius), their
/// cosines taken under `seen` with the geometry `moved` gives (by sphere and observation;
/// `None`: the observation's own).
fn pool(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    seen: &Vector3<f64>,
    moved: impl Fn(usize, usize) -> Option<(Vector3<f64>, Vector3<f64>)>,
) -> Vec<Radius> {
    let mut radii: Vec<Radius> = Vec::new();
    for (i, s) in spheres.iter().enumerate() {
        let at = match radii
            .iter()
            .position(|r| (r.radius_mm - s.radius_mm).abs() < 1e-9)
        {
            Some(i) => i,
            None => {
                radii.push(Radius {
                    radius_mm: s.radius_mm,
                    pixels: [vec![], vec![], vec![]],
                });
                radii.len() - 1
            }
        };
        for (k, (o, w)) in s.obs.iter().zip(&s.curve_weight).enumerate() {
            let (n, v) = (o.geometry.normal, o.geometry.view);
            if !fitted(&n, &v, light) {
                continue;
            }
            let (n, v) = moved(i, k).unwrap_or((n, v));
            for (c, pixels) in radii[at].pixels.iter_mut().enumerate() {
                if o.weight[c] > 0.0 {
                    pixels.push(Px::at(&n, &v, seen, o.radiance[c], w[c]));
                }
            }
        }
    }
    radii.retain(|r| r.pixels.iter().all(|p| !p.is_empty()));
    radii.sort_by(|a, b| a.radius_mm.total_cmp(&b.radius_mm));
    radii
}
