//! From a session and its detections to the solver's observations: decode every photo, take the
//! pixels of every detected sphere ([`crate::detect::samples`]), leave out the saturated ones and those
//! that straddle the silhouette, and weight each pixel's channel by 1/σ of its noise.
//!
//! The noise is measured, not assumed: per sphere and channel, a shot-plus-read model
//! σ²(L) = a + b·L fitted to the differences of horizontally adjacent unflagged pixels (the
//! shading changes little from one pixel to the next, so these differences are noise): the pairs
//! are binned by level, each bin's variance is (1.4826 × MAD)² / 2 (robust to the few pairs that
//! cross an edge), and a, b come from a weighted line fit over the bins. A pixel's σ is the model
//! at the mean level of its two row neighbours (its own value would favour pixels whose noise
//! happened to be negative).
//!
//! Pixels whose row neighbours lie within 3σ of full scale are left out with the clipped ones: near
//! clipping the noise is censored and what remains averages low. Impulses are left out too (dust,
//! a hot pixel, a Monte Carlo firefly): a channel more than 6σ + 20% of the level (50% in the
//! highlight) from its row neighbours' mean, before pooling averages them into cells where the
//! robust loss can no longer see them.
//!
//! The dark room's floor (stray light, the sensor's black level) is measured as the median of the
//! pixels away from the spheres ([`background`]) and subtracted from every sample; where those
//! pixels are lit, none is measured ([`SphereData::floor`] `None`) and the joint fit fits it
//! ([`crate::fit::solver::fit_with_floor`]).

use crate::camera::outline::Projection;
use crate::detect::samples::{self, Sample};
use crate::error::{Error, Result};
use crate::fit::noise::{IMPULSE_FRACTION, IMPULSE_FRACTION_HIGHLIGHT, IMPULSE_SIGMA};
use crate::fit::solver::Obs;
use crate::formats::detections::{Detections, SphereDetection};
use crate::formats::photo::{Decoded, LinearRgb};
use crate::formats::session::{ImageInfo, Session, SessionReport};
use crate::model::Geometry;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::time::Instant;

/// The usable pixels of one sphere.
#[derive(Clone, Debug)]
pub struct SphereData {
    /// Photo file (as in session.json) and the sphere's place in it.
    pub image: String,
    pub index: usize,
    pub radius_mm: f64,
    pub obs: Vec<Obs>,
    /// Per observation: its pixel.
    pub px: Vec<[u32; 2]>,
    /// Pixels on the sphere, and how many were left out as saturated or on the edge.
    pub pixels: usize,
    pub saturated: usize,
    pub edge: usize,
    /// Pixels left out as impulses: a channel more than [`IMPULSE_SIGMA`] noise σ plus
    /// [`IMPULSE_FRACTION`] of the level ([`IMPULSE_FRACTION_HIGHLIGHT`] in the highlight) from
    /// the mean of its two row neighbours (dust, a hot pixel, a firefly).
    pub impulses: usize,
    /// Noise σ per channel at the sphere's median level (radiance units).
    pub noise: [f64; 3],
    /// The noise model per channel: σ² = a + b·L.
    pub noise_model: [[f64; 2]; 3],
    /// The noise curve per channel, σ² = a + b·L + c·L² ([`crate::fit::noise`]).
    pub noise_curve: [crate::fit::noise::NoiseCurve; 3],
    /// Per observation: 1/σ of its noise by `noise_curve` at its row neighbours' level.
    pub curve_weight: Vec<[f64; 3]>,
    /// The photo's dark floor subtracted from the radiance (`None`: not measurable).
    pub floor: Option<[f64; 3]>,
    /// The photo around the sphere, for figures.
    pub crop: Crop,
}

impl SphereData {
    /// This sphere's data less a dark floor (radiance units), which becomes its `floor`.
    pub fn less_floor(&self, floor: [f64; 3]) -> SphereData {
        SphereData {
            obs: crate::fit::solver::less_floor(&self.obs, floor),
            floor: Some(floor),
            ..self.clone()
        }
    }
}

/// The different radii among the spheres (mm), smallest first.
pub fn distinct_radii(spheres: &[&SphereData]) -> Vec<f64> {
    let mut radii: Vec<f64> = spheres.iter().map(|s| s.radius_mm).collect();
    radii.sort_by(f64::total_cmp);
    radii.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    radii
}

