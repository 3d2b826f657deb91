//! The `workbench` command line: parse arguments, call the library, print.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use workbench::camera::{Camera, Distortion};
use workbench::model::{LightAngles, Material, SpecularParams};
use workbench::synth::checkerboard::{self, BoardFormat, CheckerConfig};
use workbench::synth::session::{self, Backdrop, Format, Layout, SessionConfig};
use workbench::synth::volpath;

#[derive(Parser)]
#[command(
    name = "workbench",
    version,
    about = "Measure the curvature-dependent reflectance of translucent materials"
)]
struct Cli {
    /// No progress bars.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Render ground-truth synthetic data.
    #[command(subcommand)]
    Synth(Synth),
    /// Calibrate the camera from a folder of chessboard photos (OpenCV).
    #[cfg(feature = "opencv")]
    Calibrate(CalibrateArgs),
    /// Find the spheres, highlights and light direction of a session; write detections.json.
    Detect(DetectArgs),
    /// Fit the material (σ0, albedo, η, specular lobe, light) to a session; write fit.json.
    Solve(SolveArgs),
    /// Time and error of every stage at every setting, on freshly rendered ground truth.
    Bench(BenchArgs),
    /// Redraw a fit's figures and index.html from fit.json and its session, without solving.
    Plot(PlotArgs),
    /// Tabulate a fit's CDRF over N·L and curvature: 16-bit PNG, OpenEXR and a JSON sidecar.
    Lut(LutArgs),
    /// Render a mesh (OBJ or PLY) with a fit's CDRF, or check the renderer against the fit.
    Render(RenderArgs),
    /// Check a session folder against its files: images, sizes, intrinsics, exposures.
    Check {
        /// The session folder (or its session.json).
        session: PathBuf,
    },
}

#[derive(Args)]
struct DetectArgs {
    /// The session folder (or its session.json).
    session: PathBuf,
    /// Where to write detections.json (default: beside session.json).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Do not write the overlay pictures (overlays/<photo>.png beside detections.json).
    #[arg(long)]
    no_overlays: bool,
}

#[derive(Args)]
struct SolveArgs {
    /// The session folder (or its session.json).
    session: PathBuf,
    /// One fit across all radii (the default method).
    #[arg(long, conflicts_with = "method")]
    joint: bool,
    /// joint: everything at once; paper: the source paper's per-radius baseline.
    #[arg(long, value_enum, default_value_t = MethodArg::Joint)]
    method: MethodArg,
    /// Where to write fit.json (default: beside session.json).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Fit without the spheres of this radius (mm), then report how well the fit predicts them.
    #[arg(long, allow_hyphen_values = true)]
    holdout: Option<f64>,
    /// Prior on a parameter, NAME=MEAN:STD; only eta (default eta=1.45:0.05).
    #[arg(long, value_parser = parse_prior)]
    prior: Option<(f64, f64)>,
    /// The light's irradiance in the photos' radiance units (pixel value / exposure): makes the
    /// specular scale known (ks = E), so η is fitted instead of held at its prior.
    #[arg(long, allow_hyphen_values = true)]
    irradiance: Option<f64>,
    /// Pixel reduction: auto (the coarsest cells whose predicted parameter shift stays below 0.3
    /// standard errors), none (every pixel), or a cell width in degrees: 0.25, 0.5, 1, 2, 4.
    #[arg(long, default_value = "auto", value_parser = parse_reduce)]
    reduce: workbench::joint::Reduction,
    /// Plain least squares instead of the Huber loss.
    #[arg(long)]
    no_robust: bool,
    /// Model extensions: default (albedo-curvature with 3 or more radii, none otherwise), none,
    /// auto (chosen by held-out error; needs 4 or more radii), or any of sigma-exponent,
    /// albedo-curvature, two-gaussian (comma-separated; both = the first two).
    #[arg(long, default_value = "default", value_parser = parse_extensions)]
    extensions: workbench::solve::ExtensionChoice,
    /// Start σ0 (mm), one value or r,g,b, instead of the search over the data.
    #[arg(long, value_parser = triple)]
    start_sigma0: Option<[f64; 3]>,
    /// Start light as azimuth,elevation in degrees, instead of the detector's.
    #[arg(long, value_parser = pair, allow_hyphen_values = true)]
    start_light: Option<[f64; 2]>,
    /// Run detection even when detections.json is newer than its inputs.
    #[arg(long)]
    redetect: bool,
    /// Keep the light at the detector's estimate (or --start-light) instead of refining it.
    #[arg(long, conflicts_with = "free_light")]
    hold_light: bool,
    /// Skip the leave-one-radius-out refits (the standard errors are then the formal ones).
    #[arg(long)]
    no_jackknife: bool,
    /// Refine the light from the shading alone, without the detector's light as a prior (the
    /// default uses it as one).
    #[arg(long)]
    free_light: bool,
    /// Blur the irradiance that enters the medium, max(cos θ, 0)·T(cos θ; η), instead of the
    /// bare clamped cosine (entry-side Fresnel transmission; about 4× the solve time).
    #[arg(long)]
    entry_transmission: bool,
    /// Write figures (PNG and SVG) and index.html into this folder; runs --baseline too.
    #[arg(long)]
    plots: Option<PathBuf>,
    /// Also run the paper's baseline beside the joint fit (written to fit.json as "baseline").
    #[arg(long)]
    baseline: bool,
}

