//! Rendering meshes with a measured CDRF: a CPU rasterizer, parallel over image bands with rayon.
//!
//! Per pixel radiance, per colour channel,
//!
//!     L_c = D_c(n·l, κ) · T(n·v; η)  +  ks · D · G · F / (4 n·v)
//!
//! with D_c the look-up table of [`crate::render::lut`] (κ the mesh's per-vertex curvature, interpolated),
//! T the exit Fresnel transmission and the fitted GGX lobe of [`crate::model::specular`], the same model
//! the solver fits ([`crate::model`]). [`Shading::Lambert`] reads the table's κ = 0 row instead:
//! the same material without translucency, a plain clamped cosine.
//!
//! The camera is a pinhole in the OpenCV frame (x right, y down, z forward); pixel (i, j) is
//! centred on image coordinates (i, j). Each pixel takes [`Samples`] coverage samples; the
//! surfaces a pixel's samples see are shaded once each at the centroid of their samples and
//! averaged by coverage (multisample anti-aliasing). Samples on triangles sharing a vertex count as
//! one surface (normals and curvature are interpolated continuously across them), so a pixel
//! inside a surface is shaded once however small its triangles; a silhouette or an occluding edge
//! shades each side. Triangles with a vertex behind the camera are
//! skipped (no clipping): [`View`] frames the whole mesh in front of the camera. Triangles whose
//! three vertex normals all face away from the camera (n·v < −0.3) are culled: on a closed surface
//! something nearer always hides them; through a hole in an open mesh the background shows instead
//! of the inside.

use crate::camera::Camera;
use crate::model::specular;
use crate::render::lut::Lut;
use crate::render::mesh::Mesh;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Where the camera looks from: it orbits the mesh's bounding sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Around the mesh's vertical (+y) axis, degrees; 0 looks along −z (from +z).
    pub azimuth_deg: f64,
    /// Above the horizontal plane, degrees (clamped to ±89).
    pub elevation_deg: f64,
    /// Distance from the bounding sphere's centre in units of the distance that makes the sphere
    /// just touch the frame's nearer edges (1: tight; larger: smaller in the frame).
    pub distance: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance: 1.05,
        }
    }
}

/// A mesh in the camera frame, ready to rasterize (f32).
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Curvature per vertex (1/mm).
    pub curvature: Vec<f32>,
    pub triangles: Vec<[u32; 3]>,
}

impl Scene {
    /// A mesh already in the camera frame.
    pub fn new(mesh: &Mesh, curvature: &[f64]) -> Scene {
        Scene::transformed(mesh, curvature, &Matrix3::identity(), &Vector3::zeros())
    }

    /// p_camera = R (p − eye), n_camera = R n.
    pub(crate) fn transformed(
        mesh: &Mesh,
        curvature: &[f64],
        r: &Matrix3<f64>,
        eye: &Vector3<f64>,
    ) -> Scene {
        let f = |v: Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
        Scene {
            positions: mesh.positions.iter().map(|p| f(r * (p - eye))).collect(),
            normals: mesh.normals.iter().map(|n| f(r * n)).collect(),
            curvature: curvature.iter().map(|&k| k as f32).collect(),
            triangles: mesh.triangles.clone(),
        }
    }

    /// The mesh seen from `view` (mesh coordinates y up), framed in `cam`.
    pub fn framed(mesh: &Mesh, curvature: &[f64], view: &View, cam: &Camera) -> Scene {
        let (centre, radius) = mesh.bounds();
        let (az, el) = (
            view.azimuth_deg.to_radians(),
            view.elevation_deg.clamp(-89.0, 89.0).to_radians(),
        );
        let dir = Vector3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
        let d = view.distance * radius.max(1e-9) / cam.half_fov().sin();
        let eye = centre + dir * d;
        let z = -dir;
        let x = z.cross(&Vector3::y()).normalize();
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        Scene::transformed(mesh, curvature, &r, &eye)
    }
}

