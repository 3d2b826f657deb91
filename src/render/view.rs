//! `workbench view`: a static page (no server, no network) that shows a fit's material on a row
//! of its spheres and on a mesh in WebGL2, with an orbit camera and a light the user drags.
//!
//! The page is three files and the fit's figures: `index.html` and `viewer.js` (the same for
//! every fit, `src/render/viewer/`), and `data.js`, which holds fit.json verbatim and the scene:
//! the generic preset's table ([`crate::render::preset`], half floats), the meshes (positions in
//! mm, normals, curvature in 1/m per vertex as `workbench render` estimates it), the shading
//! snippet (`shaders/cdrf.glsl`), and the camera, light and exposure `workbench render` would use.
//! A data.js that does not parse, a fit with a field missing or out of range, no WebGL2 or a
//! shader that does not compile shows one red line on the page, never a blank canvas.

use crate::error::{Error, Result};
use crate::formats::output::{write_bytes, OutputSet};
use crate::render::lut::read_fit;
use crate::render::mesh::{shapes, Mesh};
use crate::render::preset::{self, Encoding, Preset};
use crate::render::raster::View;
use base64::Engine as _;
use nalgebra::Vector3;
use serde_json::json;
use std::path::{Path, PathBuf};

const INDEX_HTML: &str = include_str!("viewer/index.html");
const VIEWER_JS: &str = include_str!("viewer/viewer.js");

/// Subdivisions of each sphere of the row (10 242 vertices a sphere).
const SPHERE_LEVEL: u32 = 5;

/// The mesh part of the page: a loaded mesh (already rescaled) and its curvature (1/mm).
pub struct ViewMesh {
    pub mesh: Mesh,
    pub curvature: Vec<f64>,
}

/// What `workbench view` wrote.
pub struct ViewReport {
    pub files: Vec<PathBuf>,
    pub table: (usize, usize),
    pub table_error: f64,
    pub spheres: usize,
    pub mesh_vertices: Option<usize>,
    pub light_deg: (f64, f64),
    pub exposure: f64,
}

/// The fit's spheres side by side along x, largest first, a fifth of the largest radius apart.
pub fn sphere_row(radii: &[f64]) -> Mesh {
    let mut radii = radii.to_vec();
    radii.sort_by(|a, b| b.total_cmp(a));
    radii.dedup();
    let gap = 0.2 * radii.first().copied().unwrap_or(1.0);
    let (mut positions, mut normals, mut triangles) = (vec![], vec![], vec![]);
    let mut x = 0.0;
    for &r in &radii {
        x += r;
        let s = shapes::icosphere(Vector3::new(x, 0.0, 0.0), r, SPHERE_LEVEL);
        let base = positions.len() as u32;
        positions.extend(s.positions.iter().copied());
        normals.extend(s.normals.iter().copied());
        triangles.extend(s.triangles.iter().map(|t| t.map(|v| v + base)));
        x += r + gap;
    }
    Mesh::new(positions, triangles, Some(normals), Path::new("sphere row"))
        .expect("icospheres are valid meshes")
}

fn b64_f32(v: impl Iterator<Item = f32>) -> String {
    let bytes: Vec<u8> = v.flat_map(|x| x.to_le_bytes()).collect();
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// A mesh as the page's JSON: positions (mm), normals, curvature (1/m), indices, bounds.
fn mesh_json(mesh: &Mesh, curvature_per_mm: &[f64]) -> serde_json::Value {
    let (centre, radius) = mesh.bounds();
    let idx: Vec<u8> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    json!({
        "positions": b64_f32(mesh.positions.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])),
        "normals": b64_f32(mesh.normals.iter().flat_map(|n| [n.x as f32, n.y as f32, n.z as f32])),
        "kappa": b64_f32(curvature_per_mm.iter().map(|&k| (k * 1000.0) as f32)),
        "indices": base64::engine::general_purpose::STANDARD.encode(idx),
        "centre": [centre.x, centre.y, centre.z],
        "radius": radius,
    })
}

/// Options of `workbench view`.
pub struct ViewOptions<'a> {
    pub fit: &'a Path,
    pub out: &'a Path,
    pub mesh: Option<ViewMesh>,
    /// Light (azimuth, elevation) in degrees in the camera frame (default: the fit's).
    pub light_deg: Option<(f64, f64)>,
    pub view: View,
    /// Horizontal field of view, degrees.
    pub fov_deg: f64,
}

