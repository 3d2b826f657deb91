//! Sphere silhouettes: sub-pixel edge points, a robust fit of the sphere's outline (the
//! 3-parameter tangent cone under a perspective camera, a circle under an orthographic one — never
//! a free 5-parameter ellipse), and a model-based refinement of that outline on the pixels around
//! it.
//!
//! 1. Edge points: Sobel gradient, non-maximum suppression, sub-pixel peak along the gradient.
//! 2. RANSAC on minimal 3-point samples, scored by the gradient magnitude of the inliers, where an
//!    inlier must lie on the outline *and* have its gradient point inward (brighter inside). Sharp
//!    silhouette edges outscore the soft terminator and highlight rims; a dark, unlit side simply
//!    contributes no points, and the 3-parameter outline cannot bend to follow a partial arc.
//! 3. Refinement: a threshold or gradient-peak edge is biased on a translucent sphere, because the
//!    exit transmission darkens the limb (radiance ∝ cos φ near it): the half-level crossing sits
//!    ~0.4 px inside, the foot ~0.75 px outside. So the outline is refined by fitting the pixels of
//!    a band around it with an edge model ([`refine`]): per angular sector and photo, a background
//!    with a ramp outside the rim and, inside it, a step, cos φ, the exit transmission T(φ) and
//!    T(φ)·cos φ (cos φ = √(1 − s²), see [`crate::camera::outline`]; opaque spheres need the step
//!    and cos φ, translucent ones the T terms), each term also varying linearly along the rim
//!    within its sector; each pixel integrated over 2×2 sub-samples, each spread radially by a
//!    fitted Gaussian blur (5-point Gauss–Hermite). The per-sector terms are linear and solved in
//!    closed form (variable projection); Levenberg–Marquardt ([`crate::lm`]) moves the three
//!    outline parameters and the blur. Sectors that the model does not explain (a terminator
//!    crossing the band) are down-weighted by their own residual. The medium's outlines
//!    ([`EdgeModel::Medium`]) weigh dim stretches of rim by their contrast as well and leave the
//!    T(φ)·cos φ term out.

use crate::camera::outline::{Outline, Projection};
use crate::formats::photo::Raster;
use nalgebra::{Matrix3, Vector2, Vector3};

/// A single-channel floating-point image (luminance).
pub type Plane = Raster<f32>;

/// Which edge model draws an outline.
///
/// - `Shared`: the outlines every detection draws, which the highlights, the light and the CDRF
///   use: the rim's angular sectors weighed by their residual's noise alone, inside the rim a
///   step, cos φ, T(φ) and T(φ)·cos φ.
/// - `Medium`: the outlines drawn for the medium fit. Each sector is also weighed by its rim's
///   contrast, since a dim stretch of a translucent sphere's rim draws the outline inward
///   (docs/measurements/detection.md, "Each sector weighted by its rim's contrast"). And the
///   T(φ)·cos φ term is left out: within the band it is nearly a sum of the others, so the
///   outline slid along its radius at little cost and came out small (on the eleven physically
///   based sessions the sessions' mean radius error RMS 0.063 → 0.020 px, each sphere's scatter
///   0.089 → 0.047 px; docs/measurements/detection.md, "The medium's outlines without the limb's
///   T(φ)·cos φ term").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EdgeModel {
    #[default]
    Shared,
    Medium,
}

impl EdgeModel {
    /// Whether the model has the T(φ)·cos φ term inside the rim.
    fn t_cos(self) -> bool {
        self == EdgeModel::Shared
    }
}

impl Raster<f32> {
    /// Bilinear interpolation at a pixel position (pixel centres at integers); clamped at the
    /// border.
    pub fn sample(&self, p: Vector2<f64>) -> f64 {
        let (w, h) = (self.width as f64, self.height as f64);
        let x = p.x.clamp(0.0, w - 1.0);
        let y = p.y.clamp(0.0, h - 1.0);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as u32, y0 as u32);
        let x1 = (x0 + 1).min(self.width - 1);
        let y1 = (y0 + 1).min(self.height - 1);
        let a = self.at(x0, y0) as f64 * (1.0 - fx) + self.at(x1, y0) as f64 * fx;
        let b = self.at(x0, y1) as f64 * (1.0 - fx) + self.at(x1, y1) as f64 * fx;
        a * (1.0 - fy) + b * fy
    }
}

/// A sub-pixel edge point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgePoint {
    pub px: Vector2<f64>,
    /// Its point under the projection (see [`crate::camera::outline`]).
    pub q: Vector3<f64>,
    /// Unit gradient direction (toward brighter).
    pub dir: Vector2<f64>,
    /// Gradient magnitude (per pixel).
    pub mag: f64,
}

