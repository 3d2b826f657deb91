//! Mesh curvature against analytic shapes: sphere, torus, ellipsoid, an open hemisphere, and the
//! real meshes of ../shared/data/meshes.

use nalgebra::Vector3;
use workbench::render::mesh::{shapes, Mesh, Unit};

/// Relative errors of `est` against `truth` over vertices: (median, 95th percentile, max).
fn stats(est: &[f64], truth: &[f64]) -> (f64, f64, f64) {
    let mut e: Vec<f64> = est
        .iter()
        .zip(truth)
        .map(|(a, b)| ((a - b) / b).abs())
        .collect();
    e.sort_by(|a, b| a.total_cmp(b));
    let q = |f: f64| e[((e.len() - 1) as f64 * f) as usize];
    (q(0.5), q(0.95), e[e.len() - 1])
}

fn mean_abs(k: (f64, f64)) -> f64 {
    0.5 * (k.0.abs() + k.1.abs())
}

#[test]
fn sphere_curvature_is_one_over_r() {
    for (r, level) in [(20.0, 4), (3.0, 3)] {
        let m = shapes::icosphere(Vector3::new(1.0, 2.0, 3.0), r, level);
        let k = m.curvature();
        let truth = vec![1.0 / r; k.len()];
        let (med, p95, max) = stats(&k, &truth);
        println!("sphere r {r} level {level}: median {med:.2e} p95 {p95:.2e} max {max:.2e}");
        // The vertices lie on the sphere: exact to rounding (measured 3.3e-16).
        assert!(max < 1e-15, "{max}");
    }
}

#[test]
fn torus_curvature_matches_analytic() {
    let (big, small) = (30.0, 10.0);
    let (nu, nv) = (180, 60);
    let m = shapes::torus(big, small, nu, nv);
    let k = m.curvature();
    let truth: Vec<f64> = (0..k.len())
        .map(|i| {
            let v = std::f64::consts::TAU * (i / nu) as f64 / nv as f64;
            mean_abs(shapes::torus_curvatures(big, small, v))
        })
        .collect();
    let (med, p95, max) = stats(&k, &truth);
    println!("torus {big}/{small} {nu}x{nv}: median {med:.2e} p95 {p95:.2e} max {max:.2e}");
    assert!(med < 0.01 && p95 < 0.03 && max < 0.05, "{med} {p95} {max}");
}

#[test]
fn ellipsoid_curvature_matches_analytic() {
    let (a, b, c) = (30.0, 20.0, 12.0);
    let m = shapes::ellipsoid(a, b, c, 5);
    let k = m.curvature();
    let truth: Vec<f64> = m
        .positions
        .iter()
        .map(|p| mean_abs(shapes::ellipsoid_curvatures(a, b, c, p)))
        .collect();
    let (med, p95, max) = stats(&k, &truth);
    println!(
        "ellipsoid {a}/{b}/{c} ({} vertices): median {med:.2e} p95 {p95:.2e} max {max:.2e}",
        k.len()
    );
    assert!(med < 0.01 && p95 < 0.03 && max < 0.05, "{med} {p95} {max}");
}

/// An open hemisphere: boundary vertices must not be biased by their one-sided neighbourhood.
#[test]
fn open_boundary_is_handled() {
    let full = shapes::icosphere(Vector3::zeros(), 25.0, 4);
    let triangles: Vec<[u32; 3]> = full
        .triangles
        .iter()
        .copied()
        .filter(|t| t.iter().all(|&i| full.positions[i as usize].z >= -1.0))
        .collect();
    let m = Mesh::new(
        full.positions.clone(),
        triangles,
        None,
        std::path::Path::new("hemisphere"),
    )
    .unwrap();
    let boundary = m.boundary();
    let nb = m.neighbours();
    let k = m.curvature();
    let used: Vec<usize> = (0..k.len()).filter(|&i| !nb[i].is_empty()).collect();
    let n_boundary = boundary.iter().filter(|&&b| b).count();
    assert!(n_boundary > 50, "{n_boundary} boundary vertices");
    let est: Vec<f64> = used.iter().map(|&i| k[i]).collect();
    let truth = vec![1.0 / 25.0; est.len()];
    let (med, p95, max) = stats(&est, &truth);
    println!(
        "hemisphere ({n_boundary} boundary vertices): median {med:.2e} p95 {p95:.2e} max {max:.2e}"
    );
    assert!(max < 0.05, "{max}");
}

#[test]
fn real_meshes_load_with_plausible_curvature() {
    // Skipped with a printed reason when ../shared is absent, a failure under CI=true.
    let Some(data) = crate::common::shared_data() else {
        return;
    };
    let dir = data.join("meshes");
    let bunny = dir.join("stanford-bunny.obj");
    let m = Mesh::load(&bunny, Unit::M).unwrap();
    // 35 947 vertices in the file, some on no face.
    assert!(m.positions.len() > 34_000 && m.positions.len() <= 35_947);
    assert!(m.triangles.len() > 69000);
    let (_, r) = m.bounds();
    // The bunny is about 15 cm across.
    assert!(r > 70.0 && r < 150.0, "{r}");
    let k = m.curvature();
    let mut s = k.clone();
    s.sort_by(|a, b| a.total_cmp(b));
    let med = s[s.len() / 2];
    println!(
        "bunny: bounding radius {r:.1} mm, curvature median {med:.4}/mm, p95 {:.4}/mm, boundary vertices {}",
        s[s.len() * 95 / 100],
        m.boundary().iter().filter(|&&b| b).count()
    );
    // A scanned surface is bumpy: the median radius of curvature (16 mm) lies well below the
    // bounding radius, but between a twentieth of it and it.
    assert!(med > 1.0 / r && med < 20.0 / r, "{med}");
}
