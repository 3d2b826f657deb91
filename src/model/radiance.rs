//! The radiance model workbench fits, per colour channel c:
//!
//!     L_c = a_c(r) · T(φ; η) · f(θ; σ_c(r))  +  ks · D · G · F(l·h; η) / (4 n·v)
//!     σ_c(r) = (σ0_c / r) · (r_ref / r)^q,     a_c(r) = a_c · exp(b · (r_ref / r − 1))
//!
//! with θ = angle(n, l), φ = angle(n, v), f the CDRF ([`crate::model::cdrf`]) — the blur along θ of
//! the clamped cosine, or with `entry_fresnel` of the irradiance transmitted into the medium,
//! max(cos θ, 0)·T(cos θ; η) ([`crate::model::entry`]) —,
//! T = 1 − F the exact Fresnel transmission ([`crate::model::fresnel`]), and the GGX lobe
//! ([`crate::model::specular`]).
//! The light's irradiance is folded into a_c and ks. The light direction is two angles
//! ([`LightAngles`]). Parameters are physical here; the solver maps them to unbounded ones.
//!
//! q (`sigma_exponent`) and b (`albedo_curvature`) are extensions of the plain CDRF (both 0):
//! q > 0 makes σ·r grow as r shrinks, b > 0 makes small spheres brighter. The reference radius
//! r_ref ([`Model::reference_radius_mm`]) is where σ0 and the albedo keep their plain meaning.
//!
//! The kernel's shape (`kernel_weight` w, `kernel_ratio` s) is the third extension: the blur is a
//! sum of two Gaussians, f → (1 − w)·f(θ; σ_c) + w·f(θ; s·σ_c) ([`mixture::eval`]), one shape
//! shared by the channels, each channel's width scaled by its σ0 (w = 0: the plain Gaussian).

use crate::model::cdrf::Convolution;
use crate::model::entry;
use crate::model::fresnel;
use crate::model::lanes::{f64x4, Real};
use crate::model::mixture::{self, Blur};
use crate::model::specular;
use crate::model::table::{Slice, Table};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Number of model parameters: σ0 ×3, albedo ×3, η, ks, α, light azimuth, light elevation,
/// the two extensions q and b, and the kernel's weight and width ratio.
pub const N_PARAMS: usize = 15;
/// Parameter indices into a gradient row.
pub mod idx {
    pub const SIGMA0: usize = 0; // .. 3
    pub const ALBEDO: usize = 3; // .. 6
    pub const ETA: usize = 6;
    pub const KS: usize = 7;
    pub const ALPHA: usize = 8;
    pub const AZIMUTH: usize = 9;
    pub const ELEVATION: usize = 10;
    pub const SIGMA_EXPONENT: usize = 11;
    pub const ALBEDO_CURVATURE: usize = 12;
    pub const KERNEL_WEIGHT: usize = 13;
    pub const KERNEL_RATIO: usize = 14;
}
/// Human-readable parameter names, in index order.
pub const PARAM_NAMES: [&str; N_PARAMS] = [
    "sigma0_r",
    "sigma0_g",
    "sigma0_b",
    "albedo_r",
    "albedo_g",
    "albedo_b",
    "eta",
    "ks",
    "alpha",
    "light_azimuth",
    "light_elevation",
    "sigma_exponent",
    "albedo_curvature",
    "kernel_weight",
    "kernel_ratio",
];

/// Material parameters, named as in `truth.json` and `fit.json`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Scattering length per channel (mm): σ = σ0 / r radians on a sphere of radius r.
    pub sigma0_mm: [f64; 3],
    /// Diffuse albedo per channel, light irradiance folded in.
    pub albedo: [f64; 3],
    /// Index of refraction.
    pub eta: f64,
    pub specular: SpecularParams,
    /// Extension q: σ = (σ0 / r) · (r_ref / r)^q (0: the plain CDRF).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub sigma_exponent: f64,
    /// Extension b: albedo · exp(b · (r_ref / r − 1)) (0: the same albedo at every radius).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub albedo_curvature: f64,
    /// The kernel's tail weight w ∈ [0, 1) (0: one Gaussian).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub kernel_weight: f64,
    /// The tail's width over the core's, s > 1 (unused when w = 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub kernel_ratio: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpecularParams {
    /// Lobe scale (light irradiance folded in; 1 for a physical dielectric lobe under unit light).
    pub ks: f64,
    /// GGX roughness α.
    pub alpha: f64,
}

