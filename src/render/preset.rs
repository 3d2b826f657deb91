//! Engine-ready tables (`workbench lut --preset unity|unreal|godot|blender|generic`): the fitted
//! diffuse term of [`crate::render::lut`] laid out the way a GPU samples a texture, in the
//! engine's curvature unit and texture origin, with a sidecar that states every convention.
//!
//! A GPU samples a texture of W × H texels at (u, v) ∈ [0, 1]² with texel i centred on
//! u = (i + ½)/W, bilinear between centres, and — with clamp addressing — the edge texel's value
//! in the half texel beyond the last centre. So texel (i, j) holds the diffuse term at
//!
//!     N·L = 2 (i + ½)/W − 1,   κ = κ_min + (κ_max − κ_min)(j + ½)/H
//!
//! and a shader looks it up at u = N·L · ½ + ½, v = (κ − κ_min)/(κ_max − κ_min), κ in the
//! engine's unit (1/m for Unity, Godot, Blender and generic; 1/cm for Unreal, whose unit is the
//! centimetre). j counts rows from the texture's origin: the bottom row of the picture for Unity
//! and Blender (OpenGL's convention), the top row for Unreal, Godot and generic (DirectX's, glTF's
//! and WebGL's without a flip). Odd widths put the clamped cosine's kink, N·L = 0, on a texel
//! centre. [`EngineTable::lookup`] reproduces the GPU's sampling on the CPU; the measured error
//! (including the texture's storage precision) is what a shader gets.

use crate::error::{Error, Result};
use crate::formats::fit::FitFile;
use crate::formats::output::{write_bytes, write_json, OutputSet};
use crate::formats::photo::{srgb_decode, srgb_encode, write_png16_rgb};
use crate::model::Material;
use crate::render::lut::{file_name, with_extension, FitMaterial, InterpolationError};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(crate) const SCHEMA: &str = "workbench.engine-lut/1";

/// The shading snippets (`src/render/shaders/`): the table, the exit Fresnel transmission and the
/// specular lobe as `workbench render` shades, in GLSL (WebGL2, OpenGL, Godot), HLSL (Unity,
/// Unreal) and WGSL (WebGPU). tests/it/shaders.rs compiles each with a reference front end.
pub const GLSL: &str = include_str!("shaders/cdrf.glsl");
pub const HLSL: &str = include_str!("shaders/cdrf.hlsl");
pub const WGSL: &str = include_str!("shaders/cdrf.wgsl");

/// Probes per texel interval and axis in [`EngineTable::error`].
const PROBES: usize = 4;

/// The engines `--preset` knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    Unity,
    Unreal,
    Godot,
    Blender,
    Generic,
}

/// Which row of the picture a texture coordinate v = 0 reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// v = 0 is the picture's bottom row (OpenGL, Unity, Blender).
    BottomLeft,
    /// v = 0 is the picture's top row (DirectX, Unreal, Godot, glTF, WebGL without a flip).
    TopLeft,
}

