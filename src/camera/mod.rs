//! Pinhole camera with OpenCV's distortion model (k1 k2 p1 p2 k3), in the OpenCV camera frame
//! (x right, y down, z forward). Pixel centres are at integer coordinates, as in OpenCV.
//!
//! For undistorted normalised coordinates (x, y) with r² = x² + y²:
//!
//!     radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
//!     xd = x·radial + 2 p1 x y + p2 (r² + 2x²)
//!     yd = y·radial + p1 (r² + 2y²) + 2 p2 x y
//!     u = fx·xd + cx,  v = fy·yd + cy

pub mod outline;
pub mod sphere;

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// OpenCV's five-coefficient distortion model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    pub(crate) fn is_zero(&self) -> bool {
        *self == Distortion::default()
    }

    /// Undistorted normalised coordinates → distorted normalised coordinates.
    pub fn apply(&self, p: Vector2<f64>) -> Vector2<f64> {
        self.apply_with_jacobian(p).0
    }

    /// The distortion map and its 2×2 Jacobian.
    pub(crate) fn apply_with_jacobian(&self, p: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let (x, y) = (p.x, p.y);
        let Distortion { k1, k2, p1, p2, k3 } = *self;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2); // ∂radial/∂(r²)
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        let j = Matrix2::new(
            radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x,
            2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
            2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
            radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x,
        );
        (Vector2::new(xd, yd), j)
    }

    /// Inverse of [`apply`](Self::apply) by damped Newton iteration. `tol` is the allowed
    /// residual in distorted normalised units. Returns `None` when the point has no preimage in
    /// the region where the distortion map is one-to-one (beyond the fold of strong barrel
    /// distortion) or the iteration does not converge.
    ///
    /// Not a least-squares fit, so not [`crate::lm`]'s: the map is square (2 → 2) and has an exact
    /// preimage, so Newton's step J⁻¹r solves it directly, halved only to stay where the residual
    /// falls; damping toward gradient descent would slow the quadratic convergence it needs for
    /// 460 000 pixels per image.
    pub fn remove(&self, target: Vector2<f64>, tol: f64) -> Option<Vector2<f64>> {
        if self.is_zero() {
            return Some(target);
        }
        // Fixed-point start (OpenCV's first step), then Newton.
        let mut p = target;
        {
            let r2 = p.norm_squared();
            let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
            if radial > 0.1 {
                p /= radial;
            }
        }
        let (mut f, mut j) = self.apply_with_jacobian(p);
        let mut res = f - target;
        for _ in 0..100 {
            if res.norm() <= tol {
                break;
            }
            let step = j.try_inverse()? * res;
            let mut lambda = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                let q = p - lambda * step;
                let (fq, jq) = self.apply_with_jacobian(q);
                let rq = fq - target;
                if rq.norm() < res.norm() {
                    p = q;
                    f = fq;
                    j = jq;
                    res = rq;
                    accepted = true;
                    break;
                }
                lambda *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        let _ = f;
        (res.norm() <= tol && j.determinant() > 0.0).then_some(p)
    }
}

/// Pinhole intrinsics plus distortion, with the image size the calibration belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: Distortion,
    /// [width, height] in pixels.
    pub image_size: [u32; 2],
}

/// Residual allowed when undistorting, in pixels.
pub(crate) const UNDISTORT_TOL_PX: f64 = 1e-10;

impl Camera {
    /// A 1280×960 camera, f = 1400 px, mild barrel distortion: synthetic data's default and the
    /// tests' camera.
    pub(crate) fn example() -> Camera {
        Camera {
            fx: 1400.0,
            fy: 1400.0,
            cx: 643.2,
            cy: 478.5,
            distortion: Distortion {
                k1: -0.12,
                k2: 0.08,
                p1: 4e-4,
                p2: -3e-4,
                k3: 0.0,
            },
            image_size: [1280, 960],
        }
    }

