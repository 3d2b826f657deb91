//! Specular highlights and the light direction they imply.
//!
//! At the peak of a mirror-like highlight the normal bisects light and view, so the light is
//! l = 2(n·v)n − v with that pixel's own normal and view vector (perspective: v differs per pixel).
//! Locating the peak as the brightest pixel or a plain centroid is biased: the diffuse gradient
//! under the highlight and the off-specular shift of a rough lobe (its 1/(n·v) and masking terms)
//! pull it toward the light. So workbench fits the light itself: the pixels around the peak are
//! modelled as a smooth diffuse trend plus A · fs(n, v, l; α) · (n·l), the GGX lobe of
//! [`crate::model::specular`] with the pixel's own geometry, and Levenberg–Marquardt moves l (two angles)
//! and α while the trend and A are solved in closed form (variable projection). Clipped pixels are
//! censored observations ("at least this bright"): they cost nothing while the model is above
//! them. The trend is fitted in two forms (`Trend`); their disagreement, and the shift when the
//! clipped pixels are left out, are errors of the model that enter the light's covariance. A lobe
//! narrower than a few pixels (α·R < 4 px) is not resolved by the pixels: it, and a small clipped
//! core the lobe cannot be fitted to, are located by the intensity-weighted centroid of their
//! excess over a local plane (fitted on a ring around them) — sub-pixel even for a blob of a few
//! clipped pixels. docs/commands.md ("detect") has the rules.
//!
//! Each estimate carries a covariance of the two light angles: from the fit's Jacobian (σ²(JᵀJ)⁻¹)
//! or, for a centroid, from a quarter-pixel position error mapped through the reflection.
//! An estimate is accepted only if the lobe stands out of the noise (6σ) and of the diffuse
//! level (2%); otherwise the sphere is reported as having no usable highlight.

use crate::camera::outline::{reflect, tangent_basis, Outline, Projection};
use crate::detect::silhouette::{blobs, Plane};
use crate::model::specular;
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Matrix3x2, SMatrix, SVector, Vector2, Vector3};

/// Index of refraction used for the lobe's Fresnel factor while locating a highlight (the
/// factor's variation across a highlight is small; its scale goes into A).
const ETA: f64 = 1.5;

/// A lobe is resolved when α times the sphere's image radius reaches this many pixels.
const RESOLVED_PX: f64 = 4.0;

/// Largest clipped share of the disc that can still hold a highlight: beyond it the clipping is
/// diffuse shading.
const MAX_CLIPPED: f64 = 0.5;

/// Largest clipped share of the disc located by the centroid of its clipped core when the lobe
/// fit fails.
const CENTROID_CLIPPED: f64 = 0.02;

/// Roughest lobe the fit accepts (GGX α); broader ones blend into the diffuse shading.
const MAX_ALPHA: f64 = 0.25;
/// Smoothest lobe the fit accepts: at the solver's floor of 10⁻³ a lobe is a spike between pixels.
const MIN_ALPHA: f64 = 1.5e-3;
/// The roughnesses the lobe fit starts from.
const LOBE_STARTS: [f64; 3] = [0.03, 0.08, 0.2];

/// A fitted roughness inside the accepted range, away from its ends: a fit stopped at a bound
/// rather than at a minimum, and its covariance says nothing (a lobe at the largest roughness
/// trades with the diffuse trend; one at 0.25 was measured 22 of its std off the light).
fn interior(alpha: f64) -> bool {
    (MIN_ALPHA..0.99 * MAX_ALPHA).contains(&alpha)
}

use crate::formats::detections::Method;

/// A located highlight and the light it implies.
#[derive(Clone, Debug, PartialEq)]
pub struct Highlight {
    /// Pixel of the mirror point.
    pub px: Vector2<f64>,
    /// Unit light direction (camera frame, toward the light).
    pub light: Vector3<f64>,
    /// Covariance of the light direction (3×3, rank 2, radians²).
    pub cov: Matrix3<f64>,
    pub method: Method,
    /// Fitted GGX roughness (lobe fit only).
    pub alpha: Option<f64>,
    /// Its standard error (lobe fit only): the formal one combined with the trend model's error,
    /// the larger of half the difference to the α fitted with the other kind of diffuse trend and
    /// the shift when the clipped pixels are left out rather than censored (as for the light).
    pub alpha_std: Option<f64>,
    /// Saturated pixels in the highlight.
    pub saturated: usize,
    /// Angular radius of the highlight region on the sphere (normals within it are flagged).
    pub radius: f64,
    /// The lobe fit's model error (radians; 0 for a centroid): the larger of half the angle
    /// between the lights fitted with the two kinds of diffuse trend and the shift when the
    /// clipped pixels are left out rather than censored. Shared by every sphere of a session;
    /// included in `cov`.
    pub trend_spread: f64,
}

impl Highlight {
    /// 1-σ angular uncertainty in the worst direction (radians).
    pub fn std(&self) -> f64 {
        self.cov.symmetric_eigenvalues().max().max(0.0).sqrt()
    }
}

/// Why no highlight was used.
#[derive(Clone, Debug, PartialEq)]
pub struct NoHighlight(pub String);

#[derive(Clone, Copy)]
struct Px {
    px: Vector2<f64>,
    n: Vector3<f64>,
    v: Vector3<f64>,
    value: f64,
    /// Clipped: the true value is at least `value` (a censored observation).
    clipped: bool,
}

/// The lobe's shape at a pixel for light l and roughness α (ks = 1): fs · (n·l).
fn shape(p: &Px, l: &Vector3<f64>, alpha: f64) -> f64 {
    specular::lobe(p.n.dot(l), p.n.dot(&p.v), l.dot(&p.v), 1.0, alpha, ETA).value
}

/// Linear terms: the diffuse trend (10, either kind of [`Trend`]) and the lobe amplitude.
const NLIN: usize = 11;
type Lin = SVector<f64, NLIN>;

struct Fit {
    l0: Vector3<f64>,
    /// The light of the located peak: fits may not move more than 20° from it.
    anchor: Vector3<f64>,
    e1: Vector3<f64>,
    e2: Vector3<f64>,
    center: Vector2<f64>,
    scale: f64,
    trend: Trend,
}

/// The smooth diffuse shading under the lobe, solved linearly beside the lobe's amplitude.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Trend {
    /// A cubic in the image coordinates.
    Image,
    /// A quartic in n·l, and the same times n·v: any shading of a sphere under a directional
    /// light that depends on the two angles.
    Shading,
}

/// The linear problem's solution at one point: the linear terms, the rows that entered their
/// solve (unclipped, or clipped while the model is below them) and the inverse of their
/// normal matrix.
struct Linear {
    c: Lin,
    used: Vec<bool>,
    ginv: SMatrix<f64, NLIN, NLIN>,
}

impl Fit {
    fn light(&self, x: &Vector3<f64>) -> Vector3<f64> {
        (self.l0 + self.e1 * x.x + self.e2 * x.y).normalize()
    }

    /// ∂l/∂x and ∂l/∂y of [`Fit::light`]: the basis vectors less their part along l, over |m|.
    fn light_derivatives(&self, x: &Vector3<f64>) -> [Vector3<f64>; 2] {
        let m = self.l0 + self.e1 * x.x + self.e2 * x.y;
        let (norm, l) = (m.norm(), m.normalize());
        [self.e1, self.e2].map(|e| (e - l * l.dot(&e)) / norm)
    }