/// Each sphere's position in `radii` (from [`distinct_radii`], in any order).
pub fn radius_index(spheres: &[&SphereData], radii: &[f64]) -> Vec<usize> {
    spheres
        .iter()
        .map(|s| {
            radii
                .iter()
                .position(|&r| (s.radius_mm - r).abs() < 1e-9)
                .expect("a sphere's radius among the distinct radii")
        })
        .collect()
}

/// A display copy of the photo around a sphere: sRGB 8-bit means of `step` × `step` pixel blocks,
/// the first block's corner at pixel (x0, y0). At most [`Crop::MAX_CELLS`] blocks across. A dark
/// crop (99th percentile below 0.45 of full scale) is brightened by `gain` (at most 8) so that its
/// 99th percentile shows at 0.9.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Crop {
    pub x0: u32,
    pub y0: u32,
    pub step: u32,
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub gain: f64,
}

impl Crop {
    pub(crate) const MAX_CELLS: u32 = 160;

    /// The crop of `bx` = [x0, y0, x1, y1] (inclusive pixel box), grown by 10% each side.
    pub fn of(img: &crate::formats::photo::LinearRgb, bx: [u32; 4]) -> Crop {
        let grow = ((bx[2] - bx[0]).max(bx[3] - bx[1]) / 10).max(2);
        let x0 = bx[0].saturating_sub(grow);
        let y0 = bx[1].saturating_sub(grow);
        let x1 = (bx[2] + grow).min(img.width.saturating_sub(1));
        let y1 = (bx[3] + grow).min(img.height.saturating_sub(1));
        if x1 < x0 || y1 < y0 {
            return Crop::default();
        }
        let step = (x1 - x0 + 1)
            .max(y1 - y0 + 1)
            .div_ceil(Crop::MAX_CELLS)
            .max(1);
        let width = (x1 - x0 + 1).div_ceil(step);
        let height = (y1 - y0 + 1).div_ceil(step);
        let mut lin = Vec::with_capacity((3 * width * height) as usize);
        for j in 0..height {
            for i in 0..width {
                let mut sum = [0.0f64; 3];
                let mut n = 0.0;
                for y in (y0 + j * step)..(y0 + (j + 1) * step).min(y1 + 1) {
                    for x in (x0 + i * step)..(x0 + (i + 1) * step).min(x1 + 1) {
                        let k = 3 * (y as usize * img.width as usize + x as usize);
                        for (s, v) in sum.iter_mut().zip(&img.data[k..k + 3]) {
                            *s += *v as f64;
                        }
                        n += 1.0;
                    }
                }
                lin.extend(sum.map(|s| s / n));
            }
        }
        let mut sorted = lin.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let p99 = sorted
            .get((sorted.len() as f64 * 0.99) as usize)
            .copied()
            .unwrap_or(1.0);
        let gain = if p99 > 0.0 && p99 < 0.45 {
            (0.9 / p99).min(8.0)
        } else {
            1.0
        };
        let rgb = lin
            .iter()
            .map(|v| (255.0 * crate::formats::photo::srgb_encode(gain * v)).round() as u8)
            .collect();
        Crop {
            x0,
            y0,
            step,
            width,
            height,
            rgb,
            gain,
        }
    }

    /// The block holding a pixel.
    pub fn cell(&self, px: [u32; 2]) -> Option<(u32, u32)> {
        if self.step == 0 || px[0] < self.x0 || px[1] < self.y0 {
            return None;
        }
        let (i, j) = ((px[0] - self.x0) / self.step, (px[1] - self.y0) / self.step);
        (i < self.width && j < self.height).then_some((i, j))
    }
}

/// Observations of a session, with the time spent decoding and sampling.
#[derive(Clone, Debug)]
pub struct Observed {
    pub spheres: Vec<SphereData>,
    pub decode_s: f64,
    pub samples_s: f64,
    /// The floor subtracted from each photo (radiance units, per channel; `None`: not measurable,
    /// nothing subtracted).
    pub floors: Vec<Option<[f64; 3]>>,
    /// session.json's grey card, its pixels read while the photos are decoded.
    pub reference: Option<ReferencePixels>,
}

/// session.json's diffuse reference and its box's pixels (linear, as decoded; the part of the
/// box inside the photo).
#[derive(Clone, Debug, PartialEq)]
pub struct ReferencePixels {
    pub reference: crate::formats::session::SessionReference,
    /// The photo it is in (its place in the session).
    pub image: usize,
    /// Per channel, the sum of the box's pixel values, and how many.
    pub sum: [f64; 3],
    pub pixels: usize,
    /// The first clipped pixel, if any.
    pub clipped: Option<[u32; 2]>,
}

