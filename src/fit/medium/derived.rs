//! What a renderer takes from the medium fit, with stated errors: σa, σs′, η, the transport mean
//! free path and the surface's diffuse albedo, each std by its gradient in the fit's u.

use super::errors::std_of;
use super::problem::{ETA, IRRADIANCE};
use crate::model::dipole::{Dipole, Medium};
use nalgebra::{DMatrix, DVector};

/// A value per channel with its std.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerChannel {
    pub value: [f64; 3],
    pub std: [f64; 3],
}

/// What a renderer takes, with stated errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Derived {
    pub sigma_a: PerChannel,
    pub sigma_s_reduced: PerChannel,
    pub eta: (f64, f64),
    /// The transport mean free path 1/σt′ (mm).
    pub mean_free_path: PerChannel,
    /// The dipole's total diffuse reflectance of a flat surface of the medium (Jensen et al.).
    pub diffuse_albedo: PerChannel,
    /// The irradiance per channel (its std 0 when given).
    pub irradiance: PerChannel,
}

/// The quantities a renderer takes for `media` (and the irradiance), each std from
/// `covariance` (of u, as [`super::MediumFit::u`]) by its gradient in u.
pub(super) fn of(
    media: &[Medium; 3],
    irradiance: [f64; 3],
    irradiance_given: bool,
    covariance: &DMatrix<f64>,
) -> Derived {
    // gᵀCg over the parameters g reaches (a not-determined one elsewhere stays out).
    let var = |g: &DVector<f64>| {
        let mut v = 0.0;
        for i in (0..g.len()).filter(|&i| g[i] != 0.0) {
            for j in (0..g.len()).filter(|&j| g[j] != 0.0) {
                v += g[i] * covariance[(i, j)] * g[j];
            }
        }
        v
    };
    let sqrt = std_of;
    let n = covariance.nrows();
    let per = |f: &dyn Fn(&Medium) -> f64| -> PerChannel {
        let mut out = PerChannel {
            value: [0.0; 3],
            std: [0.0; 3],
        };
        for c in 0..3 {
            let m = media[c];
            out.value[c] = f(&m);
            // ∂/∂ln σa, ∂/∂ln σs′ by central differences of 1e-5; ∂/∂ln(η − 1) likewise.
            let h = 1e-5;
            let mut g = DVector::zeros(n);
            let moved = |da: f64, ds: f64, de: f64| {
                f(&Medium {
                    sigma_a: m.sigma_a * da.exp(),
                    sigma_s_reduced: m.sigma_s_reduced * ds.exp(),
                    eta: 1.0 + (m.eta - 1.0) * de.exp(),
                })
            };
            g[c] = (moved(h, 0.0, 0.0) - moved(-h, 0.0, 0.0)) / (2.0 * h);
            g[3 + c] = (moved(0.0, h, 0.0) - moved(0.0, -h, 0.0)) / (2.0 * h);
            g[ETA] = (moved(0.0, 0.0, h) - moved(0.0, 0.0, -h)) / (2.0 * h);
            out.std[c] = sqrt(var(&g));
        }
        out
    };
    let irradiance = PerChannel {
        value: irradiance,
        std: std::array::from_fn(|c| {
            if irradiance_given {
                0.0
            } else {
                irradiance[c] * sqrt(covariance[(IRRADIANCE + c, IRRADIANCE + c)])
            }
        }),
    };
    Derived {
        sigma_a: per(&|m| m.sigma_a),
        sigma_s_reduced: per(&|m| m.sigma_s_reduced),
        eta: (
            media[0].eta,
            (media[0].eta - 1.0) * sqrt(covariance[(ETA, ETA)]),
        ),
        mean_free_path: per(&|m| 1.0 / m.sigma_t_reduced()),
        diffuse_albedo: per(&|m| Dipole::new(m).total()),
        irradiance,
    }
}