/// A light's direction l and its derivatives ∂l/∂azimuth, ∂l/∂elevation ([`LightAngles::frame`]):
/// what every pixel of one evaluation shares ([`Prepared`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightFrame {
    pub l: Vector3<f64>,
    pub dl_da: Vector3<f64>,
    pub dl_de: Vector3<f64>,
}

/// Light direction as azimuth and elevation (radians), camera frame:
/// l = (cos e · sin a, −sin e, −cos e · cos a). (0, 0) is a light at the camera; positive azimuth
/// is toward +x (right), positive elevation toward −y (up). Both poles (light straight above or
/// below) are the only singular directions; the camera axis and the back-light are regular.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightAngles {
    pub azimuth: f64,
    pub elevation: f64,
}

impl LightAngles {
    pub fn direction(&self) -> Vector3<f64> {
        let (sa, ca) = self.azimuth.sin_cos();
        let (se, ce) = self.elevation.sin_cos();
        Vector3::new(ce * sa, -se, -ce * ca)
    }

    /// The direction and its derivatives, computed once for many pixels.
    pub fn frame(&self) -> LightFrame {
        let (dl_da, dl_de) = self.jacobian();
        LightFrame {
            l: self.direction(),
            dl_da,
            dl_de,
        }
    }

    /// ∂l/∂azimuth and ∂l/∂elevation.
    pub(crate) fn jacobian(&self) -> (Vector3<f64>, Vector3<f64>) {
        let (sa, ca) = self.azimuth.sin_cos();
        let (se, ce) = self.elevation.sin_cos();
        (
            Vector3::new(ce * ca, 0.0, ce * sa),
            Vector3::new(-se * sa, -ce, se * ca),
        )
    }

    /// Angles of a direction (normalised first).
    pub fn from_direction(l: &Vector3<f64>) -> LightAngles {
        let l = l.normalize();
        LightAngles {
            elevation: (-l.y).clamp(-1.0, 1.0).asin(),
            azimuth: l.x.atan2(-l.z),
        }
    }
}

/// Everything the model needs besides geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    pub material: Material,
    pub light: LightAngles,
}

impl Params {
    /// A diffuse-only material (ks = 0, α = 0.1 for when a lobe is switched on, no extensions).
    pub fn diffuse(sigma0_mm: [f64; 3], albedo: [f64; 3], eta: f64, light: LightAngles) -> Params {
        Params {
            material: Material {
                sigma0_mm,
                albedo,
                eta,
                specular: SpecularParams {
                    ks: 0.0,
                    alpha: 0.1,
                },
                sigma_exponent: 0.0,
                albedo_curvature: 0.0,
                kernel_weight: 0.0,
                kernel_ratio: 0.0,
            },
            light,
        }
    }

    pub fn to_vec(&self) -> [f64; N_PARAMS] {
        let m = &self.material;
        [
            m.sigma0_mm[0],
            m.sigma0_mm[1],
            m.sigma0_mm[2],
            m.albedo[0],
            m.albedo[1],
            m.albedo[2],
            m.eta,
            m.specular.ks,
            m.specular.alpha,
            self.light.azimuth,
            self.light.elevation,
            m.sigma_exponent,
            m.albedo_curvature,
            m.kernel_weight,
            m.kernel_ratio,
        ]
    }

    pub fn from_vec(p: &[f64; N_PARAMS]) -> Params {
        Params {
            material: Material {
                sigma0_mm: [p[0], p[1], p[2]],
                albedo: [p[3], p[4], p[5]],
                eta: p[6],
                specular: SpecularParams {
                    ks: p[7],
                    alpha: p[8],
                },
                sigma_exponent: p[11],
                albedo_curvature: p[12],
                kernel_weight: p[13],
                kernel_ratio: p[14],
            },
            light: LightAngles {
                azimuth: p[9],
                elevation: p[10],
            },
        }
    }
}

/// Per-pixel geometry: unit normal, unit view vector, local radius of curvature (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    pub normal: Vector3<f64>,
    pub view: Vector3<f64>,
    pub radius_mm: f64,
}