/// Edge points of a region [x0, y0, x1, y1] (inclusive) whose gradient magnitude exceeds
/// `threshold`: Sobel, non-maximum suppression along the gradient, parabolic sub-pixel peak.
pub(crate) fn edge_points(
    img: &Plane,
    region: [u32; 4],
    threshold: f64,
    proj: &Projection,
) -> Vec<EdgePoint> {
    let [x0, y0, x1, y1] = region;
    let x0 = x0.max(1);
    let y0 = y0.max(1);
    let x1 = x1.min(img.width.saturating_sub(2));
    let y1 = y1.min(img.height.saturating_sub(2));
    if x1 <= x0 || y1 <= y0 {
        return vec![];
    }
    let rw = (x1 - x0 + 1) as usize;
    let rh = (y1 - y0 + 1) as usize;
    let v = |x: u32, y: u32| img.at(x, y) as f64;
    let mut gx = vec![0.0; rw * rh];
    let mut gy = vec![0.0; rw * rh];
    let mut mag = vec![0.0; rw * rh];
    for j in 0..rh {
        let y = y0 + j as u32;
        for i in 0..rw {
            let x = x0 + i as u32;
            let dx = (v(x + 1, y - 1) + 2.0 * v(x + 1, y) + v(x + 1, y + 1))
                - (v(x - 1, y - 1) + 2.0 * v(x - 1, y) + v(x - 1, y + 1));
            let dy = (v(x - 1, y + 1) + 2.0 * v(x, y + 1) + v(x + 1, y + 1))
                - (v(x - 1, y - 1) + 2.0 * v(x, y - 1) + v(x + 1, y - 1));
            let k = j * rw + i;
            gx[k] = dx / 8.0;
            gy[k] = dy / 8.0;
            mag[k] = (gx[k] * gx[k] + gy[k] * gy[k]).sqrt();
        }
    }
    let m_at = |i: f64, j: f64| -> f64 {
        // Bilinear on the magnitude grid, zero outside.
        if i < 0.0 || j < 0.0 || i > (rw - 1) as f64 || j > (rh - 1) as f64 {
            return 0.0;
        }
        let (i0, j0) = (i.floor() as usize, j.floor() as usize);
        let (fi, fj) = (i - i0 as f64, j - j0 as f64);
        let i1 = (i0 + 1).min(rw - 1);
        let j1 = (j0 + 1).min(rh - 1);
        let a = mag[j0 * rw + i0] * (1.0 - fi) + mag[j0 * rw + i1] * fi;
        let b = mag[j1 * rw + i0] * (1.0 - fi) + mag[j1 * rw + i1] * fi;
        a * (1.0 - fj) + b * fj
    };
    let mut out = vec![];
    for j in 1..rh.saturating_sub(1) {
        for i in 1..rw - 1 {
            let k = j * rw + i;
            let m0 = mag[k];
            if m0 <= threshold {
                continue;
            }
            let g = Vector2::new(gx[k], gy[k]) / m0;
            let (fi, fj) = (i as f64, j as f64);
            let mp = m_at(fi + g.x, fj + g.y);
            let mm = m_at(fi - g.x, fj - g.y);
            if !(m0 >= mp && m0 > mm) {
                continue;
            }
            let den = mm - 2.0 * m0 + mp;
            let off = if den < 0.0 {
                (0.5 * (mm - mp) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let px = Vector2::new((x0 as usize + i) as f64, (y0 as usize + j) as f64) + g * off;
            if let Some(q) = proj.point(px) {
                out.push(EdgePoint {
                    px,
                    q,
                    dir: g,
                    mag: m0,
                });
            }
        }
    }
    out
}

/// Signed distance of a point from an outline in pixels (positive outside).
fn distance_px(o: &Outline, q: &Vector3<f64>, r_px: f64) -> f64 {
    (o.s(q) - 1.0) * r_px
}

/// Whether an edge point's gradient points inward (toward the outline's centre) within `cos_tol`.
fn inward(o: &Outline, proj: &Projection, e: &EdgePoint, cos_tol: f64) -> bool {
    let Some(c) = proj.pixel(&o.center_point()) else {
        return false;
    };
    let Some(to_c) = (c - e.px).try_normalize(1e-9) else {
        return false;
    };
    e.dir.dot(&to_c) > cos_tol
}

/// The outline nearest points in pixel distance (least squares): Levenberg–Marquardt
/// ([`crate::lm`]) over the outline's own parameters ([`Outline::moved`]), with the analytic
/// Jacobian ([`Outline::ds_dmove`]). Points where the distance is not smooth are left out.
pub(crate) fn least_squares(o: &Outline, proj: &Projection, pts: &[Vector3<f64>]) -> Outline {
    let mut o = *o;
    let cost_of = |o: &Outline, r_px: f64| -> f64 {
        pts.iter()
            .map(|q| distance_px(o, q, r_px).powi(2))
            .filter(|c| c.is_finite())
            .sum()
    };
    let mut lm = crate::lm::Lm {
        lambda: 1e-6,
        lambda_min: 1e-12,
        tries: 10,
        tiny: 1e-300,
    };
    for _ in 0..30 {
        let r_px = o.radius_px(proj);
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        let mut cost = 0.0;
        for q in pts {
            let r = distance_px(&o, q, r_px);
            if !r.is_finite() {
                continue;
            }
            cost += r * r;
            if let Some(j) = o.ds_dmove(q).map(|g| g * r_px) {
                jtj += j * j.transpose();
                jtr += j * r;
            }
        }
        let unit = o.pixel_unit(proj);
        let accepted = lm.step(&jtj, &jtr, cost, |step| {
            if !step.iter().all(|v| v.is_finite()) {
                return None;
            }
            let next = o.moved(step);
            Some((cost_of(&next, r_px), (next, step.norm() < 1e-9 * unit)))
        });
        let Some((_, (next, small))) = accepted else {
            break;
        };
        o = next;
        if small {
            break;
        }
    }
    o
}

/// What [`ransac`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct OutlineFit {
    pub outline: Outline,
    /// Indices of the inlier edge points.
    pub inliers: Vec<usize>,
    /// RMS distance of the inliers (px).
    pub rms_px: f64,
}

/// Robust outline through edge points. `radius_px` bounds the image radius of candidates;
/// `tol_px` is the inlier distance. Deterministic (fixed-seed sampling).
pub(crate) fn ransac(
    pts: &[EdgePoint],
    proj: &Projection,
    radius_px: (f64, f64),
    tol_px: f64,
    iterations: usize,
) -> Option<OutlineFit> {
    use rand::{Rng, SeedableRng};
    if pts.len() < 3 {
        return None;
    }
    let cos_tol = 30f64.to_radians().cos();
    let perspective = proj.is_perspective();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5111_0E77E);
    let score = |o: &Outline, tol: f64| -> (f64, Vec<usize>) {
        let r_px = o.radius_px(proj);
        let mut s = 0.0;
        let mut inl = vec![];
        for (i, e) in pts.iter().enumerate() {
            if distance_px(o, &e.q, r_px).abs() < tol && inward(o, proj, e, cos_tol) {
                s += e.mag;
                inl.push(i);
            }
        }
        (s, inl)
    };
    let mut best: Option<(f64, Outline)> = None;
    for _ in 0..iterations {
        let i = rng.random_range(0..pts.len());
        let j = rng.random_range(0..pts.len());
        let k = rng.random_range(0..pts.len());
        if i == j || j == k || i == k {
            continue;
        }
        let Some(o) = Outline::through_three([&pts[i].q, &pts[j].q, &pts[k].q], perspective) else {
            continue;
        };
        let r = o.radius_px(proj);
        if !(r >= radius_px.0 && r <= radius_px.1) {
            continue;
        }
        // The three points themselves must agree with the candidate's inward direction.
        if ![i, j, k]
            .iter()
            .all(|&m| inward(&o, proj, &pts[m], cos_tol))
        {
            continue;
        }
        let (s, _) = score(&o, tol_px);
        if best.as_ref().is_none_or(|b| s > b.0) {
            best = Some((s, o));
        }
    }
    let (_, mut o) = best?;
    let mut inl = vec![];
    for tol in [tol_px, 0.75 * tol_px, 0.5 * tol_px] {
        inl = score(&o, tol).1;
        if inl.len() < 3 {
            return None;
        }
        let q: Vec<Vector3<f64>> = inl.iter().map(|&i| pts[i].q).collect();
        o = least_squares(&o, proj, &q);
    }
    let r_px = o.radius_px(proj);
    let rms = (inl
        .iter()
        .map(|&i| distance_px(&o, &pts[i].q, r_px).powi(2))
        .sum::<f64>()
        / inl.len() as f64)
        .sqrt();
    Some(OutlineFit {
        outline: o,
        inliers: inl,
        rms_px: rms,
    })
}