    /// A pixel's row of the linear problem (trend terms, then the lobe's shape) and, with `dl`
    /// (∂l along the two angles), its derivatives along the three parameters (angles, ln α).
    fn row(
        &self,
        p: &Px,
        l: &Vector3<f64>,
        alpha: f64,
        dl: Option<&[Vector3<f64>; 2]>,
    ) -> (Lin, [Lin; 3]) {
        let mut a = Lin::zeros();
        let mut da = [Lin::zeros(); 3];
        let (nl, nv) = (p.n.dot(l), p.n.dot(&p.v));
        match self.trend {
            Trend::Shading => {
                let mut pow = 1.0; // nl^i
                let mut dpow = 0.0; // i·nl^(i−1)
                for i in 0..5 {
                    a[2 * i] = pow;
                    a[2 * i + 1] = pow * nv;
                    if let Some(dl) = dl {
                        for k in 0..2 {
                            let d = dpow * p.n.dot(&dl[k]);
                            da[k][2 * i] = d;
                            da[k][2 * i + 1] = d * nv;
                        }
                    }
                    dpow = (i + 1) as f64 * pow;
                    pow *= nl;
                }
            }
            Trend::Image => {
                let d = (p.px - self.center) / self.scale;
                let (x, y) = (d.x, d.y);
                a.fixed_rows_mut::<10>(0).copy_from_slice(&[
                    1.0,
                    x,
                    y,
                    x * x,
                    x * y,
                    y * y,
                    x * x * x,
                    x * x * y,
                    x * y * y,
                    y * y * y,
                ]);
            }
        }
        let s = specular::lobe(nl, nv, l.dot(&p.v), 1.0, alpha, ETA);
        a[NLIN - 1] = s.value;
        if let Some(dl) = dl {
            for k in 0..2 {
                da[k][NLIN - 1] = s.d_nl * p.n.dot(&dl[k]) + s.d_lv * p.v.dot(&dl[k]);
            }
            da[2][NLIN - 1] = s.d_alpha * alpha;
        }
        (a, da)
    }

    /// The linear terms for the rows `rows` of `pix`. Censored fit: a clipped pixel says only
    /// "at least this bright", so it enters the linear solve, at its clipped value, only while
    /// the model predicts less (an active set, a few rounds), and its residual is zero once the
    /// model reaches it.
    fn linear(rows: &[Lin], pix: &[Px]) -> Option<Linear> {
        let mut active = vec![false; pix.len()];
        let mut out = None;
        for _round in 0..6 {
            let mut g = SMatrix::<f64, NLIN, NLIN>::zeros();
            let mut atb = Lin::zeros();
            let used: Vec<bool> = pix
                .iter()
                .zip(&active)
                .map(|(p, &on)| !p.clipped || on)
                .collect();
            for ((a, p), _) in rows.iter().zip(pix).zip(&used).filter(|(_, &u)| u) {
                g += a * a.transpose();
                atb += a * p.value;
            }
            let ginv = g.try_inverse()?;
            let c = ginv * atb;
            let next: Vec<bool> = rows
                .iter()
                .zip(pix)
                .map(|(a, p)| p.clipped && a.dot(&c) < p.value)
                .collect();
            let settled = next == active;
            out = Some(Linear { c, used, ginv });
            if settled {
                break;
            }
            active = next;
        }
        out
    }

    /// A pixel's residual: its value less the model's, zero for a clipped pixel the model reaches.
    fn residual(a: &Lin, p: &Px, c: &Lin) -> f64 {
        let e = p.value - a.dot(c);
        if p.clipped {
            e.max(0.0)
        } else {
            e
        }
    }

    /// Residuals with the linear terms (cubic trend, amplitude) solved, without derivatives:
    /// the tests' reference for [`Fit::residuals_and_jacobian`].
    #[cfg(test)]
    fn residuals(&self, pix: &[Px], x: &Vector3<f64>) -> Option<(DVector<f64>, Lin)> {
        let (l, alpha) = (self.light(x), x.z.exp());
        let rows: Vec<Lin> = pix.iter().map(|p| self.row(p, &l, alpha, None).0).collect();
        let Linear { c, .. } = Self::linear(&rows, pix)?;
        let r = DVector::from_iterator(
            pix.len(),
            rows.iter().zip(pix).map(|(a, p)| Self::residual(a, p, &c)),
        );
        Some((r, c))
    }

    /// The residuals, the linear terms (trend, amplitude) solved and returned, and their
    /// Jacobian along (the two angles, ln α), exact for the variable projection (Golub and
    /// Pereyra): with G = AᵀA over the rows that entered the linear solve,
    /// ∂c = G⁻¹(∂Aᵀ r − Aᵀ ∂A c) and ∂rᵢ = −(∂aᵢ·c + aᵢ·∂c), zero where a clipped pixel's
    /// residual is (docs/commands.md, "`detect`: how, per photo", step 4).
    fn residuals_and_jacobian(
        &self,
        pix: &[Px],
        x: &Vector3<f64>,
    ) -> Option<(DVector<f64>, Lin, DMatrix<f64>)> {
        let (l, alpha, dl) = (self.light(x), x.z.exp(), self.light_derivatives(x));
        let rows: Vec<(Lin, [Lin; 3])> = pix
            .iter()
            .map(|p| self.row(p, &l, alpha, Some(&dl)))
            .collect();
        let a: Vec<Lin> = rows.iter().map(|r| r.0).collect();
        let Linear { c, used, ginv } = Self::linear(&a, pix)?;
        let mut rhs = [Lin::zeros(); 3];
        for (((a, da), p), _) in rows.iter().zip(pix).zip(&used).filter(|(_, &u)| u) {
            let e = p.value - a.dot(&c);
            for k in 0..3 {
                rhs[k] += da[k] * e - a * da[k].dot(&c);
            }
        }
        let dc = rhs.map(|v| ginv * v);
        let mut j = DMatrix::zeros(pix.len(), 3);
        let mut r = DVector::zeros(pix.len());
        for (i, ((a, da), p)) in rows.iter().zip(pix).enumerate() {
            r[i] = Self::residual(a, p, &c);
            if p.clipped && r[i] == 0.0 {
                continue;
            }
            for k in 0..3 {
                j[(i, k)] = -(da[k].dot(&c) + a.dot(&dc[k]));
            }
        }
        Some((r, c, j))
    }
}

/// Solution of [`solve`]: parameters, residuals, linear terms, Jacobian.
type Solution = (Vector3<f64>, DVector<f64>, Lin, DMatrix<f64>);