/// Coverage samples per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Samples {
    /// One at the pixel centre (no anti-aliasing).
    #[value(name = "1")]
    One,
    /// Four on a rotated grid.
    #[value(name = "4")]
    Four,
    /// Sixteen on a 4 × 4 grid.
    #[value(name = "16")]
    Sixteen,
}

impl Samples {
    /// Offsets from the pixel centre.
    pub(crate) fn offsets(self) -> Vec<[f32; 2]> {
        match self {
            Samples::One => vec![[0.0, 0.0]],
            Samples::Four => vec![
                [-0.125, -0.375],
                [0.375, -0.125],
                [-0.375, 0.125],
                [0.125, 0.375],
            ],
            Samples::Sixteen => (0..16)
                .map(|k| {
                    [
                        ((k % 4) as f32 + 0.5) / 4.0 - 0.5,
                        ((k / 4) as f32 + 0.5) / 4.0 - 0.5,
                    ]
                })
                .collect(),
        }
    }
}

/// What the diffuse term is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Shading {
    /// The measured CDRF at the mesh's curvature.
    Cdrf,
    /// The table's κ = 0 row: a clamped cosine, no light past the terminator.
    Lambert,
}

/// The material and light of a render.
#[derive(Clone, Debug)]
pub struct Shader<'a> {
    pub lut: &'a Lut,
    pub eta: f64,
    /// Specular lobe (ks 0: none).
    pub ks: f64,
    pub alpha: f64,
    /// Unit vector toward the light, camera frame.
    pub light: Vector3<f64>,
    pub shading: Shading,
}

/// Exit transmission T(n·v) tabulated on this many intervals of n·v (linear interpolation: largest
/// error 5–7·10⁻⁶ for η 1.2–2, see the tests).
const FRESNEL_TABLE: usize = 1024;

impl Shader<'_> {
    fn fresnel_table(&self) -> Vec<f32> {
        (0..=FRESNEL_TABLE)
            .map(|k| {
                crate::model::fresnel::transmission(k as f64 / FRESNEL_TABLE as f64, self.eta)
                    as f32
            })
            .collect()
    }

    /// Radiance at a surface point with unit normal n, unit view v and curvature κ.
    #[inline]
    fn shade(
        &self,
        t_table: &[f32],
        l: &[f32; 3],
        n: [f32; 3],
        v: [f32; 3],
        kappa: f32,
    ) -> [f32; 3] {
        let dot = |a: &[f32; 3], b: &[f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let mut n = n;
        let mut nv = dot(&n, &v);
        // An interpolated normal can face away near a silhouette: bend it just into view.
        const MIN_NV: f32 = 1e-3;
        if nv < MIN_NV {
            let s = MIN_NV - nv;
            n = [n[0] + s * v[0], n[1] + s * v[1], n[2] + s * v[2]];
            let len = dot(&n, &n).sqrt();
            n = [n[0] / len, n[1] / len, n[2] / len];
            nv = dot(&n, &v).max(MIN_NV);
        }
        let nl = dot(&n, l);
        let k = match self.shading {
            Shading::Cdrf => kappa,
            Shading::Lambert => 0.0,
        };
        let d = self.lut.sample(nl, k);
        let x = nv.min(1.0) * FRESNEL_TABLE as f32;
        let i = (x as usize).min(FRESNEL_TABLE - 1);
        let t = t_table[i] + (t_table[i + 1] - t_table[i]) * (x - i as f32);
        let spec = if self.ks > 0.0 && nl > 0.0 {
            specular::lobe_value(
                nl as f64,
                nv as f64,
                dot(l, &v) as f64,
                self.ks,
                self.alpha,
                self.eta,
            ) as f32
        } else {
            0.0
        };
        [d[0] * t + spec, d[1] * t + spec, d[2] * t + spec]
    }
}

/// A linear-radiance RGB image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// Row-major.
    pub rgb: Vec<[f32; 3]>,
    /// Fraction of each pixel's samples that hit the mesh.
    pub coverage: Vec<f32>,
}

/// Rows per band: the unit of parallel work.
const BAND: usize = 8;

/// n·v below −BACK_FACING at all three vertices culls a triangle (v = −p/|p| toward the camera).
const BACK_FACING: f32 = 0.3;