#[derive(Args)]
struct BenchArgs {
    /// Two small sessions and a small checkerboard set (a few minutes) instead of the full run.
    #[arg(long)]
    quick: bool,
    /// Folder for the sessions and the report (default: bench-report/).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct PlotArgs {
    /// The fit (fit.json written by `workbench solve`).
    fit: PathBuf,
    /// Folder for the figures (default: plots/ beside fit.json).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct LutArgs {
    /// The fit (fit.json written by `workbench solve`).
    fit: PathBuf,
    /// Output stem: writes <out>.png, <out>.exr and <out>.json (default: lut beside fit.json).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Table nodes as N_COSxN_KAPPA (e.g. 257x129), or "auto": the smallest standard size within
    /// --tolerance.
    #[arg(long, default_value = "auto", value_parser = parse_table_size)]
    size: TableArg,
    /// Largest interpolation error allowed by --size auto, as a fraction of the table's peak.
    #[arg(long, default_value_t = workbench::lut::DEFAULT_TOLERANCE)]
    tolerance: f64,
    /// Curvature of the table's last row (1/mm; default 3 / the smallest radius fitted).
    #[arg(long)]
    kappa_max: Option<f64>,
}

#[derive(Args)]
struct RenderArgs {
    /// The mesh (.obj or .ply); not with --check.
    #[arg(required_unless_present = "check")]
    mesh: Option<PathBuf>,
    /// The fit (fit.json written by `workbench solve`).
    #[arg(long)]
    fit: PathBuf,
    /// The image to write (.png); with --check, a folder (default: render-check/ beside fit.json).
    #[arg(long, required_unless_present = "check")]
    out: Option<PathBuf>,
    /// Render every sphere of the fit's session as an ideal sphere mesh and compare it with the
    /// solver's predicted image.
    #[arg(long, conflicts_with = "mesh")]
    check: bool,
    /// Units of the mesh file's coordinates.
    #[arg(long, value_enum, default_value = "mm")]
    unit: workbench::mesh::Unit,
    /// Rescale the mesh so its bounding sphere is this many mm across.
    #[arg(long)]
    object_size: Option<f64>,
    /// Light as AZIMUTH,ELEVATION degrees in the camera frame (0,0: at the camera; azimuth to the
    /// right, elevation up). Default: the fit's light.
    #[arg(long, value_parser = parse_pair, allow_hyphen_values = true)]
    light: Option<(f64, f64)>,
    /// Camera position around the mesh as AZIMUTH,ELEVATION degrees (mesh y up; 0,0 looks along −z).
    #[arg(long, value_parser = parse_pair, default_value = "0,0", allow_hyphen_values = true)]
    view: (f64, f64),
    /// Camera distance relative to the tightest framing of the mesh's bounding sphere.
    #[arg(long, default_value_t = 1.05)]
    distance: f64,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_resolution)]
    resolution: (u32, u32),
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 30.0)]
    fov: f64,
    /// Coverage samples per pixel (anti-aliasing).
    #[arg(long, value_enum, default_value = "4")]
    samples: workbench::render::Samples,
    /// cdrf: the measured CDRF; lambert: the same material with a plain clamped cosine.
    #[arg(long, value_enum, default_value = "cdrf")]
    shading: workbench::render::Shading,
    /// Bits per channel of the PNG (8 or 16).
    #[arg(long, default_value_t = 8)]
    bits: u8,
    /// Transfer curve.
    #[arg(long, value_enum, default_value = "srgb")]
    tone: workbench::render::Tone,
    /// Exposure multiplier (1: a flat surface facing the light at 0.8 of full scale).
    #[arg(long, default_value_t = 1.0)]
    exposure: f64,
    /// Table nodes (N_COSxN_KAPPA or auto), as for `workbench lut`.
    #[arg(long, default_value = "auto", value_parser = parse_table_size)]
    table: TableArg,
}

fn parse_pair(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("expected AZIMUTH,ELEVATION in degrees, got {s:?}"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("not a finite number: {t:?}"))
    };
    Ok((p(a)?, p(b)?))
}

/// "AxB" as two numbers (`what` names them in the error).
fn parse_dims<T: std::str::FromStr>(
    s: &str,
    form: &str,
    what: &str,
) -> std::result::Result<(T, T), String> {
    let (a, b) = s
        .split_once('x')
        .ok_or_else(|| format!("expected {form}, got {s:?}"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("not a {what}: {t:?}"))
    };
    Ok((p(a)?, p(b)?))
}

fn parse_resolution(s: &str) -> std::result::Result<(u32, u32), String> {
    parse_dims(s, "WIDTHxHEIGHT", "pixel count")
}

/// A table size: None for auto.
#[derive(Clone, Copy)]
struct TableArg(Option<(usize, usize)>);

fn parse_table_size(s: &str) -> std::result::Result<TableArg, String> {
    if s == "auto" {
        return Ok(TableArg(None));
    }
    parse_dims(s, "auto or N_COSxN_KAPPA", "node count").map(|d| TableArg(Some(d)))
}