/// Levenberg–Marquardt ([`crate::lm`]) over (light angles, log α) with the variable projection's
/// exact Jacobian ([`Fit::residuals_and_jacobian`]). Returns the solution, its residual, linear
/// terms and Jacobian.
fn solve(fit: &Fit, pix: &[Px], mut x: Vector3<f64>) -> Option<Solution> {
    let (mut r, mut c, mut j) = fit.residuals_and_jacobian(pix, &x)?;
    let mut cost = r.norm_squared();
    let mut lm = crate::lm::Lm {
        lambda: 1e-3,
        lambda_min: 1e-12,
        // From the floor up to λ = 1e12: a step that overshoots is damped until it is short
        // enough. With 12 tries λ reached only 1 (a halved step), and fits stopped short of the
        // minimum by up to a quarter of the light's std.
        tries: 24,
        tiny: 1e-300,
    };
    for _ in 0..60 {
        let jtj: Matrix3<f64> = (j.transpose() * &j).fixed_view::<3, 3>(0, 0).into();
        let jtr: Vector3<f64> = (j.transpose() * &r).fixed_view::<3, 1>(0, 0).into();
        let accepted = lm.step(&jtj, &jtr, cost, |step| {
            // Keep steps modest: 5° in angle, a factor e^0.5 in α.
            let lim = Vector3::new(0.087, 0.087, 0.5);
            let step = Vector3::from_fn(|k, _| step[k].clamp(-lim[k], lim[k]));
            let xt = x + step;
            if !(xt.z > (1e-3f64).ln() && xt.z < MAX_ALPHA.ln())
                || (fit.light(&xt) - fit.anchor).norm() > 0.35
            {
                return None;
            }
            // The Jacobian with the trial's residuals: most trials are accepted, and the point
            // is not solved twice.
            let (rt, ct, jt) = fit.residuals_and_jacobian(pix, &xt)?;
            Some((rt.norm_squared(), (xt, rt, ct, jt, step.norm() < 1e-9)))
        });
        let Some((c2, (xt, rt, ct, jt, small))) = accepted else {
            break;
        };
        (x, r, c, j, cost) = (xt, rt, ct, jt, c2);
        if small {
            break;
        }
    }
    Some((x, r, c, j))
}

/// A refit under the shading trend ending above this many times the image trend's sum of
/// squares (on the same pixels) has stopped short of a minimum, not found another description of
/// them: over the 80 lobe-fitted highlights of the fifteen physically based sessions
/// (`datasets/pbr-soap`, `pbr-wax`, `pbr-seeds`, `pbr-range`, `../shared/data/pbr-jade`) the
/// ratio is 0.92–1.37; on a photo lit from below with 537 clipped pixels
/// (`detect::per_image_lights_and_a_sphere_that_stayed_put`), 18, its refit stopped where no step
/// lowers the cost and the gradient is not zero (the clipped pixels' active set changes there).
/// docs/measurements/detection.md, "A shading refit that stops short".
const FAILED_REFIT: f64 = 3.0;

/// The lobe fitted again under the shading trend `f` from the image trend's solution `x`, whose
/// sum of squares is `ss_image`: its light and roughness where it finds a lobe. Where that refit
/// fails ([`FAILED_REFIT`]) it is started again from `x`'s light at each of [`LOBE_STARTS`], and
/// the least sum of squares kept; `None` where every start fails.
fn shading_refit(
    f: &Fit,
    pix: &[Px],
    x: Vector3<f64>,
    ss_image: f64,
) -> Option<(Vector3<f64>, f64)> {
    let first = solve(f, pix, x).and_then(with_lobe);
    let best = match first {
        Some((_, ss)) if ss <= FAILED_REFIT * ss_image => first,
        _ => LOBE_STARTS
            .iter()
            .filter_map(|a0| solve(f, pix, Vector3::new(x.x, x.y, a0.ln())).and_then(with_lobe))
            .chain(first)
            .min_by(|a, b| a.1.total_cmp(&b.1)),
    };
    best.filter(|(_, ss)| *ss <= FAILED_REFIT * ss_image)
        .map(|(x2, _)| (f.light(&x2), x2.z.exp()))
}

/// A solution's unknowns and sum of squares, where it found a lobe (a positive amplitude).
fn with_lobe((x2, r, lin, _): Solution) -> Option<(Vector3<f64>, f64)> {
    (lin[NLIN - 1] > 0.0).then(|| (x2, r.norm_squared()))
}

/// The sphere's pixels as the highlight search sees them: its bounding box, the geometry of
/// every pixel well inside the silhouette, and which of those are clipped.
struct Area<'a> {
    lum: &'a Plane,
    saturated: &'a [bool],
    proj: &'a Projection,
    outline: &'a Outline,
    /// The box's first pixel and size.
    x0: u32,
    y0: u32,
    bw: usize,
    bh: usize,
    /// The sphere's radius in the image (pixels).
    r_px: f64,
    /// Per box pixel: (normal, view) where it is well inside the silhouette.
    surf: Vec<Option<(Vector3<f64>, Vector3<f64>)>>,
    /// Per box pixel: clipped and inside.
    clipped: Vec<bool>,
}

/// A lobe fit's last pass: the light, α, the residual variance, the lobe's amplitude, the trend
/// at the peak, the Jacobian and the basis its angles step along, the unclipped pixels; and the
/// pass itself (fit, pixels, parameters) for the trend checks.
struct LobePass {
    light: Vector3<f64>,
    alpha: f64,
    sigma2: f64,
    amp: f64,
    trend: f64,
    jac: DMatrix<f64>,
    basis: (Vector3<f64>, Vector3<f64>),
    unclipped: usize,
    fit: Fit,
    pix: Vec<Px>,
    x: Vector3<f64>,
}

/// The clipped core around the highlight, as angles on the sphere (from its radius, a normal
/// angle): the half-vector patch that holds the unclipped ring around it, and the highlight's
/// radius for the solve (6° past the core). Both 0 without a core.
struct Core {
    ring: f64,
    past: f64,
}

impl Core {
    fn of(blob: Option<&crate::detect::silhouette::Blob>, r_px: f64) -> Core {
        let angle = blob.map_or(0.0, |b| {
            ((b.area as f64 / std::f64::consts::PI).sqrt() / r_px)
                .min(1.0)
                .asin()
        });
        let (ring, past) = if angle > 0.0 {
            (
                (2.0 * angle + 4f64.to_radians()).min(45f64.to_radians()),
                angle + 6f64.to_radians(),
            )
        } else {
            (0.0, 0.0)
        };
        Core { ring, past }
    }
}

