//! `workbench detect <session>/`: find every sphere of every photo, its highlight, and the light
//! direction; write `detections.json` (schema `workbench.detections/2`) and an overlay per photo.
//!
//! Per photo: the background level and noise (median, MAD) → a mask of what is clearly brighter →
//! connected blobs, of which the ones carrying at least 5% of the largest one's light are the
//! spheres, left to right in the order `session.json` lists them → per sphere, edge points,
//! RANSAC outline and edge-model refinement ([`crate::detect::silhouette`]) → the highlight and its light
//! ([`crate::detect::highlight`]). Lights are combined per photo and, unless the session says
//! `"light": "per-image"`, over the whole session ([`crate::detect::highlight::combine_highlights`]).
//! Photos are processed in parallel (rayon); detection uses no OpenCV.

pub mod found;
pub mod highlight;
pub mod overlay;
pub mod samples;
pub mod silhouette;

use crate::camera::outline::{Outline, Projection};
use crate::camera::sphere::EllipseJson;
use crate::error::{Error, Result};
use crate::formats::photo::{Decoded, LinearRgb};
use crate::formats::session::{self, LightMode, Session, SessionReport};
use crate::model::LightAngles;
use found::locate_highlights;
pub use found::{Found, MediumOutline, Silhouette};
use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;

use silhouette::{blobs, EdgeModel, Plane};
use std::path::{Path, PathBuf};

/// The band of pixels the edge model fits: this far inside and outside the silhouette (px).
pub(crate) const BAND_INNER_PX: f64 = 4.0;
pub(crate) const BAND_OUTER_PX: f64 = 3.0;

/// Floor on a single light estimate's uncertainty when combining (radians): the modelling error
/// the per-fit statistics do not see.
pub(crate) const LIGHT_FLOOR: f64 = 0.02 * std::f64::consts::PI / 180.0;

use crate::formats::detections::*;

/// The backdrop of a photo: a level per band of 16 rows plus a quadratic across the image,
/// fitted to the medians of 16×16 pixel cells, the cells that stand out of it (spheres, their
/// shadows) left out in turn; the noise is 1.4826·MAD of the pixels about it (sampled). On a black
/// void it is the floor's constant; on a grey card it follows the gradient, on a table before a
/// wall the step between them (a horizontal edge: a band's level), so that a sphere is what differs
/// from its surroundings, not what is brighter than the photo's median.
pub struct Backdrop {
    rows: Vec<f64>,
    across: [f64; 2],
    width: f64,
    pub noise: f64,
}

const BACKDROP_CELL: u32 = 16;

impl Backdrop {
    pub fn at(&self, x: f64, y: f64) -> f64 {
        let band = ((y.max(0.0) as u32 / BACKDROP_CELL) as usize).min(self.rows.len() - 1);
        let u = x / self.width - 0.5;
        self.rows[band] + self.across[0] * u + self.across[1] * (u * u - 1.0 / 12.0)
    }