impl Preset {
    pub fn name(self) -> &'static str {
        match self {
            Preset::Unity => "unity",
            Preset::Unreal => "unreal",
            Preset::Godot => "godot",
            Preset::Blender => "blender",
            Preset::Generic => "generic",
        }
    }

    /// The curvature unit and how many of it make 1/mm.
    pub fn curvature_unit(self) -> (&'static str, f64) {
        match self {
            Preset::Unreal => ("1/cm", 10.0),
            _ => ("1/m", 1000.0),
        }
    }

    /// The shading snippets written with the table: (extension, text).
    pub fn shaders(self) -> Vec<(&'static str, &'static str)> {
        match self {
            Preset::Unity => vec![("hlsl", HLSL)],
            Preset::Unreal => vec![("ush", HLSL)],
            Preset::Godot => vec![("gdshaderinc", GLSL)],
            // Blender's nodes take the table; the shading is built from nodes (README).
            Preset::Blender => vec![],
            Preset::Generic => vec![("glsl", GLSL), ("wgsl", WGSL)],
        }
    }

    pub fn origin(self) -> Origin {
        match self {
            Preset::Unity | Preset::Blender => Origin::BottomLeft,
            _ => Origin::TopLeft,
        }
    }

    /// The texture's import settings in the engine's own words, for a texture stored as
    /// `encoding` (an 8-bit sRGB texture is imported as colour, so the GPU decodes it to linear
    /// before filtering; the others as linear data).
    pub fn import_settings(self, encoding: Encoding) -> Vec<String> {
        let srgb = encoding == Encoding::Png8Srgb;
        let on = |b: bool| if b { "on" } else { "off" };
        match self {
            Preset::Unity => vec![
                format!("Texture Type: Default; sRGB (Color Texture): {}", on(srgb)),
                "Wrap Mode: Clamp; Filter Mode: Bilinear; Generate Mip Maps: off".into(),
                "Non-Power of 2: None; Compression: None".into(),
            ],
            Preset::Unreal => vec![
                format!(
                    "Compression Settings: {}; sRGB: {}",
                    match encoding {
                        Encoding::ExrHalf => "HDR (RGBA16F)",
                        Encoding::Png16 => "HDR (RGBA16F) or Masks (no sRGB)",
                        Encoding::Png8Srgb => "UserInterface2D (RGBA)",
                    },
                    on(srgb)
                ),
                "Mip Gen Settings: NoMipmaps; Filter: Bilinear".into(),
                "X-axis and Y-axis Tiling Method: Clamp".into(),
            ],
            Preset::Godot => vec![
                "Import as Texture2D; Compress Mode: Lossless; Mipmaps Generate: off".into(),
                format!(
                    "in the shader: uniform sampler2D cdrf_table : {}filter_linear, repeat_disable;",
                    if srgb { "source_color, " } else { "" }
                ),
            ],
            Preset::Blender => vec![
                format!(
                    "Image Texture node: Color Space {}; Interpolation Linear; Extension Extend",
                    if srgb { "sRGB" } else { "Non-Color" }
                ),
                "Vector input: (u, v, 0) with u = N·L · 0.5 + 0.5 and v from the curvature attribute"
                    .into(),
            ],
            Preset::Generic => vec![
                if srgb {
                    "an sRGB texture format (WebGL2: SRGB8), so that sampling decodes to linear before filtering".into()
                } else {
                    "linear data (no sRGB decode)".into()
                },
                "bilinear filtering; clamp-to-edge on both axes; no mipmaps".into(),
                "WebGL: UNPACK_FLIP_Y_WEBGL false, so that v = 0 is the picture's top row".into(),
            ],
        }
    }
}

/// How the texture is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Encoding {
    /// OpenEXR, RGB half floats, linear (the default).
    ExrHalf,
    /// PNG, RGB 16 bits, linear, value = pixel / 65535 · scale.
    Png16,
    /// PNG, RGB 8 bits with the sRGB transfer curve (only when asked: 8 bits lose the dark end).
    Png8Srgb,
}

impl Encoding {
    pub fn extension(self) -> &'static str {
        match self {
            Encoding::ExrHalf => "exr",
            _ => "png",
        }
    }

    /// A stored value decoded back (what the GPU reads, before `scale`).
    fn round_trip(self, x: f32, scale: f64) -> f32 {
        match self {
            Encoding::ExrHalf => half::f16::from_f32(x).to_f32(),
            Encoding::Png16 => {
                let q = ((x as f64 / scale).clamp(0.0, 1.0) * 65535.0).round();
                (q / 65535.0 * scale) as f32
            }
            Encoding::Png8Srgb => {
                let q = (srgb_encode((x as f64 / scale).clamp(0.0, 1.0)) * 255.0).round();
                (srgb_decode(q / 255.0) * scale) as f32
            }
        }
    }
}

/// The table in texture layout: `values[j * width + i]` is texel (i, j), j counted from the
/// origin (lowest curvature first), in the fit's units.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineTable {
    pub width: usize,
    pub height: usize,
    /// κ_min and κ_max (1/mm) at v = 0 and v = 1.
    pub kappa_range_per_mm: [f64; 2],
    pub values: Vec<[f32; 3]>,
}

impl EngineTable {
    /// Tabulate the fit's diffuse term at the texel centres.
    pub fn build(fm: &FitMaterial, width: usize, height: usize, kappa_range: [f64; 2]) -> Self {
        assert!(width >= 2 && height >= 2 && kappa_range[1] > kappa_range[0]);
        let mut t = EngineTable {
            width,
            height,
            kappa_range_per_mm: kappa_range,
            values: vec![[0.0; 3]; width * height],
        };
        let cos: Vec<f64> = (0..width).map(|i| t.cos_at(i)).collect();
        let kap: Vec<f64> = (0..height).map(|j| t.kappa_at(j)).collect();
        t.values
            .par_chunks_mut(width)
            .zip(kap.par_iter())
            .for_each(|(row, &k)| {
                for (v, &c) in row.iter_mut().zip(&cos) {
                    let d = fm.diffuse(c, k);
                    *v = [d[0] as f32, d[1] as f32, d[2] as f32];
                }
            });
        t
    }