/// The radiance model with its structural choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Model {
    pub convolution: Convolution,
    /// r_ref of the extensions (mm).
    pub reference_radius_mm: f64,
    /// Multiply the diffuse term by the exit transmission T(φ) (the paper's baseline divides the
    /// data by it instead and turns this off).
    pub exit_fresnel: bool,
    /// Blur the transmitted irradiance max(cos θ, 0)·T(cos θ; η) instead of the bare clamped
    /// cosine ([`crate::model::entry`]). Off by default (`solve --entry-transmission` turns it on; why
    /// not yet by default: docs/uncertainty.md).
    pub entry_fresnel: bool,
    /// Evaluate the wrapped CDRF from its table ([`crate::model::table`]: within 1e-7 of the
    /// closed form, several times faster) instead of the closed form. On by default; synthetic
    /// ground truth is rendered with the closed form.
    pub tabulated: bool,
}

/// The reference radius of the extensions: the middle of the usual 15–35 mm sphere sets.
pub(crate) const REFERENCE_RADIUS_MM: f64 = 25.0;

impl Default for Model {
    fn default() -> Self {
        Model {
            convolution: Convolution::default(),
            reference_radius_mm: REFERENCE_RADIUS_MM,
            exit_fresnel: true,
            entry_fresnel: false,
            tabulated: true,
        }
    }
}

/// Model output for one pixel: RGB radiance and, optionally, ∂L_c/∂p for every parameter.
pub type Rgb = [f64; 3];
pub type Gradient = [[f64; N_PARAMS]; 3];

impl Model {
    /// The diffuse term's blur σ_c (radians) and albedo a_c at curvature κ = 1/r (1/mm), as in the
    /// module formula; κ = 0 is a flat surface (the limit r → ∞: σ = 0 unless q ≤ −1).
    pub(crate) fn diffuse_terms(&self, m: &Material, kappa: f64) -> ([f64; 3], [f64; 3]) {
        // κ = 0 evaluated as the limit κ → 0⁺ (a tiny κ gives σ = 0 for q > −1, σ0 / r_ref for
        // q = −1 and ∞ below, without 0 · ∞).
        let kappa = kappa.max(1e-300);
        let rr = self.reference_radius_mm * kappa;
        let scale = rr.powf(m.sigma_exponent);
        let albedo_scale = (m.albedo_curvature * (rr - 1.0)).exp();
        let sigma = std::array::from_fn(|c| (m.sigma0_mm[c] * kappa) * scale);
        (sigma, std::array::from_fn(|c| m.albedo[c] * albedo_scale))
    }

    /// The diffuse term without exit transmission, a_c · f(θ; σ_c), at cos θ = n·l and κ = 1/r:
    /// what the renderer's look-up table (`render::lut`) holds.
    pub fn diffuse(&self, m: &Material, cos_theta: f64, kappa: f64) -> Rgb {
        let theta = cos_theta.clamp(-1.0, 1.0).acos();
        let (sigma, albedo) = self.diffuse_terms(m, kappa);
        std::array::from_fn(|c| albedo[c] * self.profile(m, theta, sigma[c]).f.value)
    }

    /// The blur profile at θ for a core width σ: one Gaussian or two, of the clamped cosine or
    /// of the transmitted irradiance (`entry_fresnel`, its `d_param` then ∂/∂η).
    pub(crate) fn profile(&self, m: &Material, theta: f64, sigma: f64) -> mixture::MixtureEval {
        self.profile_with(m, theta, sigma, [None, None])
    }

    /// [`Self::profile`] with the table's slices at the core's and the tail's widths, where the
    /// caller has them ([`Prepared`]).
    fn profile_with(
        &self,
        m: &Material,
        theta: f64,
        sigma: f64,
        slices: [Option<&Slice>; 2],
    ) -> mixture::MixtureEval {
        let (w, s, conv) = (m.kernel_weight, m.kernel_ratio, self.convolution);
        if self.entry_fresnel {
            entry::with_series(m.eta, |series| {
                mixture::eval(theta, sigma, (w, s), Some(series), Blur::Closed(conv))
            })
        } else if self.tabulated && conv == Convolution::Wrapped {
            mixture::eval(theta, sigma, (w, s), None, Blur::Table(slices))
        } else {
            mixture::eval(theta, sigma, (w, s), None, Blur::Closed(conv))
        }
    }

