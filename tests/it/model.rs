//! Fresnel, GGX and the full radiance model: every analytic derivative against finite
//! differences, and the lobe against independent vector evaluation.
// Colour channels are indexed alongside several arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::common;
use common::{close, derivative};
use nalgebra::Vector3;
use workbench::model::cdrf::Convolution;
use workbench::model::fresnel;
use workbench::model::specular::{ggx_d, lobe, smith_g1};
use workbench::model::{
    idx, Geometry, LightAngles, Material, Model, Params, SpecularParams, N_PARAMS, PARAM_NAMES,
};

#[test]
fn fresnel_derivatives() {
    for &eta in &[1.0001, 1.2, 1.44, 2.0, 3.0] {
        for &c in &[0.02, 0.1, 0.3, 0.5, 0.7, 0.9, 0.999] {
            let e = fresnel::eval(c, eta);
            let fd_c = derivative(&|x| fresnel::reflectance(x, eta), c, 1e-2 * c.min(1.0 - c));
            let fd_e = derivative(&|x| fresnel::reflectance(c, x), eta, 1e-5);
            assert!(
                close(e.d_cos, fd_c, 1e-6, 1e-12),
                "η={eta} c={c}: {} {fd_c}",
                e.d_cos
            );
            assert!(
                close(e.d_eta, fd_e, 1e-6, 1e-12),
                "η={eta} c={c}: {} {fd_e}",
                e.d_eta
            );
        }
    }
}

#[test]
fn fresnel_against_schlick_and_known_values() {
    // Exact normal incidence, and Schlick's approximation within the ~0.02 the notes quote.
    let eta: f64 = 1.5;
    let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
    for i in 0..=80 {
        let th = (i as f64).to_radians();
        let schlick = f0 + (1.0 - f0) * (1.0 - th.cos()).powi(5);
        assert!(
            (fresnel::reflectance(th.cos(), eta) - schlick).abs() < 0.025,
            "{i}°"
        );
    }
    // Water at 60°: Rs = 0.1152, Rp = 0.00446 (textbook, η = 1.333).
    let f = fresnel::reflectance(60f64.to_radians().cos(), 1.333);
    assert!((f - 0.5 * (0.1152 + 0.00446)).abs() < 2e-4, "{f}");
}

#[test]
fn ggx_and_smith_derivatives() {
    for &a in &[0.01, 0.1, 0.3, 0.8] {
        for &c in &[0.05, 0.3, 0.7, 0.95] {
            let (_, dd_c, dd_a) = ggx_d(c, a);
            let (_, dg_c, dg_a) = smith_g1(c, a);
            let h = 1e-4 * a.min(c);
            let hc = 1e-3 * c.min(1.0 - c);
            assert!(close(
                dd_c,
                derivative(&|x| ggx_d(x, a).0, c, h),
                1e-6,
                1e-9
            ));
            assert!(close(
                dd_a,
                derivative(&|x| ggx_d(c, x).0, a, h),
                1e-6,
                1e-9
            ));
            let fd = derivative(&|x| smith_g1(x, a).0, c, hc);
            assert!(close(dg_c, fd, 1e-6, 1e-12), "α={a} c={c}: {dg_c} {fd}");
            assert!(close(
                dg_a,
                derivative(&|x| smith_g1(c, x).0, a, h),
                1e-6,
                1e-12
            ));
        }
    }
}

/// fs·(n·l) from vectors, written independently of the scalar form the library uses.
fn lobe_from_vectors(
    n: Vector3<f64>,
    l: Vector3<f64>,
    v: Vector3<f64>,
    ks: f64,
    a: f64,
    eta: f64,
) -> f64 {
    let (nl, nv) = (n.dot(&l), n.dot(&v));
    if nl <= 0.0 || nv <= 0.0 {
        return 0.0;
    }
    let h = (l + v).normalize();
    let nh = n.dot(&h);
    let a2 = a * a;
    let d = a2 / (std::f64::consts::PI * (nh * nh * (a2 - 1.0) + 1.0).powi(2));
    let g1 = |c: f64| 2.0 * c / (c + (a2 + (1.0 - a2) * c * c).sqrt());
    let f = fresnel::reflectance(l.dot(&h), eta);
    ks * d * g1(nl) * g1(nv) * f / (4.0 * nl * nv) * nl
}