    /// N·L at texel column i's centre.
    pub fn cos_at(&self, i: usize) -> f64 {
        2.0 * (i as f64 + 0.5) / self.width as f64 - 1.0
    }

    /// κ (1/mm) at texel row j's centre (j from the origin).
    pub fn kappa_at(&self, j: usize) -> f64 {
        let [k0, k1] = self.kappa_range_per_mm;
        k0 + (k1 - k0) * (j as f64 + 0.5) / self.height as f64
    }

    /// v of a curvature (1/mm).
    pub fn v_of(&self, kappa_per_mm: f64) -> f64 {
        let [k0, k1] = self.kappa_range_per_mm;
        (kappa_per_mm - k0) / (k1 - k0)
    }

    /// What a GPU returns at (u, v): bilinear between texel centres, clamp-to-edge.
    pub fn sample(&self, u: f64, v: f64) -> [f64; 3] {
        let axis = |t: f64, n: usize| {
            let x = (t * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
            let i = (x as usize).min(n - 2);
            (i, x - i as f64)
        };
        let (i, fu) = axis(u, self.width);
        let (j, fv) = axis(v, self.height);
        let at = |i: usize, j: usize| self.values[j * self.width + i];
        let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        std::array::from_fn(|k| {
            let lo = a[k] as f64 + (b[k] as f64 - a[k] as f64) * fu;
            let hi = c[k] as f64 + (d[k] as f64 - c[k] as f64) * fu;
            lo + (hi - lo) * fv
        })
    }

    /// The shader's look-up: u = N·L · ½ + ½, v from κ (1/mm).
    pub fn lookup(&self, cos: f64, kappa_per_mm: f64) -> [f64; 3] {
        self.sample(cos * 0.5 + 0.5, self.v_of(kappa_per_mm))
    }

    pub fn peak(&self) -> f64 {
        self.values
            .iter()
            .flat_map(|v| v.iter())
            .fold(0.0f32, |a, &b| a.max(b)) as f64
    }

    /// The same table as stored with `encoding` and read back.
    pub fn stored(&self, encoding: Encoding) -> EngineTable {
        let scale = self.peak().max(f64::MIN_POSITIVE);
        EngineTable {
            values: self
                .values
                .iter()
                .map(|v| v.map(|x| encoding.round_trip(x, scale)))
                .collect(),
            ..self.clone()
        }
    }

    /// The largest and RMS difference from the closed form between the first and last texel
    /// centres on both axes (on a grid of [`PROBES`] × [`PROBES`] points a cell: with only the
    /// centres and midpoints, random points found errors 4% larger), and the largest in the
    /// outer half texel, where clamping holds the edge texels (at N·L = ±1 and at κ_min, κ_max:
    /// about the table's slope times one texel, shrinking only as 1/size).
    pub fn error(&self, fm: &FitMaterial) -> (InterpolationError, f64) {
        let (w, h) = (self.width, self.height);
        // Probe coordinates along one axis: each texel centre and PROBES − 1 points between it
        // and the next, and the ends (border).
        let probes = |n: usize| -> Vec<(f64, bool)> {
            let mut p = vec![(0.0, true)];
            for i in 0..n {
                let steps = if i + 1 < n { PROBES } else { 1 };
                for k in 0..steps {
                    p.push((
                        (i as f64 + 0.5 + k as f64 / PROBES as f64) / n as f64,
                        false,
                    ));
                }
            }
            p.push((1.0, true));
            p
        };
        let (pu, pv) = (probes(w), probes(h));
        let [k0, k1] = self.kappa_range_per_mm;
        let rows: Vec<(f64, f64, f64, f64, usize, f64)> = pv
            .par_iter()
            .map(|&(v, v_border)| {
                let kappa = k0 + (k1 - k0) * v;
                let (mut worst, mut at, mut sq, mut n, mut border) = (0.0f64, 0.0, 0.0, 0, 0.0f64);
                for &(u, u_border) in &pu {
                    let cos = 2.0 * u - 1.0;
                    let exact = fm.diffuse(cos, kappa);
                    let got = self.sample(u, v);
                    for c in 0..3 {
                        let e = (got[c] - exact[c]).abs();
                        if u_border || v_border {
                            border = border.max(e);
                            continue;
                        }
                        sq += e * e;
                        n += 1;
                        if e > worst {
                            (worst, at) = (e, cos);
                        }
                    }
                }
                (worst, at, kappa, sq, n, border)
            })
            .collect();
        let (mut max_abs, mut at_cos, mut at_kappa, mut sq, mut n, mut border) =
            (0.0, 0.0, 0.0, 0.0, 0, 0.0f64);
        for (e, c, k, s, m, b) in rows {
            if e > max_abs {
                (max_abs, at_cos, at_kappa) = (e, c, k);
            }
            sq += s;
            n += m;
            border = border.max(b);
        }
        let peak = self.peak();
        let rel = |x: f64| if peak > 0.0 { x / peak } else { 0.0 };
        (
            InterpolationError {
                max_abs,
                rms: (sq / n.max(1) as f64).sqrt(),
                max_rel: rel(max_abs),
                at_cos,
                at_kappa_per_mm: at_kappa,
                points: n / 3,
            },
            rel(border),
        )
    }
}

/// The sidecar (`<stem>.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EngineLutJson {
    pub schema: String,
    pub preset: Preset,
    /// The fit tabulated.
    pub fit: String,
    /// The texture beside this file.
    pub image: String,
    pub encoding: Encoding,
    pub colour_space: String,
    pub width: usize,
    pub height: usize,
    /// How u is computed and what texel column i holds.
    pub u: String,
    /// How v is computed and what texel row j holds.
    pub v: String,
    /// Which picture row v = 0 reads.
    pub origin: String,
    pub addressing: String,
    pub filtering: String,
    pub curvature_unit: String,
    /// κ at v = 0 and v = 1, in `curvature_unit`.
    pub curvature_range: [f64; 2],
    /// The curvatures the fit measured (1 / its largest and smallest radius), in
    /// `curvature_unit`, and where they lie in v: beyond them the table extrapolates the model.
    pub measured_curvature: [f64; 2],
    pub measured_v: [f64; 2],
    pub extrapolation: String,
    /// A sample times `value_scale` is the table's value (the fit's radiance units).
    pub value_scale: f64,
    pub content: String,
    /// The radiance a shader computes with the table, as `workbench render` does.
    pub shading: String,
    /// Curvature on a mesh, as `workbench render` computes it, and the screen-space fallback.
    pub curvature: String,
    pub material: Material,
    pub reference_radius_mm: f64,
    /// The fit's standard errors (fit.json `std`) and what they are (`std_source`).
    pub std: serde_json::Value,
    pub std_source: String,
    /// The table against the closed form as a GPU samples it, between the outer texel centres:
    /// before storage and as stored.
    pub interpolation_error: InterpolationError,
    pub stored_error: InterpolationError,
    /// The largest error in the outer half texel (N·L near ±1, κ near its ends), where clamping
    /// holds the edge texels, over the peak (as stored).
    pub border_error: f64,
    /// The tolerance the size was chosen for (null: the size was given).
    pub tolerance: Option<f64>,
    pub import_settings: Vec<String>,
    /// The shading snippets beside this file.
    pub shaders: Vec<String>,
    /// The mesh with its curvature (`--mesh`), binary glTF, or null.
    pub mesh: Option<String>,
}