fn table_size(size: TableArg, tolerance: f64) -> workbench::render_job::TableSize {
    match size.0 {
        Some((a, b)) => workbench::render_job::TableSize::Fixed(a, b),
        None => workbench::render_job::TableSize::Auto(tolerance),
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Joint,
    Paper,
}

fn parse_prior(s: &str) -> std::result::Result<(f64, f64), String> {
    let (name, rest) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=MEAN:STD, got {s:?}"))?;
    if name.trim() != "eta" {
        return Err(format!("priors are offered for eta only, got {name:?}"));
    }
    let (m, sd) = rest
        .split_once(':')
        .ok_or_else(|| format!("expected eta=MEAN:STD, got {s:?}"))?;
    let m: f64 = m.trim().parse().map_err(|_| format!("bad mean {m:?}"))?;
    let sd: f64 = sd.trim().parse().map_err(|_| format!("bad std {sd:?}"))?;
    if !(m > 1.0 && m < 4.0 && sd > 0.0 && sd.is_finite()) {
        return Err(format!("need 1 < mean < 4 and std > 0, got {m}:{sd}"));
    }
    Ok((m, sd))
}

fn parse_reduce(s: &str) -> std::result::Result<workbench::joint::Reduction, String> {
    use workbench::joint::Reduction;
    match s {
        "auto" => Ok(Reduction::Auto),
        "none" | "0" => Ok(Reduction::None),
        _ => {
            let w: f64 = s
                .parse()
                .map_err(|_| format!("expected auto, none or degrees, got {s:?}"))?;
            let f = (w / 0.25).round() as u32;
            if workbench::reduce::FACTORS.contains(&f) && (f as f64 * 0.25 - w).abs() < 1e-9 {
                Ok(Reduction::Factor(f))
            } else {
                Err(format!(
                    "cell width must be 0.25, 0.5, 1, 2 or 4 degrees, got {s}"
                ))
            }
        }
    }
}

fn parse_extensions(s: &str) -> std::result::Result<workbench::solve::ExtensionChoice, String> {
    use workbench::joint::Extensions;
    use workbench::solve::ExtensionChoice;
    match s {
        "default" => return Ok(ExtensionChoice::Default),
        "none" => return Ok(ExtensionChoice::None),
        "auto" => return Ok(ExtensionChoice::Auto),
        "both" => {
            return Ok(ExtensionChoice::On(Extensions {
                sigma_exponent: true,
                albedo_curvature: true,
                two_gaussian: false,
            }))
        }
        _ => {}
    }
    let mut e = Extensions::default();
    for part in s.split(',') {
        match part.trim() {
            "sigma-exponent" => e.sigma_exponent = true,
            "albedo-curvature" => e.albedo_curvature = true,
            "two-gaussian" => e.two_gaussian = true,
            other => {
                return Err(format!(
                    "unknown extension {other:?} (sigma-exponent, albedo-curvature, two-gaussian)"
                ))
            }
        }
    }
    Ok(ExtensionChoice::On(e))
}

fn pair(s: &str) -> std::result::Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("expected two numbers a,b, got {s:?}"))?;
    match v.as_slice() {
        [a, b] if a.is_finite() && b.is_finite() => Ok([*a, *b]),
        _ => Err(format!("expected two numbers a,b, got {s:?}")),
    }
}

#[derive(Subcommand)]
enum Synth {
    /// Photos of translucent spheres with known material, light and camera.
    Session(SessionArgs),
    /// Views of a planar chessboard with known camera and poses.
    Checkerboard(CheckerArgs),
    /// Physically based photos of translucent spheres: volumetric path tracing of a scattering
    /// medium inside a rough dielectric boundary (not the CDRF the solver fits).
    Pbr(PbrArgs),
}

/// The light of a synthetic session.
#[derive(Args, Clone, Copy)]
struct LightArgs {
    /// Light azimuth in degrees (0 = from the camera, positive = from the right).
    #[arg(long, default_value_t = 70.0, allow_hyphen_values = true)]
    light_azimuth: f64,
    /// Light elevation in degrees (positive = from above).
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true)]
    light_elevation: f64,
}

impl LightArgs {
    fn angles(&self) -> LightAngles {
        LightAngles {
            azimuth: self.light_azimuth.to_radians(),
            elevation: self.light_elevation.to_radians(),
        }
    }
}

#[derive(Args)]
struct PbrArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    out: PathBuf,
    /// Sphere radii in mm (one photo each, every sphere at the same place).
    #[arg(long, default_value = "35,30,25,20,15", value_parser = floats)]
    radii: Floats,
    #[command(flatten)]
    camera: CameraArgs,
    #[command(flatten)]
    light: LightArgs,
    /// Extinction coefficient σt of the medium, 1/mm (one for all channels).
    #[arg(long, default_value_t = 1.0)]
    sigma_t: f64,
    /// Single-scattering albedo σs/σt, one value or r,g,b (each below 1).
    #[arg(long, default_value = "0.99,0.985,0.97", value_parser = triple)]
    albedo: [f64; 3],
    /// Index of refraction of the boundary.
    #[arg(long, default_value_t = 1.44)]
    eta: f64,
    /// GGX roughness of the boundary.
    #[arg(long, default_value_t = 0.1)]
    alpha: f64,
    /// Samples per pixel (split into two half renders for the noise estimate).
    #[arg(long, default_value_t = 2048)]
    spp: u32,
    /// Camera-to-sphere distance in mm.
    #[arg(long, default_value_t = 500.0)]
    distance: f64,
    /// Material name written into session.json.
    #[arg(long, default_value = "wax-like")]
    material: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// A comma-separated list (an alias, so clap takes it as one value).
type Floats = Vec<f64>;

/// Parse "a,b,c" into floats.
fn floats(s: &str) -> Result<Floats, String> {
    s.split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| format!("{t:?} is not a number"))
        })
        .collect()
}

fn triple(s: &str) -> Result<[f64; 3], String> {
    let v = floats(s)?;
    match v.len() {
        1 => Ok([v[0]; 3]),
        3 => Ok([v[0], v[1], v[2]]),
        _ => Err("give one value or three (r,g,b)".into()),
    }
}

#[derive(Args, Clone)]
struct CameraArgs {
    /// Image size WxH.
    #[arg(long, default_value = "1280x960")]
    size: String,
    #[arg(long, default_value_t = 1400.0)]
    fx: f64,
    /// Defaults to fx.
    #[arg(long)]
    fy: Option<f64>,
    /// Defaults to the image centre plus a small offset (643.2 for 1280 wide).
    #[arg(long)]
    cx: Option<f64>,
    #[arg(long)]
    cy: Option<f64>,
    /// Distortion k1,k2,p1,p2,k3 (OpenCV order).
    #[arg(long, default_value = "-0.12,0.08,0.0004,-0.0003,0", value_parser = floats, allow_hyphen_values = true)]
    distortion: Floats,
}