/// The reference's box read from its photo (none without a reference).
fn reference_pixels(
    report: &SessionReport,
    sess: &Session,
    images: &[LinearRgb],
) -> Option<ReferencePixels> {
    let r = sess.reference.as_ref()?;
    let k = report
        .images
        .iter()
        .position(|i| crate::formats::session::same_file(&i.file, &r.image))?;
    let img = &images[k];
    let [x0, y0, x1, y1] = r.box_px;
    let (mut sum, mut pixels, mut clipped) = ([0.0; 3], 0, None);
    for y in y0..y1.min(img.height) {
        for x in x0..x1.min(img.width) {
            let i = y as usize * img.width as usize + x as usize;
            if img.saturated[i] && clipped.is_none() {
                clipped = Some([x, y]);
            }
            (0..3).for_each(|c| sum[c] += f64::from(img.data[3 * i + c]));
            pixels += 1;
        }
    }
    Some(ReferencePixels {
        reference: r.clone(),
        image: k,
        sum,
        pixels,
        clipped,
    })
}

/// One light per photo (`"light": "per-image"`): the rotation of each photo that takes its light
/// onto `reference`. The model sees a sphere only through n·l, n·v and l·v, so photos turned this
/// way share one light and the joint fit needs no other change: the material is shared, and the
/// fitted light is the reference's, each photo's being the rotation's inverse applied to it.
pub(crate) fn light_frames(
    lights: &[Vector3<f64>],
    reference: &Vector3<f64>,
) -> Vec<nalgebra::Rotation3<f64>> {
    lights
        .iter()
        .map(|l| {
            nalgebra::Rotation3::rotation_between(l, reference)
                .unwrap_or_else(nalgebra::Rotation3::identity)
        })
        .collect()
}

/// The dark-room floor per channel: the median of the pixels outside every sphere (their pixel
/// boxes grown by a quarter), sampled on a grid of at most ~200 000 points; `None` when fewer
/// than 1000 such pixels remain (spheres filling the frame) or when they are lit (a median above
/// [`DARK_FLOOR_MAX`] of full scale: a backdrop or table, whose light is not in the spheres'
/// pixels).
pub fn background(img: &crate::formats::photo::LinearRgb, boxes: &[[u32; 4]]) -> Option<[f64; 3]> {
    let (w, h) = (img.width as usize, img.height as usize);
    let step = ((w * h / 200_000) as f64).sqrt().max(1.0) as usize;
    let grown: Vec<[f64; 4]> = boxes
        .iter()
        .map(|b| {
            let (bw, bh) = ((b[2] - b[0]) as f64, (b[3] - b[1]) as f64);
            [
                b[0] as f64 - 0.25 * bw,
                b[1] as f64 - 0.25 * bh,
                b[2] as f64 + 0.25 * bw,
                b[3] as f64 + 0.25 * bh,
            ]
        })
        .collect();
    let mut ch: [Vec<f32>; 3] = Default::default();
    for y in (0..h).step_by(step) {
        for x in (0..w).step_by(step) {
            let (xf, yf) = (x as f64, y as f64);
            if grown
                .iter()
                .any(|b| xf >= b[0] && xf <= b[2] && yf >= b[1] && yf <= b[3])
            {
                continue;
            }
            let i = 3 * (y * w + x);
            for (c, v) in ch.iter_mut().enumerate() {
                v.push(img.data[i + c]);
            }
        }
    }
    if ch[0].len() < 1000 {
        return None;
    }
    let med = ch.map(|mut v| {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2] as f64
    });
    med.iter().all(|&m| m <= DARK_FLOOR_MAX).then_some(med)
}

/// The highest level (pixel value, full scale 1) taken for a dark room's floor (stray light and
/// black level) rather than a lit backdrop.
pub(crate) const DARK_FLOOR_MAX: f64 = 0.01;