    /// σ_c / σ0_c at a radius: (r_ref / r)^q, exactly 1 with the extension off.
    fn sigma_scale(&self, m: &Material, radius_mm: f64) -> f64 {
        if m.sigma_exponent == 0.0 {
            1.0
        } else {
            (self.reference_radius_mm / radius_mm).powf(m.sigma_exponent)
        }
    }

    /// The model at `p` for many pixels ([`Prepared`]): the light's frame and, with the tabulated
    /// CDRF, the table's slices at the blur widths of each distinct radius in `radii` (the first
    /// [`MAX_SLICED_RADII`]; pixels of other radii read the whole table).
    pub fn prepare(&self, p: &Params, radii: impl IntoIterator<Item = f64>) -> Prepared {
        let mut distinct: Vec<f64> = vec![];
        let mut last = f64::NAN;
        for r in radii {
            if r != last && distinct.len() < MAX_SLICED_RADII && !distinct.contains(&r) {
                distinct.push(r);
            }
            last = r;
        }
        let sliced =
            self.tabulated && !self.entry_fresnel && self.convolution == Convolution::Wrapped;
        let m = &p.material;
        let table = Table::shared();
        let slices = if sliced {
            distinct
                .into_iter()
                .map(|r| {
                    // σ_c as `eval` computes it, to the bit: a slice serves only its own σ.
                    let scale = self.sigma_scale(m, r);
                    let sigma: [f64; 3] = std::array::from_fn(|c| m.sigma0_mm[c] / r * scale);
                    let core = sigma.map(|s| table.slice(s));
                    let tail = sigma.map(|s| {
                        (m.kernel_weight != 0.0)
                            .then(|| table.slice(m.kernel_ratio * s))
                            .flatten()
                    });
                    // Four pixels at a time need every slice this radius reads.
                    let lanes = core.iter().all(Option::is_some)
                        && (m.kernel_weight == 0.0 || tail.iter().all(Option::is_some));
                    RadiusSlices {
                        radius_mm: r,
                        ln_rr: (self.reference_radius_mm / r).ln(),
                        core,
                        tail,
                        lanes,
                    }
                })
                .collect()
        } else {
            vec![]
        };
        Prepared {
            model: *self,
            params: *p,
            frame: p.light.frame(),
            slices,
        }
    }

    /// RGB radiance at one surface point.
    pub fn radiance(&self, p: &Params, g: &Geometry) -> Rgb {
        let light = LightFrame {
            l: p.light.direction(),
            dl_da: Vector3::zeros(),
            dl_de: Vector3::zeros(),
        };
        self.eval(p, &light, g, false, None).0
    }

    /// RGB radiance and its gradient with respect to all [`N_PARAMS`] parameters.
    pub fn radiance_with_gradient(&self, p: &Params, g: &Geometry) -> (Rgb, Gradient) {
        self.eval(p, &p.light.frame(), g, true, None)
    }

    fn eval(
        &self,
        p: &Params,
        light: &LightFrame,
        g: &Geometry,
        want_grad: bool,
        slices: Option<&RadiusSlices>,
    ) -> (Rgb, Gradient) {
        let nv = g.normal.dot(&g.view);
        if nv <= 0.0 {
            return ([0.0; 3], [[0.0; N_PARAMS]; 3]);
        }
        let m = &p.material;
        let (n, v, l) = (&g.normal, &g.view, &light.l);
        let cosines = Cosines {
            nv,
            nl: n.dot(l).clamp(-1.0, 1.0),
            lv: l.dot(v).clamp(-1.0, 1.0),
            n_da: n.dot(&light.dl_da),
            n_de: n.dot(&light.dl_de),
            v_da: v.dot(&light.dl_da),
            v_de: v.dot(&light.dl_de),
        };
        let ln_rr = match slices {
            Some(s) => s.ln_rr,
            None if want_grad => (self.reference_radius_mm / g.radius_mm).ln(),
            None => 0.0,
        };
        let mut out = ([0.0; 3], [[0.0; N_PARAMS]; 3]);
        self.shade(
            m,
            &cosines,
            g.radius_mm,
            ln_rr,
            want_grad,
            &mut out,
            |c, theta, sigma| {
                let slices =
                    slices.map_or([None, None], |s| [s.core[c].as_ref(), s.tail[c].as_ref()]);
                self.profile_with(m, theta, sigma, slices)
            },
        );
        out
    }