    /// An ideal camera (no distortion) as the renderer uses: square pixels, the principal point
    /// at the centre, a horizontal field of view in degrees.
    pub fn from_fov(width: u32, height: u32, fov_deg: f64) -> Camera {
        let f = 0.5 * width as f64 / (0.5 * fov_deg.to_radians()).tan();
        Camera {
            fx: f,
            fy: f,
            cx: 0.5 * (width as f64 - 1.0),
            cy: 0.5 * (height as f64 - 1.0),
            distortion: Distortion::default(),
            image_size: [width, height],
        }
    }

    /// The same camera without its distortion: the camera of ideal (undistorted) pixels, in which
    /// detections.json gives the outlines.
    pub fn ideal(&self) -> Camera {
        Camera {
            distortion: Distortion::default(),
            ..*self
        }
    }

    /// Unit ray through the ideal (undistorted) pixel (x, y); the distortion is not applied.
    pub fn ideal_ray(&self, x: f64, y: f64) -> Vector3<f64> {
        Vector3::new((x - self.cx) / self.fx, (y - self.cy) / self.fy, 1.0).normalize()
    }

    /// The smaller half field of view (radians).
    pub(crate) fn half_fov(&self) -> f64 {
        let hx = (0.5 * self.width() as f64 / self.fx).atan();
        let hy = (0.5 * self.height() as f64 / self.fy).atan();
        hx.min(hy)
    }

    pub fn width(&self) -> u32 {
        self.image_size[0]
    }

    pub fn height(&self) -> u32 {
        self.image_size[1]
    }

    /// The 3×3 camera matrix K.
    pub fn k(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Distorted normalised coordinates → pixel.
    pub fn to_pixel(&self, d: Vector2<f64>) -> Vector2<f64> {
        Vector2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy)
    }

    /// Pixel → distorted normalised coordinates.
    pub fn from_pixel(&self, px: Vector2<f64>) -> Vector2<f64> {
        Vector2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy)
    }

    /// Project a camera-frame point (mm). `None` behind or on the camera plane.
    pub fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        self.pixel_for_ray(p)
    }

    /// The pixel a ray direction (any length, z > 0) lands on.
    pub fn pixel_for_ray(&self, d: &Vector3<f64>) -> Option<Vector2<f64>> {
        if d.z <= 0.0 || !d.iter().all(|c| c.is_finite()) {
            return None;
        }
        let n = Vector2::new(d.x / d.z, d.y / d.z);
        Some(self.to_pixel(self.distortion.apply(n)))
    }

    /// Undistorted normalised coordinates (x/z, y/z) of the ray through a pixel.
    pub fn undistort_pixel(&self, px: Vector2<f64>) -> Option<Vector2<f64>> {
        let tol = UNDISTORT_TOL_PX / self.fx.max(self.fy);
        self.distortion.remove(self.from_pixel(px), tol)
    }

    /// Unit ray direction through a pixel.
    pub fn ray_for_pixel(&self, px: Vector2<f64>) -> Option<Vector3<f64>> {
        self.undistort_pixel(px)
            .map(|n| Vector3::new(n.x, n.y, 1.0).normalize())
    }

    /// Pixel footprint in normalised units at the image centre (1/f).
    pub fn pixel_angle(&self) -> f64 {
        1.0 / self.fx.min(self.fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_finite_differences() {
        let d = Distortion {
            k1: -0.3,
            k2: 0.1,
            p1: 0.002,
            p2: -0.001,
            k3: 0.02,
        };
        let p = Vector2::new(0.31, -0.22);
        let (_, j) = d.apply_with_jacobian(p);
        let h = 1e-6;
        for c in 0..2 {
            let mut e = Vector2::zeros();
            e[c] = h;
            let fd = (d.apply(p + e) - d.apply(p - e)) / (2.0 * h);
            for r in 0..2 {
                assert!(
                    (fd[r] - j[(r, c)]).abs() < 1e-8,
                    "{r},{c}: {} {}",
                    fd[r],
                    j[(r, c)]
                );
            }
        }
    }
}
