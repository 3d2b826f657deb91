//! The medium fit's inputs: what it is given besides the pixels ([`Setup`]), and the pixels it
//! fits, pooled by radius ([`pixels`]).

use crate::fit::noise::IMPULSE_SIGMA;
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
    /// The pixels it stands for: 1, or a block's ([`MAX_PIXELS_A_SPHERE`]).
    pub members: f64,
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
            members: 1.0,
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

/// The most fitted pixels a sphere gives the medium fit one by one. A sphere with more (a photo of
/// more megapixels than the physically based sessions') gives square blocks of b×b pixels
/// instead, b the least that brings it to about this many ([`block_side`]): the fit's cost and
/// memory then stop growing with the photo's resolution while its angular resolution stays
/// that of the sessions its accuracy was measured on (pbr-jade's 35 mm sphere, the largest,
/// 24 000 fitted pixels; the physically based sessions' others 1500–15 000). Each block is one
/// observation: the members' mean radiance, the noise of that mean, and the normal and view of
/// their mean (docs/medium.md, "The medium fit", step 1).
pub const MAX_PIXELS_A_SPHERE: usize = 32_768;

/// The side of the blocks a sphere of `fitted` pixels gives the medium fit (1: each pixel
/// alone): the least b with ⌈fitted / b²⌉ at most [`MAX_PIXELS_A_SPHERE`].
pub fn block_side(fitted: usize) -> u32 {
    side_for(fitted, MAX_PIXELS_A_SPHERE)
}

/// The least b with ⌈fitted / b²⌉ at most `per_sphere` (at least 1).
fn side_for(fitted: usize, per_sphere: usize) -> u32 {
    let mut b = 1u32;
    while fitted.div_ceil((b * b) as usize) > per_sphere.max(1) {
        b += 1;
    }
    b
}

/// The spheres' fitted pixels, pooled by radius (in increasing radius), a large sphere's in
/// blocks ([`MAX_PIXELS_A_SPHERE`]).
pub fn pixels(spheres: &[&SphereData], light: &Vector3<f64>) -> Vec<Radius> {
    pixels_seen(spheres, light, light)
}

/// [`pixels`] with a sphere of more than `per_sphere` fitted pixels in blocks ([`block_side`]'s
/// rule with `per_sphere` for [`MAX_PIXELS_A_SPHERE`]).
pub fn pixels_at_most(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    per_sphere: usize,
) -> Vec<Radius> {
    pool(spheres, light, light, |_, _| None, Some(per_sphere))
}

/// Every fitted pixel of the spheres on its own, pooled by radius (in increasing radius), however
/// many a sphere has: what a prediction is scored on (the held-out radius).
pub fn each_pixel(spheres: &[&SphereData], light: &Vector3<f64>) -> Vec<Radius> {
    pool(spheres, light, light, |_, _| None, None)
}

/// The pixels [`pixels`] chooses under `light`, their cosines taken under `seen`: the same
/// pixels (and blocks) in the same order under a moved light (the fit's sensitivity to the
/// light).
pub fn pixels_seen(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    seen: &Vector3<f64>,
) -> Vec<Radius> {
    pool(spheres, light, seen, |_, _| None, Some(MAX_PIXELS_A_SPHERE))
}

/// The pixels [`pixels`] chooses under `light`, each with the normal and view `moved` gives it
/// (by sphere and observation; `None`: its own): the same pixels (and blocks) in the same order
/// on a moved sphere (the fit's sensitivity to the spheres' outlines).
pub fn pixels_moved(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    moved: impl Fn(usize, usize) -> Option<(Vector3<f64>, Vector3<f64>)>,
) -> Vec<Radius> {
    pool(spheres, light, light, moved, Some(MAX_PIXELS_A_SPHERE))
}