impl<'a> Area<'a> {
    fn of(
        lum: &'a Plane,
        saturated: &'a [bool],
        proj: &'a Projection,
        outline: &'a Outline,
    ) -> Result<Area<'a>, NoHighlight> {
        let r_px = outline.radius_px(proj);
        let [bx0, by0, bx1, by1] = outline
            .pixel_box(proj, 0.0, lum.width, lum.height)
            .ok_or_else(|| NoHighlight("the sphere leaves the image".into()))?;
        let (bw, bh) = ((bx1 - bx0 + 1) as usize, (by1 - by0 + 1) as usize);
        let w = lum.width as usize;
        let mut surf: Vec<Option<(Vector3<f64>, Vector3<f64>)>> = vec![None; bw * bh];
        for j in 0..bh {
            for i in 0..bw {
                let px = Vector2::new((bx0 as usize + i) as f64, (by0 as usize + j) as f64);
                if let Some(q) = proj.point(px) {
                    if outline.s(&q) < 0.97 {
                        if let Some(s) = outline.surface(&q) {
                            surf[j * bw + i] = Some((s.normal, s.view));
                        }
                    }
                }
            }
        }
        let mut clipped = vec![false; bw * bh];
        for j in 0..bh {
            for i in 0..bw {
                let k = (by0 as usize + j) * w + bx0 as usize + i;
                if saturated[k] && surf[j * bw + i].is_some() {
                    clipped[j * bw + i] = true;
                }
            }
        }
        Ok(Area {
            lum,
            saturated,
            proj,
            outline,
            x0: bx0,
            y0: by0,
            bw,
            bh,
            r_px,
            surf,
            clipped,
        })
    }

    /// The image pixel of box pixel (i, j).
    fn pixel(&self, i: usize, j: usize) -> Vector2<f64> {
        Vector2::new((self.x0 as usize + i) as f64, (self.y0 as usize + j) as f64)
    }

    /// Peak candidate: the largest excess of a 3×3 mean over a wide local mean (R/6 box), which
    /// favours a compact highlight over the broad diffuse maximum; means over interior pixels
    /// only (integral images of values and counts), so the dark background beyond the rim does
    /// not make the rim look like a peak. Returns the excess and the box pixel.
    fn peak(&self) -> Option<(f64, usize, usize)> {
        let (bw, bh) = (self.bw, self.bh);
        let mut integ = vec![0.0f64; (bw + 1) * (bh + 1)];
        let mut count = vec![0.0f64; (bw + 1) * (bh + 1)];
        for j in 0..bh {
            for i in 0..bw {
                let inside = self.surf[j * bw + i].is_some();
                let v = if inside {
                    self.lum.at(self.x0 + i as u32, self.y0 + j as u32) as f64
                } else {
                    0.0
                };
                let k = (j + 1) * (bw + 1) + i + 1;
                integ[k] = v + integ[k - (bw + 1)] + integ[k - 1] - integ[k - bw - 2];
                count[k] = f64::from(u8::from(inside)) + count[k - (bw + 1)] + count[k - 1]
                    - count[k - bw - 2];
            }
        }
        let box_mean = |i: usize, j: usize, r: usize| {
            let (a0, b0) = (i.saturating_sub(r), j.saturating_sub(r));
            let (a1, b1) = ((i + r + 1).min(bw), (j + r + 1).min(bh));
            let rect = |t: &[f64]| {
                t[b1 * (bw + 1) + a1] - t[b0 * (bw + 1) + a1] - t[b1 * (bw + 1) + a0]
                    + t[b0 * (bw + 1) + a0]
            };
            rect(&integ) / rect(&count).max(1.0)
        };
        let wide = ((self.r_px / 6.0).round() as usize).max(3);
        let mut best: Option<(f64, usize, usize)> = None;
        for j in 0..bh {
            for i in 0..bw {
                if self.surf[j * bw + i].is_none() {
                    continue;
                }
                let e = box_mean(i, j, 1) - box_mean(i, j, wide);
                if best.is_none_or(|b| e > b.0) {
                    best = Some((e, i, j));
                }
            }
        }
        best
    }

    /// The clipped blob (2 px at least) nearest box pixel (pi, pj).
    fn clipped_blob(&self, pi: usize, pj: usize) -> Option<crate::detect::silhouette::Blob> {
        if !self.clipped.iter().any(|&m| m) {
            return None;
        }
        blobs(&self.clipped, self.bw as u32, self.bh as u32, None)
            .into_iter()
            .filter(|b| b.area >= 2)
            .min_by(|a, b| {
                let da = (a.centroid - Vector2::new(pi as f64, pj as f64)).norm();
                let db = (b.centroid - Vector2::new(pi as f64, pj as f64)).norm();
                da.total_cmp(&db)
            })
    }

    /// The light a mirror point at this pixel implies.
    fn light_at(&self, px: Vector2<f64>) -> Option<Vector3<f64>> {
        let s = self.outline.surface(&self.proj.point(px)?)?;
        Some(reflect(&s.normal, &s.view))
    }

    /// Intensity-weighted centroid of the excess over a local plane (fitted on a 3 px ring
    /// around a disc of radius rw): sub-pixel even for a blob of a few clipped pixels.
    fn weighted(&self, c0: Vector2<f64>, rw: f64) -> Option<Vector2<f64>> {
        let (lum, w) = (self.lum, self.lum.width as usize);
        let (x0, x1) = (
            (c0.x - rw - 4.0).floor().max(0.0) as u32,
            ((c0.x + rw + 4.0).ceil() as u32).min(lum.width - 1),
        );
        let (y0, y1) = (
            (c0.y - rw - 4.0).floor().max(0.0) as u32,
            ((c0.y + rw + 4.0).ceil() as u32).min(lum.height - 1),
        );
        let mut ata = Matrix3::zeros();
        let mut atb = Vector3::zeros();
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = Vector2::new(x as f64, y as f64) - c0;
                let r = d.norm();
                if r > rw && r <= rw + 3.0 && !self.saturated[y as usize * w + x as usize] {
                    let a = Vector3::new(1.0, d.x, d.y);
                    ata += a * a.transpose();
                    atb += a * lum.at(x, y) as f64;
                }
            }
        }
        let plane = ata.try_inverse()? * atb;
        let (mut sw, mut sp) = (0.0, Vector2::zeros());
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = Vector2::new(x as f64, y as f64) - c0;
                if d.norm() <= rw {
                    let e =
                        (lum.at(x, y) as f64 - plane.dot(&Vector3::new(1.0, d.x, d.y))).max(0.0);
                    sw += e;
                    sp += d * e;
                }
            }
        }
        (sw > 0.0).then(|| c0 + sp / sw)
    }

    /// The centroid method, from a start pixel and a window radius (px).
    fn centroid(
        &self,
        start: Vector2<f64>,
        rw: f64,
        clipped: usize,
    ) -> Result<Highlight, NoHighlight> {
        let mut c = start;
        for _ in 0..3 {
            c = self.weighted(c, rw).unwrap_or(c);
        }
        let l = self
            .light_at(c)
            .ok_or_else(|| NoHighlight("highlight outside the sphere".into()))?;
        // A quarter-pixel position error, mapped through the reflection.
        let mut jm = Matrix3x2::zeros();
        for k in 0..2 {
            let mut d = Vector2::zeros();
            d[k] = 0.5;
            let (a, b2) = (self.light_at(c + d), self.light_at(c - d));
            let (Some(a), Some(b2)) = (a, b2) else {
                return Err(NoHighlight("highlight at the silhouette".into()));
            };
            jm.set_column(k, &(a - b2));
        }
        let cov = jm * Matrix2::identity() * 0.0625 * jm.transpose();
        Ok(Highlight {
            px: c,
            light: l,
            cov,
            method: Method::Centroid,
            alpha: None,
            alpha_std: None,
            saturated: clipped,
            radius: (rw / self.r_px).min(1.0).asin() * 2.0 + 0.02,
            trend_spread: 0.0,
        })
    }

    /// The centroid of a clipped blob.
    fn blob_centroid(&self, b: &crate::detect::silhouette::Blob) -> Result<Highlight, NoHighlight> {
        let c = Vector2::new(self.x0 as f64 + b.centroid.x, self.y0 as f64 + b.centroid.y);
        self.centroid(
            c,
            (b.area as f64 / std::f64::consts::PI).sqrt() + 3.0,
            b.area,
        )
    }

    /// The pixels whose half-vector for light `l0` lies within `theta_max` of their normal.
    fn patch(&self, l0: &Vector3<f64>, theta_max: f64) -> Vec<Px> {
        let mut pix = vec![];
        for j in 0..self.bh {
            for i in 0..self.bw {
                let Some((n, v)) = self.surf[j * self.bw + i] else {
                    continue;
                };
                let h = (l0 + v).normalize();
                if n.dot(&h).min(1.0).acos() < theta_max {
                    let px = self.pixel(i, j);
                    pix.push(Px {
                        px,
                        n,
                        v,
                        value: self.lum.at(px.x as u32, px.y as u32) as f64,
                        clipped: self.clipped[j * self.bw + i],
                    });
                }
            }
        }
        pix
    }

    /// Lobe fit in two passes: a 30° patch of half-vector angles (or the ring around a clipped
    /// core) tried from three roughnesses (the best fit with a positive lobe wins), then a patch
    /// sized by the fitted α. `None` when a pass has too few unclipped pixels or no lobe.
    fn lobe_fit(
        &self,
        l_start: Vector3<f64>,
        start_px: Vector2<f64>,
        core: &Core,
    ) -> Option<LobePass> {
        let mut result = None;
        let mut l0 = l_start;
        let mut starts = LOBE_STARTS.to_vec();
        // The first pass's patch: 30°, or the ring around a larger clipped core (a patch inside
        // the core leaves the fit only spikes between its few unclipped pixels).
        let mut theta_max = 30f64.to_radians().max(core.ring);
        for _pass in 0..2 {
            let pix = self.patch(&l0, theta_max);
            let unclipped = pix.iter().filter(|p| !p.clipped).count();
            if unclipped < 20 {
                return None;
            }
            let (e1, e2) = tangent_basis(&l0);
            let fit = Fit {
                l0,
                anchor: l_start,
                e1,
                e2,
                center: start_px,
                scale: theta_max.sin() * self.r_px,
                trend: Trend::Image,
            };
            let best_of = |starts: &[f64]| {
                starts
                    .iter()
                    .filter_map(|&a0: &f64| solve(&fit, &pix, Vector3::new(0.0, 0.0, a0.ln())))
                    // A lobe at the smallest roughness is a spike inside a clipped core, which
                    // the censored pixels cannot refute: not a candidate.
                    .filter(|(x, _, c, _)| {
                        c[NLIN - 1] > 0.0 && (MIN_ALPHA..MAX_ALPHA).contains(&x.z.exp())
                    })
                    .min_by(|a, b| a.1.norm_squared().total_cmp(&b.1.norm_squared()))
            };
            // The second pass starts from the first one's α, and from the three starts again
            // when that runs off (a patch grown around a large clipped core can lead it to a
            // spike).
            let best = best_of(&starts)
                .or_else(|| (starts.len() == 1).then(|| best_of(&LOBE_STARTS)).flatten());
            let (x, r, c, j) = best?;
            let l = fit.light(&x);
            let alpha = x.z.exp();
            let dof = unclipped.saturating_sub(NLIN + 3).max(1) as f64;
            let amp = c[NLIN - 1] * pix.iter().map(|p| shape(p, &l, alpha)).fold(0.0, f64::max);
            result = Some(LobePass {
                light: l,
                alpha,
                sigma2: r.norm_squared() / dof,
                amp,
                trend: c[0],
                jac: j,
                basis: (e1, e2),
                unclipped,
                fit,
                pix,
                x,
            });
            l0 = l;
            starts = vec![alpha];
            // At least twice the clipped core's angular radius: its ring is what locates the lobe.
            theta_max = (3.0 * alpha)
                .atan()
                .max(core.ring)
                .clamp(6f64.to_radians(), 45f64.to_radians());
        }
        result
    }

    /// A lobe fit as a highlight, when it is significant (6σ over the noise, 2% of the trend) and
    /// plausible (α inside its range, 20 unclipped pixels), and the lobe fitted with the other
    /// kind of diffuse trend lies near it: the light is their midpoint, and half their distance
    /// (or the shift when the clipped pixels are left out rather than censored) enters its
    /// covariance, isotropic in the tangent plane — an error of the trend model that σ²(JᵀJ)⁻¹
    /// does not see (a broad lobe trades with the shading under it).
    fn lobe_highlight(
        &self,
        pass: LobePass,
        noise: f64,
        clipped_area: usize,
        core: &Core,
    ) -> Option<Highlight> {
        let LobePass {
            light: l,
            alpha,
            sigma2,
            amp,
            trend,
            jac: j,
            basis: (b1, b2),
            unclipped: npix,
            fit,
            pix,
            x,
        } = pass;
        let significant = amp > 6.0 * sigma2.sqrt().max(noise) && amp > 0.02 * trend.abs();
        let plausible = interior(alpha) && npix >= 20;
        if !(significant && plausible) {
            return None;
        }
        let cov3 = (j.transpose() * &j).try_inverse()? * sigma2;
        // The angles are steps along the last pass's basis (b1, b2) at its start direction.
        let e = Matrix3x2::from_columns(&[b1, b2]);
        let c2 = Matrix2::new(cov3[(0, 0)], cov3[(0, 1)], cov3[(1, 0)], cov3[(1, 1)]);
        // Each alternative fit's light and roughness, when it finds a lobe.
        let refit = |f: &Fit, pix: &[Px]| {
            solve(f, pix, x)
                .and_then(with_lobe)
                .map(|(x2, _)| (f.light(&x2), x2.z.exp()))
        };
        let dof = npix.saturating_sub(NLIN + 3).max(1) as f64;
        let shading = shading_refit(
            &Fit {
                trend: Trend::Shading,
                ..fit
            },
            &pix,
            x,
            sigma2 * dof,
        );
        let uncensored = if pix.iter().any(|p| p.clipped) {
            let kept: Vec<Px> = pix.iter().filter(|p| !p.clipped).copied().collect();
            refit(&fit, &kept)
        } else {
            None
        };
        let (l, spread, alpha_spread) = match shading {
            Some((l2, a2)) if l2.angle(&l) < 0.35 => {
                let mid = (l + l2).normalize();
                let (censoring, alpha_censoring) =
                    uncensored.map_or((0.0, 0.0), |(l3, a3)| (l3.angle(&l), (a3 - alpha).abs()));
                (
                    mid,
                    (0.5 * l2.angle(&l)).max(censoring),
                    (0.5 * (a2 - alpha).abs()).max(alpha_censoring),
                )
            }
            // The other trend found no lobe, or one far away: the trend decides, so the light is
            // not measured by this highlight.
            _ => return None,
        };
        // x.z is ln α: its variance times α² is α's.
        let alpha_std =
            (alpha * alpha * cov3[(2, 2)].max(0.0) + alpha_spread * alpha_spread).sqrt();
        let q = self.outline.mirror_point(&l)?;
        let px = self.proj.pixel(&q)?;
        let tangent = Matrix3::identity() - l * l.transpose();
        Some(Highlight {
            px,
            light: l,
            cov: e * c2 * e.transpose() + tangent * spread * spread,
            method: Method::LobeFit,
            alpha: Some(alpha),
            alpha_std: Some(alpha_std),
            saturated: clipped_area,
            // Past a clipped core: the solve keeps the pixels within this radius for the lobe,
            // and one inside the core left it none (0.9° of light error at 26% clipped). 6° past
            // the core, not the whole ring the fit used: the ring's outer pixels cost the solved
            // light (0.017° against 0.010° at 6% clipped) and time.
            radius: (3.0 * alpha).atan().max(2f64.to_radians()).max(core.past),
            trend_spread: spread,
        })
    }
}

