//! A sphere as the detector sees it: its outline in the image and the surface geometry under each
//! pixel, for a perspective camera (the tangent cone of the sphere, fitted to undistorted rays) or,
//! without intrinsics, an orthographic one (a circle in pixels, view direction −z).
//!
//! Every pixel is first turned into a *point* q by the [`Projection`]: the unit ray through it
//! (perspective) or the pixel itself (orthographic, q = (x, y, 0)). Outlines work on points, so
//! silhouette fitting, the edge model and the highlight fit are written once for both cameras.
//!
//! The normalised radial coordinate s of a point is 1 on the silhouette, 0 at the centre:
//! perspective s = sin β / sin α (β: angle from the cone axis, α: half-angle; by the sine rule
//! s = sin φ, φ the angle between normal and view), orthographic s = |q − c| / R. So in both
//! cases cos φ = √(1 − s²) inside.

use crate::camera::sphere::Sphere;
use crate::camera::Camera;
use nalgebra::{Vector2, Vector3};

/// How pixels map to points (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub enum Projection {
    Perspective(Camera),
    Orthographic,
}

impl Projection {
    /// The point of a pixel (`None` where the lens model has no inverse).
    pub fn point(&self, px: Vector2<f64>) -> Option<Vector3<f64>> {
        match self {
            Projection::Perspective(c) => c.ray_for_pixel(px),
            Projection::Orthographic => Some(Vector3::new(px.x, px.y, 0.0)),
        }
    }

    /// The pixel of a point.
    pub fn pixel(&self, q: &Vector3<f64>) -> Option<Vector2<f64>> {
        match self {
            Projection::Perspective(c) => c.pixel_for_ray(q),
            Projection::Orthographic => Some(q.xy()),
        }
    }

    pub(crate) fn is_perspective(&self) -> bool {
        matches!(self, Projection::Perspective(_))
    }
}

/// The silhouette of a sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outline {
    /// Perspective: unit axis toward the centre and half-angle (radians).
    Cone { axis: Vector3<f64>, half_angle: f64 },
    /// Orthographic: centre and radius in pixels.
    Circle { center: Vector2<f64>, radius: f64 },
}

/// Surface geometry under a point: unit normal and unit view vector (toward the camera).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub normal: Vector3<f64>,
    pub view: Vector3<f64>,
}

/// An orthonormal basis (e1, e2) of the plane perpendicular to a unit vector.
pub(crate) fn tangent_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let e1 = a
        .cross(&if a.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        })
        .normalize();
    (e1, a.cross(&e1))
}

impl Outline {
    /// The cone through three rays, or the circle through three pixels.
    pub(crate) fn through_three(q: [&Vector3<f64>; 3], perspective: bool) -> Option<Outline> {
        if perspective {
            let m = nalgebra::Matrix3::from_rows(&[
                q[0].transpose(),
                q[1].transpose(),
                q[2].transpose(),
            ]);
            let w = m.try_inverse()? * Vector3::new(1.0, 1.0, 1.0);
            let n = w.norm();
            if !(n > 1.0) || !n.is_finite() {
                return None;
            }
            let mut axis = w / n;
            if axis.z < 0.0 {
                axis = -axis;
            }
            Some(Outline::Cone {
                axis,
                half_angle: (1.0 / n).acos(),
            })
        } else {
            let (a, b, c) = (q[0].xy(), q[1].xy(), q[2].xy());
            let d = 2.0 * (a.x * (b.y - c.y) + b.x * (c.y - a.y) + c.x * (a.y - b.y));
            if d.abs() < 1e-9 {
                return None;
            }
            let (a2, b2, c2) = (a.norm_squared(), b.norm_squared(), c.norm_squared());
            let center = Vector2::new(
                (a2 * (b.y - c.y) + b2 * (c.y - a.y) + c2 * (a.y - b.y)) / d,
                (a2 * (c.x - b.x) + b2 * (a.x - c.x) + c2 * (b.x - a.x)) / d,
            );
            let radius = (a - center).norm();
            radius
                .is_finite()
                .then_some(Outline::Circle { center, radius })
        }
    }

    /// The outline of a known sphere (the tests' ground truth).
    #[cfg(test)]
    pub(crate) fn of_sphere(s: &Sphere) -> Option<Outline> {
        Some(Outline::Cone {
            axis: s.center.normalize(),
            half_angle: s.cone_half_angle()?,
        })
    }