    pub fn of(lum: &Plane) -> Backdrop {
        const CELL: u32 = BACKDROP_CELL;
        let (w, h) = (lum.width, lum.height);
        let (nx, ny) = (w.div_ceil(CELL) as usize, h.div_ceil(CELL) as usize);
        let mut cells = vec![];
        for cy in 0..ny as u32 {
            for cx in 0..nx as u32 {
                let mut v: Vec<f32> = (cy * CELL..((cy + 1) * CELL).min(h))
                    .flat_map(|y| (cx * CELL..((cx + 1) * CELL).min(w)).map(move |x| (x, y)))
                    .map(|(x, y)| lum.at(x, y))
                    .collect();
                let k = v.len() / 2;
                let m = *v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1 as f64;
                let x = ((cx * CELL) as f64 + 0.5 * CELL as f64).min(w as f64 - 1.0);
                cells.push((x, cy as usize, m));
            }
        }
        let median = |v: Vec<f64>| crate::stats::percentile(v, 0.5);
        let all = median(cells.iter().map(|c| c.2).collect());
        let mut b = Backdrop {
            rows: vec![all; ny],
            across: [0.0, 0.0],
            width: w as f64,
            noise: 0.0,
        };
        let mut keep = vec![true; cells.len()];
        let basis = |x: f64, width: f64| {
            let u = x / width - 0.5;
            [u, u * u - 1.0 / 12.0]
        };
        for _round in 0..8 {
            // The level of each band from its kept cells, or from all of them where a sphere
            // covers most of the band.
            for band in 0..ny {
                let of = |only_kept: bool| -> Vec<f64> {
                    cells
                        .iter()
                        .zip(&keep)
                        .filter(|((_, cb, _), &k)| *cb == band && (k || !only_kept))
                        .map(|(&(x, _, m), _)| {
                            let q = basis(x, b.width);
                            m - b.across[0] * q[0] - b.across[1] * q[1]
                        })
                        .collect()
                };
                let kept = of(true);
                b.rows[band] = median(if 4 * kept.len() >= nx {
                    kept
                } else {
                    of(false)
                });
            }
            // The gradient across, from what the bands leave.
            let mut ata = nalgebra::Matrix2::<f64>::zeros();
            let mut atb = nalgebra::Vector2::<f64>::zeros();
            for (&(x, band, m), _) in cells.iter().zip(&keep).filter(|(_, &k)| k) {
                let q = nalgebra::Vector2::from(basis(x, b.width));
                ata += q * q.transpose();
                atb += q * (m - b.rows[band]);
            }
            if let Some(inv) = ata.try_inverse() {
                b.across = (inv * atb).into();
            }
            let res: Vec<f64> = cells
                .iter()
                .map(|&(x, band, m)| m - b.at(x, (band as u32 * CELL) as f64))
                .collect();
            let mad = crate::stats::robust_sigma(
                res.iter()
                    .zip(&keep)
                    .filter(|(_, &k)| k)
                    .map(|(r, _)| r.abs())
                    .collect(),
            );
            // Cells more than 3 MADs (and 1% of full scale) off the surface are not backdrop.
            let lim = (3.0 * mad).max(0.01);
            keep = res.iter().map(|r| r.abs() <= lim).collect();
        }
        // Pixel noise about the surface, from pixels of the cells kept.
        let step = (lum.data.len() / 200_000).max(1);
        let mut dev: Vec<f64> = (0..lum.data.len())
            .step_by(step)
            .filter_map(|i| {
                let (x, y) = (i as u32 % w, i as u32 / w);
                let cell = (y / CELL) as usize * nx + (x / CELL) as usize;
                keep[cell].then(|| (lum.data[i] as f64 - b.at(x as f64, y as f64)).abs())
            })
            .collect();
        if dev.is_empty() {
            dev.push(0.0);
        }
        b.noise = crate::stats::robust_sigma(dev);
        b
    }
}

/// Luminance plane of a linear photo.
pub fn luminance(img: &LinearRgb) -> Plane {
    Plane {
        width: img.width,
        height: img.height,
        data: img
            .data
            .chunks_exact(3)
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .collect(),
    }
}

/// The photo's pixels that stand out of the backdrop: each pixel's excess over the backdrop
/// under it, the mask of those above the threshold (8 noise σ, or 3% of the 99.9th percentile
/// of the excess), and the threshold.
fn excess_mask(lum: &Plane, backdrop: &Backdrop) -> (Vec<f32>, Vec<bool>, f64) {
    let w = lum.width as usize;
    let excess: Vec<f32> = lum
        .data
        .iter()
        .enumerate()
        .map(|(i, &v)| (v as f64 - backdrop.at((i % w) as f64, (i / w) as f64)).max(0.0) as f32)
        .collect();
    let mut top: Vec<f32> = excess
        .iter()
        .step_by((lum.data.len() / 200_000).max(1))
        .cloned()
        .collect();
    top.sort_by(|a, b| a.total_cmp(b));
    let p999 = top[((top.len() as f64 * 0.999) as usize).min(top.len() - 1)] as f64;
    let thr = (8.0 * backdrop.noise).max(0.03 * p999);
    let mask: Vec<bool> = excess.iter().map(|&v| v as f64 > thr).collect();
    (excess, mask, thr)
}