struct Setup {
    /// Screen positions and 1/z of the three vertices.
    x: [f32; 3],
    y: [f32; 3],
    iz: [f32; 3],
    /// 1 / (signed doubled area).
    inv_area: f32,
    /// ∂λ_e/∂x and ∂λ_e/∂y of the three barycentrics.
    dx: [f32; 3],
    dy: [f32; 3],
    bbox: [i32; 4],
}

fn setup(scene: &Scene, cam: &Camera, t: &[u32; 3]) -> Option<Setup> {
    let (w, h) = (cam.width() as i32, cam.height() as i32);
    let mut x = [0.0f32; 3];
    let mut y = [0.0f32; 3];
    let mut iz = [0.0f32; 3];
    // Clearly back-facing (every vertex normal turned away from the camera by more than
    // BACK_FACING): hidden behind the front of the surface, never drawn.
    let away = t.iter().all(|&v| {
        let (p, n) = (scene.positions[v as usize], scene.normals[v as usize]);
        n[0] * p[0] + n[1] * p[1] + n[2] * p[2]
            > BACK_FACING * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
    });
    if away {
        return None;
    }
    for k in 0..3 {
        let p = scene.positions[t[k] as usize];
        if !(p[2] > 1e-6) {
            return None;
        }
        let inv = 1.0 / p[2];
        x[k] = (cam.fx as f32) * p[0] * inv + cam.cx as f32;
        y[k] = (cam.fy as f32) * p[1] * inv + cam.cy as f32;
        iz[k] = inv;
    }
    let area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
    if !(area.abs() > 1e-12) {
        return None;
    }
    let min = |a: [f32; 3]| a[0].min(a[1]).min(a[2]);
    let max = |a: [f32; 3]| a[0].max(a[1]).max(a[2]);
    let bbox = [
        ((min(x) - 0.5).ceil() as i32).max(0),
        ((min(y) - 0.5).ceil() as i32).max(0),
        ((max(x) + 0.5).floor() as i32).min(w - 1),
        ((max(y) + 0.5).floor() as i32).min(h - 1),
    ];
    if bbox[0] > bbox[2] || bbox[1] > bbox[3] {
        return None;
    }
    let inv_area = 1.0 / area;
    // λ_0 = ((x2 − x1)(py − y1) − (px − x1)(y2 − y1)) / area, and cyclically.
    let dx = [
        -(y[2] - y[1]) * inv_area,
        -(y[0] - y[2]) * inv_area,
        -(y[1] - y[0]) * inv_area,
    ];
    let dy = [
        (x[2] - x[1]) * inv_area,
        (x[0] - x[2]) * inv_area,
        (x[1] - x[0]) * inv_area,
    ];
    Some(Setup {
        x,
        y,
        iz,
        inv_area,
        dx,
        dy,
        bbox,
    })
}

impl Setup {
    /// Screen-space barycentrics of (px, py) (inside: all ≥ 0).
    #[inline]
    fn bary(&self, px: f32, py: f32) -> [f32; 3] {
        let (x, y) = (&self.x, &self.y);
        let e = |a: usize, b: usize| {
            ((x[b] - x[a]) * (py - y[a]) - (px - x[a]) * (y[b] - y[a])) * self.inv_area
        };
        [e(1, 2), e(2, 0), e(0, 1)]
    }
}

/// Render `scene` through `cam`.
pub fn render(scene: &Scene, cam: &Camera, shader: &Shader, samples: Samples) -> Image {
    let mut img = Image {
        width: cam.width(),
        height: cam.height(),
        rgb: Vec::new(),
        coverage: Vec::new(),
    };
    render_into(scene, cam, shader, samples, &mut img);
    img
}

/// What every band of the image is rasterized with.
struct Bands<'a> {
    scene: &'a Scene,
    shader: &'a Shader<'a>,
    setups: &'a [Option<Setup>],
    /// The samples' offsets within a pixel.
    offsets: &'a [[f32; 2]],
    /// The exit transmission over n·v.
    t_table: &'a [f32],
    l: [f32; 3],
    /// Image width.
    w: usize,
}