    /// Normalised radial coordinate of a point (1 on the silhouette).
    pub fn s(&self, q: &Vector3<f64>) -> f64 {
        match self {
            Outline::Cone { axis, half_angle } => {
                let c = q.dot(axis);
                let sin_b = q.cross(axis).norm();
                if c <= 0.0 {
                    return f64::INFINITY;
                }
                sin_b / half_angle.sin()
            }
            Outline::Circle { center, radius } => (q.xy() - center).norm() / radius,
        }
    }

    /// Image radius in pixels (approximate for a cone: the focal length times tan α).
    pub fn radius_px(&self, proj: &Projection) -> f64 {
        match (self, proj) {
            (Outline::Cone { half_angle, .. }, Projection::Perspective(c)) => {
                0.5 * (c.fx + c.fy) * half_angle.tan()
            }
            (Outline::Circle { radius, .. }, _) => *radius,
            (Outline::Cone { half_angle, .. }, Projection::Orthographic) => *half_angle,
        }
    }

    /// The point in the middle: the cone axis or the circle centre.
    pub(crate) fn center_point(&self) -> Vector3<f64> {
        match self {
            Outline::Cone { axis, .. } => *axis,
            Outline::Circle { center, .. } => Vector3::new(center.x, center.y, 0.0),
        }
    }

    /// Normal and view under a point inside the outline.
    pub fn surface(&self, q: &Vector3<f64>) -> Option<Surface> {
        match self {
            Outline::Cone { axis, half_angle } => {
                let sp = Sphere::new(axis / half_angle.sin(), 1.0).surface_at(q)?;
                Some(Surface {
                    normal: sp.normal,
                    view: sp.view,
                })
            }
            Outline::Circle { center, radius } => {
                let u = (q.xy() - center) / *radius;
                let s2 = u.norm_squared();
                if s2 >= 1.0 {
                    return None;
                }
                Some(Surface {
                    normal: Vector3::new(u.x, u.y, -(1.0 - s2).sqrt()),
                    view: Vector3::new(0.0, 0.0, -1.0),
                })
            }
        }
    }

