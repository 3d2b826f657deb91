//! Per-pixel samples for the solver: every pixel whose centre lies inside a detected silhouette,
//! with its geometry (normal, view, θ and φ for a given light), the sphere's radius, the linear
//! radiance per channel normalised by the photo's exposure, and flags.

use crate::camera::outline::{Outline, Projection};
use crate::formats::photo::LinearRgb;
use nalgebra::{Vector2, Vector3};

/// Any channel clipped at full scale.
pub(crate) const SATURATED: u8 = 1;
/// Within 1.5 px of the silhouette: the pixel may straddle it.
pub const EDGE: u8 = 2;
/// Inside the specular highlight (normal within the highlight radius of the half vector).
pub(crate) const HIGHLIGHT: u8 = 4;

/// One pixel of one sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub px: [u32; 2],
    pub normal: Vector3<f64>,
    pub view: Vector3<f64>,
    /// Angle between normal and light (radians; NaN without a light).
    pub theta: f64,
    /// Angle between normal and view (radians).
    pub phi: f64,
    pub radius_mm: f64,
    /// Linear radiance divided by the relative exposure.
    pub radiance: [f64; 3],
    pub flags: u8,
}

use crate::formats::detections::Counts;

pub fn counts(s: &[Sample]) -> Counts {
    let n = |f: u8| s.iter().filter(|x| x.flags & f != 0).count();
    Counts {
        total: s.len(),
        saturated: n(SATURATED),
        edge: n(EDGE),
        highlight: n(HIGHLIGHT),
    }
}

/// The samples of one sphere. `exposure` divides the radiance (1 when unknown: then samples of
/// different photos are not comparable, which the caller must check). `light` gives θ and the
/// highlight flag (pixels whose normal lies within `highlight_radius` radians of their half
/// vector).
pub fn sphere_samples(
    img: &LinearRgb,
    exposure: f64,
    proj: &Projection,
    outline: &Outline,
    radius_mm: f64,
    light: Option<&Vector3<f64>>,
    highlight_radius: Option<f64>,
) -> Vec<Sample> {
    let r_px = outline.radius_px(proj);
    let Some([x0, y0, x1, y1]) = outline.pixel_box(proj, 0.0, img.width, img.height) else {
        return vec![];
    };
    let mut out = vec![];
    for y in y0..=y1 {
        for x in x0..=x1 {
            let Some(q) = proj.point(Vector2::new(x as f64, y as f64)) else {
                continue;
            };
            let s = outline.s(&q);
            if !(s < 1.0) {
                continue;
            }
            let Some(surf) = outline.surface(&q) else {
                continue;
            };
            let i = (y * img.width + x) as usize;
            let mut flags = 0;
            if img.saturated[i] {
                flags |= SATURATED;
            }
            if (1.0 - s) * r_px < 1.5 {
                flags |= EDGE;
            }
            let theta = light.map_or(f64::NAN, |l| surf.normal.dot(l).clamp(-1.0, 1.0).acos());
            if let (Some(l), Some(hr)) = (light, highlight_radius) {
                let h = (l + surf.view).normalize();
                if surf.normal.dot(&h).clamp(-1.0, 1.0).acos() < hr {
                    flags |= HIGHLIGHT;
                }
            }
            let rgb = &img.data[3 * i..3 * i + 3];
            out.push(Sample {
                px: [x, y],
                normal: surf.normal,
                view: surf.view,
                theta,
                phi: surf.normal.dot(&surf.view).clamp(-1.0, 1.0).acos(),
                radius_mm,
                radiance: [0, 1, 2].map(|c| rgb[c] as f64 / exposure),
                flags,
            });
        }
    }
    out
}