/// Everything `write` needs besides the table.
pub struct WriteRequest<'a> {
    pub stem: &'a Path,
    pub preset: Preset,
    pub encoding: Encoding,
    pub fit: &'a FitFile,
    pub fit_path: &'a Path,
    pub fm: &'a FitMaterial,
    /// The table's error before storage ([`EngineTable::error`], measured when its size was
    /// chosen).
    pub error: InterpolationError,
    pub tolerance: Option<f64>,
    /// A mesh (mm) and its curvature (1/mm), written beside the table as `<stem>.glb`.
    pub mesh: Option<(&'a crate::render::mesh::Mesh, &'a [f64])>,
}

/// The texture, the shading snippets and the sidecar (in that order, as one set). Returns the
/// paths written and the sidecar.
pub fn write(req: &WriteRequest, t: &EngineTable) -> Result<(Vec<PathBuf>, EngineLutJson)> {
    let with = |ext: &str| with_extension(req.stem, ext);
    let image = with(req.encoding.extension());
    let json = with("json");
    let shaders: Vec<(PathBuf, &str)> = req
        .preset
        .shaders()
        .into_iter()
        .map(|(ext, text)| (with(ext), text))
        .collect();
    let glb = with("glb");
    let mut members: Vec<&Path> = vec![&image, &json];
    members.extend(shaders.iter().map(|(p, _)| p.as_path()));
    if req.mesh.is_some() {
        members.push(&glb);
    }
    let set = OutputSet::begin(&members)?;
    let colour_space = write_image(req, t, &image)?;
    let sidecar = sidecar(req, t, &image, colour_space, &shaders, &glb)?;
    for (path, text) in &shaders {
        write_bytes(path, text.as_bytes())?;
    }
    write_mesh(req, t, &glb)?;
    write_json(&json, &sidecar)?;
    set.commit()?;
    let mut paths = vec![image];
    paths.extend(shaders.into_iter().map(|(p, _)| p));
    if req.mesh.is_some() {
        paths.push(glb);
    }
    paths.push(json);
    Ok((paths, sidecar))
}