#[test]
fn lobe_matches_vector_form_and_its_derivatives() {
    let n = Vector3::new(0.2, -0.3, -0.9).normalize();
    let v = Vector3::new(0.05, 0.1, -1.0).normalize();
    for &(az, el) in &[(0.3, 0.2), (0.8, -0.1), (1.2, 0.4), (0.0, 0.0)] {
        let l = LightAngles {
            azimuth: az,
            elevation: el,
        }
        .direction();
        for &a in &[0.05, 0.2, 0.5] {
            let e = lobe(n.dot(&l), n.dot(&v), l.dot(&v), 0.7, a, 1.45);
            let indep = lobe_from_vectors(n, l, v, 0.7, a, 1.45);
            assert!(close(e.value, indep, 1e-12, 1e-15), "{} {indep}", e.value);
            let (nl, nv, lv) = (n.dot(&l), n.dot(&v), l.dot(&v));
            let h = 1e-5;
            let f =
                |nl: f64, lv: f64, ks: f64, a: f64, eta: f64| lobe(nl, nv, lv, ks, a, eta).value;
            assert!(close(
                e.d_nl,
                derivative(&|x| f(x, lv, 0.7, a, 1.45), nl, h),
                1e-6,
                1e-10
            ));
            assert!(close(
                e.d_lv,
                derivative(&|x| f(nl, x, 0.7, a, 1.45), lv, h),
                1e-6,
                1e-10
            ));
            assert!(close(
                e.d_ks,
                derivative(&|x| f(nl, lv, x, a, 1.45), 0.7, h),
                1e-6,
                1e-12
            ));
            assert!(close(
                e.d_alpha,
                derivative(&|x| f(nl, lv, 0.7, x, 1.45), a, 1e-4 * a),
                1e-6,
                1e-10
            ));
            assert!(close(
                e.d_eta,
                derivative(&|x| f(nl, lv, 0.7, a, x), 1.45, h),
                1e-6,
                1e-12
            ));
        }
    }
}

fn params(az: f64, el: f64) -> Params {
    Params {
        material: Material {
            sigma0_mm: [4.0, 3.0, 2.2],
            albedo: [0.8, 0.62, 0.45],
            eta: 1.44,
            specular: SpecularParams {
                ks: 1.0,
                alpha: 0.15,
            },
            // Non-zero extensions, so their derivatives are checked too.
            sigma_exponent: 0.4,
            albedo_curvature: 0.1,
            // A two-Gaussian kernel, so its derivatives are checked too.
            kernel_weight: 0.3,
            kernel_ratio: 2.5,
        },
        light: LightAngles {
            azimuth: az,
            elevation: el,
        },
    }
}

#[test]
fn light_angles_round_trip() {
    for &(az, el) in &[(0.0, 0.0), (1.2, 0.3), (-2.5, -0.7), (3.0, 1.2)] {
        let l = LightAngles {
            azimuth: az,
            elevation: el,
        };
        let d = l.direction();
        assert!((d.norm() - 1.0).abs() < 1e-15);
        let back = LightAngles::from_direction(&d);
        assert!((back.azimuth - az).abs() < 1e-12 && (back.elevation - el).abs() < 1e-12);
    }
    // The light at the camera is (0, 0, −1): it points from the surface toward the camera side.
    let d = LightAngles {
        azimuth: 0.0,
        elevation: 0.0,
    }
    .direction();
    assert_eq!(d, Vector3::new(0.0, -0.0, -1.0));
}

