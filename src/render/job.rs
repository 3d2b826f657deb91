//! `workbench render` and `workbench lut` as library calls: read the fit and the mesh, build the
//! table, frame, render, tone-map and write (atomically).

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::formats::photo::MAX_PIXELS;
use crate::model::LightAngles;
use crate::render::check::{self, SphereComparison};
use crate::render::lut::{self, FitMaterial, InterpolationError, Lut};
use crate::render::mesh::{Mesh, Unit};
use crate::render::raster::{self, Image, Samples, Scene, Shader, Shading, Tone, View};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How the table is sized.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TableSize {
    /// The smallest of [`lut::SIZES`] within this fraction of the table's peak.
    Auto(f64),
    /// n_cos × n_kappa nodes.
    Fixed(usize, usize),
}

impl Default for TableSize {
    fn default() -> Self {
        TableSize::Auto(lut::DEFAULT_TOLERANCE)
    }
}

/// A table built for a fit, with its measured error.
pub struct Table {
    pub lut: Lut,
    pub error: InterpolationError,
    /// Sizes tried (auto) with their largest relative error.
    pub tried: Vec<lut::Tried>,
    pub tolerance: Option<f64>,
    pub seconds: f64,
}

/// The largest κ_max accepted (1/mm): a radius of a micrometre, far past any mesh's detail and
/// where every blur is already the flat limit; beyond it the blur σ0·κ overflows (a table of
/// `inf`, issue 33).
const KAPPA_MAX_LIMIT: f64 = 1e3;

/// κ_max (1/mm): the one given, checked, or 3 / the smallest radius fitted.
fn kappa_max_of(fm: &FitMaterial, given: Option<f64>) -> Result<f64> {
    let kmax = given.unwrap_or_else(|| fm.kappa_max());
    if !(kmax > 0.0 && kmax <= KAPPA_MAX_LIMIT) {
        return Err(Error::Argument(format!(
            "--kappa-max must lie in (0, {KAPPA_MAX_LIMIT}] 1/mm, got {kmax}"
        )));
    }
    Ok(kmax)
}

/// A table of the size asked for: `build` makes a table of n × m nodes or texels and measures its
/// error; a fixed size is checked, `auto` takes the smallest standard size within its tolerance.
/// Returns the table, its error, the sizes tried and the tolerance.
#[allow(clippy::type_complexity)]
fn sized<T>(
    size: TableSize,
    build: impl Fn(usize, usize) -> (T, InterpolationError),
) -> Result<(T, InterpolationError, Vec<lut::Tried>, Option<f64>)> {
    match size {
        TableSize::Fixed(n, m) => {
            // 2049 a side: twice the largest `auto` size, built and measured in about 20 s (an
            // engine preset at 2049×2049 on 2 cores); 8193 ran past two minutes (issue 33).
            if !(2..=2049).contains(&n) || !(2..=2049).contains(&m) {
                return Err(Error::Argument(format!(
                    "table size {n}x{m}: each side must be 2..2049"
                )));
            }
            let (t, e) = build(n, m);
            Ok((t, e, vec![((n, m), e.max_rel)], None))
        }
        TableSize::Auto(tol) => {
            if !(tol > 0.0) {
                return Err(Error::Argument(format!(
                    "--tolerance must be > 0, got {tol}"
                )));
            }
            let (t, e, tried) = lut::choose(tol, build);
            if e.max_rel > tol {
                // Not met even by the largest size: said, not recorded as met.
                let ((n, m), _) = tried[tried.len() - 1];
                return Err(Error::Argument(format!(
                    "--tolerance {tol:e}: the largest table, {n}x{m}, is {:.2e} of the peak off: give a tolerance of at least that",
                    e.max_rel
                )));
            }
            Ok((t, e, tried, Some(tol)))
        }
    }
}

