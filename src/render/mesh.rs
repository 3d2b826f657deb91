//! Triangle meshes: loading (Wavefront OBJ through `tobj`, PLY through `ply-rs-bw`), vertex
//! normals, and per-vertex curvature for the CDRF look-up.
//!
//! Curvature (1/mm) is estimated from edges. For vertex i with normal n_i and each neighbour j,
//! the edge e = p_j − p_i gives the normal curvature along its tangent direction,
//! κ_e = (n_j − n_i)·e / |e|² (exact on a sphere with exact normals). A least-squares fit of the
//! second fundamental form II = [[a, b], [b, c]] in the tangent plane to those samples,
//! κ_e = a x² + 2b xy + c y², gives the principal curvatures k1, k2; the vertex gets the mean
//! absolute curvature (|k1| + |k2|) / 2: 1/r on a sphere, the mean curvature on convex parts, not
//! zero on saddles (light scatters there too). With fewer than three independent edge directions
//! the mean of the κ_e is used. Open-boundary vertices (on an edge with one face) see half a
//! neighbourhood and take the mean of their interior neighbours' estimates; interior vertices leave
//! edges to boundary vertices out of their fit. The estimate is then
//! smoothed ([`SMOOTHING_ROUNDS`] rounds of one-ring averaging) and clamped by the caller to the
//! table's range.

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;
use std::path::Path;

/// Units of a mesh file's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Unit {
    Mm,
    M,
}

impl Unit {
    /// Millimetres per file unit.
    pub fn mm(self) -> f64 {
        match self {
            Unit::Mm => 1.0,
            Unit::M => 1000.0,
        }
    }
}

/// An indexed triangle mesh, positions in mm.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vector3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals (from the file when it has them for every vertex, else computed).
    pub normals: Vec<Vector3<f64>>,
}

/// One-ring smoothing rounds applied to the raw curvature estimate.
pub(crate) const SMOOTHING_ROUNDS: usize = 2;

/// Largest mesh accepted (vertices or triangles).
pub(crate) const MAX_ELEMENTS: usize = 50_000_000;