/// Where the user said to look: a disc of the hinted size per sphere, searched in its own box.
fn hinted_blobs(
    img: &LinearRgb,
    hints: &[([f64; 2], f64)],
    path: &Path,
) -> Result<Vec<crate::detect::silhouette::Blob>> {
    let mut v = vec![];
    for &(c, r) in hints {
        if !(c[0] >= 0.0 && c[1] >= 0.0 && c[0] < img.width as f64 && c[1] < img.height as f64) {
            return Err(Error::invalid(
                path,
                format!(
                    "center_px ({:.0}, {:.0}) lies outside the {}×{} photo",
                    c[0], c[1], img.width, img.height
                ),
            ));
        }
        let clamp = |v: f64, hi: u32| v.clamp(0.0, (hi - 1) as f64) as u32;
        v.push(crate::detect::silhouette::Blob {
            area: (std::f64::consts::PI * r * r) as usize,
            centroid: Vector2::new(c[0], c[1]),
            bbox: [
                clamp(c[0] - r, img.width),
                clamp(c[1] - r, img.height),
                clamp(c[0] + r, img.width),
                clamp(c[1] + r, img.height),
            ],
            extent: r,
            mass: std::f64::consts::PI * r * r,
        });
    }
    Ok(v)
}

/// A blob holding a grey card's box is left out as the card when it fills less of the circle of
/// its extent than this (a square card 0.64, a disc about 1).
const CARD_FILL: f64 = 0.85;

/// The blobs of the mask that can be spheres: a sphere stands well out of the backdrop; a patch
/// of backdrop the surface does not follow (a table's edge against the wall) only just crosses
/// the threshold; a grey card's blob (its bounding box holds the card's `box_px`) is not one.
fn sphere_blobs(
    img: &LinearRgb,
    mask: &[bool],
    excess: &[f32],
    (thr, card): (f64, Option<[u32; 4]>),
) -> Vec<crate::detect::silhouette::Blob> {
    // The card's blob holds its box and is no disc (a square fills 2/π of its extent's circle,
    // a disc all of it): a disc holding the box is a sphere with the box on it, which the
    // irradiance's reading refuses.
    let holds_card = |b: &crate::detect::silhouette::Blob| {
        b.fill() < CARD_FILL
            && card.is_some_and(|[x0, y0, x1, y1]| {
                b.bbox[0] <= x0 && b.bbox[1] <= y0 && b.bbox[2] + 1 >= x1 && b.bbox[3] + 1 >= y1
            })
    };
    let all: Vec<_> = blobs(mask, img.width, img.height, Some(excess))
        .into_iter()
        .filter(|b| !holds_card(b))
        .collect();
    let biggest = all.iter().map(|b| b.mass).fold(0.0, f64::max);
    all.into_iter()
        .filter(|b| b.mass >= 0.05 * biggest && b.area >= 30 && b.mass >= 4.0 * thr * b.area as f64)
        .collect()
}

/// More blobs than spheres: the least disc-like go (a pin or stand under a sphere, a cable) — a
/// disc fills π·extent² about its centroid, a pin a few percent of it. Only past 30%: a lit
/// crescent of a back-lit sphere fills less than a disc, and is still a sphere.
fn drop_least_disclike(found: &mut Vec<crate::detect::silhouette::Blob>, spheres: usize) {
    if found.len() > spheres {
        found.sort_by(|a, b| b.fill().total_cmp(&a.fill()));
        while found.len() > spheres && found.last().is_some_and(|b| b.fill() < 0.3) {
            found.pop();
        }
    }
}

/// Find the spheres of one photo and their silhouettes (left to right; `radii` as listed in the
/// session). `lum` is the photo's [`luminance`]; `card`, the box of a grey card in it (session.json's
/// reference), whose blob is not a sphere. The steps: the pixels above the backdrop, the blobs (or
/// the hinted discs), as many as the session lists and none cut by the frame, then each one's
/// silhouette.
pub(crate) fn find_spheres(
    img: &LinearRgb,
    lum: &Plane,
    (proj, medium): (&Projection, bool),
    (spheres, card): (&[crate::formats::session::SessionSphere], Option<[u32; 4]>),
    path: &Path,
) -> Result<Vec<Silhouette>> {
    let radii: Vec<f64> = spheres.iter().map(|s| s.radius_mm).collect();
    let hints: Option<Vec<([f64; 2], f64)>> = spheres.iter().map(|s| s.hint()).collect();
    let backdrop = Backdrop::of(lum);
    let (excess, mask, thr) = excess_mask(lum, &backdrop);
    let mut found = match &hints {
        Some(h) => hinted_blobs(img, h, path)?,
        None => sphere_blobs(img, &mask, &excess, (thr, card)),
    };
    drop_least_disclike(&mut found, radii.len());
    if found.len() != radii.len() {
        return Err(Error::invalid(
            path,
            format!(
                "found {} sphere(s), session.json lists {} for this photo",
                found.len(),
                radii.len()
            ),
        ));
    }
    if let Some(b) = found
        .iter()
        .find(|b| b.touches_border(img.width, img.height))
    {
        return Err(Error::invalid(
            path,
            format!(
                "a sphere touches the frame border near pixel ({:.0}, {:.0}): its silhouette is cut",
                b.centroid.x, b.centroid.y
            ),
        ));
    }
    // Left to right, as session.json lists them (hinted spheres are where the hints say).
    if hints.is_none() {
        found.sort_by(|a, b| a.centroid.x.total_cmp(&b.centroid.x));
    }
    let photo = Photo {
        img,
        lum,
        proj,
        mask: &mask,
        excess: &excess,
        noise: backdrop.noise,
        hinted: hints.is_some(),
        medium,
        path,
    };
    found
        .iter()
        .zip(&radii)
        .enumerate()
        .map(|(k, (b, &radius_mm))| photo.silhouette(b, radius_mm, (k, radii.len())))
        .collect()
}