/// Build the table of a fit.
pub fn table(fm: &FitMaterial, size: TableSize, kappa_max: Option<f64>) -> Result<Table> {
    let t0 = Instant::now();
    let kmax = kappa_max_of(fm, kappa_max)?;
    let (lut, error, tried, tolerance) = sized(size, |nc, nk| {
        let l = Lut::build(&fm.model, &fm.material, nc, nk, kmax);
        let e = lut::interpolation_error(&l, &fm.model, &fm.material);
        (l, e)
    })?;
    Ok(Table {
        lut,
        error,
        tried,
        tolerance,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// An engine preset's table of a fit over curvature 0 to κ_max (1/mm; default 3 / the smallest
/// radius fitted), with its error before storage, the sizes tried and the tolerance.
#[allow(clippy::type_complexity)]
pub fn engine_table(
    fm: &FitMaterial,
    size: TableSize,
    kappa_max: Option<f64>,
) -> Result<(
    crate::render::preset::EngineTable,
    InterpolationError,
    Vec<lut::Tried>,
    Option<f64>,
)> {
    let range = [0.0, kappa_max_of(fm, kappa_max)?];
    sized(size, |w, h| {
        let t = crate::render::preset::EngineTable::build(fm, w, h, range);
        let (e, _) = t.error(fm);
        (t, e)
    })
}

/// An engine-ready table written: its size search, the table and its sidecar.
pub struct EngineLut {
    pub tried: Vec<lut::Tried>,
    pub table: crate::render::preset::EngineTable,
    pub sidecar: crate::render::preset::EngineLutJson,
    pub paths: Vec<PathBuf>,
}

/// `workbench lut --preset`: the table in an engine's layout ([`crate::render::preset`]), over
/// curvature 0 to `kappa_max` (1/mm; default 3 / the smallest radius fitted), with `mesh` and its
/// curvature as binary glTF beside it when given.
pub fn write_engine_lut(
    fit_path: &Path,
    stem: &Path,
    preset: crate::render::preset::Preset,
    encoding: crate::render::preset::Encoding,
    size: TableSize,
    kappa_max: Option<f64>,
    mesh: Option<&Prepared>,
) -> Result<EngineLut> {
    use crate::render::preset::{self, WriteRequest};
    let (fit, fm) = lut::read_fit(fit_path)?;
    let (table, error, tried, tolerance) = engine_table(&fm, size, kappa_max)?;
    let req = WriteRequest {
        stem,
        preset,
        encoding,
        fit: &fit,
        fit_path,
        fm: &fm,
        error,
        tolerance,
        mesh: mesh.map(|m| (&m.mesh, m.curvature.as_slice())),
    };
    let (paths, sidecar) = preset::write(&req, &table)?;
    Ok(EngineLut {
        tried,
        table,
        sidecar,
        paths,
    })
}

/// `workbench lut`: build and write the table. Returns it with the paths written.
pub fn write_lut(
    fit_path: &Path,
    out: &Path,
    size: TableSize,
    kappa_max: Option<f64>,
) -> Result<(Table, FitMaterial, [PathBuf; 3])> {
    let (_, fm) = lut::read_fit(fit_path)?;
    let t = table(&fm, size, kappa_max)?;
    let paths = lut::write(out, &t.lut, &fm, fit_path, &t.error, t.tolerance)?;
    Ok((t, fm, paths))
}

/// Options of `workbench render`.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub mesh: PathBuf,
    pub fit: PathBuf,
    pub out: PathBuf,
    pub unit: Unit,
    /// Rescale the mesh so its bounding sphere has this diameter (mm).
    pub object_size_mm: Option<f64>,
    /// Light (azimuth, elevation) in degrees in the camera frame (default: the fit's).
    pub light_deg: Option<(f64, f64)>,
    pub view: View,
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub fov_deg: f64,
    pub samples: Samples,
    pub shading: Shading,
    pub bits: u8,
    pub tone: Tone,
    /// Multiplies the default exposure (a flat surface facing the light at 0.8 of full scale).
    pub exposure: f64,
    pub table: TableSize,
}

impl RenderOptions {
    pub fn new(mesh: impl Into<PathBuf>, fit: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        RenderOptions {
            mesh: mesh.into(),
            fit: fit.into(),
            out: out.into(),
            unit: Unit::Mm,
            object_size_mm: None,
            light_deg: None,
            view: View::default(),
            width: 1280,
            height: 720,
            fov_deg: 30.0,
            samples: Samples::Four,
            shading: Shading::Cdrf,
            bits: 8,
            tone: Tone::Srgb,
            exposure: 1.0,
            table: TableSize::default(),
        }
    }
}

/// What a render did.
#[derive(Clone, Debug)]
pub struct RenderReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Bounding-sphere radius of the mesh as rendered (mm).
    pub radius_mm: f64,
    /// Curvature percentiles 5/50/95 (1/mm) and the fraction of vertices above the table's range.
    pub curvature: [f64; 3],
    pub clamped: f64,
    pub table: (usize, usize),
    pub table_error: f64,
    pub light: LightAngles,
    pub exposure: f64,
    pub load_s: f64,
    pub curvature_s: f64,
    pub table_s: f64,
    pub frame_s: f64,
    pub write_s: f64,
}

/// Mesh with its curvature, ready to frame.
pub struct Prepared {
    pub mesh: Mesh,
    pub curvature: Vec<f64>,
    pub load_s: f64,
    pub curvature_s: f64,
}

/// Load a mesh (rescaled to `object_size_mm` when given) and estimate its curvature.
pub fn prepare(path: &Path, unit: Unit, object_size_mm: Option<f64>) -> Result<Prepared> {
    let t0 = Instant::now();
    let mut mesh = Mesh::load(path, unit)?;
    if let Some(d) = object_size_mm {
        // A micrometre to a kilometre: beyond, the camera's framing and the curvature leave
        // the range of f64 arithmetic that the rasterizer and the table keep finite (black
        // images, issue 33).
        if !(1e-3..=1e6).contains(&d) {
            return Err(Error::Argument(format!(
                "--object-size must lie in [0.001, 1000000] mm, got {d}"
            )));
        }
        let (c, r) = mesh.bounds();
        let s = 0.5 * d / r;
        for p in &mut mesh.positions {
            *p = c + (*p - c) * s;
        }
    }
    let load_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let curvature = mesh.curvature();
    Ok(Prepared {
        mesh,
        curvature,
        load_s,
        curvature_s: t1.elapsed().as_secs_f64(),
    })
}

/// The default exposure: a flat surface facing the light, seen head-on, at 0.8 of full scale;
/// `flat` is the table's diffuse term there (N·L = 1, κ = 0).
pub(crate) fn default_exposure(flat: [f64; 3], eta: f64) -> f64 {
    let peak =
        flat.iter().fold(0.0f64, |a, &b| a.max(b)) * crate::model::fresnel::transmission(1.0, eta);
    if peak > 0.0 {
        0.8 / peak
    } else {
        1.0
    }
}

/// The shader of a fit.
pub fn shader<'a>(
    fm: &FitMaterial,
    lut: &'a Lut,
    light: LightAngles,
    shading: Shading,
) -> Shader<'a> {
    Shader {
        lut,
        eta: fm.material.eta,
        ks: fm.material.specular.ks,
        alpha: fm.material.specular.alpha,
        light: light.direction(),
        shading,
    }
}