impl Mesh {
    /// Build from positions (mm) and triangles: checks indices and values, drops degenerate
    /// triangles (repeated or collinear vertices), computes normals when none are given.
    pub fn new(
        positions: Vec<Vector3<f64>>,
        triangles: Vec<[u32; 3]>,
        normals: Option<Vec<Vector3<f64>>>,
        file: &Path,
    ) -> Result<Mesh> {
        if positions.len() > MAX_ELEMENTS || triangles.len() > MAX_ELEMENTS {
            return Err(Error::invalid(
                file,
                format!("mesh larger than {MAX_ELEMENTS} elements"),
            ));
        }
        if let Some(k) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::invalid(file, format!("vertex {k} is not finite")));
        }
        let n = positions.len();
        if let Some(t) = triangles
            .iter()
            .find(|t| t.iter().any(|&i| i as usize >= n))
        {
            return Err(Error::invalid(
                file,
                format!("face {:?} refers to a vertex beyond the {n} given", t),
            ));
        }
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                (b - a).cross(&(c - a)).norm_squared() > 0.0
            })
            .collect();
        if triangles.is_empty() {
            return Err(Error::invalid(file, "no triangles with area"));
        }
        let normals = match normals {
            Some(ns)
                if ns.len() == n
                    && ns
                        .iter()
                        .all(|v| v.norm() > 0.0 && v.iter().all(|c| c.is_finite())) =>
            {
                ns.iter().map(|v| v.normalize()).collect()
            }
            _ => {
                // Normals from the winding, turned outward: a mesh wound clockwise (negative
                // enclosed volume) is flipped.
                let mut ns = vertex_normals(&positions, &triangles);
                if signed_volume(&positions, &triangles) < 0.0 {
                    ns.iter_mut().for_each(|v| *v = -*v);
                }
                ns
            }
        };
        Ok(Mesh {
            positions,
            triangles,
            normals,
        })
    }

    /// Load an OBJ or PLY file (by extension), scaling coordinates by `unit`.
    pub fn load(path: &Path, unit: Unit) -> Result<Mesh> {
        crate::formats::input::regular_file(path)?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        let (mut pos, tris, normals) = match ext.as_deref() {
            Some("obj") => read_obj(path)?,
            Some("ply") => read_ply(path)?,
            _ => {
                return Err(Error::invalid(
                    path,
                    "not a mesh: expected a .obj or .ply file",
                ))
            }
        };
        let s = unit.mm();
        for p in &mut pos {
            *p *= s;
        }
        Mesh::new(pos, tris, normals, path)
    }

    /// Centre and radius of a sphere holding every vertex (the bounding box's centre).
    pub fn bounds(&self) -> (Vector3<f64>, f64) {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in &self.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let c = (lo + hi) / 2.0;
        let r = self
            .positions
            .iter()
            .map(|p| (p - c).norm())
            .fold(0.0, f64::max);
        (c, r)
    }

    /// The vertices on an open boundary (an edge used by one triangle).
    pub fn boundary(&self) -> Vec<bool> {
        let mut count: HashMap<(u32, u32), u32> = HashMap::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut out = vec![false; self.positions.len()];
        for ((a, b), c) in count {
            if c == 1 {
                out[a as usize] = true;
                out[b as usize] = true;
            }
        }
        out
    }

    /// Each vertex's neighbours (sorted, unique).
    pub fn neighbours(&self) -> Vec<Vec<u32>> {
        let mut nb: Vec<Vec<u32>> = vec![Vec::new(); self.positions.len()];
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                nb[a as usize].push(b);
                nb[b as usize].push(a);
            }
        }
        for v in &mut nb {
            v.sort_unstable();
            v.dedup();
        }
        nb
    }

    /// Per-vertex curvature (1/mm), as the module describes; vertices on no triangle get 0.
    pub fn curvature(&self) -> Vec<f64> {
        use rayon::prelude::*;
        let nb = self.neighbours();
        let boundary = self.boundary();
        let raw: Vec<f64> = (0..self.positions.len())
            .into_par_iter()
            .map(|i| {
                // An interior vertex leaves out its boundary neighbours (their normals see one side
                // only) while three or more others remain.
                let inner: Vec<u32> = nb[i]
                    .iter()
                    .copied()
                    .filter(|&j| !boundary[j as usize])
                    .collect();
                if !boundary[i] && inner.len() >= 3 {
                    self.vertex_curvature(i, &inner)
                } else {
                    self.vertex_curvature(i, &nb[i])
                }
            })
            .collect();
        // Boundary vertices: mean over interior neighbours (kept when they have none).
        let mut k: Vec<f64> = (0..raw.len())
            .map(|i| {
                if !boundary[i] {
                    return raw[i];
                }
                let inner: Vec<f64> = nb[i]
                    .iter()
                    .filter(|&&j| !boundary[j as usize])
                    .map(|&j| raw[j as usize])
                    .collect();
                if inner.is_empty() {
                    raw[i]
                } else {
                    inner.iter().sum::<f64>() / inner.len() as f64
                }
            })
            .collect();
        for _ in 0..SMOOTHING_ROUNDS {
            k = (0..k.len())
                .into_par_iter()
                .map(|i| {
                    (k[i] + nb[i].iter().map(|&j| k[j as usize]).sum::<f64>())
                        / (1 + nb[i].len()) as f64
                })
                .collect();
        }
        k
    }

    fn vertex_curvature(&self, i: usize, nb: &[u32]) -> f64 {
        if nb.is_empty() {
            return 0.0;
        }
        let p = self.positions[i];
        let n = self.normals[i];
        // Tangent frame.
        let helper = if n.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let t1 = n.cross(&helper).normalize();
        let t2 = n.cross(&t1);
        let mut ata = Matrix3::zeros();
        let mut atb = Vector3::zeros();
        let mut mean = 0.0;
        for &j in nb {
            let e = self.positions[j as usize] - p;
            let l2 = e.norm_squared();
            let ke = (self.normals[j as usize] - n).dot(&e) / l2;
            mean += ke;
            let d = e - n * n.dot(&e);
            let dn = d.norm();
            if dn == 0.0 {
                continue;
            }
            let (x, y) = (d.dot(&t1) / dn, d.dot(&t2) / dn);
            let row = Vector3::new(x * x, 2.0 * x * y, y * y);
            ata += row * row.transpose();
            atb += row * ke;
        }
        mean /= nb.len() as f64;
        // Well-posed when the edge directions span the three quadratic terms.
        let scale = ata.trace();
        if nb.len() >= 3 && ata.determinant() > 1e-6 * scale * scale * scale {
            if let Some(s) = ata.cholesky().map(|c| c.solve(&atb)) {
                let (a, b, c) = (s.x, s.y, s.z);
                let h = 0.5 * (a + c);
                let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
                return 0.5 * ((h + r).abs() + (h - r).abs());
            }
        }
        mean.abs()
    }
}

/// The volume a closed mesh encloses, positive when its triangles wind counter-clockwise seen
/// from outside (for an open mesh, of the cone from the origin over it).
pub(crate) fn signed_volume(positions: &[Vector3<f64>], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            a.dot(&b.cross(&c))
        })
        .sum::<f64>()
        / 6.0
}