/// Find the highlight on one sphere. `lum` is the luminance, `saturated` the clipped pixels,
/// `noise` the image noise level (image units) used to judge significance. The steps: the
/// sphere's pixels, the peak candidate, the clipped blob nearest it, the lobe fit from the blob
/// or the peak, and the choice between the lobe and a centroid.
pub fn find(
    lum: &Plane,
    saturated: &[bool],
    proj: &Projection,
    outline: &Outline,
    noise: f64,
) -> Result<Highlight, NoHighlight> {
    let area = Area::of(lum, saturated, proj, outline)?;
    let Some((excess, pi, pj)) = area.peak() else {
        return Err(NoHighlight("sphere too small to search".into()));
    };
    let peak = area.pixel(pi, pj);
    let sat_blob = area.clipped_blob(pi, pj);
    // More than half the disc clipped is clipped diffuse shading, not a highlight.
    let clipped = area.clipped.iter().filter(|&&m| m).count();
    let disc = std::f64::consts::PI * area.r_px * area.r_px;
    let clipped_frac = clipped as f64 / disc;
    if clipped_frac > MAX_CLIPPED {
        return Err(NoHighlight(format!(
            "{clipped} px ({:.0}% of the sphere) clipped: lower the exposure",
            100.0 * clipped_frac
        )));
    }
    let start_px = match &sat_blob {
        Some(b) => Vector2::new(area.x0 as f64 + b.centroid.x, area.y0 as f64 + b.centroid.y),
        None => peak,
    };
    let Some(l_start) = area.light_at(start_px) else {
        return Err(NoHighlight("peak outside the sphere".into()));
    };
    let core = Core::of(sat_blob.as_ref(), area.r_px);
    let clipped_area = sat_blob.as_ref().map_or(0, |b| b.area);
    let fitted = area
        .lobe_fit(l_start, start_px, &core)
        .and_then(|pass| area.lobe_highlight(pass, noise, clipped_area, &core));
    // A clipped highlight whose lobe spans only a few pixels is located better by the centroid
    // of its clipped blob than by a lobe fitted to the handful of pixels around it.
    let resolved = |h: &Highlight| h.alpha.is_some_and(|a| a * area.r_px >= RESOLVED_PX);
    match (fitted, &sat_blob) {
        (Some(h), Some(b)) if !resolved(&h) && clipped_frac <= CENTROID_CLIPPED => {
            area.blob_centroid(b)
        }
        (Some(h), None) if !resolved(&h) => area.centroid(
            h.px,
            (3.0 * h.alpha.unwrap_or(0.0) * area.r_px).max(2.0) + 1.0,
            0,
        ),
        (Some(h), _) => Ok(h),
        // The centroid of a large clipped core is pulled by the diffuse shading under it: only a
        // small one is located that way.
        (None, Some(b)) if clipped_frac <= CENTROID_CLIPPED => area.blob_centroid(b),
        (None, Some(_)) => Err(NoHighlight(format!(
            "{clipped} px ({:.0}% of the sphere) clipped, and the unclipped ring around them does not determine the lobe (no significant, plausible fit): lower the exposure",
            100.0 * clipped_frac
        ))),
        (None, None) => Err(NoHighlight(format!(
            "no significant specular peak (largest local excess {excess:.3e}, noise {noise:.1e})"
        ))),
    }
}