/// The noise model σ² = a + b·L per channel from adjacent-pixel differences (see the module
/// docs); `floor` is the smallest σ allowed (a quantisation step). Without enough pairs: a
/// constant.
pub(crate) fn noise_model(s: &[Sample], floor: f64) -> [[f64; 2]; 3] {
    let skip = samples::SATURATED | samples::EDGE | samples::HIGHLIGHT;
    let mut pairs: [Vec<(f64, f64)>; 3] = Default::default();
    for w in s.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if b.px[1] == a.px[1] && b.px[0] == a.px[0] + 1 && (a.flags | b.flags) & skip == 0 {
            for (c, p) in pairs.iter_mut().enumerate() {
                p.push((
                    0.5 * (a.radiance[c] + b.radiance[c]),
                    (a.radiance[c] - b.radiance[c]).abs(),
                ));
            }
        }
    }
    let f2 = floor * floor;
    // A difference of two pixels has √2 times a pixel's noise.
    let robust_var = |d: Vec<f64>| {
        let sd = crate::stats::robust_sigma(d) / std::f64::consts::SQRT_2;
        (sd * sd).max(f2)
    };
    pairs.map(|mut p| {
        const BINS: usize = 12;
        if p.is_empty() {
            return [f2, 0.0];
        }
        if p.len() < 20 * BINS {
            return [robust_var(p.iter().map(|x| x.1).collect()), 0.0];
        }
        p.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Per bin: mean level, variance, and the variance's weight (count / var²).
        let mut pts = vec![];
        for chunk in p.chunks(p.len().div_ceil(BINS)) {
            let level = chunk.iter().map(|x| x.0).sum::<f64>() / chunk.len() as f64;
            let var = robust_var(chunk.iter().map(|x| x.1).collect());
            pts.push((level, var, chunk.len() as f64 / (var * var)));
        }
        // Weighted least squares of var = a + b·level.
        let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(x, y, w) in &pts {
            sw += w;
            sx += w * x;
            sy += w * y;
            sxx += w * x * x;
            sxy += w * x * y;
        }
        let det = sw * sxx - sx * sx;
        let (a, b) = if det > 0.0 {
            ((sy * sxx - sx * sxy) / det, (sw * sxy - sx * sy) / det)
        } else {
            (sy / sw, 0.0)
        };
        if b < 0.0 || !b.is_finite() {
            // No shot noise visible: a constant.
            [(sy / sw).max(f2), 0.0]
        } else {
            [a.max(f2), b]
        }
    })
}

/// The noise curve per channel ([`crate::fit::noise::measure`]) from each unflagged pixel
/// against its two row neighbours' mean: x₁ − (x₀ + x₂)/2 has 1.5 times a pixel's variance and
/// none of the shading's slope; scaled by √(4/3) it reads as the difference of two pixels that
/// `measure` takes. `floor` is the smallest σ allowed.
pub(crate) fn noise_curve(s: &[Sample], floor: f64) -> [crate::fit::noise::NoiseCurve; 3] {
    let skip = samples::SATURATED | samples::EDGE | samples::HIGHLIGHT;
    let mut pairs: [Vec<(f64, f64)>; 3] = Default::default();
    let scale = (4.0f64 / 3.0).sqrt();
    for w in s.windows(3) {
        let (a, b, d) = (&w[0], &w[1], &w[2]);
        let in_row = b.px[1] == a.px[1] && d.px[1] == a.px[1];
        let adjacent = b.px[0] == a.px[0] + 1 && d.px[0] == a.px[0] + 2;
        if in_row && adjacent && (a.flags | b.flags | d.flags) & skip == 0 {
            for (c, p) in pairs.iter_mut().enumerate() {
                let (x0, x1, x2) = (a.radiance[c], b.radiance[c], d.radiance[c]);
                p.push(((x0 + x1 + x2) / 3.0, scale * (x1 - 0.5 * (x0 + x2)).abs()));
            }
        }
    }
    pairs.map(|p| crate::fit::noise::measure(p, floor))
}