/// Every entry of the model gradient against Richardson-extrapolated central differences, over
/// many surface points and light directions (front, side, back light; across the terminator and
/// through the highlight), for both convolutions.
#[test]
fn model_gradient_matches_finite_differences() {
    let lights = [
        (0.3, 0.2),
        (1.2, 0.35),
        (2.6, -0.2),
        (0.0, 0.0),
        (-1.0, 0.5),
    ];
    let mut checked = 0;
    for (conv, entry_fresnel) in [
        (Convolution::Wrapped, true),
        (Convolution::Line, true),
        (Convolution::Wrapped, false),
    ] {
        let model = Model {
            convolution: conv,
            entry_fresnel,
            ..Model::default()
        };
        for &(az, el) in &lights {
            let p = params(az, el);
            let l = p.light.direction();
            // The fit's path: the table's slices at two of the three radii (the third reads the
            // whole table).
            let prepared = model.prepare(&p, [15.0, 25.0, 15.0]);
            for i in 0..40 {
                // Points on the visible hemisphere of a sphere seen from −z.
                let u = (i as f64 + 0.5) / 40.0;
                let (ph, ct) = (u * 37.0, 0.15 + 0.84 * ((i * 7 % 40) as f64 / 40.0));
                let st = (1.0 - ct * ct).sqrt();
                let n = Vector3::new(st * ph.cos(), st * ph.sin(), -ct);
                let v = Vector3::new(0.02, -0.01, -1.0).normalize();
                let radius_mm = [15.0, 25.0, 35.0][i % 3];
                let g = Geometry {
                    normal: n,
                    view: v,
                    radius_mm,
                };
                // Away from kinks: the lobe switches off at n·l = 0 and the Line form kinks at θ = π.
                if n.dot(&l).abs() < 1e-3 || n.dot(&v) < 1e-3 {
                    continue;
                }
                let (_, grad) = model.radiance_with_gradient(&p, &g);
                let (_, grad_prepared) = prepared.radiance_with_gradient(&g);
                let base = p.to_vec();
                for k in 0..N_PARAMS {
                    // With the entry transmission the tolerance is 1e-5 and η's step larger: the
                    // series' coefficients are a projection with large alternating weights
                    // (src/model/entry.rs) whose rounding leaves ~4e-11 of noise in the value — 2e-7 in
                    // an η difference quotient at h 1e-4, 4e-8 at h 1e-3 (measured).
                    let (h, rel, abs) = match (entry_fresnel, k == idx::ETA) {
                        (true, true) => (1e-3, 1e-5, 1e-7),
                        (true, false) => (1e-5 * base[k].abs().max(0.1), 1e-5, 1e-10),
                        (false, _) => (1e-5 * base[k].abs().max(0.1), 1e-6, 1e-10),
                    };
                    for c in 0..3 {
                        let f = |x: f64| {
                            let mut q = base;
                            q[k] = x;
                            model.radiance(&Params::from_vec(&q), &g)[c]
                        };
                        let fd = derivative(&f, base[k], h);
                        for (path, g) in [("", &grad), (" prepared", &grad_prepared)] {
                            assert!(
                                close(g[c][k], fd, rel, abs),
                                "{conv:?} entry {entry_fresnel}{path} light ({az},{el}) point {i} ∂{}[{c}]: analytic {} fd {fd}",
                                PARAM_NAMES[k],
                                g[c][k]
                            );
                            checked += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 24000, "{checked}");
}

/// The wrapped Gaussian blur of max(cos θ', 0)·T(cos θ'; η) at θ by composite Simpson quadrature
/// over the lit half-circle (images at ±2π, ±4π): independent of the closed form.
fn blurred_transmitted_cosine(theta: f64, sigma: f64, eta: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let n = 20_000;
    let h = PI / n as f64;
    let mut sum = 0.0;
    for j in 0..=n {
        let t = -FRAC_PI_2 + h * j as f64;
        let c = t.cos().max(0.0);
        let src = c * fresnel::transmission(c, eta);
        let mut g = 0.0;
        for k in -2..=2 {
            let u = theta - t + 2.0 * PI * k as f64;
            g += (-0.5 * (u / sigma).powi(2)).exp() / (sigma * (2.0 * PI).sqrt());
        }
        let w = if j == 0 || j == n {
            1.0
        } else if j % 2 == 1 {
            4.0
        } else {
            2.0
        };
        sum += w * src * g;
    }
    sum * h / 3.0
}

#[test]
fn entry_transmission_blur_matches_quadrature() {
    let mut worst: f64 = 0.0;
    for eta in [1.3, 1.5, 1.9] {
        for sigma in [0.03, 0.1, 0.3, 0.9, 2.0] {
            for i in 0..=36 {
                let th = std::f64::consts::PI * i as f64 / 36.0;
                let s = workbench::model::entry::series(eta);
                let closed =
                    workbench::model::cdrf::eval_series(th, sigma, &s, Convolution::Wrapped);
                let quad = blurred_transmitted_cosine(th, sigma, eta);
                worst = worst.max((closed.f.value - quad).abs());
            }
        }
    }
    // The series' own error (≤ 1.5e-5 of the unit peak) is what remains; measured 1.1e-5.
    assert!(worst < 4e-5, "{worst:e}");
}

#[test]
fn model_pieces_are_what_the_readme_says() {
    // Diffuse only (ks = 0): L = a · T(φ) · f(θ; σ0/r), computed independently; f blurs the
    // transmitted irradiance max(cos θ, 0)·T(cos θ; η) (checked by quadrature), or with
    // `entry_fresnel` off the bare clamped cosine (checked here against cdrf::value).
    let mut p = params(0.9, 0.2);
    p.material.specular.ks = 0.0;
    let n = Vector3::new(0.3, -0.2, -0.93).normalize();
    let v = Vector3::new(0.0, 0.0, -1.0);
    let g = Geometry {
        normal: n,
        view: v,
        radius_mm: 20.0,
    };
    let l = p.light.direction();
    let th = n.dot(&l).acos();
    let t = 1.0 - fresnel::reflectance(n.dot(&v), 1.44);
    // The closed-form CDRF (the table is checked against it in cdrf.rs).
    let plain = Model {
        entry_fresnel: false,
        tabulated: false,
        ..Model::default()
    };
    let out = plain.radiance(&p, &g);
    // With the extensions: σ = (σ0/r)(25/r)^q, albedo · exp(b (25/r − 1)), and the kernel
    // (1 − w)·f(θ; σ) + w·f(θ; s·σ).
    let (q, b) = (p.material.sigma_exponent, p.material.albedo_curvature);
    let (w, s) = (p.material.kernel_weight, p.material.kernel_ratio);
    assert!(w > 0.0 && s > 1.0);
    for c in 0..3 {
        let sigma = p.material.sigma0_mm[c] / 20.0 * (25.0f64 / 20.0).powf(q);
        let f = (1.0 - w) * workbench::model::cdrf::value(th, sigma, Convolution::Wrapped)
            + w * workbench::model::cdrf::value(th, s * sigma, Convolution::Wrapped);
        let a = p.material.albedo[c] * (b * (25.0 / 20.0 - 1.0)).exp();
        assert!((out[c] - a * t * f).abs() < 1e-15);
        let entry = Model {
            entry_fresnel: true,
            ..Model::default()
        }
        .radiance(&p, &g)[c];
        let f_entry = (1.0 - w) * blurred_transmitted_cosine(th, sigma, 1.44)
            + w * blurred_transmitted_cosine(th, s * sigma, 1.44);
        assert!(
            (entry - a * t * f_entry).abs() < 4e-5 * a,
            "{entry} {}",
            a * t * f_entry
        );
    }
    // The paper's variant without the exit transmission.
    let bare = Model {
        exit_fresnel: false,
        ..plain
    }
    .radiance(&p, &g);
    for c in 0..3 {
        assert!((bare[c] * t - out[c]).abs() < 1e-15);
    }
    // Back-facing to the camera: nothing.
    let g2 = Geometry {
        normal: -n,
        view: v,
        radius_mm: 20.0,
    };
    assert_eq!(Model::default().radiance(&p, &g2), [0.0; 3]);
    assert_eq!(idx::KERNEL_RATIO, N_PARAMS - 1);
}

/// The kernel tests' parameters: the extensions (q, b) and two Gaussians on, or all off.
fn extensions_on_or_off(plain: bool) -> Params {
    let mut p = params(1.2, 0.35);
    if plain {
        p.material.sigma_exponent = 0.0;
        p.material.albedo_curvature = 0.0;
        p.material.kernel_weight = 0.0;
    }
    p
}

/// The kernel tests' pixel i of 2000 at a radius: normals spread over the visible hemisphere
/// (across the terminator and the highlight), one view.
fn kernel_pixel(i: usize, radius_mm: f64) -> Geometry {
    let u = (i as f64 + 0.5) / 2000.0;
    let (ph, ct) = (u * 371.0, 0.02 + 0.97 * (i as f64 * 0.618_034).fract());
    let st = (1.0 - ct * ct).sqrt();
    Geometry {
        normal: Vector3::new(st * ph.cos(), st * ph.sin(), -ct),
        view: Vector3::new(0.02, -0.01, -1.0).normalize(),
        radius_mm,
    }
}

/// The model prepared for many pixels (the fit's kernel: the CDRF table's slices at each radius's
/// widths) is the model, to rounding: radiance and every gradient entry, over points across the
/// terminator and the highlight, with the extensions and two Gaussians on and off, at radii with
/// slices and without.
#[test]
fn prepared_model_equals_the_model() {
    let model = Model::default();
    let mut worst = 0.0f64;
    for plain in [false, true] {
        let p = extensions_on_or_off(plain);
        let prepared = model.prepare(&p, [15.0, 25.0, 35.0, 25.0]);
        for i in 0..2000 {
            let g = kernel_pixel(i, [15.0, 25.0, 35.0, 50.0][i % 4]);
            let (a, ga) = model.radiance_with_gradient(&p, &g);
            let (b, gb) = prepared.radiance_with_gradient(&g);
            for c in 0..3 {
                worst = worst.max((a[c] - b[c]).abs() / a[c].abs().max(1e-3));
                for k in 0..N_PARAMS {
                    worst = worst.max((ga[c][k] - gb[c][k]).abs() / ga[c][k].abs().max(1e-3));
                }
            }
        }
    }
    println!("prepared against plain: largest relative difference {worst:.1e}");
    // The same interpolant summed in another order: rounding only, which the Hermite sums'
    // cancellation at the terminator amplifies (measured 5.2e-12).
    assert!(worst < 1.6e-11, "{worst:e}");
}

/// The prepared model on four pixels at once (lanes: the fit's kernel) is the one-pixel model at
/// each, to rounding: radiance and every gradient entry, with the extensions and two Gaussians on
/// and off. Groups the lanes cannot take (mixed radii, a radius without slices, a pixel facing
/// away) are refused, for the one-pixel path.
#[test]
fn four_lanes_equal_one_pixel_each() {
    let model = Model::default();
    let mut worst = 0.0f64;
    let mut taken = 0;
    for plain in [false, true] {
        let p = extensions_on_or_off(plain);
        let prepared = model.prepare(&p, [15.0, 25.0, 35.0]);
        let pixel = kernel_pixel;
        for q in 0..500 {
            let radius = [15.0, 25.0, 35.0, 50.0][q % 4];
            let g: [Geometry; 4] = std::array::from_fn(|k| pixel(4 * q + k, radius));
            let mut out = Default::default();
            let four = [&g[0], &g[1], &g[2], &g[3]];
            let Some(()) = prepared.radiance_with_gradient_x4(four, &mut out) else {
                assert_eq!(radius, 50.0, "refused a group of sliced radius {radius}");
                continue;
            };
            assert_ne!(radius, 50.0, "took a radius without slices");
            let (l, grad) = out;
            taken += 1;
            for (k, gk) in g.iter().enumerate() {
                let (a, ga) = prepared.radiance_with_gradient(gk);
                for c in 0..3 {
                    worst = worst.max((a[c] - l[c].to_array()[k]).abs() / a[c].abs().max(1e-3));
                    for j in 0..N_PARAMS {
                        let b = grad[c][j].to_array()[k];
                        worst = worst.max((ga[c][j] - b).abs() / ga[c][j].abs().max(1e-3));
                    }
                }
            }
        }
        let mixed = [
            pixel(1, 15.0),
            pixel(2, 15.0),
            pixel(3, 25.0),
            pixel(4, 15.0),
        ];
        assert!(prepared
            .radiance_with_gradient_x4(
                [&mixed[0], &mixed[1], &mixed[2], &mixed[3]],
                &mut Default::default()
            )
            .is_none());
        let mut away = [
            pixel(1, 15.0),
            pixel(2, 15.0),
            pixel(3, 15.0),
            pixel(4, 15.0),
        ];
        away[2].normal = -away[2].normal;
        assert!(prepared
            .radiance_with_gradient_x4(
                [&away[0], &away[1], &away[2], &away[3]],
                &mut Default::default()
            )
            .is_none());
    }
    assert_eq!(taken, 750);
    println!("four lanes against one pixel: largest relative difference {worst:.1e}");
    // acos and ln within an ulp of the standard library's (model::lanes), amplified as in the
    // test above by the Hermite sums' cancellation at the terminator (measured 1.1e-12).
    assert!(worst < 3.3e-12, "{worst:e}");
}