/// `workbench render <mesh> --fit <fit.json> --out <image>`.
pub fn run(o: &RenderOptions) -> Result<RenderReport> {
    if !matches!(o.bits, 8 | 16) {
        return Err(Error::Argument(format!(
            "--bits must be 8 or 16, got {}",
            o.bits
        )));
    }
    let pixels = o.width as u64 * o.height as u64;
    if o.width < 16 || o.height < 16 || o.width > 16384 || o.height > 16384 || pixels > MAX_PIXELS {
        return Err(Error::Argument(format!(
            "--resolution {}x{}: each side must be 16..16384 and the image at most {} MP (what workbench reads)",
            o.width,
            o.height,
            MAX_PIXELS / 1_000_000
        )));
    }
    if !(o.fov_deg > 1.0 && o.fov_deg < 170.0) {
        return Err(Error::Argument(format!(
            "--fov must be in (1, 170) degrees, got {}",
            o.fov_deg
        )));
    }
    if !(o.view.distance >= 1.0) || !o.view.distance.is_finite() {
        return Err(Error::Argument(format!(
            "--distance must be ≥ 1, got {}",
            o.view.distance
        )));
    }
    if !(o.exposure > 0.0) || !o.exposure.is_finite() {
        return Err(Error::Argument(format!(
            "--exposure must be > 0, got {}",
            o.exposure
        )));
    }
    let ext = o
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    if ext.as_deref() != Some("png") {
        return Err(Error::invalid(&o.out, "the output must be a .png file"));
    }
    let (_, fm) = lut::read_fit(&o.fit)?;
    let prep = prepare(&o.mesh, o.unit, o.object_size_mm)?;
    let table = table(&fm, o.table, None)?;
    let light = match o.light_deg {
        Some((a, e)) => LightAngles {
            azimuth: a.to_radians(),
            elevation: e.to_radians(),
        },
        None => fm.light,
    };
    let cam = Camera::from_fov(o.width, o.height, o.fov_deg);
    let scene = Scene::framed(&prep.mesh, &prep.curvature, &o.view, &cam);
    let sh = shader(&fm, &table.lut, light, o.shading);
    let t2 = Instant::now();
    let img = raster::render(&scene, &cam, &sh, o.samples);
    let frame_s = t2.elapsed().as_secs_f64();
    let exposure =
        default_exposure(table.lut.sample(1.0, 0.0).map(f64::from), fm.material.eta) * o.exposure;
    let t3 = Instant::now();
    write_image(&o.out, &img, exposure, o.tone, o.bits)?;
    let write_s = t3.elapsed().as_secs_f64();
    let mut k = prep.curvature.clone();
    k.sort_by(|a, b| a.total_cmp(b));
    let q = |f: f64| k[((k.len() - 1) as f64 * f) as usize];
    let clamped = k.iter().filter(|&&x| x > table.lut.kappa_max).count() as f64 / k.len() as f64;
    Ok(RenderReport {
        vertices: prep.mesh.positions.len(),
        triangles: prep.mesh.triangles.len(),
        radius_mm: prep.mesh.bounds().1,
        curvature: [q(0.05), q(0.5), q(0.95)],
        clamped,
        table: (table.lut.n_cos, table.lut.n_kappa),
        table_error: table.error.max_rel,
        light,
        exposure,
        load_s: prep.load_s,
        curvature_s: prep.curvature_s,
        table_s: table.seconds,
        frame_s,
        write_s,
    })
}