/// Collect the observations of every sphere of `det` from the session's photos (`decoded`, or
/// decoded here when `None`), with θ and the highlight flag from each photo's light in `lights`
/// (one per photo, or one for all; and the highlight radius `highlight_radius`). With `frame`,
/// each photo's normals and view vectors are turned by its rotation (see [`light_frames`]).
#[allow(clippy::too_many_arguments)]
pub fn observe(
    report: &SessionReport,
    sess: &Session,
    det: &Detections,
    proj: &Projection,
    lights: &[Option<Vector3<f64>>],
    highlight_radius: Option<f64>,
    frame: Option<&[nalgebra::Rotation3<f64>]>,
    decoded: Option<&Decoded>,
) -> Result<Observed> {
    let here;
    let decoded = match decoded {
        Some(d) => d,
        None => {
            here = report.decode(sess)?;
            &here
        }
    };
    let (images, decode_s) = (&decoded.images, decoded.seconds);
    let t1 = Instant::now();
    let floors = dark_floors(report, sess, det, proj, images);
    let jobs = sphere_jobs(report, det)?;
    let spheres: Vec<SphereData> = jobs
        .par_iter()
        .map(|&(i, j, s)| {
            let photo = PhotoSamples {
                img: &images[i],
                info: &report.images[i],
                light: lights.get(i).or(lights.first()).and_then(|l| l.as_ref()),
                highlight_radius,
                turn: frame.map(|f| f[i]),
                floor: floors[i],
            };
            photo.sphere(proj, j, s)
        })
        .collect();
    Ok(Observed {
        spheres,
        decode_s,
        samples_s: t1.elapsed().as_secs_f64(),
        floors,
        reference: reference_pixels(report, sess, images),
    })
}

/// Each photo's dark floor (radiance units): session.json's, else measured on the photo around
/// the spheres' boxes; `None` where neither is there.
fn dark_floors(
    report: &SessionReport,
    sess: &Session,
    det: &Detections,
    proj: &Projection,
    images: &[LinearRgb],
) -> Vec<Option<[f64; 3]>> {
    images
        .par_iter()
        .zip(&det.images)
        .zip(&report.images)
        .map(|((img, d), info)| {
            let boxes: Vec<[u32; 4]> = d
                .spheres
                .iter()
                .filter_map(|s| {
                    s.outline
                        .outline()
                        .pixel_box(proj, 2.0, img.width, img.height)
                })
                .collect();
            sess.floor
                .map(|f| [f; 3])
                .or_else(|| background(img, &boxes))
                .map(|b| b.map(|v| v / info.exposure.unwrap_or(1.0)))
        })
        .collect()
}

/// Every (photo, sphere, detection), once the detections are checked to list the session's
/// spheres.
fn sphere_jobs<'a>(
    report: &SessionReport,
    det: &'a Detections,
) -> Result<Vec<(usize, usize, &'a SphereDetection)>> {
    let mut jobs = vec![];
    for (i, (info, d)) in report.images.iter().zip(&det.images).enumerate() {
        if d.spheres.len() != info.radii_mm.len() {
            return Err(Error::invalid(
                &report.session_file,
                format!(
                    "{}: detections list {} spheres, session.json {}",
                    info.file,
                    d.spheres.len(),
                    info.radii_mm.len()
                ),
            ));
        }
        for (j, s) in d.spheres.iter().enumerate() {
            jobs.push((i, j, s));
        }
    }
    Ok(jobs)
}

/// One photo as its spheres' observations need it.
struct PhotoSamples<'a> {
    img: &'a LinearRgb,
    info: &'a ImageInfo,
    /// The light the samples are flagged against (the highlight's pixels).
    light: Option<&'a Vector3<f64>>,
    highlight_radius: Option<f64>,
    /// The photo's rotation onto the common light frame (one light per photo).
    turn: Option<nalgebra::Rotation3<f64>>,
    floor: Option<[f64; 3]>,
}