/// The edge model's own error on a medium's outline ([`EdgeModel::Medium`], px), beyond the
/// error it states ([`Refined::std_px`]), measured on the physically based wax and soap renders
/// (the two bundled sessions and the six of `datasets/pbr-seeds`, 40 spheres;
/// `scripts/outline-errors.sh --model medium`; docs/measurements/detection.md, "The medium's
/// outlines without the limb's T(φ)·cos φ term"): the outlines' centres and radii against
/// truth.json's scatter within a session by 0.029–0.038 px where their stated std is
/// 0.057–0.071 px RMS, but a few spheres state 0.006–0.02 px, and |error|/std has an RMS of
/// 1.27 in the centre's first coordinate: 0.97 with the `independent` part in quadrature. Each
/// session's mean is off by 0.016–0.020 px (RMS over sessions), about what five spheres'
/// scatter gives (0.014–0.019): the `common` parts, shared by every sphere of a session (the
/// same material, camera and light), hold that much. (With the T(φ)·cos φ term the means were
/// off by 0.035 px in the centre and 0.046–0.077 px in the radius, and the terms were 0.05,
/// 0.03 and 0.07 px.)
pub const EDGE_MODEL_ERROR: EdgeModelError = EdgeModelError {
    independent: 0.02,
    common_centre: 0.02,
    common_radius: 0.02,
};

/// The edge model's own error per outline coordinate (px): [`EDGE_MODEL_ERROR`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeModelError {
    /// Each outline's own, in every coordinate.
    pub independent: f64,
    /// Shared by a session's outlines: in each of the centre's two coordinates, and in the
    /// radius.
    pub common_centre: f64,
    pub common_radius: f64,
}

/// What the edge-model refinement reports.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    pub outline: Outline,
    /// Fitted blur (Gaussian σ of the lens, px) on top of the pixel's own footprint.
    pub blur_px: f64,
    /// Pixels in the band and sectors whose edge carried weight.
    pub pixels: usize,
    pub sectors_used: usize,
    /// Weighted RMS residual of the edge model (image units).
    pub rms: f64,
    /// 1-σ uncertainty of the outline's centre and radius (px): the diagonal of `cov`.
    pub std_px: [f64; 3],
    /// The covariance of the outline's three parameters (units of [`Outline::moved`]): the larger
    /// (by trace) of σ²(JᵀWJ)⁻¹ at the solution and the arcs' jackknife ([`arc_jackknife`]).
    pub cov: Matrix3<f64>,
    pub iterations: usize,
}

const SECTORS: usize = 48;
/// The fewest sectors (small spheres).
const MIN_SECTORS: usize = 8;
const SUBSAMPLES: usize = 2;
const SUB: usize = SUBSAMPLES;
/// Index of refraction of the limb's exit-transmission term (its shape near grazing changes
/// little over 1.3–1.7).
const LIMB_ETA: f64 = 1.44;
/// Linear terms per sector: background, step, cos φ, the exit transmission T(φ), T(φ)·cos φ, and
/// a background ramp (distance outside the rim).
/// Near the rim cos θ is linear in cos φ, so an opaque sphere's radiance is a + b·cos φ and a
/// translucent one's T(φ)·(a + b·cos φ). The medium's edge model ([`EdgeModel::Medium`]) leaves
/// T(φ)·cos φ out (its feature 0).
const NBASE: usize = 6;
/// Each base term also varies linearly with the angle along the rim within its sector (the
/// brightness changes along the rim toward the terminator).
const NLIN: usize = 2 * NBASE;
/// Gauss–Hermite nodes and weights (5 points) for the radial blur.
const GH_X: [f64; 5] = [
    -2.020_182_870_456_086,
    -0.958_572_464_613_819,
    0.0,
    0.958_572_464_613_819,
    2.020_182_870_456_086,
];
const GH_W: [f64; 5] = [
    0.019_953_242_059_046,
    0.393_619_323_152_241,
    0.945_308_720_482_942,
    0.393_619_323_152_241,
    0.019_953_242_059_046,
];