/// One photo as the silhouette search sees it.
struct Photo<'a> {
    img: &'a LinearRgb,
    lum: &'a Plane,
    proj: &'a Projection,
    mask: &'a [bool],
    excess: &'a [f32],
    /// The backdrop's noise.
    noise: f64,
    /// The spheres are where session.json's hints say.
    hinted: bool,
    /// Draw each outline for the medium fit too ([`MediumOutline`]).
    medium: bool,
    path: &'a Path,
}

impl Photo<'_> {
    /// The silhouette of the sphere in blob `b`: edges around it above a threshold from the
    /// noise and the sphere's level, a RANSAC outline among them, refined on the edge model
    /// (kept when it stays within 5% of the radius). `which`: its place and the sphere count.
    fn silhouette(
        &self,
        b: &crate::detect::silhouette::Blob,
        radius_mm: f64,
        which: (usize, usize),
    ) -> Result<Silhouette> {
        let (img, lum, proj, mask, excess, noise, path) = (
            self.img,
            self.lum,
            self.proj,
            self.mask,
            self.excess,
            self.noise,
            self.path,
        );
        let pad = if self.hinted {
            (0.4 * b.extent).ceil() as u32 + 4
        } else {
            b.extent.ceil() as u32 + 4
        };
        let region = [
            b.bbox[0].saturating_sub(pad),
            b.bbox[1].saturating_sub(pad),
            (b.bbox[2] + pad).min(img.width - 1),
            (b.bbox[3] + pad).min(img.height - 1),
        ];
        let mut inside: Vec<f64> = (b.bbox[1]..=b.bbox[3])
            .flat_map(|y| (b.bbox[0]..=b.bbox[2]).map(move |x| (x, y)))
            .filter(|&(x, y)| mask[(y * img.width + x) as usize])
            .map(|(x, y)| excess[(y * img.width + x) as usize] as f64)
            .collect();
        inside.sort_by(|a, b| a.total_cmp(b));
        let Some(&level) = inside.get(inside.len() * 9 / 10) else {
            return Err(Error::invalid(
                path,
                format!(
                    "nothing brighter than the backdrop near pixel ({:.0}, {:.0}): no sphere there",
                    b.centroid.x, b.centroid.y
                ),
            ));
        };
        // The sphere's own noise (shot noise grows with the level, so the background's says
        // little about it): 1.4826 × MAD / √2 of horizontal neighbour differences inside the
        // blob. A Sobel component of white noise σ has σ·√12/8 ≈ 0.43σ: 2.5σ keeps false edges
        // inside the sphere below one in a million pixels.
        let diffs: Vec<f64> = (b.bbox[1]..=b.bbox[3])
            .flat_map(|y| (b.bbox[0]..b.bbox[2]).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                mask[(y * img.width + x) as usize] && mask[(y * img.width + x + 1) as usize]
            })
            .map(|(x, y)| (lum.at(x + 1, y) as f64 - lum.at(x, y) as f64).abs())
            .collect();
        // A difference of two pixels has √2 times a pixel's noise.
        let inner_noise = if diffs.is_empty() {
            0.0
        } else {
            crate::stats::robust_sigma(diffs) / std::f64::consts::SQRT_2
        };
        let threshold = (5.0 * noise).max(2.5 * inner_noise).max(0.03 * level);
        let mut edges = silhouette::edge_points(lum, region, threshold, proj);
        // With a hint, only edges near the hinted rim: a close neighbour's are not this sphere's.
        let range = if self.hinted {
            edges.retain(|e| {
                let d = (e.px - b.centroid).norm();
                d > 0.6 * b.extent && d < 1.4 * b.extent
            });
            (0.8 * b.extent, 1.25 * b.extent)
        } else {
            // The blob's size: its farthest pixel, unless something thin hangs on it (a pin
            // under the sphere), when its area says better.
            let size = b
                .extent
                .min(1.5 * (b.area as f64 / std::f64::consts::PI).sqrt());
            (0.3 * size, 2.5 * size)
        };
        let fail = |what: &str| {
            Error::invalid(
                path,
                format!(
                    "sphere {} of {} (r = {radius_mm} mm, near pixel ({:.0}, {:.0})): {what}",
                    which.0 + 1,
                    which.1,
                    b.centroid.x,
                    b.centroid.y
                ),
            )
        };
        let fit = silhouette::ransac(&edges, proj, range, 1.5, 800)
            .ok_or_else(|| fail("no silhouette found among the edges"))?;
        if fit.inliers.len() < 20 {
            return Err(fail("too few silhouette edge points"));
        }
        let (refined, outline, medium) = self
            .refined(&fit.outline)
            .ok_or_else(|| fail("silhouette refinement failed"))?;
        Ok(Silhouette {
            radius_mm,
            outline,
            std_px: refined.std_px,
            blur_px: refined.blur_px,
            photos: 1,
            noise: noise.max(1e-6),
            edge_points: edges.len(),
            inlier_px: fit.inliers.iter().map(|&i| edges[i].px).collect(),
            medium,
        })
    }

    /// The RANSAC outline `start` refined on the shared edge model ([`EdgeModel::Shared`]; kept
    /// where it stays within 5% of the radius, else `start`), and, where the medium was asked
    /// for, refined from the same start on the medium's ([`EdgeModel::Medium`], a
    /// [`MediumOutline`]; where that fails, the shared one). Started from the shared outline
    /// instead, the medium's (then its contrast weights alone) put jade-3's radius 0.20 px small
    /// instead of 0.15: the sector weights are the start's. None where the shared refinement
    /// fails.
    fn refined(
        &self,
        start: &Outline,
    ) -> Option<(silhouette::Refined, Outline, Option<MediumOutline>)> {
        let refine = |model| {
            silhouette::refine_repeated(
                &[(self.lum, Some(&self.img.saturated))],
                self.proj,
                start,
                (BAND_INNER_PX, BAND_OUTER_PX),
                model,
            )
        };
        // The refinement may not wander off: it starts within a pixel of the edges.
        let kept = |refined: &silhouette::Refined| {
            let shift = start.distance_px(&refined.outline, self.proj);
            if shift < (0.05 * start.radius_px(self.proj)).max(3.0) {
                refined.outline
            } else {
                *start
            }
        };
        let refined = refine(EdgeModel::Shared)?;
        let outline = kept(&refined);
        let medium = self.medium.then(|| match refine(EdgeModel::Medium) {
            Some(r) => MediumOutline {
                outline: kept(&r),
                std_px: r.std_px,
            },
            None => MediumOutline {
                outline,
                std_px: refined.std_px,
            },
        });
        Some((refined, outline, medium))
    }
}

