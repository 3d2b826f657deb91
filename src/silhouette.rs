//! Sphere silhouettes under a perspective camera: the 3-parameter tangent cone (axis direction and
//! half-angle) fitted to undistorted silhouette rays, robustly (RANSAC on minimal 3-ray samples,
//! then Gauss–Newton on the angular residuals of the inliers), and the sphere centre it implies
//! for a known radius (|C| = R / sin α).
//!
//! Rays d on the cone satisfy d·a = cos α, i.e. d·w = 1 with w = a / cos α: three rays determine
//! w by a 3×3 solve, and many give it by linear least squares — the start for the refinement.
//! Unlike a free 5-parameter ellipse, the cone cannot bend to follow part of an outline (the lit
//! side only, say), so a partial arc still pins the sphere.

use nalgebra::{Matrix3, Vector2, Vector3};

/// A fitted silhouette cone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Unit axis: the direction of the sphere's centre.
    pub axis: Vector3<f64>,
    /// Half-angle (radians).
    pub half_angle: f64,
    /// RMS angular residual of the inliers (radians).
    pub rms: f64,
    pub inliers: usize,
}

impl Cone {
    /// Signed angular distance of a unit ray from the cone (positive outside).
    pub fn residual(&self, d: &Vector3<f64>) -> f64 {
        d.dot(&self.axis).clamp(-1.0, 1.0).acos() - self.half_angle
    }

    /// The sphere centre for a known radius (mm).
    pub fn center(&self, radius_mm: f64) -> Vector3<f64> {
        self.axis * (radius_mm / self.half_angle.sin())
    }
}

/// The cone through exactly three rays (`None` when they are degenerate).
fn cone_from_three(d: [&Vector3<f64>; 3]) -> Option<(Vector3<f64>, f64)> {
    let m = Matrix3::from_rows(&[d[0].transpose(), d[1].transpose(), d[2].transpose()]);
    let w = m.try_inverse()? * Vector3::new(1.0, 1.0, 1.0);
    cone_of_w(&w)
}

fn cone_of_w(w: &Vector3<f64>) -> Option<(Vector3<f64>, f64)> {
    let n = w.norm();
    if !(n > 1.0) || !n.is_finite() {
        return None;
    }
    let mut axis = w / n;
    if axis.z < 0.0 {
        axis = -axis;
    }
    Some((axis, (1.0 / n).acos()))
}

/// Least-squares cone through many rays: solve D w = 1.
fn cone_linear(rays: &[Vector3<f64>]) -> Option<(Vector3<f64>, f64)> {
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    for d in rays {
        ata += d * d.transpose();
        atb += d;
    }
    cone_of_w(&(ata.try_inverse()? * atb))
}

/// Gauss–Newton on the angular residuals r_i = acos(d_i·a) − α, with the axis parameterised by
/// two angles in its tangent plane.
fn refine(rays: &[Vector3<f64>], axis: Vector3<f64>, half: f64) -> (Vector3<f64>, f64) {
    let (mut a, mut h) = (axis, half);
    for _ in 0..20 {
        let e1 = a
            .cross(&if a.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            })
            .normalize();
        let e2 = a.cross(&e1);
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        for d in rays {
            let c = d.dot(&a).clamp(-1.0, 1.0);
            let s = (1.0 - c * c).sqrt().max(1e-12);
            let r = c.acos() - h;
            // ∂acos(d·a)/∂a = −d/ sin: along e1, e2 (a moves as a + u e1 + v e2).
            let j = Vector3::new(-d.dot(&e1) / s, -d.dot(&e2) / s, -1.0);
            jtj += j * j.transpose();
            jtr += j * r;
        }
        let Some(step) = jtj.try_inverse().map(|m| -(m * jtr)) else {
            break;
        };
        a = (a + e1 * step.x + e2 * step.y).normalize();
        h += step.z;
        if step.norm() < 1e-14 {
            break;
        }
    }
    (a, h)
}