impl Bands<'_> {
    /// The nearest triangle at every sample of the band starting at row `y0` (`rows` rows): its
    /// id and inverse depth.
    fn depth_test(&self, bin: &[u32], y0: usize, rows: usize, depth: &mut [f32], id: &mut [u32]) {
        let (w, ns, setups, offsets) = (self.w, self.offsets.len(), self.setups, self.offsets);
        let mut delta = vec![[0.0f32; 3]; ns];
        for &t in bin {
            let s = setups[t as usize]
                .as_ref()
                .expect("binned triangles have a setup");
            // Barycentrics step by dx per pixel; each sample adds a fixed offset. A pixel
            // whose centre lies further than half a pixel outside an edge holds no sample.
            for (d, o) in delta.iter_mut().zip(offsets) {
                *d = std::array::from_fn(|e| s.dx[e] * o[0] + s.dy[e] * o[1]);
            }
            let margin: [f32; 3] = std::array::from_fn(|e| -0.5 * (s.dx[e].abs() + s.dy[e].abs()));
            let ya = (s.bbox[1] as usize).max(y0);
            let yb = (s.bbox[3] as usize).min(y0 + rows - 1);
            let (xa, xb) = (s.bbox[0] as usize, s.bbox[2] as usize);
            for py in ya..=yb {
                let mut lam = s.bary(xa as f32, py as f32);
                for px in xa..=xb {
                    if lam[0] >= margin[0] && lam[1] >= margin[1] && lam[2] >= margin[2] {
                        let base = ((py - y0) * w + px) * ns;
                        for (k, d) in delta.iter().enumerate() {
                            let bc = [lam[0] + d[0], lam[1] + d[1], lam[2] + d[2]];
                            if bc[0] < 0.0 || bc[1] < 0.0 || bc[2] < 0.0 {
                                continue;
                            }
                            let iz = bc[0] * s.iz[0] + bc[1] * s.iz[1] + bc[2] * s.iz[2];
                            if iz > depth[base + k] {
                                depth[base + k] = iz;
                                id[base + k] = t;
                            }
                        }
                    }
                    lam = [lam[0] + s.dx[0], lam[1] + s.dx[1], lam[2] + s.dx[2]];
                }
            }
        }
    }

    /// Each pixel of the band between columns `xa` and `xb`: its samples grouped by surface,
    /// each group shaded once at its centroid, averaged; the coverage the share of samples hit.
    fn resolve(
        &self,
        (y0, rows): (usize, usize),
        (xa, xb): (usize, usize),
        id: &[u32],
        out: &mut [[f32; 3]],
        cov: &mut [f32],
    ) {
        let (w, ns, setups, offsets) = (self.w, self.offsets.len(), self.setups, self.offsets);
        let (scene, shader, t_table, l) = (self.scene, self.shader, self.t_table, &self.l);
        for r in 0..rows {
            for px in xa..xb {
                let base = (r * w + px) * ns;
                let ids = &id[base..base + ns];
                if ids.iter().all(|&t| t == u32::MAX) {
                    continue;
                }
                let mut acc = [0.0f32; 3];
                let mut hit = 0usize;
                // Samples whose triangle shares a vertex with an earlier group's triangle
                // belong to the same surface (interpolated normals are continuous across it):
                // they join that group, so a pixel inside a surface is shaded once.
                let mut group = [u8::MAX; 16];
                for k in 0..ns {
                    let t = ids[k];
                    if t == u32::MAX {
                        continue;
                    }
                    let tri = &scene.triangles[t as usize];
                    group[k] = (0..k as u8)
                        .find(|&m| {
                            let m = m as usize;
                            ids[m] != u32::MAX && group[m] as usize == m && {
                                let o = &scene.triangles[ids[m] as usize];
                                tri.iter().any(|v| o.contains(v))
                            }
                        })
                        .unwrap_or(k as u8);
                }
                for k in 0..ns {
                    if group[k] as usize != k {
                        continue;
                    }
                    // This group's samples: count and centroid (on the leader's triangle).
                    let t = ids[k];
                    let (mut n, mut sx, mut sy) = (0usize, 0.0f32, 0.0f32);
                    for (m, o) in offsets.iter().enumerate().skip(k) {
                        if group[m] as usize == k {
                            n += 1;
                            sx += o[0];
                            sy += o[1];
                        }
                    }
                    let s = setups[t as usize]
                        .as_ref()
                        .expect("hit triangles have a setup");
                    let (qx, qy) = (px as f32 + sx / n as f32, (y0 + r) as f32 + sy / n as f32);
                    let c = shade_at(
                        scene,
                        shader,
                        t_table,
                        l,
                        s,
                        &scene.triangles[t as usize],
                        qx,
                        qy,
                    );
                    for ch in 0..3 {
                        acc[ch] += c[ch] * n as f32;
                    }
                    hit += n;
                }
                let inv = 1.0 / ns as f32;
                out[r * w + px] = [acc[0] * inv, acc[1] * inv, acc[2] * inv];
                cov[r * w + px] = hit as f32 * inv;
            }
        }
    }
}