struct BandPixel {
    value: f64,
    /// Image index × sectors + angular sector.
    sector: usize,
    /// Its place in [`Band::rays`] (the same pixel of every photo shares one).
    at: usize,
}

/// The band of every photo: each pixel's place's sub-sample rays and angle from its sector's
/// middle (in sector widths, −½ … ½), once for all photos, and the photos' pixels.
struct Band {
    /// Whether the edge model has its T(φ)·cos φ term ([`EdgeModel::t_cos`]); without it that
    /// feature is 0 and the ridge of [`band_residuals`] gives it no weight.
    t_cos: bool,
    rays: Vec<([Vector3<f64>; SUB * SUB], f64)>,
    pixels: Vec<BandPixel>,
}

type Lin = nalgebra::SVector<f64, NLIN>;
type LinM = nalgebra::SMatrix<f64, NLIN, NLIN>;

/// Exit transmission T(φ) at cos φ = u for [`LIMB_ETA`], from a 1025-entry table (linear
/// interpolation; within 1e-5 of the exact value).
fn limb_transmission(u: f64) -> f64 {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        (0..=1024)
            .map(|i| crate::model::fresnel::transmission(i as f64 / 1024.0, LIMB_ETA))
            .collect()
    });
    let x = u.clamp(0.0, 1.0) * 1024.0;
    let i = (x as usize).min(1023);
    let f = x - i as f64;
    t[i] * (1.0 - f) + t[i + 1] * f
}

/// Linear features of a band pixel under an outline and blur ([`NBASE`] terms and their linear
/// variation along the rim): the means of coverage, cos φ, T(φ) and T(φ)·cos φ (0 without
/// `t_cos`), and the background ramp, over the pixel's 2×2 sub-samples, each sub-sample spread
/// radially by the blur (Gauss–Hermite). cos φ = √(1 − s²) inside, with s moved by a radial
/// offset δ px as s − δ/R.
fn features(
    o: &Outline,
    (q, dpsi): &([Vector3<f64>; SUB * SUB], f64),
    r_px: f64,
    blur: f64,
    t_cos: bool,
) -> Lin {
    let mut f = Lin::zeros();
    f[0] = 1.0;
    let nodes = if blur > 1e-6 { 5 } else { 1 };
    for q in q {
        let s0 = o.s(q);
        for k in 0..nodes {
            let (ds, w) = if nodes == 1 {
                (0.0, 1.0)
            } else {
                (
                    GH_X[k] * std::f64::consts::SQRT_2 * blur / r_px,
                    GH_W[k] / std::f64::consts::PI.sqrt(),
                )
            };
            // The sub-sample as a radial strip of width 1/SUB px, inward distance d from the
            // rim: its covered part [lo, hi] and the limb terms at the middle of that part.
            // Continuous in the outline (a point sample would jump as it crosses the rim).
            let d = (1.0 - (s0 + ds)) * r_px;
            let half = 0.5 / SUB as f64;
            let (lo, hi) = ((d - half).max(0.0), d + half);
            // Background ramp: the uncovered part times its distance outside (px).
            let out_lo = (-d - half).max(0.0);
            let out_hi = (-d + half).max(0.0);
            f[5] += w * (out_hi - out_lo) / (2.0 * half) * 0.5 * (out_lo + out_hi);
            if hi > 0.0 {
                let cov = (hi - lo) / (2.0 * half);
                let sm = 1.0 - 0.5 * (lo + hi) / r_px;
                let u = (1.0 - sm * sm).max(0.0).sqrt();
                let t = limb_transmission(u);
                let w = w * cov;
                f[1] += w;
                f[2] += w * u;
                f[3] += w * t;
                if t_cos {
                    f[4] += w * t * u;
                }
            }
        }
    }
    let n = (SUB * SUB) as f64;
    for k in 1..NBASE {
        f[k] /= n;
    }
    for k in 0..NBASE {
        f[NBASE + k] = f[k] * dpsi;
    }
    f
}