/// The spheres' pixels fitted under `light`, pooled by radius (in increasing radius), their
/// cosines taken under `seen` with the geometry `moved` gives (by sphere and observation;
/// `None`: the observation's own); a sphere of more than `per_sphere` fitted pixels (None: no
/// limit) in blocks ([`blocks`]), which the fitted pixels under `light` and their places in the
/// photo choose, so that a moved light or outline keeps them.
fn pool(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    seen: &Vector3<f64>,
    moved: impl Fn(usize, usize) -> Option<(Vector3<f64>, Vector3<f64>)>,
    per_sphere: Option<usize>,
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
        // The observations fitted under the unmoved light, by index.
        let kept: Vec<usize> = (0..s.obs.len())
            .filter(|&k| {
                let g = &s.obs[k].geometry;
                fitted(&g.normal, &g.view, light)
            })
            .collect();
        let side = per_sphere.map_or(1, |m| side_for(kept.len(), m));
        let geometry = |k: usize| {
            let g = &s.obs[k].geometry;
            moved(i, k).unwrap_or((g.normal, g.view))
        };
        if side == 1 {
            for k in kept {
                let (o, w) = (&s.obs[k], &s.curve_weight[k]);
                let (n, v) = geometry(k);
                for (c, pixels) in radii[at].pixels.iter_mut().enumerate() {
                    if o.weight[c] > 0.0 {
                        pixels.push(Px::at(&n, &v, seen, o.radiance[c], w[c]));
                    }
                }
            }
        } else {
            let pooled = blocks(s, &kept, side, geometry, seen);
            for (pixels, pooled) in radii[at].pixels.iter_mut().zip(pooled) {
                pixels.extend(pooled);
            }
        }
    }
    radii.retain(|r| r.pixels.iter().all(|p| !p.is_empty()));
    radii.sort_by(|a, b| a.radius_mm.total_cmp(&b.radius_mm));
    radii
}

/// One block of pixels in one channel, accumulated: its members, their radiance and noise
/// variance summed, and their normals and views summed.
#[derive(Clone, Copy)]
struct Block {
    members: f64,
    radiance: f64,
    variance: f64,
    normal: Vector3<f64>,
    view: Vector3<f64>,
}

impl Block {
    const EMPTY: Block = Block {
        members: 0.0,
        radiance: 0.0,
        variance: 0.0,
        normal: Vector3::new(0.0, 0.0, 0.0),
        view: Vector3::new(0.0, 0.0, 0.0),
    };
}

/// Sphere `s`'s `fitted` observations in blocks of `side`×`side` pixels of its photo, per
/// channel (each channel's members those it weighs), in the order their first members come:
/// each block the mean of its members' radiance, the noise of that mean, and the normal and
/// view of the mean of theirs (`geometry`), its cosines under `seen`. The noise of the mean is
/// its members' σ as independent (n/√Σσᵢ²) times the sphere's [`block_noise_factor`] for the
/// channel: neighbouring pixels' noise is correlated (a render's filter, a camera's
/// demosaicing), which differences of adjacent pixels, the noise curve's measure, do not see.
fn blocks(
    s: &SphereData,
    fitted: &[usize],
    side: u32,
    geometry: impl Fn(usize) -> (Vector3<f64>, Vector3<f64>),
    seen: &Vector3<f64>,
) -> [Vec<Px>; 3] {
    // Each block's place in `acc` by its key, and the keys in that order.
    let mut index: std::collections::HashMap<[u32; 2], usize> = Default::default();
    let (mut acc, mut keys): (Vec<[Block; 3]>, Vec<[u32; 2]>) = (vec![], vec![]);
    for &k in fitted {
        let [x, y] = s.px[k];
        let key = [x / side, y / side];
        let b = *index.entry(key).or_insert_with(|| {
            acc.push([Block::EMPTY; 3]);
            keys.push(key);
            acc.len() - 1
        });
        let (o, w) = (&s.obs[k], &s.curve_weight[k]);
        let (n, v) = geometry(k);
        for (c, block) in acc[b].iter_mut().enumerate() {
            if o.weight[c] > 0.0 && w[c] > 0.0 {
                block.members += 1.0;
                block.radiance += o.radiance[c];
                block.variance += (1.0 / w[c]).powi(2);
                block.normal += n;
                block.view += v;
            }
        }
    }
    std::array::from_fn(|c| {
        let factor = block_noise_factor((&index, &keys), &acc, c);
        acc.iter()
            .map(|b| b[c])
            .filter(|b| b.members > 0.0)
            .map(|b| Px {
                members: b.members,
                ..Px::at(
                    &b.normal.normalize(),
                    &b.view.normalize(),
                    seen,
                    b.radiance / b.members,
                    b.members / (factor * b.variance.sqrt()),
                )
            })
            .collect()
    })
}