    /// The module formula into `out.0` and, with `want_grad`, its gradient into `out.1` (whose
    /// entries it sets all), on one pixel or four ([`Real`]) of one radius whose n·v > 0, with
    /// the blur profile of channel c at (θ, σ_c) from `profile`; `ln_rr` = ln(r_ref / r), needed
    /// only for the gradient.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn shade<T: Real>(
        &self,
        m: &Material,
        g: &Cosines<T>,
        radius_mm: f64,
        ln_rr: f64,
        want_grad: bool,
        (out, grad): &mut ([T; 3], [[T; N_PARAMS]; 3]),
        profile: impl Fn(usize, T, f64) -> mixture::MixtureEval<T>,
    ) {
        let zero = T::splat(0.0);
        let (nl, nv) = (g.nl, g.nv);
        let theta = nl.acos();
        // sin θ for ∂f/∂(cos θ), once for the three channels.
        let sin_theta = ((-nl + 1.0) * (nl + 1.0)).sqrt();
        let fr = if self.exit_fresnel {
            fresnel::eval(nv, m.eta)
        } else {
            fresnel::FresnelEval {
                reflectance: zero,
                d_cos: zero,
                d_eta: zero,
            }
        };
        let t_exit = fr.transmission();
        let rr = self.reference_radius_mm / radius_mm;
        // Off extensions scale by exactly 1, without the transcendental calls.
        let sigma_scale = self.sigma_scale(m, radius_mm);
        let albedo_scale = if m.albedo_curvature == 0.0 {
            1.0
        } else {
            (m.albedo_curvature * (rr - 1.0)).exp()
        };
        let spec = specular::lobe(nl, nv, g.lv, m.specular.ks, m.specular.alpha, m.eta);
        for c in 0..3 {
            let sigma = m.sigma0_mm[c] / radius_mm * sigma_scale;
            let mix = profile(c, theta, sigma);
            let f = mix.f;
            let a = m.albedo[c] * albedo_scale;
            let at = t_exit * a;
            out[c] = at * f.value + spec.value;
            if !want_grad {
                continue;
            }
            let row = &mut grad[c];
            for other in (0..3).filter(|&o| o != c) {
                row[idx::SIGMA0 + other] = zero;
                row[idx::ALBEDO + other] = zero;
            }
            row[idx::SIGMA0 + c] = at * f.d_sigma * sigma / m.sigma0_mm[c];
            row[idx::ALBEDO + c] = t_exit * albedo_scale * f.value;
            row[idx::ETA] = (t_exit * mix.d_param - f.value * fr.d_eta) * a + spec.d_eta;
            row[idx::KS] = spec.d_ks;
            row[idx::ALPHA] = spec.d_alpha;
            row[idx::SIGMA_EXPONENT] = at * f.d_sigma * sigma * ln_rr;
            row[idx::ALBEDO_CURVATURE] = at * f.value * (rr - 1.0);
            row[idx::KERNEL_WEIGHT] = at * mix.d_weight;
            row[idx::KERNEL_RATIO] = at * mix.d_ratio;
            // ∂L/∂l = (∂L/∂(n·l)) n + (∂L/∂(l·v)) v, projected on ∂l/∂azimuth and ∂l/∂elevation.
            let d_nl = at * f.d_cos_at(sin_theta, nl) + spec.d_nl;
            row[idx::AZIMUTH] = d_nl * g.n_da + spec.d_lv * g.v_da;
            row[idx::ELEVATION] = d_nl * g.n_de + spec.d_lv * g.v_de;
        }
    }
}

/// What the model needs of a pixel's geometry, on one pixel or four ([`Real`]): n·v, n·l and
/// l·v (the last two clamped to [−1, 1]), and the normal's and the view's projections on the
/// light's derivatives ∂l/∂azimuth and ∂l/∂elevation.
struct Cosines<T> {
    nv: T,
    nl: T,
    lv: T,
    n_da: T,
    n_de: T,
    v_da: T,
    v_de: T,
}