impl CameraArgs {
    fn camera(&self) -> Result<Camera> {
        let (w, h) = self
            .size
            .split_once(['x', 'X'])
            .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
            .with_context(|| format!("--size {:?}: expected WIDTHxHEIGHT", self.size))?;
        if w < 8 || h < 8 || w > 20000 || h > 20000 {
            bail!("--size {w}x{h}: each side must be between 8 and 20000 pixels");
        }
        let d = &self.distortion;
        if d.len() != 5 {
            bail!("--distortion needs five numbers k1,k2,p1,p2,k3");
        }
        Ok(Camera {
            fx: self.fx,
            fy: self.fy.unwrap_or(self.fx),
            cx: self.cx.unwrap_or(w as f64 * 0.5 + 3.2),
            cy: self.cy.unwrap_or(h as f64 * 0.5 - 1.5),
            distortion: Distortion {
                k1: d[0],
                k2: d[1],
                p1: d[2],
                p2: d[3],
                k3: d[4],
            },
            image_size: [w, h],
        })
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum LayoutArg {
    Separate,
    Row,
}

#[derive(Clone, Copy, ValueEnum)]
enum BackdropArg {
    Black,
    Grey,
    Table,
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Png16,
    Jpeg,
}

#[derive(Args)]
struct SessionArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    out: PathBuf,
    /// Sphere radii in mm.
    #[arg(long, default_value = "35,30,25,20,15", value_parser = floats)]
    radii: Floats,
    /// One photo per sphere, or all spheres in one photo.
    #[arg(long, value_enum, default_value = "separate")]
    layout: LayoutArg,
    /// Behind the spheres: a black void, a grey card (8–22% of full scale, a gradient), or a lit
    /// matte table the spheres rest on, with their shadows, before a grey wall.
    #[arg(long, value_enum, default_value = "black")]
    backdrop: BackdropArg,
    /// Hold each sphere up on a thin matte pin under it.
    #[arg(long)]
    stand: bool,
    #[command(flatten)]
    camera: CameraArgs,
    #[command(flatten)]
    light: LightArgs,
    /// Scattering length σ0 in mm, one value or r,g,b.
    #[arg(long, default_value = "4,3,2.2", value_parser = triple)]
    sigma0: [f64; 3],
    /// Albedo, one value or r,g,b.
    #[arg(long, default_value = "0.8,0.62,0.45", value_parser = triple)]
    albedo: [f64; 3],
    /// Index of refraction.
    #[arg(long, default_value_t = 1.44)]
    eta: f64,
    /// Specular scale.
    #[arg(long, default_value_t = 1.0)]
    ks: f64,
    /// GGX roughness.
    #[arg(long, default_value_t = 0.1)]
    alpha: f64,
    /// Model extension q: σ = (σ0/r)·(25 mm/r)^q (0: the plain CDRF).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    sigma_exponent: f64,
    /// Model extension b: albedo·exp(b·(25 mm/r − 1)) (0: one albedo for all radii).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    albedo_curvature: f64,
    /// The kernel's tail weight w: (1 − w)·f(θ; σ) + w·f(θ; s·σ) (0: one Gaussian).
    #[arg(long, default_value_t = 0.0)]
    kernel_weight: f64,
    /// The kernel's tail width ratio s (> 1; used when --kernel-weight is not 0).
    #[arg(long, default_value_t = 3.0)]
    kernel_ratio: f64,
    /// Material name written into session.json.
    #[arg(long, default_value = "synthetic wax")]
    material: String,
    /// Relative exposure (1 = 1/30 s, f/8, ISO 100).
    #[arg(long, default_value_t = 1.2)]
    exposure: f64,
    /// Shot noise, standard deviation at full scale.
    #[arg(long, default_value_t = 0.01)]
    noise: f64,
    /// Read noise, standard deviation relative to full scale.
    #[arg(long, default_value_t = 5e-4)]
    read_noise: f64,
    /// Ambient floor relative to full scale.
    #[arg(long, default_value_t = 2e-3)]
    ambient: f64,
    /// Edge supersampling n (n×n samples per silhouette pixel).
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    #[arg(long, value_enum, default_value = "png16")]
    format: FormatArg,
    #[arg(long, default_value_t = 95)]
    jpeg_quality: u8,
    /// Camera-to-sphere distance in mm (default: framed automatically).
    #[arg(long)]
    distance: Option<f64>,
    /// What session.json's "intrinsics" points to; without it the true camera is written as
    /// intrinsics.json in the output folder.
    #[arg(long)]
    intrinsics_ref: Option<String>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the first image as an 8-bit sRGB PNG here, for looking at.
    #[arg(long)]
    preview: Option<PathBuf>,
}

#[derive(Args)]
struct CalibrateArgs {
    /// Folder of chessboard photos (JPEG, PNG, TIFF).
    dir: PathBuf,
    /// Inner corners COLSxROWS (default: detected).
    #[arg(long)]
    pattern: Option<String>,
    /// Square size, e.g. 25mm or 25.
    #[arg(long, default_value = "25mm")]
    square: String,
    /// Where intrinsics.json goes (default: in the folder); the OpenCV YAML goes beside it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Folder for the diagnostic plots (default: plots/ beside the output).
    #[arg(long)]
    plots: Option<PathBuf>,
    /// auto: classic everywhere, the slower sector-based detector where the classic one fails
    /// or gives a view whose error stands out; or classic, sb, both.
    #[arg(long, value_enum, default_value = "auto")]
    detector: DetectorArg,
    /// cornerSubPix half-window in px (default: a third of the corner spacing, 3 to 25).
    #[arg(long)]
    subpix_window: Option<u32>,
}

#[derive(Clone, Copy, ValueEnum)]
enum DetectorArg {
    Auto,
    Classic,
    Sb,
    Both,
}

#[derive(Args)]
struct CheckerArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    out: PathBuf,
    /// Inner corners COLSxROWS.
    #[arg(long, default_value = "9x6")]
    pattern: String,
    /// Square size in mm.
    #[arg(long, default_value_t = 25.0)]
    square: f64,
    /// White margin in mm (default: one square).
    #[arg(long)]
    margin: Option<f64>,
    #[arg(long, default_value_t = 15)]
    views: u32,
    #[command(flatten)]
    camera: CameraArgs,
    /// Blur σ in pixels.
    #[arg(long, default_value_t = 0.7)]
    blur: f64,
    #[arg(long, default_value_t = 0.01)]
    noise: f64,
    #[arg(long, default_value_t = 2e-3)]
    read_noise: f64,
    /// Brightness loss at the frame corners (0..1).
    #[arg(long, default_value_t = 0.3)]
    vignetting: f64,
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// png or jpeg.
    #[arg(long, default_value = "png")]
    format: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn synth_session(a: SessionArgs, quiet: bool) -> Result<()> {
    if !(0.0..1.0).contains(&a.kernel_weight) {
        bail!(
            "--kernel-weight must lie in [0, 1), got {}",
            a.kernel_weight
        );
    }
    if a.kernel_weight > 0.0 && !(a.kernel_ratio > 1.0 && a.kernel_ratio.is_finite()) {
        bail!(
            "--kernel-ratio must be a number above 1, got {}",
            a.kernel_ratio
        );
    }
    let cfg = SessionConfig {
        radii_mm: a.radii,
        layout: match a.layout {
            LayoutArg::Separate => Layout::Separate,
            LayoutArg::Row => Layout::Row,
        },
        backdrop: match a.backdrop {
            BackdropArg::Black => Backdrop::Black,
            BackdropArg::Grey => Backdrop::Grey,
            BackdropArg::Table => Backdrop::Table,
        },
        stand: a.stand,
        camera: a.camera.camera()?,
        light: a.light.angles(),
        material: Material {
            sigma0_mm: a.sigma0,
            albedo: a.albedo,
            eta: a.eta,
            specular: SpecularParams {
                ks: a.ks,
                alpha: a.alpha,
            },
            sigma_exponent: a.sigma_exponent,
            albedo_curvature: a.albedo_curvature,
            kernel_weight: a.kernel_weight,
            kernel_ratio: if a.kernel_weight > 0.0 {
                a.kernel_ratio
            } else {
                0.0
            },
        },
        material_name: a.material,
        exposure: a.exposure,
        noise: a.noise,
        read_noise: a.read_noise,
        ambient: a.ambient,
        supersample: a.supersample,
        format: match a.format {
            FormatArg::Png16 => Format::Png16,
            FormatArg::Jpeg => Format::Jpeg,
        },
        jpeg_quality: a.jpeg_quality,
        seed: a.seed,
        distance_mm: a.distance,
        intrinsics_ref: a.intrinsics_ref,
        ..SessionConfig::default()
    };
    let t0 = std::time::Instant::now();
    let out = session::generate(&cfg, &a.out, a.preview.as_deref(), quiet)
        .with_context(|| format!("synth session into {}", a.out.display()))?;
    println!(
        "wrote {} image(s), {} and {} in {:.2} s",
        out.images.len(),
        out.session_file.display(),
        out.truth_file.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn synth_pbr(a: PbrArgs, quiet: bool) -> Result<()> {
    let cfg = volpath::PbrConfig {
        radii_mm: a.radii,
        camera: a.camera.camera()?,
        light: a.light.angles(),
        medium: volpath::Medium {
            sigma_t: a.sigma_t,
            albedo: a.albedo,
        },
        eta: a.eta,
        alpha: a.alpha,
        spp: a.spp,
        seed: a.seed,
        distance_mm: a.distance,
        material_name: a.material,
    };
    let t0 = std::time::Instant::now();
    let out = volpath::generate(&cfg, &a.out, quiet)
        .with_context(|| format!("synth pbr into {}", a.out.display()))?;
    let noise: Vec<String> = out
        .truth
        .images
        .iter()
        .map(|p| format!("{:.1}%", 100.0 * p.noise_rel_median_lit))
        .collect();
    println!(
        "wrote {} photo(s), session.json and truth.json into {} in {:.1} s (noise per lit pixel {}; irradiance {:.4} in PNG units)",
        out.images.len(),
        a.out.display(),
        t0.elapsed().as_secs_f64(),
        noise.join(" "),
        out.truth.irradiance_in_png_units
    );
    Ok(())
}

fn synth_checkerboard(a: CheckerArgs, quiet: bool) -> Result<()> {
    let (cols, rows) = a
        .pattern
        .split_once(['x', 'X'])
        .and_then(|(c, r)| Some((c.parse::<u32>().ok()?, r.parse::<u32>().ok()?)))
        .with_context(|| {
            format!(
                "--pattern {:?}: expected COLSxROWS inner corners, e.g. 9x6",
                a.pattern
            )
        })?;
    let format = match a.format.to_ascii_lowercase().as_str() {
        "png" => BoardFormat::Png,
        "jpg" | "jpeg" => BoardFormat::Jpeg,
        other => bail!("--format {other:?}: expected png or jpeg"),
    };
    let cfg = CheckerConfig {
        inner: [cols, rows],
        square_mm: a.square,
        margin_mm: a.margin.unwrap_or(a.square),
        views: a.views,
        camera: a.camera.camera()?,
        blur_px: a.blur,
        noise: a.noise,
        read_noise: a.read_noise,
        vignetting: a.vignetting,
        supersample: a.supersample,
        format,
        seed: a.seed,
        ..CheckerConfig::default()
    };
    let t0 = std::time::Instant::now();
    let out = checkerboard::generate(&cfg, &a.out, quiet)
        .with_context(|| format!("synth checkerboard into {}", a.out.display()))?;
    println!(
        "wrote {} view(s) and {} in {:.2} s",
        out.images.len(),
        out.truth_file.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

#[cfg(feature = "opencv")]
fn calibrate(a: CalibrateArgs, quiet: bool) -> Result<()> {
    use workbench::calibration::{run, Pattern};
    let pattern = match &a.pattern {
        Some(p) => Some(Pattern::parse(p).with_context(|| {
            format!("--pattern {p:?}: expected COLSxROWS inner corners, at least 2x2, e.g. 9x6")
        })?),
        None => None,
    };
    let sq = a.square.trim().trim_end_matches("mm").trim();
    let square_mm: f64 = sq
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v > 0.0)
        .with_context(|| {
            format!(
                "--square {:?}: expected a positive size in mm, e.g. 25mm",
                a.square
            )
        })?;
    workbench::cv::set_threads(1);
    use workbench::calibration::DetectorChoice;
    let detector = match a.detector {
        DetectorArg::Auto => DetectorChoice::Auto,
        DetectorArg::Classic => DetectorChoice::Classic,
        DetectorArg::Sb => DetectorChoice::SectorBased,
        DetectorArg::Both => DetectorChoice::Both,
    };
    let opts = run::Options {
        dir: a.dir.clone(),
        pattern,
        square_mm,
        out: a.out,
        plots: a.plots,
        detector,
        subpix_window: a.subpix_window,
        quiet,
    };
    let r = run::run(&opts, &workbench::cv::OpenCvDetect, &workbench::cv::OpenCv)?;
    let c = &r.calibration;
    let cam = &c.camera;
    println!(
        "pattern  {} inner corners, {square_mm} mm squares",
        r.pattern
    );
    println!(
        "views    {} used, {} rejected as outliers, {} unusable, of {} image(s) read",
        c.used.len(),
        c.rejected.len(),
        r.unusable.len(),
        r.images_read
    );
    for (f, why) in &r.unusable {
        println!("         {f}: {why}");
    }
    for n in &c.notes {
        println!("note     {n}");
    }
    let sd = c.std.unwrap_or_default();
    println!("model    {}", c.model.name());
    println!("fx       {:10.3} ± {:.3} px", cam.fx, sd.fx);
    println!("fy       {:10.3} ± {:.3} px", cam.fy, sd.fy);
    println!("cx       {:10.3} ± {:.3} px", cam.cx, sd.cx);
    println!("cy       {:10.3} ± {:.3} px", cam.cy, sd.cy);
    let d = cam.distortion;
    let e = sd.distortion;
    println!(
        "k1 k2    {:+.5} ± {:.5}   {:+.5} ± {:.5}",
        d.k1, e.k1, d.k2, e.k2
    );
    println!(
        "p1 p2 k3 {:+.6} ± {:.6}   {:+.6} ± {:.6}   {:+.5} ± {:.5}",
        d.p1, e.p1, d.p2, e.p2, d.k3, e.k3
    );
    println!("RMS      {:.4} px over the used views", c.rms_px);
    if let Some(cv) = c.cross_validation.iter().find(|v| v.model == c.model) {
        let j = cv.jackknife_std;
        println!(
            "cross-validation ({}-fold): held-out RMS {:.4} px; jackknife std fx {:.2} fy {:.2} cx {:.2} cy {:.2} px",
            cv.folds, cv.heldout_rms_px, j[0], j[1], j[2], j[3]
        );
    }
    for n in r.exif_notes.iter().filter(|n| !n.starts_with("warning: ")) {
        println!("exif     {n}");
    }
    for w in &c.warnings {
        println!("warning  {w}");
    }
    println!(
        "wrote    {} and {}",
        r.intrinsics_file.display(),
        r.yaml_file.display()
    );
    if let Some(dir) = r.plot_files.first().and_then(|p| p.parent()) {
        println!("plots    {} ({} files)", dir.display(), r.plot_files.len());
    }
    println!(
        "time     detection {:.2} s, calibration {:.2} s",
        r.detection_s, r.calibration_s
    );
    Ok(())
}

fn detect(a: DetectArgs, quiet: bool) -> Result<()> {
    use workbench::detect::{self, Options};
    let opts = Options {
        session: a.session.clone(),
        out: a.out.clone(),
        overlays: !a.no_overlays,
        quiet,
    };
    let d = detect::run(&opts)?;
    println!("session  {} ({} camera)", d.session, d.projection);
    let deg = |v: &[f64; 3]| {
        let l = workbench::model::LightAngles::from_direction(&nalgebra::Vector3::from(*v));
        format!(
            "[{:+.4}, {:+.4}, {:+.4}] (az {:.2}°, el {:.2}°)",
            v[0],
            v[1],
            v[2],
            l.azimuth.to_degrees(),
            l.elevation.to_degrees()
        )
    };
    for im in &d.images {
        for n in &im.exif_notes {
            println!("exif     {:<12} {n}", im.file);
        }
        for (k, s) in im.spheres.iter().enumerate() {
            let light = match (&s.light_direction, &s.highlight, &s.no_highlight) {
                (Some(l), Some(h), _) => format!(
                    "light {} ± {:.3}°{}{}",
                    deg(l),
                    s.light_std_deg.unwrap_or(f64::NAN),
                    match h.method {
                        workbench::highlight::Method::LobeFit => " (lobe fit)",
                        workbench::highlight::Method::Centroid => " (centroid)",
                    },
                    if h.outlier { " OUTLIER" } else { "" }
                ),
                (_, _, Some(why)) => format!("no highlight: {why}"),
                _ => "no highlight".into(),
            };
            let e = &s.ellipse;
            println!(
                "image    {:<12} #{} r {} mm: centre ({:.2}, {:.2}) px, axes {:.2}×{:.2} px ± {:.3} px; {light}",
                im.file,
                k + 1,
                s.radius_mm,
                e.center_px[0],
                e.center_px[1],
                e.axes_px[0],
                e.axes_px[1],
                s.silhouette_std_px[2],
            );
        }
        if d.light_direction.is_none() {
            if let Some(l) = &im.light_direction {
                println!(
                    "light    {:<12} {} ± {:.3}°",
                    im.file,
                    deg(l),
                    im.light_std_deg.unwrap_or(f64::NAN)
                );
            }
        }
    }
    match (&d.light_direction, d.light) {
        (Some(l), _) => println!(
            "light    session {} ± {:.3}°",
            deg(l),
            d.light_std_deg.unwrap_or(f64::NAN)
        ),
        (None, workbench::session::LightMode::Shared) => {
            println!("light    none: no usable highlight on any sphere")
        }
        (None, workbench::session::LightMode::PerImage) => {}
    }
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&d.session).with_file_name("detections.json"));
    println!("wrote    {} in {:.2} s", out.display(), d.seconds);
    Ok(())
}

fn solve(a: SolveArgs, quiet: bool) -> Result<()> {
    use workbench::solve::{self, Method, Options};
    let _ = a.joint;
    let mut o = Options::new(&a.session);
    o.out = a.out.clone();
    o.method = match a.method {
        MethodArg::Joint => Method::Joint,
        MethodArg::Paper => Method::Paper,
    };
    o.holdout = a.holdout;
    if let Some(p) = a.prior {
        o.eta_prior = p;
    }
    if let Some(e) = a.irradiance {
        if !(e.is_finite() && e > 0.0) {
            bail!("--irradiance must be a positive number, got {e}");
        }
        o.irradiance = Some(e);
    }
    o.reduction = a.reduce;
    o.robust = !a.no_robust;
    o.extensions = a.extensions;
    if let Some(s) = a.start_sigma0 {
        if s.iter().any(|v| v.is_nan() || *v <= 0.0) {
            bail!("--start-sigma0 must be positive");
        }
    }
    o.start_sigma0 = a.start_sigma0;
    o.start_light = a.start_light.map(|[az, el]| LightAngles {
        azimuth: az.to_radians(),
        elevation: el.to_radians(),
    });
    o.redetect = a.redetect;
    o.light_fit = if a.hold_light {
        workbench::joint::LightFit::Hold
    } else if a.free_light {
        workbench::joint::LightFit::Free
    } else {
        workbench::joint::LightFit::Prior
    };
    o.jackknife = !a.no_jackknife;
    o.entry_transmission = a.entry_transmission;
    o.plots = a.plots.clone();
    o.baseline = a.baseline;
    o.quiet = quiet;
    let f = solve::run(&o).with_context(|| format!("solve {}", a.session.display()))?;
    print!("{}", solve::summary(&f));
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&f.session).with_file_name("fit.json"));
    println!("wrote    {}", out.display());
    if let Some(d) = &a.plots {
        println!(
            "figures  {} (open {})",
            d.display(),
            d.join("index.html").display()
        );
    }
    if !f.convergence.converged {
        eprintln!(
            "error: the fit did not converge (see convergence in {})",
            out.display()
        );
        std::process::exit(3);
    }
    Ok(())
}