/// The table as the preset's picture (rows in its origin's order), written in the request's
/// encoding. Returns the colour space it says.
fn write_image(req: &WriteRequest, t: &EngineTable, image: &Path) -> Result<&'static str> {
    let (w, h) = (t.width, t.height);
    let scale = t.peak().max(f64::MIN_POSITIVE);
    // Picture rows top to bottom: texel row j is picture row j (top-left origin) or h − 1 − j.
    let row_of = |r: usize| match req.preset.origin() {
        Origin::TopLeft => r,
        Origin::BottomLeft => h - 1 - r,
    };
    let picture: Vec<[f32; 3]> = (0..h)
        .flat_map(|r| t.values[row_of(r) * w..(row_of(r) + 1) * w].iter().copied())
        .collect();
    Ok(match req.encoding {
        Encoding::ExrHalf => {
            use exr::prelude::*;
            let img = Image::from_channels(
                (w, h),
                SpecificChannels::rgb(|p: Vec2<usize>| {
                    let v = picture[p.y() * w + p.x()];
                    (
                        f16::from_f32(v[0]),
                        f16::from_f32(v[1]),
                        f16::from_f32(v[2]),
                    )
                }),
            );
            let mut bytes = std::io::Cursor::new(Vec::new());
            img.write()
                .to_buffered(&mut bytes)
                .map_err(|e| crate::error::Error::invalid(image, format!("EXR encoding: {e}")))?;
            write_bytes(image, bytes.get_ref())?;
            "linear (no transfer curve), half float"
        }
        Encoding::Png16 => {
            let q: Vec<u16> = picture
                .iter()
                .flat_map(|v| v.iter())
                .map(|&x| ((x as f64 / scale).clamp(0.0, 1.0) * 65535.0).round() as u16)
                .collect();
            write_png16_rgb(image, w as u32, h as u32, &q)?;
            "linear (no transfer curve), 16-bit unsigned normalised"
        }
        Encoding::Png8Srgb => {
            let q: Vec<u8> = picture
                .iter()
                .flat_map(|v| v.iter())
                .map(|&x| (srgb_encode((x as f64 / scale).clamp(0.0, 1.0)) * 255.0).round() as u8)
                .collect();
            crate::formats::photo::write_8bit(image, w as u32, h as u32, 3, &q, 100, None)?;
            "sRGB transfer curve, 8-bit (import as colour: the GPU decodes it to linear)"
        }
    })
}

