//! Fewer residuals for the solver: on one sphere under one distant light the model depends on a
//! pixel's geometry only through θ = angle(n, l) and φ = angle(n, v) (and l·v, nearly constant
//! over a sphere), so pixels are pooled in (θ, φ) cells of a given width per sphere. A cell
//! becomes one observation: the mean radiance, a virtual pixel at exactly the cell's mean (θ, φ)
//! (the view of the member nearest that mean, and the normal with those two angles on that
//! member's side of the light–view plane), and its channel weights multiplied by √(pixel count) — the mean of n pixels has 1/√n
//! of their noise. The price is the model's curvature inside a cell (second order in the width);
//! [`crate::solver`] fits are compared at several widths in the tests and the benchmark.

use crate::solver::Obs;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Pool observations in (radius, θ, φ) cells `width` radians wide, θ measured from `light`.
/// Pixels whose normal lies within `keep` radians of their half vector (the specular highlight,
/// where the lobe changes by its whole height across a cell: near the mirror point θ + φ reaches
/// the angle between light and view, and the half-vector angle grows like the square root of the
/// distance from that edge) are kept as they are.
pub fn pool(obs: &[Obs], light: &Vector3<f64>, width: f64, keep: f64) -> Vec<Obs> {
    if !(width > 0.0) {
        return obs.to_vec();
    }
    struct Cell {
        n: usize,
        sum: [f64; 3],
        theta: f64,
        phi: f64,
        members: Vec<usize>,
    }
    let angles: Vec<(f64, f64)> = obs
        .iter()
        .map(|o| {
            let g = &o.geometry;
            (
                g.normal.dot(light).clamp(-1.0, 1.0).acos(),
                g.normal.dot(&g.view).clamp(-1.0, 1.0).acos(),
            )
        })
        .collect();
    let mut cells: HashMap<(u64, i64, i64, [u64; 3]), Cell> = HashMap::new();
    let mut kept = vec![];
    for (i, (o, &(t, p))) in obs.iter().zip(&angles).enumerate() {
        let g = &o.geometry;
        let h = (light + g.view).normalize();
        if g.normal.dot(&h).clamp(-1.0, 1.0).acos() < keep {
            kept.push((i, *o));
            continue;
        }
        let key = (
            o.geometry.radius_mm.to_bits(),
            (t / width).floor() as i64,
            (p / width).floor() as i64,
            o.weight.map(f64::to_bits),
        );
        let c = cells.entry(key).or_insert(Cell {
            n: 0,
            sum: [0.0; 3],
            theta: 0.0,
            phi: 0.0,
            members: vec![],
        });
        c.n += 1;
        for k in 0..3 {
            c.sum[k] += o.radiance[k];
        }
        c.theta += t;
        c.phi += p;
        c.members.push(i);
    }
    let mut out: Vec<(usize, Obs)> = cells
        .into_values()
        .map(|c| {
            let n = c.n as f64;
            let (mt, mp) = (c.theta / n, c.phi / n);
            let rep = *c
                .members
                .iter()
                .min_by(|&&a, &&b| {
                    let da = (angles[a].0 - mt).powi(2) + (angles[a].1 - mp).powi(2);
                    let db = (angles[b].0 - mt).powi(2) + (angles[b].1 - mp).powi(2);
                    da.total_cmp(&db)
                })
                .expect("a cell has a member");
            let o = &obs[rep];
            let mut geometry = o.geometry;
            if let Some(n) = normal_with_angles(&o.geometry.view, light, mt, mp, &o.geometry.normal)
            {
                geometry.normal = n;
            }
            (
                rep,
                Obs {
                    geometry,
                    radiance: c.sum.map(|s| s / n),
                    weight: o.weight.map(|w| w * n.sqrt()),
                },
            )
        })
        .collect();
    out.extend(kept);
    // Deterministic order (the map's is not).
    out.sort_by_key(|(rep, _)| *rep);
    out.into_iter().map(|(_, o)| o).collect()
}

/// The unit normal at angle θ from `light` and φ from `view`, on the side of the light–view plane
/// where `near` lies (`None` when the two directions are parallel).
pub fn normal_with_angles(
    view: &Vector3<f64>,
    light: &Vector3<f64>,
    theta: f64,
    phi: f64,
    near: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let w = view.dot(light);
    let s2 = 1.0 - w * w;
    if s2 < 1e-12 {
        return None;
    }
    let (ct, cp) = (theta.cos(), phi.cos());
    let a = (cp - w * ct) / s2;
    let b = (ct - w * cp) / s2;
    let e = view.cross(light) / s2.sqrt();
    let in_plane = view * a + light * b;
    let g = (1.0 - in_plane.norm_squared()).max(0.0).sqrt();
    let sign = if near.dot(&e) < 0.0 { -1.0 } else { 1.0 };
    Some((in_plane + e * (sign * g)).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_normal_has_the_asked_angles_on_the_asked_side() {
        let v = Vector3::new(0.1, -0.05, -1.0).normalize();
        let l = Vector3::new(0.8, -0.3, -0.5).normalize();
        let e = v.cross(&l);
        // Feasible pairs: |θ − φ| ≤ angle(v, l) ≈ 0.93 ≤ θ + φ.
        for (t, p) in [(0.5, 0.6), (1.2, 0.9), (0.7, 1.4)] {
            for side in [1.0, -1.0] {
                let n = normal_with_angles(&v, &l, t, p, &(e * side)).unwrap();
                assert!((n.norm() - 1.0).abs() < 1e-12);
                assert!((n.dot(&l).acos() - t).abs() < 1e-9, "θ");
                assert!((n.dot(&v).acos() - p).abs() < 1e-9, "φ");
                assert!(n.dot(&e) * side >= 0.0);
            }
        }
    }
}