impl PhotoSamples<'_> {
    /// Sphere `j` of the photo (detection `s`): its samples less the dark floor, its noise model,
    /// and the observations kept ([`PhotoSamples::keep`]).
    fn sphere(&self, proj: &Projection, j: usize, s: &SphereDetection) -> SphereData {
        let (img, info) = (self.img, self.info);
        let exposure = info.exposure.unwrap_or(1.0);
        let mut smp = samples::sphere_samples(
            img,
            exposure,
            proj,
            &s.outline.outline(),
            s.radius_mm,
            self.light,
            self.highlight_radius,
        );
        // Less the floor, then over the photo's light intensity (session.json), per channel.
        let floor_rgb = self.floor.unwrap_or([0.0; 3]);
        let intensity = info.light_intensity.unwrap_or([1.0; 3]);
        for x in smp.iter_mut() {
            for c in 0..3 {
                x.radiance[c] = (x.radiance[c] - floor_rgb[c]) / intensity[c];
            }
        }
        // The smallest σ: half a level step (a noise-free render).
        let brightest = intensity.iter().cloned().fold(0.0, f64::max);
        let floor = 0.5 / ((1u32 << img.bits.min(16)) as f64) / exposure / brightest;
        let model = noise_model(&smp, floor);
        let curve = noise_curve(&smp, floor);
        let sigma = |c: usize, level: f64| (model[c][0] + model[c][1] * level.max(0.0)).sqrt();
        // Full scale (pixel value 1) in the samples' units.
        let full_scale = [0, 1, 2].map(|c| (1.0 / exposure - floor_rgb[c]) / intensity[c]);
        let noise = {
            let mut lv: Vec<f64> = smp.iter().map(|x| x.radiance[1]).collect();
            lv.sort_by(|a, b| a.total_cmp(b));
            let med = lv.get(lv.len() / 2).copied().unwrap_or(0.0);
            [0, 1, 2].map(|c| sigma(c, med))
        };
        let mut out = SphereData {
            image: info.file.clone(),
            index: j,
            radius_mm: s.radius_mm,
            obs: vec![],
            px: vec![],
            pixels: smp.len(),
            saturated: 0,
            edge: 0,
            impulses: 0,
            noise,
            noise_model: model,
            noise_curve: curve,
            curve_weight: vec![],
            floor: self.floor,
            crop: s
                .outline
                .outline()
                .pixel_box(proj, 2.0, img.width, img.height)
                .map(|b| Crop::of(img, b))
                .unwrap_or_default(),
        };
        self.keep(&mut out, &smp, &sigma, full_scale);
        out
    }

    /// The samples kept as observations, each weighted by the noise at its row neighbours'
    /// level; the others counted as saturated, on the edge or impulses.
    fn keep(
        &self,
        out: &mut SphereData,
        smp: &[Sample],
        sigma: &dyn Fn(usize, f64) -> f64,
        full_scale: [f64; 3],
    ) {
        let turn = &self.turn;
        for (k, x) in smp.iter().enumerate() {
            if x.flags & samples::SATURATED != 0 {
                out.saturated += 1;
                continue;
            }
            if x.flags & samples::EDGE != 0 {
                out.edge += 1;
                continue;
            }
            // The level of the pixel's row neighbours (not its own value: a weight that
            // depends on the pixel's own noise biases the fit toward its low values).
            let mut level = [0.0; 3];
            let mut n = 0.0;
            for nb in [k.wrapping_sub(1), k + 1] {
                if let Some(y) = smp.get(nb) {
                    if y.px[1] == x.px[1] && y.px[0].abs_diff(x.px[0]) == 1 {
                        for (l, v) in level.iter_mut().zip(&y.radiance) {
                            *l += v;
                        }
                        n += 1.0;
                    }
                }
            }
            let level = [0, 1, 2].map(|c| if n > 0.0 { level[c] / n } else { x.radiance[c] });
            // An impulse: the shading is smooth from one pixel to the next (the highlight
            // less so), so a pixel far from its two neighbours' mean (whose difference has
            // variance 1.5σ²) is not the sphere. A pooled cell would average it in, where
            // the robust loss no longer sees it.
            let fraction = if x.flags & samples::HIGHLIGHT == 0 {
                IMPULSE_FRACTION
            } else {
                IMPULSE_FRACTION_HIGHLIGHT
            };
            if n == 2.0
                && (0..3).any(|c| {
                    (x.radiance[c] - level[c]).abs()
                        > IMPULSE_SIGMA * 1.5f64.sqrt() * sigma(c, level[c])
                            + fraction * level[c].abs()
                })
            {
                out.impulses += 1;
                continue;
            }
            // Near full scale the noise is censored (values pushed over it were clipped and
            // left out), so the rest average low: leave out pixels whose neighbours' level
            // is within 3σ of clipping.
            if (0..3).any(|c| level[c] + 3.0 * sigma(c, level[c]) >= full_scale[c]) {
                out.saturated += 1;
                continue;
            }
            let (normal, view) = match &turn {
                Some(r) => (r * x.normal, r * x.view),
                None => (x.normal, x.view),
            };
            out.obs.push(Obs {
                geometry: Geometry {
                    normal,
                    view,
                    radius_mm: out.radius_mm,
                },
                radiance: x.radiance,
                weight: [0, 1, 2].map(|c| 1.0 / sigma(c, level[c])),
            });
            out.curve_weight
                .push([0, 1, 2].map(|c| 1.0 / out.noise_curve[c].sigma(level[c])));
            out.px.push(x.px);
        }
    }
}