fn bench(a: BenchArgs, quiet: bool) -> Result<()> {
    use workbench::bench;
    let out = a.out.unwrap_or_else(bench::default_out);
    let r = bench::run(&bench::BenchOptions {
        out: out.clone(),
        quick: a.quick,
        quiet,
    })
    .with_context(|| format!("bench into {}", out.display()))?;
    print!("{}", bench::markdown(&r));
    println!("wrote    {}", out.join("report.md").display());
    Ok(())
}

/// `name` in the folder of `file`.
fn beside(file: &std::path::Path, name: &str) -> PathBuf {
    file.parent()
        .unwrap_or(std::path::Path::new("."))
        .join(name)
}

fn plot(a: PlotArgs, quiet: bool) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "plots"));
    let files = workbench::fitplot::replot(&a.fit, &out, quiet)
        .with_context(|| format!("plot {}", a.fit.display()))?;
    println!("figures  {} ({} files)", out.display(), files.len());
    println!("index    {}", out.join("index.html").display());
    Ok(())
}

fn lut(a: LutArgs) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "lut"));
    let (t, fm, paths) = workbench::render_job::write_lut(
        &a.fit,
        &out,
        table_size(a.size, a.tolerance),
        a.kappa_max,
    )
    .with_context(|| format!("lut {}", a.fit.display()))?;
    for ((nc, nk), e) in &t.tried {
        println!(
            "size     {nc}x{nk}: largest interpolation error {:.2e} of the peak",
            e
        );
    }
    let e = &t.error;
    println!(
        "table    {}x{} nodes, N·L -1..1, curvature 0..{:.4}/mm (fit measured {:.4}..{:.4}/mm)",
        t.lut.n_cos, t.lut.n_kappa, t.lut.kappa_max, fm.measured_kappa[0], fm.measured_kappa[1]
    );
    println!(
        "error    largest {:.2e} ({:.2e} of the peak {:.4}) at N·L {:.3}, curvature {:.4}/mm; rms {:.2e}",
        e.max_abs,
        e.max_rel,
        t.lut.peak(),
        e.at_cos,
        e.at_kappa_per_mm,
        e.rms
    );
    for p in &paths {
        println!("wrote    {}", p.display());
    }
    Ok(())
}