    /// The point whose surface normal is `n` (on the visible side: n·v > 0 is not checked).
    pub(crate) fn point_with_normal(&self, n: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Outline::Cone { axis, half_angle } => (axis / half_angle.sin() + n).normalize(),
            Outline::Circle { center, radius } => {
                let p = center + n.xy() * *radius;
                Vector3::new(p.x, p.y, 0.0)
            }
        }
    }

    /// The point on the sphere where the normal bisects the light and the view: the mirror point
    /// of a light direction (found by a fixed-point iteration on the per-point view vector).
    pub(crate) fn mirror_point(&self, light: &Vector3<f64>) -> Option<Vector3<f64>> {
        let mut q = self.center_point();
        let mut v = self.surface(&q)?.view;
        for _ in 0..50 {
            let h = (light + v).try_normalize(1e-12)?;
            let q_new = self.point_with_normal(&h);
            let v_new = self.surface(&q_new)?.view;
            let done = (q_new - q).norm() < 1e-15 * (1.0 + q.norm());
            q = q_new;
            v = v_new;
            if done {
                break;
            }
        }
        Some(q)
    }

    /// A copy moved by `d` in the outline's own three parameters: the axis turned by (d0, d1)
    /// radians and the half-angle grown by d2 (cone), or the centre moved by (d0, d1) and the
    /// radius grown by d2 pixels (circle).
    pub(crate) fn moved(&self, d: &Vector3<f64>) -> Outline {
        match self {
            Outline::Cone { axis, half_angle } => {
                let (e1, e2) = tangent_basis(axis);
                Outline::Cone {
                    axis: (axis + e1 * d.x + e2 * d.y).normalize(),
                    half_angle: half_angle + d.z,
                }
            }
            Outline::Circle { center, radius } => Outline::Circle {
                center: center + d.xy(),
                radius: radius + d.z,
            },
        }
    }

    /// ∂s/∂d at d = 0 for a point `q`: how the normalised distance [`Outline::s`] of `q`
    /// changes as the outline is [`moved`](Outline::moved) by `d` (`None` where s is not
    /// smooth: `q` on the axis or behind the camera, or at the circle's centre).
    pub(crate) fn ds_dmove(&self, q: &Vector3<f64>) -> Option<Vector3<f64>> {
        match self {
            Outline::Cone { axis, half_angle } => {
                if q.dot(axis) <= 0.0 {
                    return None;
                }
                // s = |q × a′| / sin h with a′ = normalize(a + e1 dx + e2 dy), h = α + dz: at
                // d = 0, ∂a′/∂dx = e1 (e1 ⊥ a), so ∂|q × a′|/∂dx = (q × a)·(q × e1) / |q × a|.
                let (e1, e2) = tangent_basis(axis);
                let qa = q.cross(axis);
                let sin_b = qa.norm();
                if sin_b == 0.0 {
                    return None;
                }
                let sh = half_angle.sin();
                Some(Vector3::new(
                    qa.dot(&q.cross(&e1)) / (sin_b * sh),
                    qa.dot(&q.cross(&e2)) / (sin_b * sh),
                    -sin_b * half_angle.cos() / (sh * sh),
                ))
            }
            Outline::Circle { center, radius } => {
                // s = |q.xy − c − d.xy| / (ρ + dz).
                let v = q.xy() - center;
                let n = v.norm();
                if n == 0.0 {
                    return None;
                }
                Some(Vector3::new(
                    -v.x / (n * radius),
                    -v.y / (n * radius),
                    -n / (radius * radius),
                ))
            }
        }
    }

    /// The size of one pixel in the units of [`Outline::moved`].
    pub(crate) fn pixel_unit(&self, proj: &Projection) -> f64 {
        match self {
            Outline::Cone { half_angle, .. } => half_angle / self.radius_px(proj),
            Outline::Circle { .. } => 1.0,
        }
    }

    /// `n` points evenly around the silhouette.
    pub fn rim(&self, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|k| {
                let t = k as f64 * std::f64::consts::TAU / n as f64;
                match self {
                    Outline::Cone { axis, half_angle } => {
                        let (e1, e2) = tangent_basis(axis);
                        axis * half_angle.cos() + (e1 * t.cos() + e2 * t.sin()) * half_angle.sin()
                    }
                    Outline::Circle { center, radius } => Vector3::new(
                        center.x + radius * t.cos(),
                        center.y + radius * t.sin(),
                        0.0,
                    ),
                }
            })
            .collect()
    }

    /// The silhouette as an ellipse in ideal (undistorted pinhole) pixels; for a circle, the
    /// circle itself.
    pub fn ellipse(&self, proj: &Projection) -> Option<crate::camera::sphere::Ellipse> {
        match (self, proj) {
            (Outline::Cone { axis, half_angle }, Projection::Perspective(cam)) => {
                Sphere::new(axis / half_angle.sin(), 1.0).image_ellipse(cam)
            }
            (Outline::Circle { center, radius }, _) => Some(crate::camera::sphere::Ellipse {
                center: *center,
                semi_axes: [*radius, *radius],
                angle: 0.0,
            }),
            _ => None,
        }
    }

    /// Largest pixel distance between the rims of two outlines (72 points compared).
    pub(crate) fn distance_px(&self, other: &Outline, proj: &Projection) -> f64 {
        self.rim(72)
            .iter()
            .zip(other.rim(72))
            .filter_map(|(p, q)| Some((proj.pixel(p)? - proj.pixel(&q)?).norm()))
            .fold(0.0, f64::max)
    }

    /// Inclusive pixel box [x0, y0, x1, y1] of the silhouette (720 rim points), padded by `pad`
    /// pixels and clipped to a `width` × `height` image; `None` when part of the rim has no pixel.
    pub(crate) fn pixel_box(
        &self,
        proj: &Projection,
        pad: f64,
        width: u32,
        height: u32,
    ) -> Option<[u32; 4]> {
        let rim: Vec<Vector2<f64>> = self.rim(720).iter().filter_map(|q| proj.pixel(q)).collect();
        if rim.len() < 720 || width == 0 || height == 0 {
            return None;
        }
        let lo =
            |f: fn(&Vector2<f64>) -> f64| rim.iter().map(f).fold(f64::INFINITY, f64::min) - pad;
        let hi =
            |f: fn(&Vector2<f64>) -> f64| rim.iter().map(f).fold(f64::NEG_INFINITY, f64::max) + pad;
        let clip = |v: f64, max: u32| v.clamp(0.0, (max - 1) as f64) as u32;
        Some([
            clip(lo(|p| p.x).floor(), width),
            clip(lo(|p| p.y).floor(), height),
            clip(hi(|p| p.x).ceil(), width),
            clip(hi(|p| p.y).ceil(), height),
        ])
    }

    /// The sphere's centre (mm) for a known radius; `None` for an orthographic outline.
    pub fn center_mm(&self, radius_mm: f64) -> Option<Vector3<f64>> {
        match self {
            Outline::Cone { axis, half_angle } => Some(axis * (radius_mm / half_angle.sin())),
            Outline::Circle { .. } => None,
        }
    }
}