/// Angle-weighted vertex normals (orientation from the triangles' winding).
pub(crate) fn vertex_normals(
    positions: &[Vector3<f64>],
    triangles: &[[u32; 3]],
) -> Vec<Vector3<f64>> {
    let mut acc = vec![Vector3::zeros(); positions.len()];
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        let fnorm = (p[1] - p[0]).cross(&(p[2] - p[0]));
        let len = fnorm.norm();
        if len == 0.0 {
            continue;
        }
        let fnorm = fnorm / len;
        for k in 0..3 {
            let a = (p[(k + 1) % 3] - p[k]).normalize();
            let b = (p[(k + 2) % 3] - p[k]).normalize();
            let angle = a.dot(&b).clamp(-1.0, 1.0).acos();
            acc[t[k] as usize] += fnorm * angle;
        }
    }
    acc.into_iter()
        .map(|v| {
            let l = v.norm();
            if l > 0.0 {
                v / l
            } else {
                Vector3::z()
            }
        })
        .collect()
}

type Loaded = (Vec<Vector3<f64>>, Vec<[u32; 3]>, Option<Vec<Vector3<f64>>>);

fn read_obj(path: &Path) -> Result<Loaded> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are not used: a missing .mtl is no error.
    let (models, _) = tobj::load_obj(path, &opts).map_err(|e| match e {
        tobj::LoadError::OpenFileFailed => {
            Error::io(path, std::io::Error::other("cannot open the file"))
        }
        e => Error::invalid(path, format!("not a readable OBJ file: {e}")),
    })?;
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    let mut normals = Vec::new();
    let mut all_normals = true;
    for m in &models {
        let mesh = &m.mesh;
        let base = pos.len() as u32;
        let nv = mesh.positions.len() / 3;
        pos.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|c| Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64)),
        );
        if mesh.normals.len() == mesh.positions.len() {
            normals.extend(
                mesh.normals
                    .chunks_exact(3)
                    .map(|c| Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64)),
            );
        } else {
            all_normals = false;
        }
        for t in mesh.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= nv) {
                return Err(Error::invalid(
                    path,
                    format!("face refers to vertex {} of {nv}", t.iter().max().unwrap()),
                ));
            }
            tris.push([base + t[0], base + t[1], base + t[2]]);
        }
    }
    if pos.is_empty() {
        return Err(Error::invalid(path, "no vertices"));
    }
    Ok((pos, tris, all_normals.then_some(normals)))
}