/// Each band of `BAND` rows: the triangles whose boxes reach it.
fn bin_triangles(setups: &[Option<Setup>], h: usize) -> Vec<Vec<u32>> {
    let n_bands = h.div_ceil(BAND);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); n_bands];
    for (k, s) in setups.iter().enumerate() {
        if let Some(s) = s {
            let (b0, b1) = (s.bbox[1] as usize / BAND, s.bbox[3] as usize / BAND);
            for bin in &mut bins[b0..=b1] {
                bin.push(k as u32);
            }
        }
    }
    bins
}

/// Render into `img`, reusing its buffers (every pixel is written): the frame loop of an
/// interactive viewer, and what `benches/render.rs` times.
pub fn render_into(
    scene: &Scene,
    cam: &Camera,
    shader: &Shader,
    samples: Samples,
    img: &mut Image,
) {
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    img.width = cam.width();
    img.height = cam.height();
    img.rgb.resize(w * h, [0.0; 3]);
    img.coverage.resize(w * h, 0.0);
    let setups: Vec<Option<Setup>> = scene
        .triangles
        .par_iter()
        .map(|t| setup(scene, cam, t))
        .collect();
    let bins = bin_triangles(&setups, h);
    let offsets = samples.offsets();
    let ns = offsets.len();
    let t_table = shader.fresnel_table();
    let bands = Bands {
        scene,
        shader,
        setups: &setups,
        offsets: &offsets,
        t_table: &t_table,
        l: [
            shader.light.x as f32,
            shader.light.y as f32,
            shader.light.z as f32,
        ],
        w,
    };
    img.rgb
        .par_chunks_mut(w * BAND)
        .zip(img.coverage.par_chunks_mut(w * BAND))
        .zip(bins.par_iter())
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; BAND * w * ns], vec![u32::MAX; BAND * w * ns]),
            |(depth, id), (b, ((out, cov), bin))| {
                let y0 = b * BAND;
                let rows = out.len() / w;
                // Only the columns this band's triangles reach need clearing and resolving.
                let (xa, xb) = bin.iter().fold((w, 0), |(a, b), &t| {
                    let s = setups[t as usize]
                        .as_ref()
                        .expect("binned triangles have a setup");
                    (a.min(s.bbox[0] as usize), b.max(s.bbox[2] as usize + 1))
                });
                for r in 0..rows {
                    out[r * w..(r + 1) * w].fill([0.0; 3]);
                    cov[r * w..(r + 1) * w].fill(0.0);
                    if xa < xb {
                        depth[(r * w + xa) * ns..(r * w + xb) * ns].fill(0.0);
                        id[(r * w + xa) * ns..(r * w + xb) * ns].fill(u32::MAX);
                    }
                }
                bands.depth_test(bin, y0, rows, depth, id);
                bands.resolve((y0, rows), (xa, xb), id, out, cov);
            },
        );
}