/// How much noisier channel `c`'s block means are than their members' σ as independent says
/// (at least 1; the blocks `acc` with their keys, and each key's place): from each block's difference to the mean of its left and right neighbours
/// (which a smooth shading's gradient does not reach, and its curvature hardly), whose variance
/// is σⱼ² + (σₗ² + σᵣ²)/4 for independent blocks, the RMS of those differences over it. A
/// difference beyond [`IMPULSE_SIGMA`] of it is left out; fewer than [`FACTOR_BLOCKS`] blocks
/// with both neighbours: 1.
fn block_noise_factor(
    (index, keys): (&std::collections::HashMap<[u32; 2], usize>, &[[u32; 2]]),
    acc: &[[Block; 3]],
    c: usize,
) -> f64 {
    let at = |key: [u32; 2]| {
        index
            .get(&key)
            .map(|&i| acc[i][c])
            .filter(|b| b.members > 0.0)
    };
    let mean_and_var = |b: Block| (b.radiance / b.members, b.variance / (b.members * b.members));
    // In the blocks' order, so that the sum is the same on every run.
    let ratios: Vec<f64> = keys
        .iter()
        .filter_map(|&[x, y]| {
            let (m, v) = mean_and_var(at([x, y])?);
            let (ml, vl) = mean_and_var(at([x.checked_sub(1)?, y])?);
            let (mr, vr) = mean_and_var(at([x + 1, y])?);
            let d = m - 0.5 * (ml + mr);
            Some(d * d / (v + 0.25 * (vl + vr)))
        })
        .filter(|r| *r < IMPULSE_SIGMA * IMPULSE_SIGMA)
        .collect();
    if ratios.len() < FACTOR_BLOCKS {
        return 1.0;
    }
    (ratios.iter().sum::<f64>() / ratios.len() as f64)
        .sqrt()
        .max(1.0)
}

/// The blocks with both neighbours a channel needs for [`block_noise_factor`].
const FACTOR_BLOCKS: usize = 50;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    /// 80×80 blocks of 2×2 pixels of σ 1 on a shading that grows along the rows (which the
    /// factor's differences must not see), each pixel's noise `shared` of a variance common to
    /// its block and the rest its own.
    fn factor_with(shared: f64) -> f64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut normal = || rng.sample::<f64, _>(StandardNormal);
        let (mut index, mut keys, mut acc) = (std::collections::HashMap::new(), vec![], vec![]);
        for y in 0..80u32 {
            for x in 0..80u32 {
                let common = shared.sqrt() * normal();
                let mut b = Block::EMPTY;
                for _ in 0..4 {
                    b.members += 1.0;
                    b.radiance +=
                        100.0 + 0.5 * x as f64 + common + (1.0 - shared).sqrt() * normal();
                    b.variance += 1.0;
                }
                index.insert([x, y], acc.len());
                keys.push([x, y]);
                acc.push([b; 3]);
            }
        }
        block_noise_factor((&index, &keys), &acc, 0)
    }

    /// Independent pixels: the block's mean has the noise its members' σ says (the factor 1,
    /// measured 1.000, at its floor; the shading's gradient unseen). Half the variance shared
    /// within a block: the mean's variance is 0.5 + 0.5/4 against 1/4, a factor √2.5 = 1.581
    /// (measured 1.5765).
    #[test]
    fn the_blocks_noise_factor_sees_correlated_noise() {
        let (independent, half) = (factor_with(0.0), factor_with(0.5));
        println!("independent {independent:.4}, half shared {half:.4}");
        assert!((independent - 1.0).abs() < 0.02, "{independent}");
        assert!((half - 2.5f64.sqrt()).abs() < 0.015, "{half}");
    }
}