/// Residuals of the band under an outline and blur, the per-sector linear terms solved in
/// closed form. Returns residuals and per-sector RMS (NaN for sectors without enough pixels).
/// The features are computed once a place and shared by the photos.
fn band_residuals(
    o: &Outline,
    blur: f64,
    band: &Band,
    sectors: usize,
    r_px: f64,
) -> (Vec<f64>, Vec<f64>) {
    use rayon::prelude::*;
    let at: Vec<Lin> = band
        .rays
        .par_iter()
        .map(|r| features(o, r, r_px, blur, band.t_cos))
        .collect();
    let band = &band.pixels;
    let feats = || band.iter().map(|p| &at[p.at]);
    let mut ata = vec![LinM::zeros(); sectors];
    let mut atb = vec![Lin::zeros(); sectors];
    let mut count = vec![0usize; sectors];
    for (p, f) in band.iter().zip(feats()) {
        ata[p.sector] += f * f.transpose();
        atb[p.sector] += f * p.value;
        count[p.sector] += 1;
    }
    let coef: Vec<Option<Lin>> = (0..sectors)
        .map(|k| {
            if count[k] < 3 * NLIN {
                return None;
            }
            // A small ridge keeps sectors without an edge (all background) solvable.
            let m = ata[k] + LinM::identity() * 1e-9 * ata[k].trace().max(1e-30);
            m.try_inverse().map(|mi| mi * atb[k])
        })
        .collect();
    let mut res = vec![0.0; band.len()];
    let mut ss = vec![0.0; sectors];
    for (i, (p, f)) in band.iter().zip(feats()).enumerate() {
        if let Some(c) = coef[p.sector] {
            let r = p.value - c.dot(f);
            res[i] = r;
            ss[p.sector] += r * r;
        } else {
            res[i] = f64::NAN;
        }
    }
    let rms = (0..sectors)
        .map(|k| {
            if coef[k].is_some() {
                (ss[k] / count[k] as f64).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect();
    (res, rms)
}

/// One band pixel's geometry, shared by every photo: its pixel, sector, the rays of its
/// sub-samples and its place across the sector.
type BandGeometry = (u32, u32, usize, [Vector3<f64>; SUB * SUB], f64);

/// The band `inner_px` inside to `outer_px` outside an outline, in the box `[x0, y0, x1, y1]`,
/// split in `nsec` sectors around `center_px`.
fn band_geometry(
    proj: &Projection,
    start: &Outline,
    [x0, y0, x1, y1]: [u32; 4],
    center_px: Vector2<f64>,
    nsec: usize,
    (inner_px, outer_px): (f64, f64),
) -> Vec<BandGeometry> {
    let r_px = start.radius_px(proj);
    let mut geo = vec![];
    for y in y0..=y1 {
        for x in x0..=x1 {
            let px = Vector2::new(x as f64, y as f64);
            let Some(q) = proj.point(px) else { continue };
            let d = (start.s(&q) - 1.0) * r_px;
            if !(d > -inner_px && d < outer_px) {
                continue;
            }
            let mut qs = [Vector3::zeros(); SUB * SUB];
            let mut ok = true;
            for (k, qk) in qs.iter_mut().enumerate() {
                let off = Vector2::new(
                    ((k % SUB) as f64 + 0.5) / SUB as f64 - 0.5,
                    ((k / SUB) as f64 + 0.5) / SUB as f64 - 0.5,
                );
                match proj.point(px + off) {
                    Some(v) => *qk = v,
                    None => ok = false,
                }
            }
            if !ok {
                continue;
            }
            let a = (px - center_px).y.atan2((px - center_px).x);
            let t = (a + std::f64::consts::PI) / std::f64::consts::TAU * nsec as f64;
            let sector = (t as usize).min(nsec - 1);
            geo.push((x, y, sector, qs, t - sector as f64 - 0.5));
        }
    }
    geo
}

/// Every photo's band pixels (each photo's sectors its own), less the pixels it leaves out;
/// `None` when the photos differ in size.
fn band_pixels(
    images: &[(&Plane, Option<&[bool]>)],
    geo: &[BandGeometry],
    nsec: usize,
    t_cos: bool,
) -> Option<Band> {
    let (width, height) = (images[0].0.width, images[0].0.height);
    let mut pixels = vec![];
    for (i, (img, skip)) in images.iter().enumerate() {
        if img.width != width || img.height != height {
            return None;
        }
        for (at, (x, y, sector, _, _)) in geo.iter().enumerate() {
            if skip.is_some_and(|m| m[*y as usize * width as usize + *x as usize]) {
                continue;
            }
            pixels.push(BandPixel {
                value: img.at(*x, *y) as f64,
                sector: i * nsec + sector,
                at,
            });
        }
    }
    let rays = geo.iter().map(|(_, _, _, q, dpsi)| (*q, *dpsi)).collect();
    Some(Band {
        t_cos,
        rays,
        pixels,
    })
}

/// Sector weights from the starting fit: 1/rms², the rms floored at the median (a sector of
/// pure noise is not more trustworthy than the typical one), under [`EdgeModel::Medium`]
/// times the sector's rim contrast over its photo's largest ([`sector_contrast`]); 0 for a sector
/// without its terms. The contrast factor: a dim stretch of rim (the unlit side's limb, which the
/// light scattered round a translucent sphere brightens, and the terminator crossing it) draws
/// the outline inward, and at 1/rms² it weighs as much as a bright one. On the eleven
/// physically based sessions of docs/medium.md (55 spheres) it takes the sessions' mean radius
/// error from RMS 0.103 to 0.063 px and the centre's from 0.067 to 0.035 px, each sphere's
/// scatter about its session's mean unchanged; on the CDRF's own synthetic sessions, whose dim
/// sectors are not biased, it moves the detector's light beyond its stated error
/// (docs/measurements/detection.md, "Each sector weighted by its rim's contrast").
fn sector_weights(
    start: &Outline,
    band: &Band,
    (sectors, nsec): (usize, usize),
    r_px: f64,
    model: EdgeModel,
) -> Option<Vec<f64>> {
    let (_, rms0) = band_residuals(start, 0.0, band, sectors, r_px);
    let mut finite: Vec<f64> = rms0.iter().cloned().filter(|v| v.is_finite()).collect();
    finite.sort_by(|a, b| a.total_cmp(b));
    let floor = finite.get(finite.len() / 2)?.max(1e-12);
    let contrast = match model {
        EdgeModel::Medium => sector_contrast(start, band, (sectors, nsec), r_px),
        EdgeModel::Shared => vec![1.0; sectors],
    };
    Some(
        rms0.iter()
            .zip(&contrast)
            .map(|(r, c)| {
                if r.is_finite() {
                    c / r.max(floor).powi(2)
                } else {
                    0.0
                }
            })
            .collect(),
    )
}

/// Each sector's weight factor from its rim's contrast, the mean of its band pixels more than
/// 1 px inside the outline `start` less the mean of those more than 1 px outside: where the
/// sphere is the brighter, the contrast over the largest such of its photo's sectors (sectors of
/// photo i are i·nsec …); where it is the darker (a dark side against a lit backdrop, whose edge
/// no glow blurs), 1; 0 where a side has no pixel.
fn sector_contrast(
    start: &Outline,
    band: &Band,
    (sectors, nsec): (usize, usize),
    r_px: f64,
) -> Vec<f64> {
    let mut sums = vec![[(0.0, 0usize); 2]; sectors];
    for p in &band.pixels {
        let d = (1.0 - start.s(&band.rays[p.at].0[0])) * r_px;
        let side = if d > 1.0 {
            0
        } else if d < -1.0 {
            1
        } else {
            continue;
        };
        sums[p.sector][side].0 += p.value;
        sums[p.sector][side].1 += 1;
    }
    let contrast: Vec<Option<f64>> = sums
        .iter()
        .map(|[(a, na), (b, nb)]| (*na > 0 && *nb > 0).then(|| a / *na as f64 - b / *nb as f64))
        .collect();
    contrast
        .chunks(nsec.max(1))
        .flat_map(|photo| {
            let top = photo.iter().flatten().cloned().fold(0.0, f64::max);
            photo.iter().map(move |c| match c {
                Some(c) if *c > 0.0 => c / top,
                Some(_) => 1.0,
                None => 0.0,
            })
        })
        .collect()
}

type V4 = nalgebra::Vector4<f64>;
type M4 = nalgebra::Matrix4<f64>;

/// Where the edge model's fit ended: the parameters (the outline's three, moved from the start,
/// and v = blur² in px²), the residuals, the weighted cost, JᵀWJ and the Jacobian's columns at
/// the last point where they were taken (the end, or one short step before it), iterations.
struct BandFit {
    x: V4,
    res: Vec<f64>,
    cost: f64,
    jtj: M4,
    cols: [Vec<f64>; 4],
    iterations: usize,
}

/// Levenberg–Marquardt ([`crate::lm`]) of the edge model over the outline and the blur, the
/// per-sector linear terms in closed form at each point, with a finite-difference Jacobian
/// (one-sided at the blur's lower bound); no step moves the outline more than 2 px or the blur
/// by more than 1 px².
fn fit_band(
    start: &Outline,
    band: &Band,
    sectors: usize,
    (r_px, unit): (f64, f64),
    wpix: &[f64],
) -> BandFit {
    let cost = |r: &[f64]| -> f64 {
        r.iter()
            .zip(wpix)
            .map(|(r, w)| if r.is_finite() { w * r * r } else { 0.0 })
            .sum()
    };
    let eval = |x: &V4| -> (Vec<f64>, f64) {
        let o = start.moved(&Vector3::new(x[0], x[1], x[2]));
        let (r, _) = band_residuals(&o, x[3].max(0.0).sqrt(), band, sectors, r_px);
        let c = cost(&r);
        (r, c)
    };
    let mut x = V4::zeros();
    let (mut res, mut c) = eval(&x);
    let steps = V4::new(0.02 * unit, 0.02 * unit, 0.02 * unit, 0.01);
    let mut lm = crate::lm::Lm {
        lambda: 1e-3,
        lambda_min: 1e-9,
        tries: 10,
        tiny: 1e-30,
    };
    let mut iterations = 0;
    let mut jtj = M4::zeros();
    let mut cols: [Vec<f64>; 4] = Default::default();
    for it in 0..25 {
        iterations = it + 1;
        cols = jacobian(&eval, &x, &steps);
        let jtr;
        (jtj, jtr) = normal_equations(&cols, &res, wpix, (1, |_| 0))[0];
        // Never move more than 2 px, nor the blur by more than 1 px², in one step.
        let accepted = lm.step(&jtj, &jtr, c, |step| {
            let geo_norm = Vector3::new(step[0], step[1], step[2]).norm();
            let g = (2.0 * unit / geo_norm.max(2.0 * unit)).min(1.0 / step[3].abs().max(1.0));
            let mut trial = x + step * g;
            trial[3] = trial[3].max(0.0);
            let (r2, c2) = eval(&trial);
            let small =
                (geo_norm * g < 1e-3 * unit && (step[3] * g).abs() < 1e-4) || c - c2 < 1e-7 * c;
            Some((c2, (trial, r2, small)))
        });
        let mut improved = false;
        if let Some((c2, (trial, r2, small))) = accepted {
            x = trial;
            res = r2;
            c = c2;
            improved = !small;
        }
        if !improved {
            break;
        }
    }
    BandFit {
        x,
        res,
        cost: c,
        jtj,
        cols,
        iterations,
    }
}

/// The residuals' derivatives in the four parameters at `x` by central differences of `steps`
/// (one-sided at the blur's lower bound), one column a parameter.
fn jacobian(eval: &impl Fn(&V4) -> (Vec<f64>, f64), x: &V4, steps: &V4) -> [Vec<f64>; 4] {
    std::array::from_fn(|k| {
        let mut d = V4::zeros();
        d[k] = steps[k];
        let mut lo = x - d;
        let mut span = 2.0 * steps[k];
        if k == 3 && lo[3] < 0.0 {
            lo = *x;
            span = steps[k];
        }
        let (rp, _) = eval(&(x + d));
        let (rm, _) = eval(&lo);
        rp.iter().zip(&rm).map(|(a, b)| (a - b) / span).collect()
    })
}

/// JᵀWJ and JᵀWr of each of `groups` groups of band pixels (`group` of a pixel's index), in
/// one pass over the band: pixels with a finite residual and derivatives and a weight above 0.
fn normal_equations(
    cols: &[Vec<f64>; 4],
    res: &[f64],
    wpix: &[f64],
    (groups, group): (usize, impl Fn(usize) -> usize),
) -> Vec<(M4, V4)> {
    let mut sums = vec![(M4::zeros(), V4::zeros()); groups];
    for i in 0..res.len() {
        if !res[i].is_finite() || wpix[i] == 0.0 {
            continue;
        }
        let j = V4::new(cols[0][i], cols[1][i], cols[2][i], cols[3][i]);
        if !j.iter().all(|v| v.is_finite()) {
            continue;
        }
        let (jtj, jtr) = &mut sums[group(i)];
        *jtj += wpix[i] * j * j.transpose();
        *jtr += wpix[i] * j * res[i];
    }
    sums
}

/// Arcs of the rim the outline's jackknife leaves out in turn.
const ARCS: usize = 8;

/// The outline's jackknife over [`ARCS`] arcs of the rim: the fit without each arc in turn, by one
/// Gauss–Newton step on the normal equations less that arc's part, and the estimates' spread,
/// widened by t(n − 1)/2 as the radii's jackknife is (src/fit/joint/jackknife.rs). Whatever
/// disturbs part of the rim — a stand or pin, a backdrop's edge, a shadow, an occluder, a
/// composited background — moves the arcs' outlines apart, which the noise-only error
/// σ²(JᵀWJ)⁻¹ cannot see. The covariance of the outline's three parameters (units of
/// [`Outline::moved`]); `None` with fewer than 4 arcs carrying weight.
fn arc_jackknife(
    band: &[BandPixel],
    nsec: usize,
    cols: &[Vec<f64>; 4],
    res: &[f64],
    wpix: &[f64],
) -> Option<Matrix3<f64>> {
    let arcs = normal_equations(
        cols,
        res,
        wpix,
        (ARCS, |i| (band[i].sector % nsec) * ARCS / nsec),
    );
    let (h, b) = arcs
        .iter()
        .fold((M4::zeros(), V4::zeros()), |(h, b), (hg, bg)| {
            (h + hg, b + bg)
        });
    let estimates: Vec<Vector3<f64>> = arcs
        .iter()
        .filter(|(hg, _)| hg.trace() > 0.0)
        .filter_map(|(hg, bg)| {
            let step = -(h - hg).try_inverse()? * (b - bg);
            Some(Vector3::new(step[0], step[1], step[2]))
        })
        .collect();
    let n = estimates.len();
    if n < 4 {
        return None;
    }
    let widen = crate::stats::jackknife_widening(n);
    Some(crate::stats::jackknife_covariance(&estimates) * (widen * widen))
}

/// Refine an outline with the edge model on a band `inner_px` inside to `outer_px` outside the
/// current outline, over one or more photos of the same, unmoved sphere (`images`: luminance and
/// pixels to leave out, e.g. saturated ones). Each photo has its own per-sector terms; the
/// outline and the blur are shared. The steps: the band's geometry and pixels, the sectors'
/// weights, the fit, its covariance.
pub(crate) fn refine(
    images: &[(&Plane, Option<&[bool]>)],
    proj: &Projection,
    start: &Outline,
    (inner_px, outer_px): (f64, f64),
    model: EdgeModel,
) -> Option<Refined> {
    let r_px = start.radius_px(proj);
    if images.is_empty() {
        return None;
    }
    let (width, height) = (images[0].0.width, images[0].0.height);
    let pixel_box = start.pixel_box(proj, outer_px + 2.0, width, height)?;
    let center_px = proj.pixel(&start.center_point())?;
    // Fewer sectors on small spheres: each needs 4 × NLIN band pixels for its linear terms.
    let band_area = std::f64::consts::TAU * r_px * (inner_px + outer_px);
    let nsec = ((band_area / (4 * NLIN) as f64) as usize).clamp(MIN_SECTORS, SECTORS);
    let geo = band_geometry(
        proj,
        start,
        pixel_box,
        center_px,
        nsec,
        (inner_px, outer_px),
    );
    let band = band_pixels(images, &geo, nsec, model.t_cos())?;
    let sectors = images.len() * nsec;
    if band.pixels.len() < 50 {
        return None;
    }
    let w = sector_weights(start, &band, (sectors, nsec), r_px, model)?;
    let sectors_used = w.iter().filter(|&&v| v > 0.0).count();
    let wpix: Vec<f64> = band.pixels.iter().map(|p| w[p.sector]).collect();
    let unit = start.pixel_unit(proj);
    let BandFit {
        x,
        res,
        cost: c,
        jtj,
        cols,
        iterations,
    } = fit_band(start, &band, sectors, (r_px, unit), &wpix);
    let m = res.iter().filter(|r| r.is_finite()).count();
    let wsum: f64 = wpix
        .iter()
        .zip(&res)
        .filter(|(_, r)| r.is_finite())
        .map(|(w, _)| w)
        .sum();
    // σ² = cost / (m − n); cov = σ² (JᵀWJ)⁻¹ (outline block).
    let sigma2 = c / (m.saturating_sub(4 + NLIN * sectors_used).max(1)) as f64;
    let formal = jtj
        .try_inverse()
        .map(|mi| mi * sigma2)
        .map(|cv| cv.fixed_view::<3, 3>(0, 0).into_owned());
    // The larger of the noise's error and the arcs' disagreement (by trace; each a full
    // covariance of the outline's three parameters).
    let arcs = arc_jackknife(&band.pixels, nsec, &cols, &res, &wpix);
    let cov = match (formal, arcs) {
        (Some(f), Some(a)) if a.trace() > f.trace() => a,
        (Some(f), _) => f,
        (None, _) => Matrix3::from_element(f64::NAN),
    };
    let std_px = [0, 1, 2].map(|k| cov[(k, k)].max(0.0).sqrt() / unit);
    Some(Refined {
        outline: start.moved(&Vector3::new(x[0], x[1], x[2])),
        blur_px: x[3].max(0.0).sqrt(),
        pixels: band.pixels.len(),
        sectors_used,
        rms: (c / wsum.max(1e-300)).sqrt(),
        std_px,
        cov,
        iterations,
    })
}

/// [`refine`] repeated from its own result (the band and the sector weights re-centred on the
/// better outline) until the outline moves less than 0.01 px, at most four times.
pub(crate) fn refine_repeated(
    images: &[(&Plane, Option<&[bool]>)],
    proj: &Projection,
    start: &Outline,
    band: (f64, f64),
    model: EdgeModel,
) -> Option<Refined> {
    let mut r = refine(images, proj, start, band, model)?;
    for _ in 0..3 {
        let next = refine(images, proj, &r.outline, band, model)?;
        let moved = next.outline.distance_px(&r.outline, proj);
        r = next;
        if moved < 0.01 {
            break;
        }
    }
    Some(r)
}

/// A connected region of a boolean mask (4-connected).
#[derive(Clone, Debug, PartialEq)]
pub struct Blob {
    pub area: usize,
    /// Pixel centroid.
    pub centroid: Vector2<f64>,
    /// Inclusive bounding box [x0, y0, x1, y1].
    pub bbox: [u32; 4],
    /// Greatest distance of a blob pixel from the centroid (px).
    pub extent: f64,
    /// Sum of the weights of its pixels (its area when no weights are given).
    pub mass: f64,
}

impl Blob {
    /// The share of the circle of its extent it fills: a disc about 1, a square 2/π, a pin or a
    /// cable a few percent.
    pub(crate) fn fill(&self) -> f64 {
        self.area as f64 / (std::f64::consts::PI * self.extent * self.extent).max(1.0)
    }

    /// Whether the blob touches the image border.
    pub(crate) fn touches_border(&self, width: u32, height: u32) -> bool {
        self.bbox[0] == 0
            || self.bbox[1] == 0
            || self.bbox[2] + 1 >= width
            || self.bbox[3] + 1 >= height
    }
}

/// Connected components of a mask (row-major, `width` wide), largest first.
pub fn blobs(mask: &[bool], width: u32, height: u32, weight: Option<&[f32]>) -> Vec<Blob> {
    let (w, h) = (width as usize, height as usize);
    let mut label = vec![u32::MAX; w * h];
    let mut out = vec![];
    let mut stack = vec![];
    for start in 0..w * h {
        if !mask[start] || label[start] != u32::MAX {
            continue;
        }
        let id = out.len() as u32;
        let mut members = vec![];
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            members.push(i);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if mask[j] && label[j] == u32::MAX {
                    label[j] = id;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        let n = members.len() as f64;
        let (sx, sy) = members.iter().fold((0.0, 0.0), |a, &i| {
            (a.0 + (i % w) as f64, a.1 + (i / w) as f64)
        });
        let centroid = Vector2::new(sx / n, sy / n);
        let mut bbox = [u32::MAX, u32::MAX, 0, 0];
        let mut extent: f64 = 0.0;
        let mass = match weight {
            Some(wt) => members.iter().map(|&i| wt[i] as f64).sum(),
            None => n,
        };
        for &i in &members {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            bbox = [
                bbox[0].min(x),
                bbox[1].min(y),
                bbox[2].max(x),
                bbox[3].max(y),
            ];
            extent = extent.max((Vector2::new(x as f64, y as f64) - centroid).norm());
        }
        out.push(Blob {
            area: members.len(),
            centroid,
            bbox,
            extent,
            mass,
        });
    }
    out.sort_by_key(|b| std::cmp::Reverse(b.area));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limb_table_matches_fresnel() {
        for k in 0..=1000 {
            let u = k as f64 / 1000.0;
            let exact = crate::model::fresnel::transmission(u, LIMB_ETA);
            assert!((limb_transmission(u) - exact).abs() < 1e-5, "{u}");
        }
    }

    fn edge(o: &Outline, proj: &Projection, q: Vector3<f64>, mag: f64) -> EdgePoint {
        let px = proj.pixel(&q).unwrap();
        let c = proj.pixel(&o.center_point()).unwrap();
        EdgePoint {
            px,
            q,
            dir: (c - px).normalize(),
            mag,
        }
    }

    #[test]
    fn ransac_finds_the_rim_among_a_terminator_arc() {
        let cam = crate::camera::Camera::example();
        let proj = Projection::Perspective(cam);
        let s = crate::camera::sphere::Sphere::new(Vector3::new(-30.0, 20.0, 300.0), 15.0);
        let o = Outline::of_sphere(&s).unwrap();
        // Half the rim (the lit side), strong edges.
        let mut pts: Vec<EdgePoint> = o.rim(200)[..100]
            .iter()
            .map(|q| edge(&o, &proj, *q, 1.0))
            .collect();
        // A soft terminator: a smaller arc inside, weaker edges, gradients toward its own centre.
        let inner =
            Outline::of_sphere(&crate::camera::sphere::Sphere::new(s.center, 11.0)).unwrap();
        pts.extend(
            inner.rim(200)[100..170]
                .iter()
                .map(|q| edge(&inner, &proj, *q, 0.3)),
        );
        let fit = ransac(&pts, &proj, (10.0, 200.0), 1.5, 300).unwrap();
        assert_eq!(fit.inliers.len(), 100);
        let c = fit.outline.center_mm(15.0).unwrap();
        assert!((c - s.center).norm() < 1e-6, "{c:?}");
    }

    #[test]
    fn blobs_are_labelled_largest_first() {
        // Two squares (3×3 and 2×2) and a single pixel touching the border, in an 8×6 mask.
        let (w, h) = (8u32, 6u32);
        let mut m = vec![false; 48];
        let on = [
            (1, 1),
            (2, 1),
            (3, 1),
            (1, 2),
            (2, 2),
            (3, 2),
            (1, 3),
            (2, 3),
            (3, 3),
            (5, 2),
            (6, 2),
            (5, 3),
            (6, 3),
            (7, 5),
        ];
        for (x, y) in on {
            m[y * 8 + x] = true;
        }
        let b = blobs(&m, w, h, None);
        assert_eq!(b.iter().map(|b| b.area).collect::<Vec<_>>(), [9, 4, 1]);
        assert_eq!(b[0].centroid, Vector2::new(2.0, 2.0));
        assert_eq!(b[1].bbox, [5, 2, 6, 3]);
        assert!(!b[0].touches_border(w, h) && b[2].touches_border(w, h));
        assert!((b[0].extent - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(b[0].mass, 9.0);
    }
}