/// Spheres that stayed put across the photos (same radii in every photo, outlines within 2 px):
/// refit each outline over all photos at once. Each photo lights a different part of the rim, so
/// the edge model's light-dependent errors average out (photometric-stereo sets). `per_image`:
/// each photo, its luminance and its silhouettes. The outlines drawn for the medium, where they
/// were, are pooled the same way from their own.
pub(crate) fn pool_static_spheres(
    per_image: &mut [(&LinearRgb, Plane, Vec<Silhouette>)],
    proj: &Projection,
) {
    if per_image.len() < 2 {
        return;
    }
    let radii = |fs: &[Silhouette]| fs.iter().map(|f| f.radius_mm).collect::<Vec<_>>();
    let first = radii(&per_image[0].2);
    if per_image.iter().any(|(_, _, fs)| radii(fs) != first) {
        return;
    }
    for j in 0..first.len() {
        let outlines: Vec<Outline> = per_image.iter().map(|(_, _, fs)| fs[j].outline).collect();
        if let Some((joint, n)) = pooled(per_image, &outlines, proj, EdgeModel::Shared) {
            for (_, _, fs) in per_image.iter_mut() {
                let f = &mut fs[j];
                f.outline = joint.outline;
                f.std_px = joint.std_px;
                f.blur_px = joint.blur_px;
                f.photos = n;
            }
        }
        let medium: Option<Vec<Outline>> = per_image
            .iter()
            .map(|(_, _, fs)| fs[j].medium.map(|m| m.outline))
            .collect();
        if let Some((joint, _)) =
            medium.and_then(|o| pooled(per_image, &o, proj, EdgeModel::Medium))
        {
            for (_, _, fs) in per_image.iter_mut() {
                fs[j].medium = Some(MediumOutline {
                    outline: joint.outline,
                    std_px: joint.std_px,
                });
            }
        }
    }
}