fn render(a: RenderArgs) -> Result<()> {
    let table = table_size(a.table, workbench::lut::DEFAULT_TOLERANCE);
    if a.check {
        let dir = a
            .out
            .clone()
            .unwrap_or_else(|| beside(&a.fit, "render-check"));
        let res = workbench::render_job::check(&a.fit, &dir, table)
            .with_context(|| format!("render --check {}", a.fit.display()))?;
        println!("sphere               radius  pixels  silhouette  rel. RMS   largest");
        for c in &res {
            println!(
                "{:<16} {:>2}  {:>5.1}  {:>6}  {:>10}  {:>8.2e}  {:>8.2e}",
                c.image, c.index, c.radius_mm, c.pixels, c.silhouette_px, c.rel_rmse, c.max_rel
            );
        }
        println!("wrote    {}", dir.join("sphere-check.json").display());
        return Ok(());
    }
    let (Some(mesh), Some(out)) = (a.mesh.clone(), a.out.clone()) else {
        bail!("a mesh and --out are needed without --check");
    };
    let mut o = workbench::render_job::RenderOptions::new(&mesh, &a.fit, &out);
    o.unit = a.unit;
    o.object_size_mm = a.object_size;
    o.light_deg = a.light;
    o.view = workbench::render::View {
        azimuth_deg: a.view.0,
        elevation_deg: a.view.1,
        distance: a.distance,
    };
    (o.width, o.height) = a.resolution;
    o.fov_deg = a.fov;
    o.samples = a.samples;
    o.shading = a.shading;
    o.bits = a.bits;
    o.tone = a.tone;
    o.exposure = a.exposure;
    o.table = table;
    let r = workbench::render_job::run(&o).with_context(|| format!("render {}", mesh.display()))?;
    println!(
        "mesh     {} vertices, {} triangles, {:.1} mm across",
        r.vertices,
        r.triangles,
        2.0 * r.radius_mm
    );
    println!(
        "curvature 5/50/95%: {:.4} {:.4} {:.4} /mm; {:.1}% of vertices beyond the table's range (clamped)",
        r.curvature[0],
        r.curvature[1],
        r.curvature[2],
        100.0 * r.clamped
    );
    println!(
        "table    {}x{} (largest error {:.2e} of the peak); light azimuth {:.1}°, elevation {:.1}°",
        r.table.0,
        r.table.1,
        r.table_error,
        r.light.azimuth.to_degrees(),
        r.light.elevation.to_degrees()
    );
    println!(
        "time     load {:.3} s, curvature {:.3} s, table {:.3} s, frame {:.1} ms, write {:.3} s",
        r.load_s,
        r.curvature_s,
        r.table_s,
        1e3 * r.frame_s,
        r.write_s
    );
    println!("wrote    {}", out.display());
    Ok(())
}