/// Tone-map and write a PNG (8 or 16 bits).
pub fn write_image(path: &Path, img: &Image, exposure: f64, tone: Tone, bits: u8) -> Result<()> {
    let v = raster::tone_map(img, exposure, tone);
    if bits == 16 {
        let px: Vec<u16> = v.iter().map(|&x| (x * 65535.0).round() as u16).collect();
        crate::formats::photo::write_png16_rgb(path, img.width, img.height, &px)
    } else {
        let px: Vec<u8> = v.iter().map(|&x| (x * 255.0).round() as u8).collect();
        crate::formats::photo::write_8bit(path, img.width, img.height, 3, &px, 95, None)
    }
}

/// `workbench render --check`: every sphere of the fit rendered as an ideal sphere mesh against
/// the solver's prediction; writes `<dir>/sphere-check.json` and one picture per sphere
/// (rendered | predicted | difference ×10, sRGB). Returns the comparisons.
pub fn check(fit_path: &Path, dir: &Path, table_size: TableSize) -> Result<Vec<SphereComparison>> {
    let (fit, fm) = lut::read_fit(fit_path)?;
    let t = table(&fm, table_size, None)?;
    let results = check::check_fit(&fit, fit_path, &fm, &t.lut)?;
    let exposure = default_exposure(t.lut.sample(1.0, 0.0).map(f64::from), fm.material.eta);
    // One set: the pictures, then sphere-check.json last.
    let set = crate::formats::output::OutputSet::begin(&[dir])?;
    let mut out = Vec::new();
    for (cmp, rendered, predicted) in results {
        let strip = side_by_side(&rendered, &predicted, 10.0);
        let stem = Path::new(&cmp.image)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        write_image(
            &dir.join(format!("sphere-{stem}-{}.png", cmp.index)),
            &strip,
            exposure,
            Tone::Srgb,
            8,
        )?;
        out.push(cmp);
    }
    #[derive(serde::Serialize)]
    struct CheckJson<'a> {
        schema: &'a str,
        fit: String,
        table: [usize; 2],
        table_error: f64,
        icosphere_level: u32,
        spheres: &'a [SphereComparison],
    }
    crate::formats::output::write_json(
        &dir.join("sphere-check.json"),
        &CheckJson {
            schema: "workbench.sphere-check/1",
            fit: fit_path.display().to_string(),
            table: [t.lut.n_cos, t.lut.n_kappa],
            table_error: t.error.max_rel,
            icosphere_level: check::LEVEL,
            spheres: &out,
        },
    )?;
    set.commit()?;
    Ok(out)
}

/// The sphere's bounding box in both images, cropped and laid out rendered | predicted |
/// |difference| × `gain`.
fn side_by_side(a: &Image, b: &Image, gain: f32) -> Image {
    let w = a.width as usize;
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (k, (&ca, &cb)) in a.coverage.iter().zip(&b.coverage).enumerate() {
        if ca > 0.0 || cb > 0.0 {
            let (x, y) = (k % w, k / w);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        (x0, y0, x1, y1) = (0, 0, 0, 0);
    }
    let pad = 4;
    let (x0, y0) = (x0.saturating_sub(pad), y0.saturating_sub(pad));
    let (x1, y1) = ((x1 + pad).min(w - 1), (y1 + pad).min(a.height as usize - 1));
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut rgb = vec![[0.0f32; 3]; 3 * cw * ch];
    for y in 0..ch {
        for x in 0..cw {
            let k = (y0 + y) * w + x0 + x;
            let (p, q) = (a.rgb[k], b.rgb[k]);
            rgb[y * 3 * cw + x] = p;
            rgb[y * 3 * cw + cw + x] = q;
            rgb[y * 3 * cw + 2 * cw + x] = std::array::from_fn(|c| (p[c] - q[c]).abs() * gain);
        }
    }
    Image {
        width: (3 * cw) as u32,
        height: ch as u32,
        coverage: vec![1.0; rgb.len()],
        rgb,
    }
}