/// One sphere's `outlines` (one a photo) refitted over all photos at once, with how many photos
/// it took: when at least three quarters of them agree within 2 px of their medoid (the rest are
/// failed fits of the same sphere, and get the common outline too) and the refit stays within
/// 2 px of it. None otherwise.
fn pooled(
    per_image: &[(&LinearRgb, Plane, Vec<Silhouette>)],
    outlines: &[Outline],
    proj: &Projection,
    model: EdgeModel,
) -> Option<(silhouette::Refined, usize)> {
    let medoid = outlines.iter().min_by(|a, b| {
        let da: f64 = outlines.iter().map(|o| a.distance_px(o, proj)).sum();
        let db: f64 = outlines.iter().map(|o| b.distance_px(o, proj)).sum();
        da.total_cmp(&db)
    })?;
    let agree: Vec<bool> = outlines
        .iter()
        .map(|o| o.distance_px(medoid, proj) <= 2.0)
        .collect();
    if 4 * agree.iter().filter(|&&a| a).count() < 3 * outlines.len() {
        return None;
    }
    let images: Vec<(&Plane, Option<&[bool]>)> = per_image
        .iter()
        .zip(&agree)
        .filter(|(_, &a)| a)
        .map(|((img, lum, _), _)| (lum, Some(img.saturated.as_slice())))
        .collect();
    let joint =
        silhouette::refine_repeated(&images, proj, medoid, (BAND_INNER_PX, BAND_OUTER_PX), model)?;
    (joint.outline.distance_px(medoid, proj) <= 2.0).then_some((joint, images.len()))
}

fn arr3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Options of `workbench detect`.
#[derive(Clone, Debug)]
pub struct Options {
    pub session: PathBuf,
    /// Where detections.json goes (default: beside session.json).
    pub out: Option<PathBuf>,
    /// Write overlay PNGs (into `overlays/` beside detections.json).
    pub overlays: bool,
    pub quiet: bool,
    /// Draw each outline for the medium fit too (`SphereDetection::medium_outline`; `detect
    /// --model medium`, `solve --model medium`).
    pub medium_outlines: bool,
}

/// The lights the highlights give: each photo's combined, and the session's (one light for
/// all), with which estimates each combination set aside as outliers.
struct Lights {
    image: Vec<Option<highlight::Combined>>,
    /// Every (photo, sphere) with a highlight, in order: the session combination's inputs.
    all: Vec<(usize, usize)>,
    session: Option<highlight::Combined>,
    mode: LightMode,
}

fn estimate(f: &Found) -> Option<&highlight::Highlight> {
    f.highlight.as_ref().ok()
}

impl Lights {
    fn of(per_image: &[(&LinearRgb, Vec<Found>)], mode: LightMode) -> Lights {
        let image: Vec<Option<highlight::Combined>> = per_image
            .iter()
            .map(|(_, fs)| {
                let e: Vec<_> = fs.iter().filter_map(estimate).collect();
                highlight::combine_highlights(&e, LIGHT_FLOOR)
            })
            .collect();
        let all: Vec<(usize, usize)> = per_image
            .iter()
            .enumerate()
            .flat_map(|(i, (_, fs))| {
                fs.iter()
                    .enumerate()
                    .filter(|(_, f)| f.highlight.is_ok())
                    .map(move |(j, _)| (i, j))
            })
            .collect();
        let session = match mode {
            LightMode::Shared => {
                let e: Vec<_> = all
                    .iter()
                    .filter_map(|&(i, j)| estimate(&per_image[i].1[j]))
                    .collect();
                highlight::combine_highlights(&e, LIGHT_FLOOR)
            }
            LightMode::PerImage => None,
        };
        Lights {
            image,
            all,
            session,
            mode,
        }
    }