/// The sidecar: every convention of the table, the fit's material and errors, and the errors
/// measured on the table as stored.
fn sidecar(
    req: &WriteRequest,
    t: &EngineTable,
    image: &Path,
    colour_space: &str,
    shaders: &[(PathBuf, &str)],
    glb: &Path,
) -> Result<EngineLutJson> {
    let (w, h) = (t.width, t.height);
    let scale = t.peak().max(f64::MIN_POSITIVE);
    let (unit, per_mm) = req.preset.curvature_unit();
    let [k0, k1] = t.kappa_range_per_mm;
    let meas = req.fm.measured_kappa;
    let measured_v = [t.v_of(meas[0]), t.v_of(meas[1])];
    let value_scale = match req.encoding {
        Encoding::ExrHalf => 1.0,
        _ => scale,
    };
    let name = |p: &Path| file_name(p);
    let (stored_err, border_err) = t.stored(req.encoding).error(req.fm);
    Ok(EngineLutJson {
        schema: SCHEMA.into(),
        preset: req.preset,
        fit: req.fit_path.display().to_string(),
        image: name(image),
        encoding: req.encoding,
        colour_space: colour_space.into(),
        width: w,
        height: h,
        u: format!("u = N·L · 0.5 + 0.5; texel column i (0 at the left) holds N·L = 2 (i + 0.5) / {w} − 1"),
        v: format!(
            "v = (kappa − {}) / ({} − {}), kappa in {unit}; texel row j (0 at the origin) holds kappa = {} + {} · (j + 0.5) / {h}",
            k0 * per_mm,
            k1 * per_mm,
            k0 * per_mm,
            k0 * per_mm,
            (k1 - k0) * per_mm
        ),
        origin: match req.preset.origin() {
            Origin::BottomLeft => "bottom-left: v = 0 reads the picture's bottom row (its last row in the file)",
            Origin::TopLeft => "top-left: v = 0 reads the picture's top row (its first row in the file)",
        }
        .into(),
        addressing: "clamp to edge on both axes".into(),
        filtering: "bilinear, no mipmaps".into(),
        curvature_unit: unit.into(),
        curvature_range: [k0 * per_mm, k1 * per_mm],
        measured_curvature: [meas[0] * per_mm, meas[1] * per_mm],
        measured_v,
        extrapolation: format!(
            "measured between v = {:.4} and v = {:.4} (spheres of radius {:.1} to {:.1} mm); below, toward a flat surface, and above, the model is extrapolated",
            measured_v[0],
            measured_v[1],
            1.0 / meas[0],
            1.0 / meas[1]
        ),
        value_scale,
        content: "diffuse term a_c(kappa) · f(acos(N·L); sigma_c(kappa)) per channel (R, G, B), linear radiance with the photographed light's irradiance folded in, without the exit Fresnel transmission or the specular lobe".into(),
        shading: "L_c = table_c(u, v) · value_scale · T(n·v; eta) + ks · D(n·h; alpha) · G1(n·l) · G1(n·v) · F(l·h; eta) / (4 n·v), for n·l > 0 and n·v > 0 (the lobe 0 otherwise); T = 1 − F, F the exact unpolarised dielectric Fresnel reflectance, D the GGX distribution alpha² / (pi ((n·h)² (alpha² − 1) + 1)²), G1(c) = 2c / (c + sqrt(alpha² + (1 − alpha²) c²)); n, l, v unit vectors, l and v pointing away from the surface".into(),
        curvature: "per vertex, as workbench render computes it (src/render/mesh.rs): the mean absolute principal curvature (|k1| + |k2|) / 2 from a least-squares fit of the normal curvatures along the vertex's edges, in curvature_unit, passed as a vertex attribute (lut --preset --mesh writes the mesh as binary glTF with it: attribute _CDRF_KAPPA in curvature_unit, and v in COLOR_0); fallback (an approximation, noisy on coarse meshes): kappa ≈ length(fwidth(N)) / length(fwidth(P)) in screen space".into(),
        material: req.fm.material,
        reference_radius_mm: req.fm.model.reference_radius_mm,
        std: serde_json::to_value(&req.fit.std)
            .map_err(|e| Error::invalid(req.fit_path, format!("std: {e}")))?,
        std_source: req.fit.std_source.clone(),
        interpolation_error: req.error,
        stored_error: stored_err,
        border_error: border_err,
        tolerance: req.tolerance,
        import_settings: req.preset.import_settings(req.encoding),
        shaders: shaders.iter().map(|(p, _)| name(p)).collect(),
        mesh: req.mesh.map(|_| name(glb)),
    })
}

/// The mesh as binary glTF with workbench's curvature per vertex (and its v in the table).
fn write_mesh(req: &WriteRequest, t: &EngineTable, glb: &Path) -> Result<()> {
    let (_, per_mm) = req.preset.curvature_unit();
    if let Some((mesh, curvature)) = req.mesh {
        let f = |v: &nalgebra::Vector3<f64>, s: f64| {
            [(v.x * s) as f32, (v.y * s) as f32, (v.z * s) as f32]
        };
        let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| f(p, 1e-3)).collect();
        let normals: Vec<[f32; 3]> = mesh.normals.iter().map(|n| f(n, 1.0)).collect();
        let kappa: Vec<f32> = curvature.iter().map(|&k| (k * per_mm) as f32).collect();
        let v: Vec<f32> = curvature
            .iter()
            .map(|&k| t.v_of(k).clamp(0.0, 1.0) as f32)
            .collect();
        let bytes = crate::formats::glb::encode(
            &crate::formats::glb::GlbMesh {
                positions: &positions,
                normals: &normals,
                kappa: &kappa,
                v: &v,
                triangles: &mesh.triangles,
            },
            concat!("workbench ", env!("CARGO_PKG_VERSION")),
        );
        write_bytes(glb, &bytes)?;
    }
    Ok(())
}