fn check(session: PathBuf) -> Result<()> {
    let r = workbench::session::inspect(&session)?;
    println!("session  {}", r.session_file.display());
    if let Some(m) = &r.material {
        println!("material {m}");
    }
    match (&r.intrinsics_file, &r.camera) {
        (Some(f), Some(c)) => println!(
            "camera   {} — {}×{}, fx {:.1} fy {:.1} cx {:.1} cy {:.1}, k1 {:+.4} k2 {:+.4}",
            f.display(),
            c.image_size[0],
            c.image_size[1],
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            c.distortion.k1,
            c.distortion.k2
        ),
        _ => println!("camera   none given: orthographic"),
    }
    for im in &r.images {
        let exposure = match (im.exposure, im.exposure_source) {
            (Some(e), Some(src)) => format!("exposure {e:.4} ({src})"),
            _ => "exposure unknown".into(),
        };
        let radii: Vec<String> = im.radii_mm.iter().map(|r| format!("{r}")).collect();
        println!(
            "image    {:<12} {}×{} {}-bit {} {}, {exposure}, spheres {} mm",
            im.file,
            im.width,
            im.height,
            im.bits,
            if im.channels >= 3 { "RGB" } else { "grey" },
            if im.linear { "linear" } else { "sRGB" },
            radii.join(" ")
        );
        for n in &im.exif_notes {
            println!("exif     {:<12} {n}", im.file);
        }
    }
    let radii: std::collections::BTreeSet<String> = r
        .images
        .iter()
        .flat_map(|i| i.radii_mm.iter().map(|r| format!("{r}")))
        .collect();
    println!(
        "ok: {} image(s), {} distinct radii",
        r.images.len(),
        radii.len()
    );
    Ok(())
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // --help, --version, and no subcommand at all: clap's full text.
        Err(e)
            if !e.use_stderr()
                || e.kind() == clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand =>
        {
            e.exit()
        }
        Err(e) => {
            // One line: clap's message (its lines joined) without its usage block and hints.
            let text = e.render().to_string();
            let message: Vec<&str> = text
                .lines()
                .take_while(|l| !l.starts_with("Usage:") && !l.trim_start().starts_with("tip:"))
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .collect();
            if message.is_empty() {
                eprintln!("error: bad arguments");
            } else {
                eprintln!("{}", message.join(" "));
            }
            std::process::exit(2);
        }
    };
    let res = match cli.command {
        Command::Synth(Synth::Session(a)) => synth_session(a, cli.quiet),
        Command::Synth(Synth::Checkerboard(a)) => synth_checkerboard(a, cli.quiet),
        Command::Synth(Synth::Pbr(a)) => synth_pbr(a, cli.quiet),
        Command::Detect(a) => detect(a, cli.quiet),
        Command::Solve(a) => solve(a, cli.quiet),
        Command::Plot(a) => plot(a, cli.quiet),
        Command::Bench(a) => bench(a, cli.quiet),
        Command::Lut(a) => lut(a),
        Command::Render(a) => render(a),
        Command::Check { session } => check(session),
        #[cfg(feature = "opencv")]
        Command::Calibrate(a) => calibrate(a, cli.quiet),
    };
    if let Err(e) = res {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