fn read_ply(path: &Path) -> Result<Loaded> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| {
            Error::invalid(
                path,
                format!(
                    "not a readable PLY file: {}",
                    crate::error::one_line(&e.to_string())
                ),
            )
        })?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or_else(|| Error::invalid(path, "no \"vertex\" element"))?;
    let scalar = |e: &DefaultElement, k: &str| -> Option<f64> {
        match e.get(k)? {
            Property::Float(v) => Some(*v as f64),
            Property::Double(v) => Some(*v),
            p => p.to_f32_lossy().map(|v| v as f64),
        }
    };
    let mut pos = Vec::with_capacity(vertices.len());
    let mut normals = Vec::with_capacity(vertices.len());
    for (k, v) in vertices.iter().enumerate() {
        let (Some(x), Some(y), Some(z)) = (scalar(v, "x"), scalar(v, "y"), scalar(v, "z")) else {
            return Err(Error::invalid(path, format!("vertex {k} has no x, y, z")));
        };
        pos.push(Vector3::new(x, y, z));
        if let (Some(x), Some(y), Some(z)) = (scalar(v, "nx"), scalar(v, "ny"), scalar(v, "nz")) {
            normals.push(Vector3::new(x, y, z));
        }
    }
    let faces = ply
        .payload
        .get("face")
        .ok_or_else(|| Error::invalid(path, "no \"face\" element"))?;
    let mut tris = Vec::with_capacity(faces.len());
    for (k, f) in faces.iter().enumerate() {
        let list = f.get("vertex_indices").or_else(|| f.get("vertex_index"));
        let idx: Vec<i64> = match list {
            Some(Property::ListInt(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUInt(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListShort(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUShort(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListChar(v)) => v.iter().map(|&i| i as i64).collect(),
            Some(Property::ListUChar(v)) => v.iter().map(|&i| i as i64).collect(),
            _ => {
                return Err(Error::invalid(
                    path,
                    format!("face {k} has no integer vertex_indices list"),
                ))
            }
        };
        if idx.iter().any(|&i| i < 0 || i >= pos.len() as i64) {
            return Err(Error::invalid(
                path,
                format!("face {k} refers to a vertex outside 0..{}", pos.len()),
            ));
        }
        // Fan triangulation of polygons.
        for w in 1..idx.len().saturating_sub(1) {
            tris.push([idx[0] as u32, idx[w] as u32, idx[w + 1] as u32]);
        }
    }
    let normals = (normals.len() == pos.len()).then_some(normals);
    Ok((pos, tris, normals))
}

/// Analytic test shapes (mm), for checks and demos.
pub mod shapes {
    use super::*;

    /// An icosphere: the icosahedron subdivided `level` times, vertices on the sphere, exact
    /// normals.
    pub fn icosphere(center: Vector3<f64>, radius: f64, level: u32) -> Mesh {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut v: Vec<Vector3<f64>> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
        .collect();
        let mut f: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..level {
            let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
            let mut next = Vec::with_capacity(f.len() * 4);
            let mut midpoint = |a: u32, b: u32, v: &mut Vec<Vector3<f64>>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push((v[a as usize] + v[b as usize]).normalize());
                    v.len() as u32 - 1
                })
            };
            for [a, b, c] in f {
                let ab = midpoint(a, b, &mut v);
                let bc = midpoint(b, c, &mut v);
                let ca = midpoint(c, a, &mut v);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            f = next;
        }
        Mesh {
            positions: v.iter().map(|u| center + u * radius).collect(),
            triangles: f,
            normals: v,
        }
    }

    /// A (u, v) grid mesh of a closed parametric surface (periodic in both), normals computed.
    fn grid(nu: usize, nv: usize, point: impl Fn(f64, f64) -> Vector3<f64>) -> Mesh {
        let mut positions = Vec::with_capacity(nu * nv);
        for j in 0..nv {
            for i in 0..nu {
                let u = std::f64::consts::TAU * i as f64 / nu as f64;
                let v = std::f64::consts::TAU * j as f64 / nv as f64;
                positions.push(point(u, v));
            }
        }
        let id = |i: usize, j: usize| ((j % nv) * nu + (i % nu)) as u32;
        let mut triangles = Vec::with_capacity(2 * nu * nv);
        for j in 0..nv {
            for i in 0..nu {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let normals = vertex_normals(&positions, &triangles);
        Mesh {
            positions,
            triangles,
            normals,
        }
    }

    /// Torus about the z axis: major radius `big`, tube radius `small`; u around the axis, v around
    /// the tube (v = 0 outermost).
    pub fn torus(big: f64, small: f64, nu: usize, nv: usize) -> Mesh {
        grid(nu, nv, |u, v| {
            let w = big + small * v.cos();
            Vector3::new(w * u.cos(), w * u.sin(), small * v.sin())
        })
    }

    /// Principal curvatures of the torus at tube angle v: 1/small and cos v / (big + small cos v).
    pub fn torus_curvatures(big: f64, small: f64, v: f64) -> (f64, f64) {
        (1.0 / small, v.cos() / (big + small * v.cos()))
    }

    /// Ellipsoid x²/a² + y²/b² + z²/c² = 1 from a subdivided icosphere scaled along the axes
    /// (normals computed from the faces).
    pub fn ellipsoid(a: f64, b: f64, c: f64, level: u32) -> Mesh {
        let s = icosphere(Vector3::zeros(), 1.0, level);
        let positions: Vec<Vector3<f64>> = s
            .positions
            .iter()
            .map(|p| Vector3::new(a * p.x, b * p.y, c * p.z))
            .collect();
        let normals = vertex_normals(&positions, &s.triangles);
        Mesh {
            positions,
            triangles: s.triangles,
            normals,
        }
    }

    /// Principal curvatures of the ellipsoid at a point on it: from the Gaussian curvature
    /// K = 1 / (a²b²c² s²) and the mean curvature H = (a² + b² + c² − |p|²) / (2 a²b²c² s^{3/2})
    /// in absolute value, with s = x²/a⁴ + y²/b⁴ + z²/c⁴.
    pub fn ellipsoid_curvatures(a: f64, b: f64, c: f64, p: &Vector3<f64>) -> (f64, f64) {
        let (a2, b2, c2) = (a * a, b * b, c * c);
        let s = p.x * p.x / (a2 * a2) + p.y * p.y / (b2 * b2) + p.z * p.z / (c2 * c2);
        let k = 1.0 / (a2 * b2 * c2 * s * s);
        let h = (p.norm_squared() - a2 - b2 - c2).abs() / (2.0 * a2 * b2 * c2 * s.powf(1.5));
        let d = (h * h - k).max(0.0).sqrt();
        (h + d, h - d)
    }
}