/// Write the page into `out` (created; its files replaced), as one set.
pub fn write(o: ViewOptions) -> Result<ViewReport> {
    let (fit, fm) = read_fit(o.fit)?;
    // The table of the generic preset, as `lut --preset generic` chooses it.
    let (table, err, _, _) =
        crate::render::job::engine_table(&fm, crate::render::job::TableSize::default(), None)?;
    let range = table.kappa_range_per_mm;
    let stored = table.stored(Encoding::ExrHalf);
    let scale = table.peak().max(f64::MIN_POSITIVE);
    let half: Vec<u8> = table
        .values
        .iter()
        .flat_map(|v| v.iter())
        .flat_map(|&x| half::f16::from_f32(x).to_bits().to_le_bytes())
        .collect();
    let (unit, per_mm) = Preset::Generic.curvature_unit();
    debug_assert_eq!(unit, "1/m");
    let radii: Vec<f64> = fit.rmse.spheres.iter().map(|s| s.radius_mm).collect();
    let row = sphere_row(&radii);
    let row_kappa = row.curvature();
    let light = match o.light_deg {
        Some((a, e)) => (a, e),
        None => (
            fm.light.azimuth.to_degrees(),
            fm.light.elevation.to_degrees(),
        ),
    };
    // The exposure `workbench render` picks, from this table.
    let exposure = crate::render::job::default_exposure(stored.lookup(1.0, 0.0), fm.material.eta);
    // The fit's figures, copied beside the page: those `solve --plots` draws for this fit, as
    // regular files (not whatever else the folder holds, nor a link to elsewhere).
    let plots = o.fit.parent().unwrap_or(Path::new(".")).join("plots");
    let mut figures: Vec<(PathBuf, String)> = vec![];
    for stem in crate::figures::fitplot::figure_names(&fit) {
        for ext in ["png", "svg"] {
            let file = format!("{stem}.{ext}");
            let p = plots.join(&file);
            if std::fs::symlink_metadata(&p).is_ok_and(|m| m.is_file()) {
                figures.push((p, format!("figures/{file}")));
            }
        }
    }
    figures.sort_by(|a, b| a.1.cmp(&b.1));
    let scene = json!({
        "table": {
            "width": table.width,
            "height": table.height,
            "kappa_range": [range[0] * per_mm, range[1] * per_mm],
            "scale": 1.0,
            "half_rgb": base64::engine::general_purpose::STANDARD.encode(half),
            "peak": scale,
        },
        "glsl": preset::GLSL,
        "spheres": mesh_json(&row, &row_kappa),
        "mesh": o.mesh.as_ref().map(|m| mesh_json(&m.mesh, &m.curvature)),
        "light_deg": [light.0, light.1],
        "exposure": exposure,
        "fov_deg": o.fov_deg,
        "view": {
            "azimuth_deg": o.view.azimuth_deg,
            "elevation_deg": o.view.elevation_deg,
            "distance": o.view.distance,
        },
        "figures": figures.iter().map(|(_, n)| n.clone()).collect::<Vec<_>>(),
    });
    // fit.json as read, its known fields written again: the page checks it (and says so when
    // it is broken); an unknown field, however deeply nested, stays out (issue 33: a 100 000-deep
    // one made a data.js that browsers reject).
    let fit_json = serde_json::to_string(&fit).map_err(|e| Error::Json {
        path: o.fit.to_path_buf(),
        err: e,
    })?;
    let data = format!("window.WORKBENCH = {{\n\"fit\": {fit_json},\n\"scene\": {scene}\n}};\n");
    std::fs::create_dir_all(o.out).map_err(|e| Error::io(o.out, e))?;
    let index = o.out.join("index.html");
    let js = o.out.join("viewer.js");
    let data_js = o.out.join("data.js");
    let fig_dir = o.out.join("figures");
    let set = OutputSet::begin(&[&index, &js, &data_js, &fig_dir])?;
    let mut files = vec![];
    for (src, name) in &figures {
        let bytes = std::fs::read(src).map_err(|e| Error::io(src, e))?;
        let dst = o.out.join(name);
        write_bytes(&dst, &bytes)?;
        files.push(dst);
    }
    write_bytes(&js, VIEWER_JS.as_bytes())?;
    write_bytes(&data_js, data.as_bytes())?;
    write_bytes(&index, INDEX_HTML.as_bytes())?;
    set.commit()?;
    files.extend([js, data_js, index]);
    Ok(ViewReport {
        files,
        table: (table.width, table.height),
        table_error: err.max_rel,
        spheres: radii.len(),
        mesh_vertices: o.mesh.as_ref().map(|m| m.mesh.positions.len()),
        light_deg: light,
        exposure,
    })
}