/// A robust combination of light estimates (unit vectors with 3×3 covariances).
#[derive(Clone, Debug, PartialEq)]
pub struct Combined {
    pub light: Vector3<f64>,
    pub cov: Matrix3<f64>,
    /// Per estimate: whether it was rejected as an outlier.
    pub outlier: Vec<bool>,
    /// How far each kept estimate scatters beyond its own error (radians, isotropic): the
    /// random-effects τ of [`combine`], 0 where they agree within their errors.
    pub tau: f64,
}

impl Combined {
    pub fn std(&self) -> f64 {
        self.cov.symmetric_eigenvalues().max().max(0.0).sqrt()
    }
}

/// The least error the spheres of a session share (radians): on the project's own renders the
/// combined light lies 0.01–0.05° from the truth with formal errors of 0.012–0.016° (black, grey
/// card, table; docs/measurements/detection.md), the same sign on every sphere, so averaging does not remove it.
pub(crate) const SHARED_FLOOR: f64 = 0.03 * std::f64::consts::PI / 180.0;

/// Combine highlights' lights ([`combine`]); the trend-model error, shared by every sphere and so
/// not averaged down, is added back: the median `trend_spread` of the estimates kept (at least
/// [`SHARED_FLOOR`]), isotropic in the tangent plane.
pub(crate) fn combine_highlights(hs: &[&Highlight], floor: f64) -> Option<Combined> {
    let est: Vec<_> = hs.iter().map(|h| (h.light, h.cov)).collect();
    let mut c = combine(&est, floor)?;
    let kept: Vec<f64> = hs
        .iter()
        .zip(&c.outlier)
        .filter(|(_, &o)| !o)
        .map(|(h, _)| h.trend_spread)
        .collect();
    let s = crate::stats::percentile(kept, 0.5);
    let s = if s.is_finite() { s } else { 0.0 }.max(SHARED_FLOOR);
    c.cov += (Matrix3::identity() - c.light * c.light.transpose()) * s * s;
    Some(c)
}

