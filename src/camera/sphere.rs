//! A sphere seen by a perspective camera: its silhouette cone and image ellipse, and the surface
//! geometry (point, normal, view vector) under each pixel.
//!
//! The rays tangent to a sphere of radius R centred at C form a circular cone with axis C/|C| and
//! half-angle asin(R/|C|). In normalised image coordinates x = (x, y, 1) the cone is the conic
//! xᵀ Q x = 0 with Q = C Cᵀ − (|C|² − R²) I (positive inside the silhouette). Its image is an
//! ellipse whose centre is *not* the image of C unless C lies on the optical axis.

use crate::camera::Camera;
use nalgebra::{Matrix2, Matrix3, SymmetricEigen, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// An ellipse in pixel coordinates: centre, semi-axes (major first) and the angle of the major
/// axis from the +x axis (radians, in (−π/2, π/2]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipse {
    pub center: Vector2<f64>,
    pub semi_axes: [f64; 2],
    pub angle: f64,
}

/// The JSON form of an ellipse (degrees for the human-facing angle).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EllipseJson {
    pub center_px: [f64; 2],
    /// Semi-axes in pixels, major first.
    pub axes_px: [f64; 2],
    /// Angle of the major axis from +x, degrees (image y points down).
    pub angle_deg: f64,
}

impl From<Ellipse> for EllipseJson {
    fn from(e: Ellipse) -> Self {
        EllipseJson {
            center_px: [e.center.x, e.center.y],
            axes_px: e.semi_axes,
            angle_deg: e.angle.to_degrees(),
        }
    }
}

impl Ellipse {
    /// Implicit value ((u·a)/A)² + ((u·b)/B)² − 1 at a pixel: 0 on the ellipse, < 0 inside.
    pub fn implicit(&self, p: Vector2<f64>) -> f64 {
        let u = p - self.center;
        let (s, c) = self.angle.sin_cos();
        let a = (u.x * c + u.y * s) / self.semi_axes[0];
        let b = (-u.x * s + u.y * c) / self.semi_axes[1];
        a * a + b * b - 1.0
    }

    /// The ellipse of a symmetric 3×3 conic matrix M (points p with [p 1] M [p 1]ᵀ = 0).
    pub(crate) fn from_conic(m: &Matrix3<f64>) -> Option<Ellipse> {
        let a = Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
        let b = Vector2::new(m[(0, 2)], m[(1, 2)]);
        let center = -a.try_inverse()? * b;
        let fc = b.dot(&center) + m[(2, 2)];
        if fc == 0.0 || !fc.is_finite() {
            return None;
        }
        let s = a / -fc;
        let eig = SymmetricEigen::new(s);
        let (i_min, i_max) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let (l_min, l_max) = (eig.eigenvalues[i_min], eig.eigenvalues[i_max]);
        if l_min <= 0.0 {
            return None; // not an ellipse (the sphere crosses the camera plane)
        }
        let v = eig.eigenvectors.column(i_min);
        let mut angle = v.y.atan2(v.x);
        if angle <= -std::f64::consts::FRAC_PI_2 {
            angle += std::f64::consts::PI;
        } else if angle > std::f64::consts::FRAC_PI_2 {
            angle -= std::f64::consts::PI;
        }
        Some(Ellipse {
            center,
            semi_axes: [1.0 / l_min.sqrt(), 1.0 / l_max.sqrt()],
            angle,
        })
    }
}

/// Geometry of the visible surface point under one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The 3D point, camera frame (mm).
    pub point: Vector3<f64>,
    /// Outward unit normal.
    pub normal: Vector3<f64>,
    /// Unit vector from the point toward the camera.
    pub view: Vector3<f64>,
    /// Distance along the ray (mm).
    pub t: f64,
}

/// A sphere in the camera frame (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vector3<f64>,
    pub radius: f64,
}

impl Sphere {
    pub fn new(center: Vector3<f64>, radius: f64) -> Self {
        Sphere { center, radius }
    }

    /// Half-angle of the tangent cone, asin(R/|C|); `None` if the camera is inside the sphere.
    pub(crate) fn cone_half_angle(&self) -> Option<f64> {
        let d = self.center.norm();
        (d > self.radius).then(|| (self.radius / d).asin())
    }

    /// Q = C Cᵀ − (|C|² − R²) I: the silhouette cone as a conic in normalised coordinates.
    pub(crate) fn normalized_conic(&self) -> Matrix3<f64> {
        let c = self.center;
        c * c.transpose() - Matrix3::identity() * (c.norm_squared() - self.radius * self.radius)
    }

    /// The silhouette conic in (undistorted, ideal pinhole) pixel coordinates: K⁻ᵀ Q K⁻¹.
    pub(crate) fn image_conic(&self, cam: &Camera) -> Matrix3<f64> {
        // K⁻¹ in closed form (K is upper triangular without skew).
        let kinv = Matrix3::new(
            1.0 / cam.fx,
            0.0,
            -cam.cx / cam.fx,
            0.0,
            1.0 / cam.fy,
            -cam.cy / cam.fy,
            0.0,
            0.0,
            1.0,
        );
        kinv.transpose() * self.normalized_conic() * kinv
    }

    /// The silhouette ellipse in ideal pinhole pixel coordinates (distortion not applied: with a
    /// distorting lens the observed outline is this ellipse mapped through the distortion).
    pub fn image_ellipse(&self, cam: &Camera) -> Option<Ellipse> {
        Ellipse::from_conic(&self.image_conic(cam))
    }

    /// Nearest intersection of the ray t·d (d unit, from the camera centre) with the sphere.
    pub(crate) fn intersect(&self, d: &Vector3<f64>) -> Option<f64> {
        let b = d.dot(&self.center);
        let disc = b * b - (self.center.norm_squared() - self.radius * self.radius);
        if disc < 0.0 || b <= 0.0 {
            return None;
        }
        // Stable form of b − sqrt(disc).
        let q = b + disc.sqrt();
        let t = (self.center.norm_squared() - self.radius * self.radius) / q;
        (t > 0.0).then_some(t)
    }

    /// Surface point, normal and view vector for a unit ray direction.
    pub fn surface_at(&self, d: &Vector3<f64>) -> Option<SurfacePoint> {
        let t = self.intersect(d)?;
        let point = d * t;
        let normal = (point - self.center) / self.radius;
        Some(SurfacePoint {
            point,
            normal: normal.normalize(),
            view: -d,
            t,
        })
    }

    /// Angular distance of a unit ray from the silhouette (positive outside), radians.
    pub fn angle_outside(&self, d: &Vector3<f64>) -> Option<f64> {
        let half = self.cone_half_angle()?;
        let c = d.dot(&self.center) / self.center.norm();
        Some(c.clamp(-1.0, 1.0).acos() - half)
    }
}

/// θ = angle(n, l) and φ = angle(n, v) at a surface point, radians.
pub fn angles(sp: &SurfacePoint, light: &Vector3<f64>) -> (f64, f64) {
    (
        sp.normal.dot(light).clamp(-1.0, 1.0).acos(),
        sp.normal.dot(&sp.view).clamp(-1.0, 1.0).acos(),
    )
}