    /// Whether sphere `j` of photo `i` (`found`: that photo's) was set aside.
    fn outlier(&self, i: usize, j: usize, found: &[Found]) -> bool {
        match (&self.session, self.mode) {
            (Some(c), LightMode::Shared) => self
                .all
                .iter()
                .position(|&p| p == (i, j))
                .is_some_and(|k| c.outlier[k]),
            _ => {
                let k = found[..j].iter().filter(|f| f.highlight.is_ok()).count();
                self.image[i].as_ref().is_some_and(|c| c.outlier[k])
            }
        }
    }

    /// The light the samples of photo `i` are flagged against.
    fn for_photo(&self, i: usize) -> Option<Vector3<f64>> {
        match self.mode {
            LightMode::Shared => self.session.as_ref().map(|c| c.light),
            LightMode::PerImage => self.image[i].as_ref().map(|c| c.light),
        }
    }
}

/// Each photo's spheres found, and the outlines of spheres that stayed put refitted over all
/// photos.
fn outlines<'a>(
    report: &SessionReport,
    sess: &Session,
    (proj, medium): (&Projection, bool),
    images: &'a [LinearRgb],
    quiet: bool,
) -> Result<Vec<(&'a LinearRgb, Plane, Vec<Silhouette>)>> {
    let pb = crate::progress::bar(report.images.len() as u64, "detect", quiet);
    let per_image: Vec<Result<(&LinearRgb, Plane, Vec<Silhouette>)>> = images
        .par_iter()
        .zip(&report.images)
        .zip(&sess.images)
        .map(|((img, info), si)| {
            let lum = luminance(img);
            // A grey card in this photo (session.json's reference) is a bright blob too.
            let card = sess
                .reference
                .as_ref()
                .filter(|r| crate::formats::session::same_file(&r.image, &si.file))
                .map(|r| r.box_px);
            let f = find_spheres(img, &lum, (proj, medium), (&si.spheres, card), &info.path)?;
            pb.inc(1);
            Ok((img, lum, f))
        })
        .collect();
    pb.finish_and_clear();
    let mut per_image: Vec<(&LinearRgb, Plane, Vec<Silhouette>)> =
        per_image.into_iter().collect::<Result<_>>()?;
    pool_static_spheres(&mut per_image, proj);
    Ok(per_image)
}

/// One sphere's record: its outline, highlight and light, and its samples' counts.
fn sphere_detection(
    f: &Found,
    img: &LinearRgb,
    exposure: f64,
    proj: &Projection,
    light: Option<&Vector3<f64>>,
    outlier: bool,
) -> SphereDetection {
    let hl = f.highlight.as_ref().ok();
    let smp = samples::sphere_samples(
        img,
        exposure,
        proj,
        &f.silhouette.outline,
        f.silhouette.radius_mm,
        light,
        hl.map(|h| h.radius),
    );
    SphereDetection {
        radius_mm: f.silhouette.radius_mm,
        ellipse: f
            .silhouette
            .outline
            .ellipse(proj)
            .map(EllipseJson::from)
            .unwrap_or(EllipseJson {
                center_px: [f64::NAN; 2],
                axes_px: [f64::NAN; 2],
                angle_deg: f64::NAN,
            }),
        center_mm: f
            .silhouette
            .outline
            .center_mm(f.silhouette.radius_mm)
            .map(|c| arr3(&c)),
        outline: OutlineJson::from(&f.silhouette.outline),
        silhouette_std_px: f.silhouette.std_px,
        silhouette_blur_px: f.silhouette.blur_px,
        silhouette_photos: f.silhouette.photos,
        edge_points: f.silhouette.edge_points,
        edge_inliers: f.silhouette.inlier_px.len(),
        highlight_px: hl.map(|h| [h.px.x, h.px.y]),
        light_direction: hl.map(|h| arr3(&h.light)),
        light_std_deg: hl.map(|h| h.std().to_degrees()),
        highlight: hl.map(|h| HighlightJson {
            method: h.method,
            alpha: h.alpha,
            alpha_std: h.alpha_std,
            saturated_px: h.saturated,
            radius_deg: h.radius.to_degrees(),
            outlier,
        }),
        no_highlight: f.highlight.as_ref().err().cloned(),
        samples: samples::counts(&smp),
        medium_outline: f.silhouette.medium.map(|m| MediumOutlineJson {
            outline: OutlineJson::from(&m.outline),
            std_px: m.std_px,
        }),
    }
}