/// Combine light estimates, each with its covariance floored at `floor` radians (a modelling
/// error the statistics do not see):
///
/// 1. **Outliers**: IRLS with Huber weights on the Mahalanobis distance, from the medoid;
///    estimates beyond 5σ are set aside while they are a minority of at most
///    max(1, ⌊(n − 1)/3⌋) of n ≥ 3 (one of three to six spheres; none of two).
/// 2. **Errors that scale with the stated ones** (the usual case: the kept estimates agree, or
///    scatter in proportion to their errors): the Huber-weighted mean, its covariance inflated
///    by the reduced χ² (the Birge ratio) where the scatter exceeds the errors.
/// 3. **Scatter beyond every error**: where more than that minority lies beyond 5σ, the spheres
///    are not a few broken ones but each moved its own way by something the formal errors do
///    not see (a disturbed outline: a composited backdrop, a stand, a shadow). Setting most of
///    them aside would keep whichever few happen to agree, with those few's small errors. So
///    every estimate is kept and combined as a random-effects mean: each covariance plus τ²
///    (isotropic in the tangent plane), τ² chosen so that the scatter's χ² equals its 2(n − 1)
///    degrees of freedom (Paule–Mandel). The estimates then weigh nearly alike and the stated
///    error is their scatter's.
///
/// `Combined::tau` is the Paule–Mandel τ of the kept estimates in either case (0 where they
/// agree within their errors).
pub(crate) fn combine(est: &[(Vector3<f64>, Matrix3<f64>)], floor: f64) -> Option<Combined> {
    if est.is_empty() {
        return None;
    }
    let medoid = est
        .iter()
        .min_by(|a, b| {
            let sa: f64 = est.iter().map(|e| a.0.angle(&e.0)).sum();
            let sb: f64 = est.iter().map(|e| b.0.angle(&e.0)).sum();
            sa.total_cmp(&sb)
        })?
        .0;
    let n = est.len();
    let mut excluded = vec![false; n];
    let mut m = medoid;
    // How many lie beyond 5σ: those set aside, and those the last round would set aside.
    let mut beyond = 0;
    for _round in 0..5 {
        let (mean, _, r) = weighted_mean(est, &excluded, m, floor * floor, true)?;
        m = mean;
        let newly: Vec<usize> = (0..n).filter(|&i| !excluded[i] && r[i] > 5.0).collect();
        beyond = excluded.iter().filter(|&&x| x).count() + newly.len();
        if newly.is_empty() || excluded.iter().filter(|&&x| !x).count() <= newly.len() {
            break;
        }
        for i in newly {
            excluded[i] = true;
        }
    }
    let scattered = beyond > if n >= 3 { ((n - 1) / 3).max(1) } else { 0 };
    if scattered {
        excluded = vec![false; n];
    }
    let kept = excluded.iter().filter(|&&x| !x).count();
    let dof = 2.0 * (kept as f64 - 1.0);
    let (tau2, (mut m, mut info, _)) = paule_mandel(est, &excluded, m, floor, dof)?;
    if !scattered {
        let r;
        (m, info, r) = weighted_mean(est, &excluded, m, floor * floor, true)?;
        let chi2: f64 = r
            .iter()
            .zip(&excluded)
            .filter(|(_, &x)| !x)
            .map(|(&r, _)| if r > 2.5 { 2.5 * r } else { r * r })
            .sum();
        if kept > 1 {
            info /= (chi2 / dof).max(1.0);
        }
    }
    let (e1, e2) = tangent_basis(&m);
    let e = Matrix3x2::from_columns(&[e1, e2]);
    Some(Combined {
        light: m,
        cov: e * info.try_inverse()? * e.transpose(),
        outlier: excluded,
        tau: tau2.sqrt(),
    })
}