/// Fit the cone to silhouette rays, ignoring outliers (rays farther than `tol` radians from the
/// cone of the best minimal sample). Deterministic: samples come from a fixed-seed generator.
pub fn fit_cone(rays: &[Vector3<f64>], tol: f64, iterations: usize) -> Option<Cone> {
    use rand::{Rng, SeedableRng};
    if rays.len() < 3 {
        return None;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5111_0E77E);
    let count = |axis: &Vector3<f64>, half: f64| {
        rays.iter()
            .filter(|d| (d.dot(axis).clamp(-1.0, 1.0).acos() - half).abs() < tol)
            .count()
    };
    let mut best: Option<(usize, Vector3<f64>, f64)> =
        cone_linear(rays).map(|(a, h)| (count(&a, h), a, h));
    for _ in 0..iterations {
        let i = rng.random_range(0..rays.len());
        let j = rng.random_range(0..rays.len());
        let k = rng.random_range(0..rays.len());
        if i == j || j == k || i == k {
            continue;
        }
        if let Some((a, h)) = cone_from_three([&rays[i], &rays[j], &rays[k]]) {
            let n = count(&a, h);
            if best.as_ref().is_none_or(|b| n > b.0) {
                best = Some((n, a, h));
            }
        }
    }
    let (_, mut axis, mut half) = best?;
    // Refine on the inliers, re-select, refine again.
    for _ in 0..3 {
        let inl: Vec<Vector3<f64>> = rays
            .iter()
            .filter(|d| (d.dot(&axis).clamp(-1.0, 1.0).acos() - half).abs() < tol)
            .cloned()
            .collect();
        if inl.len() < 3 {
            return None;
        }
        (axis, half) = refine(&inl, axis, half);
    }
    let inl: Vec<f64> = rays
        .iter()
        .map(|d| d.dot(&axis).clamp(-1.0, 1.0).acos() - half)
        .filter(|r| r.abs() < tol)
        .collect();
    let rms = (inl.iter().map(|r| r * r).sum::<f64>() / inl.len().max(1) as f64).sqrt();
    (half > 0.0 && half < std::f64::consts::FRAC_PI_2).then_some(Cone {
        axis,
        half_angle: half,
        rms,
        inliers: inl.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sphere::Sphere;

    fn tangent_rays(s: &Sphere, n: usize, from: f64, to: f64) -> Vec<Vector3<f64>> {
        let axis = s.center.normalize();
        let half = s.cone_half_angle().unwrap();
        let e1 = axis.cross(&Vector3::y()).normalize();
        let e2 = axis.cross(&e1);
        (0..n)
            .map(|k| {
                let t = from + (to - from) * k as f64 / (n - 1) as f64;
                axis * half.cos() + (e1 * t.cos() + e2 * t.sin()) * half.sin()
            })
            .collect()
    }

    #[test]
    fn exact_rays_give_the_sphere_back() {
        let s = Sphere::new(Vector3::new(80.0, -50.0, 400.0), 25.0);
        // Half the outline only (the lit side of a sphere).
        let rays = tangent_rays(&s, 60, -1.2, 1.9);
        let c = fit_cone(&rays, 1e-3, 200).unwrap();
        assert!(
            (c.center(25.0) - s.center).norm() < 1e-9,
            "{:?}",
            c.center(25.0)
        );
        assert!(c.rms < 1e-12 && c.inliers == 60);
    }

    #[test]
    fn blobs_are_labelled_largest_first() {
        // Two squares (3×3 and 2×2) and a single pixel touching the border, in a 8×6 mask.
        let (w, h) = (8u32, 6u32);
        let mut m = vec![false; 48];
        for (x, y) in [
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
        ] {
            m[y * 8 + x] = true;
        }
        let b = blobs(&m, w, h);
        assert_eq!(b.iter().map(|b| b.area).collect::<Vec<_>>(), [9, 4, 1]);
        assert_eq!(b[0].centroid, Vector2::new(2.0, 2.0));
        assert_eq!(b[1].bbox, [5, 2, 6, 3]);
        assert!(!b[0].touches_border(w, h) && b[2].touches_border(w, h));
        assert!((b[0].extent - 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn outliers_are_ignored() {
        let s = Sphere::new(Vector3::new(-30.0, 20.0, 300.0), 15.0);
        let mut rays = tangent_rays(&s, 80, 0.0, std::f64::consts::TAU * 0.99);
        // A terminator-like arc of 30 rays well inside the silhouette.
        let inner = Sphere::new(s.center, 11.0);
        rays.extend(tangent_rays(&inner, 30, 2.0, 3.5));
        let c = fit_cone(&rays, 2e-4, 300).unwrap();
        assert_eq!(c.inliers, 80);
        assert!((c.center(15.0) - s.center).norm() < 1e-8);
    }
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
}

impl Blob {
    /// Whether the blob touches the image border.
    pub fn touches_border(&self, width: u32, height: u32) -> bool {
        self.bbox[0] == 0
            || self.bbox[1] == 0
            || self.bbox[2] + 1 >= width
            || self.bbox[3] + 1 >= height
    }
}

/// Connected components of a mask (row-major, `width` wide), largest first.
pub fn blobs(mask: &[bool], width: u32, height: u32) -> Vec<Blob> {
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
        });
    }
    out.sort_by_key(|b| std::cmp::Reverse(b.area));
    out
}