/// The most distinct radii a [`Prepared`] model holds slices for (16 KB per channel and width).
pub const MAX_SLICED_RADII: usize = 64;

/// The table's slices at one radius's blur widths, per channel: the core's σ_c and, with two
/// Gaussians, the tail's s·σ_c (`None` outside the table, or without a tail).
struct RadiusSlices {
    radius_mm: f64,
    /// ln(r_ref / r).
    ln_rr: f64,
    core: [Option<Slice>; 3],
    tail: [Option<Slice>; 3],
    /// Every slice the model reads at this radius is here (each core and, with two Gaussians,
    /// each tail): the four-pixel path may take it.
    lanes: bool,
}

/// The model at fixed parameters for many pixels ([`Model::prepare`]): what every pixel shares —
/// the light's frame and the CDRF table's slices at each radius's widths ([`Slice`]) — computed
/// once. Its radiance and gradient are [`Model::radiance_with_gradient`]'s, to rounding.
pub struct Prepared {
    model: Model,
    params: Params,
    frame: LightFrame,
    slices: Vec<RadiusSlices>,
}

impl Prepared {
    /// RGB radiance and its gradient with respect to all [`N_PARAMS`] parameters at one pixel.
    pub fn radiance_with_gradient(&self, g: &Geometry) -> (Rgb, Gradient) {
        let slices = self.slices.iter().find(|s| s.radius_mm == g.radius_mm);
        self.model.eval(&self.params, &self.frame, g, true, slices)
    }

    /// [`Prepared::radiance_with_gradient`] at four pixels at once, in lanes ([`Real`]): their
    /// radiance and gradient into `out`, lane k being pixel k's to a few units in the last place.
    /// `None` (and `out` untouched) unless the four share a radius whose table slices this model holds and every one faces
    /// the camera (n·v > 0): those are for the one-pixel path.
    pub fn radiance_with_gradient_x4(&self, g: [&Geometry; 4], out: &mut Lanes4) -> Option<()> {
        let radius_mm = g[0].radius_mm;
        if g.iter().any(|p| p.radius_mm != radius_mm) {
            return None;
        }
        let m = &self.params.material;
        let slices = self
            .slices
            .iter()
            .find(|s| s.radius_mm == radius_mm)
            .filter(|s| s.lanes)?;
        let n: [f64x4; 3] = std::array::from_fn(|i| f64x4::new(g.map(|p| p.normal[i])));
        let v: [f64x4; 3] = std::array::from_fn(|i| f64x4::new(g.map(|p| p.view[i])));
        let dot = |a: &[f64x4; 3], b: &Vector3<f64>| a[0] * b.x + a[1] * b.y + a[2] * b.z;
        let nv = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
        if <f64x4 as Real>::any(nv.le(0.0)) {
            return None;
        }
        let frame = &self.frame;
        let cosines = Cosines {
            nv,
            nl: Real::min(Real::max(dot(&n, &frame.l), -1.0), 1.0),
            lv: Real::min(Real::max(dot(&v, &frame.l), -1.0), 1.0),
            n_da: dot(&n, &frame.dl_da),
            n_de: dot(&n, &frame.dl_de),
            v_da: dot(&v, &frame.dl_da),
            v_de: dot(&v, &frame.dl_de),
        };
        let zero = f64x4::splat(0.0);
        let (w, s) = (m.kernel_weight, m.kernel_ratio);
        let profile = |c: usize, theta: f64x4, sigma: f64| {
            let core = slices.core[c].as_ref().expect("a lanes radius");
            let tail = slices.tail[c].as_ref().filter(|_| w != 0.0);
            let tail = tail.map(|t| (t.eval_in(theta), zero));
            mixture::mix((core.eval_in(theta), zero), tail, sigma, (w, s))
        };
        let model = &self.model;
        model.shade(m, &cosines, radius_mm, slices.ln_rr, true, out, profile);
        Some(())
    }
}

/// Radiance and gradient on four pixels ([`Prepared::radiance_with_gradient_x4`]).
pub type Lanes4 = ([f64x4; 3], [[f64x4; N_PARAMS]; 3]);