/// Run detection over a session.
pub fn run(opts: &Options) -> Result<Detections> {
    let t0 = std::time::Instant::now();
    let report = session::inspect(&opts.session)?;
    let (sess, _) = Session::load(&report.session_file)?;
    let decoded = report.decode(&sess)?;
    let inputs = crate::formats::fingerprint::of_files(&report.input_files())?;
    run_decoded(opts, (&report, &sess), &decoded, inputs, t0)
}

/// [`run`] on a session already inspected and loaded, its photos decoded and its inputs'
/// fingerprints taken (`workbench solve` shares them with the fit), started at `t0`.
pub fn run_decoded(
    opts: &Options,
    (report, sess): (&SessionReport, &Session),
    decoded: &Decoded,
    inputs: crate::formats::fingerprint::Inputs,
    t0: std::time::Instant,
) -> Result<Detections> {
    let proj = match &report.camera {
        Some(c) => Projection::Perspective(*c),
        None => Projection::Orthographic,
    };
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| report.session_file.with_file_name("detections.json"));
    let per_image = outlines(
        report,
        sess,
        (&proj, opts.medium_outlines),
        &decoded.images,
        opts.quiet,
    )?;
    // Highlights once the outlines are final.
    let per_image: Vec<(&LinearRgb, Vec<Found>)> = per_image
        .into_par_iter()
        .map(|(img, lum, sil)| {
            let found = locate_highlights(img, &lum, &proj, sil);
            (img, found)
        })
        .collect();
    let lights = Lights::of(&per_image, sess.light);
    let out_dir = out.parent().unwrap_or(Path::new(".")).to_path_buf();
    // One set: the overlays, then detections.json (what the reuse check trusts) last.
    let overlay_dir = out_dir.join("overlays");
    let set = crate::formats::output::OutputSet::begin(&[&out, &overlay_dir])?;
    // Photos in parallel: each one's samples and overlay (a PNG to encode) are its own.
    let images: Vec<ImageDetection> = per_image
        .par_iter()
        .zip(&report.images)
        .enumerate()
        .map(|(i, ((img, fs), info))| -> Result<ImageDetection> {
            let light = lights.for_photo(i);
            let spheres = fs
                .iter()
                .enumerate()
                .map(|(j, f)| {
                    let outlier = lights.outlier(i, j, fs);
                    let exposure = info.exposure.unwrap_or(1.0);
                    sphere_detection(f, img, exposure, &proj, light.as_ref(), outlier)
                })
                .collect();
            let overlay = if opts.overlays {
                let stem = Path::new(&info.file)
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| format!("image{i}"));
                let rel = format!("overlays/{stem}.png");
                crate::detect::overlay::write(&out_dir.join(&rel), img, &proj, fs, light.as_ref())?;
                Some(rel)
            } else {
                None
            };
            Ok(ImageDetection {
                file: info.file.clone(),
                width: img.width,
                height: img.height,
                exposure: info.exposure,
                exif_notes: info.exif_notes.clone(),
                light_direction: lights.image[i].as_ref().map(|c| arr3(&c.light)),
                light_std_deg: lights.image[i].as_ref().map(|c| c.std().to_degrees()),
                spheres,
                overlay,
            })
        })
        .collect::<Result<_>>()?;
    let session_light = lights.session;
    let angles = session_light
        .as_ref()
        .map(|c| LightAngles::from_direction(&c.light));
    let det = Detections {
        schema: SCHEMA.into(),
        session: report.session_file.display().to_string(),
        projection: if proj.is_perspective() {
            "perspective"
        } else {
            "orthographic"
        }
        .into(),
        light: sess.light,
        light_direction: session_light.as_ref().map(|c| arr3(&c.light)),
        light_std_deg: session_light.as_ref().map(|c| c.std().to_degrees()),
        light_scatter_deg: session_light.as_ref().map(|c| c.tau.to_degrees()),
        light_azimuth_deg: angles.map(|a| a.azimuth.to_degrees()),
        light_elevation_deg: angles.map(|a| a.elevation.to_degrees()),
        images,
        seconds: t0.elapsed().as_secs_f64(),
        inputs,
        build: crate::formats::fingerprint::BUILD.into(),
        edge_weights: None,
    };
    crate::formats::output::write_json(&out, &det)?;
    set.commit()?;
    Ok(det)
}