/// The Paule–Mandel τ² of the estimates not `excluded`: 0 where their χ² about the weighted mean
/// is within `dof`, else the τ² at which it equals `dof` (χ² falls monotonically in τ²: bracketed
/// by quadrupling, then bisected in log τ²). With it, the random-effects mean
/// ([`weighted_mean`] with the covariances plus τ² + floor²).
#[allow(clippy::type_complexity)]
fn paule_mandel(
    est: &[(Vector3<f64>, Matrix3<f64>)],
    excluded: &[bool],
    m: Vector3<f64>,
    floor: f64,
    dof: f64,
) -> Option<(f64, (Vector3<f64>, Matrix2<f64>, Vec<f64>))> {
    let chi2_at = |tau2: f64| {
        weighted_mean(est, excluded, m, floor * floor + tau2, false).map(|(m, info, r)| {
            let chi2 = r
                .iter()
                .zip(excluded)
                .filter(|(_, &x)| !x)
                .map(|(r, _)| r * r);
            let chi2 = chi2.sum::<f64>();
            (chi2, (m, info, r))
        })
    };
    let (chi2, at_zero) = chi2_at(0.0)?;
    if dof <= 0.0 || chi2 <= dof {
        return Some((0.0, at_zero));
    }
    let spread = est
        .iter()
        .zip(excluded)
        .filter(|(_, &x)| !x)
        .map(|(e, _)| e.0.angle(&at_zero.0).powi(2))
        .sum::<f64>()
        / (dof / 2.0 + 1.0);
    let (mut lo, mut hi) = (spread * 1e-6, spread.max(1e-18));
    while chi2_at(hi)?.0 > dof {
        hi *= 4.0;
    }
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        if chi2_at(mid)?.0 > dof {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some((hi, chi2_at(hi)?.1))
}

/// The weighted mean of the estimates not `excluded` (Newton steps in the tangent plane from
/// `m`), each with its covariance plus `var` times the identity, Huber-weighted at 2.5σ when
/// `huber`: the mean, its information matrix (in `tangent_basis(mean)`) and every estimate's
/// Mahalanobis distance from it.
fn weighted_mean(
    est: &[(Vector3<f64>, Matrix3<f64>)],
    excluded: &[bool],
    mut m: Vector3<f64>,
    var: f64,
    huber: bool,
) -> Option<(Vector3<f64>, Matrix2<f64>, Vec<f64>)> {
    let mut r = vec![0.0; est.len()];
    let mut info = Matrix2::zeros();
    for _ in 0..50 {
        let (e1, e2) = tangent_basis(&m);
        let e = Matrix3x2::from_columns(&[e1, e2]);
        info = Matrix2::zeros();
        let mut rhs = Vector2::zeros();
        for (i, (l, c)) in est.iter().enumerate() {
            // Residual and weight in the estimate's own tangent plane (its covariance is
            // degenerate along l, which another plane would not see), mapped to m's plane.
            let (f1, f2) = tangent_basis(l);
            let ei = Matrix3x2::from_columns(&[f1, f2]);
            let d = ei.transpose() * (l - m);
            let wm = (ei.transpose() * c * ei + Matrix2::identity() * var).try_inverse()?;
            let jm = ei.transpose() * e;
            r[i] = (d.transpose() * wm * d)[0].max(0.0).sqrt();
            let w = match (excluded[i], huber && r[i] > 2.5) {
                (true, _) => 0.0,
                (false, true) => 2.5 / r[i],
                (false, false) => 1.0,
            };
            info += jm.transpose() * wm * jm * w;
            rhs += jm.transpose() * wm * d * w;
        }
        let step = info.try_inverse()? * rhs;
        m = (m + e * step).normalize();
        if step.norm() < 1e-14 {
            break;
        }
    }
    Some((m, info, r))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A patch of a 1-unit sphere seen from 10 units away: a lobe on a shading trend, with the
    /// brightest `clip` share of the pixels clipped, under a light a little off the starting one.
    fn patch_and_fit(trend: Trend, clip: f64) -> (Vec<Px>, Fit, Vector3<f64>) {
        let truth = Vector3::new(0.25, -0.3, -0.92).normalize();
        let cam = Vector3::new(0.0, 0.0, -10.0);
        let l0 = Vector3::new(0.2, -0.28, -0.94).normalize();
        let (e1, e2) = tangent_basis(&l0);
        let mut pix = vec![];
        for i in 0..40 {
            for j in 0..40 {
                let (u, w) = (-0.9 + 1.8 * i as f64 / 39.0, -0.9 + 1.8 * j as f64 / 39.0);
                let z2 = 1.0 - u * u - w * w;
                if z2 <= 0.05 {
                    continue;
                }
                let n = Vector3::new(u, w, -z2.sqrt());
                let v = (cam - n).normalize();
                let value = 0.3
                    + 0.5 * n.dot(&truth).max(0.0)
                    + 0.02 * u
                    + 0.4
                        * specular::lobe(n.dot(&truth), n.dot(&v), truth.dot(&v), 1.0, 0.08, ETA)
                            .value
                    + 0.01 * ((i * 7 + j * 13) % 11) as f64 / 11.0;
                pix.push(Px {
                    px: Vector2::new(i as f64, j as f64),
                    n,
                    v,
                    value,
                    clipped: false,
                });
            }
        }
        let mut vals: Vec<f64> = pix.iter().map(|p| p.value).collect();
        vals.sort_by(|a, b| a.total_cmp(b));
        let clip = if clip > 0.0 {
            vals[((1.0 - clip) * vals.len() as f64) as usize]
        } else {
            f64::INFINITY
        };
        for p in &mut pix {
            if p.value >= clip {
                p.value = clip;
                p.clipped = true;
            }
        }
        let fit = Fit {
            l0,
            anchor: l0,
            e1,
            e2,
            center: Vector2::new(20.0, 20.0),
            scale: 20.0,
            trend,
        };
        (pix, fit, Vector3::new(0.01, -0.02, 0.1f64.ln()))
    }

    /// [`shading_refit`]: within [`FAILED_REFIT`] of the image trend's sum of squares the refit
    /// from the image trend's solution is kept as it ends; beyond it at every start, the
    /// highlight gives no light.
    #[test]
    fn a_shading_refit_that_stops_short_is_not_kept() {
        let (pix, fit, x) = patch_and_fit(Trend::Shading, 0.0);
        let (x1, r1, _, _) = solve(&fit, &pix, x).expect("the refit ends");
        let ss = r1.norm_squared();
        let kept = shading_refit(&fit, &pix, x, ss).expect("within the bound");
        assert_eq!(kept, (fit.light(&x1), x1.z.exp()));
        // Every start ends above 3 times a sum of squares a tenth of the best.
        let best = LOBE_STARTS
            .iter()
            .filter_map(|a| solve(&fit, &pix, Vector3::new(x.x, x.y, a.ln())))
            .map(|s| s.1.norm_squared())
            .fold(ss, f64::min);
        assert!(best > 0.0);
        assert_eq!(shading_refit(&fit, &pix, x, 0.1 * best), None);
    }

    /// The variable projection's Jacobian against central differences of the residuals, for
    /// both trends, with clipped pixels in and out of the active set (the image trend; the
    /// shading trend's active set does not settle on this patch, so it is checked unclipped).
    #[test]
    fn lobe_jacobian_matches_finite_differences() {
        for (trend, clip) in [
            (Trend::Image, 0.03),
            (Trend::Image, 0.0),
            (Trend::Shading, 0.0),
        ] {
            let (pix, fit, x) = patch_and_fit(trend, clip);
            assert_eq!(pix.iter().any(|p| p.clipped), clip > 0.0);
            let (r, _, j) = fit.residuals_and_jacobian(&pix, &x).unwrap();
            let (r0, _) = fit.residuals(&pix, &x).unwrap();
            assert!((&r - &r0).norm() <= 1e-14 * r0.norm().max(1.0));
            // Central differences, Richardson-extrapolated (error O(h⁴)).
            let central = |k: usize, h: f64| {
                let mut d = Vector3::zeros();
                d[k] = h;
                let (rp, _) = fit.residuals(&pix, &(x + d)).unwrap();
                let (rm, _) = fit.residuals(&pix, &(x - d)).unwrap();
                (rp - rm) / (2.0 * h)
            };
            // Errors against the largest column: the α column is the smallest, and what rounding
            // leaves of a difference quotient is the same size in every column.
            let scale = (0..3).map(|k| j.column(k).norm()).fold(0.0, f64::max);
            // The shading trend's basis is ill-conditioned: a longer step keeps rounding down,
            // and rounding leaves ~1e-6 of the scale (the image trend's ~1e-9).
            let (h, tol) = match trend {
                Trend::Shading => (1e-3, 3e-6),
                Trend::Image => (1e-4, 1e-8),
            };
            for k in 0..3 {
                let fd = (central(k, 0.5 * h) * 4.0 - central(k, h)) / 3.0;
                let err = (&fd - j.column(k)).norm() / scale;
                assert!(fd.norm() > 1e-2 * scale, "{trend:?} column {k} is empty");
                assert!(err < tol, "{trend:?} column {k}: relative error {err:e}");
            }
        }
    }

    #[test]
    fn combine_rejects_an_outlier_and_averages_the_rest() {
        let truth = Vector3::new(0.3, -0.4, -0.8).normalize();
        let (e1, e2) = tangent_basis(&truth);
        let s = 1e-3;
        let c = (e1 * e1.transpose() + e2 * e2.transpose()) * s * s;
        let offs = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)];
        let mut est: Vec<_> = offs
            .iter()
            .map(|&(a, b)| ((truth + e1 * (a * s) + e2 * (b * s)).normalize(), c))
            .collect();
        est.push(((truth + e1 * 0.2).normalize(), c));
        let k = combine(&est, 0.0).unwrap();
        assert!(k.light.angle(&truth) < 1e-9, "{}", k.light.angle(&truth));
        assert_eq!(k.outlier, [false, false, false, false, true]);
        // Four unit-σ estimates: combined σ ≈ s/2 (scatter consistent, no inflation).
        assert!((k.std() - s / 2.0).abs() < 0.2 * s, "{}", k.std());
    }

    /// Five estimates whose scatter (about 10 of their errors) is systematic, not a few broken
    /// ones: none is set aside, they weigh alike (the best one does not win), and the stated error
    /// is the scatter's: for five points of one spread s in the plane, the random-effects mean's
    /// std is (Σ|d|²/(2·4))^½/√5 by the Paule–Mandel condition, computed here independently.
    #[test]
    fn combine_widens_for_estimates_that_scatter_beyond_their_errors() {
        let truth = Vector3::new(0.3, -0.4, -0.8).normalize();
        let (e1, e2) = tangent_basis(&truth);
        let offs = [
            (0.4, 0.1),
            (0.3, -0.2),
            (0.0, 0.05),
            (-0.2, 0.25),
            (-0.5, -0.2),
        ];
        let sig = [0.015, 0.02, 0.024, 0.031, 0.04];
        let deg = std::f64::consts::PI / 180.0;
        let est: Vec<_> = offs
            .iter()
            .zip(sig)
            .map(|(&(a, b), s)| {
                let l = (truth + (e1 * a + e2 * b) * deg).normalize();
                let (f1, f2) = tangent_basis(&l);
                (
                    l,
                    (f1 * f1.transpose() + f2 * f2.transpose()) * (s * deg).powi(2),
                )
            })
            .collect();
        let k = combine(&est, 0.0).unwrap();
        assert_eq!(k.outlier, [false; 5]);
        // The plain mean of the offsets is (0, 0): with τ ≫ the errors the weights are nearly equal.
        assert!(
            k.light.angle(&truth) / deg < 0.01,
            "{}",
            k.light.angle(&truth) / deg
        );
        let ss: f64 = offs.iter().map(|(a, b)| a * a + b * b).sum();
        let expected = (ss / 8.0).sqrt() / 5f64.sqrt();
        let got = k.std() / deg;
        assert!(
            (got / expected - 1.0).abs() < 0.1,
            "{got} against {expected}"
        );
    }
}