/// The mirror direction: the light that a highlight at normal `n` seen from `v` comes from.
pub fn reflect(n: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    (2.0 * n.dot(v) * n - v).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn s_is_sin_phi_and_mirror_point_reflects() {
        let cam = crate::camera::Camera::example();
        let proj = Projection::Perspective(cam);
        let sp = Sphere::new(Vector3::new(60.0, -40.0, 500.0), 30.0);
        let o = Outline::of_sphere(&sp).unwrap();
        for px in [Vector2::new(800.0, 370.0), Vector2::new(860.0, 400.0)] {
            let q = proj.point(px).unwrap();
            let s = o.s(&q);
            let surf = o.surface(&q).unwrap();
            let phi = surf.normal.dot(&surf.view).acos();
            assert!((s - phi.sin()).abs() < 1e-12, "{s} {}", phi.sin());
            // Same normal as the sphere in mm.
            assert!((sp.surface_at(&q).unwrap().normal - surf.normal).norm() < 1e-12);
        }
        let l = Vector3::new(0.5, -0.3, -0.8).normalize();
        let q = o.mirror_point(&l).unwrap();
        let surf = o.surface(&q).unwrap();
        assert!((reflect(&surf.normal, &surf.view) - l).norm() < 1e-12);
        let c = Outline::Circle {
            center: Vector2::new(300.0, 200.0),
            radius: 70.0,
        };
        let q = c.mirror_point(&l).unwrap();
        let surf = c.surface(&q).unwrap();
        assert!((reflect(&surf.normal, &surf.view) - l).norm() < 1e-12);
    }

    #[test]
    fn three_points_give_the_outline_back() {
        let c = Outline::Circle {
            center: Vector2::new(10.0, -4.0),
            radius: 7.5,
        };
        let r = c.rim(3);
        assert_eq!(
            Outline::through_three([&r[0], &r[1], &r[2]], false).map(|o| match o {
                Outline::Circle { center, radius } =>
                    (center - Vector2::new(10.0, -4.0)).norm() < 1e-12
                        && (radius - 7.5).abs() < 1e-12,
                _ => false,
            }),
            Some(true)
        );
    }

    /// The analytic ∂s/∂d against central differences of s along each move, for a cone and a
    /// circle, at points inside, on and outside the rim.
    #[test]
    fn ds_dmove_matches_finite_differences() {
        let cam = crate::camera::Camera::example();
        let proj = Projection::Perspective(cam);
        let cone =
            Outline::of_sphere(&Sphere::new(Vector3::new(60.0, -40.0, 500.0), 30.0)).unwrap();
        let circle = Outline::Circle {
            center: Vector2::new(300.0, 200.0),
            radius: 70.0,
        };
        let points = |o: &Outline| -> Vec<Vector3<f64>> {
            let mut v = vec![];
            for (k, q) in o.rim(7).into_iter().enumerate() {
                // The rim point scaled about the centre: inside, on and outside.
                for f in [0.6, 1.0, 1.3] {
                    let c = o.center_point();
                    let p = c + (q - c) * f;
                    v.push(if k % 2 == 0 {
                        p
                    } else {
                        p.normalize() * p.norm()
                    });
                }
            }
            v
        };
        for (o, unit) in [(cone, cone.pixel_unit(&proj)), (circle, 1.0)] {
            for q in points(&o) {
                let g = o.ds_dmove(&q).expect("smooth away from the axis");
                for c in 0..3 {
                    let h = 1e-4 * unit;
                    let mut d = Vector3::zeros();
                    d[c] = h;
                    let fd = (o.moved(&d).s(&q) - o.moved(&-d).s(&q)) / (2.0 * h);
                    let tol = 1e-6 * fd.abs().max(g.norm());
                    assert!(
                        (g[c] - fd).abs() < tol,
                        "{o:?} q {q:?} ∂{c}: {} vs {fd}",
                        g[c]
                    );
                }
            }
        }
    }
}