#[allow(clippy::too_many_arguments)]
#[inline]
fn shade_at(
    scene: &Scene,
    shader: &Shader,
    t_table: &[f32],
    l: &[f32; 3],
    s: &Setup,
    tri: &[u32; 3],
    qx: f32,
    qy: f32,
) -> [f32; 3] {
    // Perspective-correct weights, from the screen-space ones.
    let bc = s.bary(qx, qy);
    let wsum = bc[0] * s.iz[0] + bc[1] * s.iz[1] + bc[2] * s.iz[2];
    let wts = [
        bc[0] * s.iz[0] / wsum,
        bc[1] * s.iz[1] / wsum,
        bc[2] * s.iz[2] / wsum,
    ];
    let mut p = [0.0f32; 3];
    let mut n = [0.0f32; 3];
    let mut kappa = 0.0f32;
    for k in 0..3 {
        let v = tri[k] as usize;
        for c in 0..3 {
            p[c] += wts[k] * scene.positions[v][c];
            n[c] += wts[k] * scene.normals[v][c];
        }
        kappa += wts[k] * scene.curvature[v];
    }
    let pl = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let v = [-p[0] / pl, -p[1] / pl, -p[2] / pl];
    let nl = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = [n[0] / nl, n[1] / nl, n[2] / nl];
    shader.shade(t_table, l, n, v, kappa)
}

/// How linear radiance becomes pixel values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Tone {
    /// The sRGB transfer curve, clipped at 1.
    Srgb,
    /// Linear (for 16-bit output meant for further processing), clipped at 1.
    Linear,
}

/// Pixel values in [0, 1] from radiance × exposure.
pub(crate) fn tone_map(img: &Image, exposure: f64, tone: Tone) -> Vec<f64> {
    img.rgb
        .iter()
        .flat_map(|p| p.iter())
        .map(|&x| {
            let y = (x as f64 * exposure).clamp(0.0, 1.0);
            match tone {
                Tone::Srgb => crate::formats::photo::srgb_encode(y),
                Tone::Linear => y,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_table_is_accurate() {
        let lut = Lut {
            n_cos: 2,
            n_kappa: 2,
            kappa_max: 1.0,
            values: vec![[0.0; 3]; 4],
        };
        for eta in [1.2, 1.45, 2.0] {
            let sh = Shader {
                lut: &lut,
                eta,
                ks: 0.0,
                alpha: 0.1,
                light: Vector3::z(),
                shading: Shading::Cdrf,
            };
            let t = sh.fresnel_table();
            let mut worst = 0.0f64;
            for k in 0..10_000 {
                let c = (k as f64 + 0.37) / 10_000.0;
                let x = c * FRESNEL_TABLE as f64;
                let i = (x as usize).min(FRESNEL_TABLE - 1);
                let got = t[i] as f64 + (t[i + 1] - t[i]) as f64 * (x - i as f64);
                worst = worst.max((got - crate::model::fresnel::transmission(c, eta)).abs());
            }
            // f32 values: 1.5e-5 covers the interpolation error (5–7e-6) and the rounding.
            assert!(worst < 1.5e-5, "eta {eta}: {worst}");
        }
    }

    /// The framing puts the bounding sphere inside the frame.
    #[test]
    fn framed_mesh_fits_the_image() {
        let m = crate::render::mesh::shapes::icosphere(Vector3::new(10.0, 5.0, -3.0), 7.0, 2);
        let cam = Camera::from_fov(320, 240, 40.0);
        for (az, el) in [(0.0, 0.0), (90.0, 30.0), (200.0, -60.0)] {
            let view = View {
                azimuth_deg: az,
                elevation_deg: el,
                distance: 1.0,
            };
            let s = Scene::framed(&m, &vec![0.0; m.positions.len()], &view, &cam);
            for p in &s.positions {
                let x = cam.fx * p[0] as f64 / p[2] as f64 + cam.cx;
                let y = cam.fy * p[1] as f64 / p[2] as f64 + cam.cy;
                assert!(x > -1.0 && x < 320.0 && y > -1.0 && y < 240.0, "{x} {y}");
            }
        }
    }
}
