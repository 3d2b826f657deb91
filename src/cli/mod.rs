//! The command line's words: every subcommand's arguments as clap structs, with their
//! documentation (what `--help` prints) and defaults.

pub(crate) mod parse;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use parse::*;

pub(crate) mod signals;
use std::path::PathBuf;
use workbench::camera::{Camera, Distortion};
use workbench::model::LightAngles;

#[derive(Parser)]
#[command(
    name = "workbench",
    version,
    about = "Measure the curvature-dependent reflectance of translucent materials"
)]
pub(crate) struct Cli {
    /// No progress bars.
    #[arg(long, global = true)]
    pub(crate) quiet: bool,
    #[command(subcommand)]
    pub(crate) command: Command,
}

// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub(crate) enum Command {
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
    /// A static page that shows a fit's material in the browser (WebGL2): a sphere row and a mesh.
    View(ViewArgs),
    /// Write a fit's measured medium (`solve` with the irradiance known, or `--model medium`) for
    /// Mitsuba, pbrt, Blender or Unreal.
    Export(ExportArgs),
    /// Path-trace a fit's measured medium back into every sphere and compare it with the photos,
    /// beside the medium model and the CDRF (closing the loop).
    CloseLoop(CloseLoopArgs),
    /// Check a session folder against its files: images, sizes, intrinsics, exposures.
    Check {
        /// The session folder (or its session.json).
        session: PathBuf,
    },
}

#[derive(Args)]
pub(crate) struct DetectArgs {
    /// The session folder (or its session.json).
    pub(crate) session: PathBuf,
    /// Where to write detections.json (default: beside session.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Do not write the overlay pictures (overlays/<photo>.png beside detections.json).
    #[arg(long)]
    pub(crate) no_overlays: bool,
    /// The model the detections are for (`solve --model`): `medium` also draws each outline for
    /// the medium (the rim weighed by its contrast too), which the medium fit needs; `auto` does
    /// where session.json names a diffuse reference (`solve`'s auto then fits the medium); the
    /// outlines every model uses are the same either way.
    #[arg(long, value_enum, default_value_t = ModelArg::Auto)]
    pub(crate) model: ModelArg,
}

#[derive(Args)]
pub(crate) struct SolveArgs {
    /// The session folder (or its session.json).
    pub(crate) session: PathBuf,
    /// One fit across all radii (the default method).
    #[arg(long, conflicts_with = "method")]
    pub(crate) joint: bool,
    /// joint: everything at once; paper: the source paper's per-radius baseline.
    #[arg(long, value_enum, default_value_t = MethodArg::Joint)]
    pub(crate) method: MethodArg,
    /// Where to write fit.json (default: beside session.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// The model: the CDRF alone, or then the medium (σa, σs′, η per channel) from its light;
    /// auto: the medium where the light's irradiance is known (--irradiance, or a reference in
    /// session.json), the CDRF alone otherwise.
    #[arg(long, value_enum, default_value_t = ModelArg::Auto)]
    pub(crate) model: ModelArg,
    /// Fit without the spheres of this radius (mm), then report how well the fit predicts them.
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) holdout: Option<f64>,
    /// Prior on a parameter, NAME=MEAN:STD; only eta (default eta=1.45:0.05).
    #[arg(long, value_parser = parse_prior)]
    pub(crate) prior: Option<(f64, f64)>,
    /// The light's irradiance in the photos' radiance units (pixel value / exposure): makes the
    /// specular scale known (ks = E), so η is fitted instead of held at its prior.
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) irradiance: Option<f64>,
    /// Pixel reduction: auto (the coarsest cells whose predicted parameter shift stays below 0.3
    /// standard errors), none (every pixel), or a cell width in degrees: 0.25, 0.5, 1, 2, 4.
    #[arg(long, default_value = "auto", value_parser = parse_reduce)]
    pub(crate) reduce: workbench::fit::joint::Reduction,
    /// Plain least squares instead of the Huber loss.
    #[arg(long)]
    pub(crate) no_robust: bool,
    /// Model extensions: default (albedo-curvature with 3 or more radii, none otherwise), none,
    /// auto (chosen by held-out error; needs 4 or more radii), or any of sigma-exponent,
    /// albedo-curvature, two-gaussian (comma-separated; both = the first two).
    #[arg(long, default_value = "default", value_parser = parse_extensions)]
    pub(crate) extensions: workbench::fit::joint::ExtensionChoice,
    /// Start σ0 (mm), one value or r,g,b, instead of the search over the data.
    #[arg(long, value_parser = triple)]
    pub(crate) start_sigma0: Option<[f64; 3]>,
    /// Start light as azimuth,elevation in degrees, instead of the detector's.
    #[arg(long, value_parser = angles, allow_hyphen_values = true)]
    pub(crate) start_light: Option<[f64; 2]>,
    /// Run detection even when detections.json records inputs of the same content.
    #[arg(long)]
    pub(crate) redetect: bool,
    /// Keep the light at the detector's estimate (or --start-light) instead of refining it.
    #[arg(long, conflicts_with = "free_light")]
    pub(crate) hold_light: bool,
    /// How the leave-one-radius-out jackknife's estimates are taken: Newton steps from the full
    /// fit (linear, one pass over the observations), the fit repeated without each radius
    /// (refit, the check of the linear one), or none (off: the standard errors are the formal
    /// ones).
    #[arg(long, value_enum, default_value_t = JackknifeArg::Linear)]
    pub(crate) jackknife: JackknifeArg,
    /// The same as --jackknife off.
    #[arg(long, conflicts_with = "jackknife")]
    pub(crate) no_jackknife: bool,
    /// Refine the light from the shading alone, without the detector's light as a prior (the
    /// default uses it as one).
    #[arg(long)]
    pub(crate) free_light: bool,
    /// Blur the irradiance that enters the medium, max(cos θ, 0)·T(cos θ; η), instead of the
    /// bare clamped cosine (entry-side Fresnel transmission; about 4× the solve time).
    #[arg(long)]
    pub(crate) entry_transmission: bool,
    /// Write figures (PNG and SVG) and index.html into this folder; runs --baseline too.
    #[arg(long)]
    pub(crate) plots: Option<PathBuf>,
    /// Also run the paper's baseline beside the joint fit (written to fit.json as "baseline").
    #[arg(long)]
    pub(crate) baseline: bool,
}

#[derive(Args)]
pub(crate) struct BenchArgs {
    /// Two small sessions and a small checkerboard set (a few minutes) instead of the full run.
    #[arg(long)]
    pub(crate) quick: bool,
    /// Folder for the sessions and the report (default: bench-report/).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct PlotArgs {
    /// The fit (fit.json written by `workbench solve`).
    pub(crate) fit: PathBuf,
    /// Folder for the figures (default: plots/ beside fit.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct LutArgs {
    /// The fit (fit.json written by `workbench solve`).
    pub(crate) fit: PathBuf,
    /// Output stem: writes <out>.png, <out>.exr and <out>.json (default: lut beside fit.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Table nodes as N_COSxN_KAPPA (e.g. 257x129), or "auto": the smallest standard size within
    /// --tolerance.
    #[arg(long, default_value = "auto", value_parser = parse_table_size)]
    pub(crate) size: TableArg,
    /// Largest interpolation error allowed by --size auto, as a fraction of the table's peak.
    #[arg(long, default_value_t = workbench::render::lut::DEFAULT_TOLERANCE)]
    pub(crate) tolerance: f64,
    /// Curvature of the table's last row (1/mm; default 3 / the smallest radius fitted).
    #[arg(long)]
    pub(crate) kappa_max: Option<f64>,
    /// An engine's layout: texel-centred axes, its curvature unit and texture origin, one texture
    /// and a sidecar (<out>.exr|png and <out>.json; default stem lut-<preset> beside fit.json).
    #[arg(long, value_enum)]
    pub(crate) preset: Option<PresetArg>,
    /// The preset's texture: exr (half float, linear), png16 (linear), png8-srgb (8-bit sRGB).
    #[arg(long, value_enum, default_value = "exr", requires = "preset")]
    pub(crate) format: TextureArg,
    /// With --preset: a mesh (.obj or .ply) written beside the table as binary glTF (metres) with
    /// workbench's per-vertex curvature in the preset's unit (attribute _CDRF_KAPPA, v in COLOR_0).
    #[arg(long, requires = "preset")]
    pub(crate) mesh: Option<PathBuf>,
    /// Units of the mesh file's coordinates.
    #[arg(long, value_enum, default_value = "mm", requires = "mesh")]
    pub(crate) unit: workbench::render::mesh::Unit,
    /// Rescale the mesh so its bounding sphere is this many mm across.
    #[arg(long, requires = "mesh")]
    pub(crate) object_size: Option<f64>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum JackknifeArg {
    Linear,
    Refit,
    Off,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum PresetArg {
    Unity,
    Unreal,
    Godot,
    Blender,
    Generic,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum TextureArg {
    Exr,
    Png16,
    Png8Srgb,
}

#[derive(Args)]
pub(crate) struct ExportArgs {
    /// fit.json with a "medium" (`solve` with the irradiance known, or `--model medium`).
    pub(crate) fit: PathBuf,
    /// The renderers, comma-separated: mitsuba, pbrt, blender, unreal.
    #[arg(long, value_delimiter = ',', required = true)]
    pub(crate) to: Vec<ExportTarget>,
    /// The folder the files go into (default: `export/` beside fit.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct CloseLoopArgs {
    /// fit.json with a "medium" (`solve` with the irradiance known, or `--model medium`).
    pub(crate) fit: PathBuf,
    /// The folder close-loop.json and its figure go into (default: `close-loop/` beside fit.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Samples per pixel; the render's own noise is taken out of its error.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(2..=1_000_000))]
    pub(crate) spp: u32,
    /// Pixels rendered per sphere at most (every k-th of the medium fit's pixels beyond it).
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    pub(crate) pixels: u64,
    /// The render's random seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
}

/// `export --to`.
#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ExportTarget {
    Mitsuba,
    Pbrt,
    Blender,
    Unreal,
}

#[derive(Args)]
pub(crate) struct ViewArgs {
    /// The fit (fit.json written by `workbench solve`).
    pub(crate) fit: PathBuf,
    /// A mesh (.obj or .ply) to show beside the sphere row.
    #[arg(long)]
    pub(crate) mesh: Option<PathBuf>,
    /// Folder for the page (default: view/ beside fit.json; its files are replaced).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
}

/// How a mesh is scaled and seen (`render`, and where `view` starts).
#[derive(Args)]
pub(crate) struct SceneArgs {
    /// Units of the mesh file's coordinates.
    #[arg(long, value_enum, default_value = "mm")]
    pub(crate) unit: workbench::render::mesh::Unit,
    /// Rescale the mesh so its bounding sphere is this many mm across.
    #[arg(long)]
    pub(crate) object_size: Option<f64>,
    /// Light as AZIMUTH,ELEVATION degrees in the camera frame (0,0: at the camera; azimuth to the
    /// right, elevation up). Default: the fit's light.
    #[arg(long, value_parser = angles, allow_hyphen_values = true)]
    pub(crate) light: Option<[f64; 2]>,
    /// Camera position around the mesh as AZIMUTH,ELEVATION degrees (mesh y up; 0,0 looks along −z).
    #[arg(long, value_parser = angles, default_value = "0,0", allow_hyphen_values = true)]
    pub(crate) view: [f64; 2],
    /// Camera distance relative to the tightest framing of the mesh's bounding sphere.
    #[arg(long, default_value_t = 1.05)]
    pub(crate) distance: f64,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub(crate) fov: f64,
}

impl SceneArgs {
    pub(crate) fn view(&self) -> workbench::render::raster::View {
        workbench::render::raster::View {
            azimuth_deg: self.view[0],
            elevation_deg: self.view[1],
            distance: self.distance,
        }
    }
}

#[derive(Args)]
pub(crate) struct RenderArgs {
    /// The mesh (.obj or .ply); not with --check.
    #[arg(required_unless_present = "check")]
    pub(crate) mesh: Option<PathBuf>,
    /// The fit (fit.json written by `workbench solve`).
    #[arg(long)]
    pub(crate) fit: PathBuf,
    /// The image to write (.png); with --check, a folder (default: render-check/ beside fit.json).
    #[arg(long, required_unless_present = "check")]
    pub(crate) out: Option<PathBuf>,
    /// Render every sphere of the fit's session as an ideal sphere mesh and compare it with the
    /// solver's predicted image.
    #[arg(long, conflicts_with = "mesh")]
    pub(crate) check: bool,
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_resolution)]
    pub(crate) resolution: (u32, u32),
    /// Coverage samples per pixel (anti-aliasing).
    #[arg(long, value_enum, default_value = "4")]
    pub(crate) samples: workbench::render::raster::Samples,
    /// cdrf: the measured CDRF; lambert: the same material with a plain clamped cosine.
    #[arg(long, value_enum, default_value = "cdrf")]
    pub(crate) shading: workbench::render::raster::Shading,
    /// Bits per channel of the PNG (8 or 16).
    #[arg(long, default_value_t = 8)]
    pub(crate) bits: u8,
    /// Transfer curve.
    #[arg(long, value_enum, default_value = "srgb")]
    pub(crate) tone: workbench::render::raster::Tone,
    /// Exposure multiplier (1: a flat surface facing the light at 0.8 of full scale).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) exposure: f64,
    /// Table nodes (N_COSxN_KAPPA or auto), as for `workbench lut`.
    #[arg(long, default_value = "auto", value_parser = parse_table_size)]
    pub(crate) table: TableArg,
}

pub(crate) fn table_size(size: TableArg, tolerance: f64) -> workbench::render::job::TableSize {
    match size.0 {
        Some((a, b)) => workbench::render::job::TableSize::Fixed(a, b),
        None => workbench::render::job::TableSize::Auto(tolerance),
    }
}

/// `solve --model`, `detect --model`.
#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ModelArg {
    /// The CDRF alone.
    Cdrf,
    /// The CDRF, then σa, σs′ and η per channel by diffusion in each sphere from its light, η
    /// and lobe (fit.json's "medium"; docs/medium.md).
    Medium,
    /// The medium where the light's irradiance is known (`--irradiance`, or a diffuse reference
    /// in session.json) and the method is joint, the CDRF alone otherwise (docs/medium.md,
    /// "Which model is the default").
    Auto,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum MethodArg {
    Joint,
    Paper,
}

#[derive(Subcommand)]
pub(crate) enum Synth {
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
pub(crate) struct LightArgs {
    /// Light azimuth in degrees (0 = from the camera, positive = from the right).
    #[arg(long, default_value_t = 70.0, allow_hyphen_values = true, value_parser = azimuth_arg)]
    pub(crate) light_azimuth: f64,
    /// Light elevation in degrees (positive = from above).
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true, value_parser = elevation_arg)]
    pub(crate) light_elevation: f64,
}

impl LightArgs {
    pub(crate) fn angles(&self) -> LightAngles {
        LightAngles {
            azimuth: self.light_azimuth.to_radians(),
            elevation: self.light_elevation.to_radians(),
        }
    }
}

#[derive(Args)]
pub(crate) struct PbrArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Sphere radii in mm (one photo each, every sphere at the same place).
    #[arg(long, default_value = "35,30,25,20,15", value_parser = floats)]
    pub(crate) radii: Floats,
    #[command(flatten)]
    pub(crate) camera: CameraArgs,
    #[command(flatten)]
    pub(crate) light: LightArgs,
    /// Extinction coefficient σt of the medium, 1/mm (one for all channels).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) sigma_t: f64,
    /// Single-scattering albedo σs/σt, one value or r,g,b (each below 1).
    #[arg(long, default_value = "0.99,0.985,0.97", value_parser = triple)]
    pub(crate) albedo: [f64; 3],
    /// Index of refraction of the boundary.
    #[arg(long, default_value_t = 1.44)]
    pub(crate) eta: f64,
    /// GGX roughness of the boundary.
    #[arg(long, default_value_t = 0.1)]
    pub(crate) alpha: f64,
    /// Samples per pixel (split into two half renders for the noise estimate).
    #[arg(long, default_value_t = 2048)]
    pub(crate) spp: u32,
    /// Camera-to-sphere distance in mm.
    #[arg(long, default_value_t = 500.0)]
    pub(crate) distance: f64,
    /// Material name written into session.json.
    #[arg(long, default_value = "wax-like")]
    pub(crate) material: String,
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
}

#[derive(Args, Clone)]
pub(crate) struct CameraArgs {
    /// Image size WxH.
    #[arg(long, default_value = "1280x960")]
    pub(crate) size: String,
    #[arg(long, default_value_t = 1400.0)]
    pub(crate) fx: f64,
    /// Defaults to fx.
    #[arg(long)]
    pub(crate) fy: Option<f64>,
    /// Defaults to the image centre plus a small offset (643.2 for 1280 wide).
    #[arg(long)]
    pub(crate) cx: Option<f64>,
    #[arg(long)]
    pub(crate) cy: Option<f64>,
    /// Distortion k1,k2,p1,p2,k3 (OpenCV order).
    #[arg(long, default_value = "-0.12,0.08,0.0004,-0.0003,0", value_parser = floats, allow_hyphen_values = true)]
    pub(crate) distortion: Floats,
}

impl CameraArgs {
    pub(crate) fn camera(&self) -> Result<Camera> {
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
pub(crate) enum LayoutArg {
    Separate,
    Row,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum BackdropArg {
    Black,
    Grey,
    Table,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum FormatArg {
    Png16,
    Jpeg,
}

#[derive(Args)]
pub(crate) struct SessionArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Sphere radii in mm.
    #[arg(long, default_value = "35,30,25,20,15", value_parser = floats)]
    pub(crate) radii: Floats,
    /// One photo per sphere, or all spheres in one photo.
    #[arg(long, value_enum, default_value = "separate")]
    pub(crate) layout: LayoutArg,
    /// Behind the spheres: a black void, a grey card (8–22% of full scale, a gradient), or a lit
    /// matte table the spheres rest on, with their shadows, before a grey wall.
    #[arg(long, value_enum, default_value = "black")]
    pub(crate) backdrop: BackdropArg,
    /// Hold each sphere up on a thin matte pin under it.
    #[arg(long)]
    pub(crate) stand: bool,
    /// The pin's radius in mm (with --stand).
    #[arg(long, default_value_t = workbench::synth::session::PIN_RADIUS_MM, requires = "stand")]
    pub(crate) stand_radius: f64,
    /// The pin at a constant value (fraction of full scale) instead of lit by the session's light
    /// (with --stand).
    #[arg(long, requires = "stand")]
    pub(crate) stand_level: Option<f64>,
    /// A pin under every n-th sphere of --radii, starting with the first (with --stand).
    #[arg(long, default_value_t = 1, requires = "stand")]
    pub(crate) stand_every: usize,
    /// How far in mm the pin reaches up in front of the sphere's lower rim, hiding it (0: behind
    /// the rim; with --stand).
    #[arg(long, default_value_t = 0.0, requires = "stand")]
    pub(crate) stand_contact: f64,
    #[command(flatten)]
    pub(crate) camera: CameraArgs,
    #[command(flatten)]
    pub(crate) light: LightArgs,
    /// Scattering length σ0 in mm, one value or r,g,b.
    #[arg(long, default_value = "4,3,2.2", value_parser = triple)]
    pub(crate) sigma0: [f64; 3],
    /// Albedo, one value or r,g,b.
    #[arg(long, default_value = "0.8,0.62,0.45", value_parser = triple)]
    pub(crate) albedo: [f64; 3],
    /// Index of refraction.
    #[arg(long, default_value_t = 1.44)]
    pub(crate) eta: f64,
    /// Specular scale.
    #[arg(long, default_value_t = 1.0)]
    pub(crate) ks: f64,
    /// GGX roughness.
    #[arg(long, default_value_t = 0.1)]
    pub(crate) alpha: f64,
    /// Model extension q: σ = (σ0/r)·(25 mm/r)^q (0: the plain CDRF).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub(crate) sigma_exponent: f64,
    /// Model extension b: albedo·exp(b·(25 mm/r − 1)) (0: one albedo for all radii).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub(crate) albedo_curvature: f64,
    /// The kernel's tail weight w: (1 − w)·f(θ; σ) + w·f(θ; s·σ) (0: one Gaussian).
    #[arg(long, default_value_t = 0.0)]
    pub(crate) kernel_weight: f64,
    /// The kernel's tail width ratio s (> 1; used when --kernel-weight is not 0).
    #[arg(long, default_value_t = 3.0)]
    pub(crate) kernel_ratio: f64,
    /// Material name written into session.json.
    #[arg(long, default_value = "synthetic wax")]
    pub(crate) material: String,
    /// Relative exposure (1 = 1/30 s, f/8, ISO 100).
    #[arg(long, default_value_t = 1.2)]
    pub(crate) exposure: f64,
    /// Shot noise, standard deviation at full scale.
    #[arg(long, default_value_t = 0.01)]
    pub(crate) noise: f64,
    /// Read noise, standard deviation relative to full scale.
    #[arg(long, default_value_t = 5e-4)]
    pub(crate) read_noise: f64,
    /// Ambient floor relative to full scale.
    #[arg(long, default_value_t = 2e-3)]
    pub(crate) ambient: f64,
    /// Edge supersampling n (n×n samples per silhouette pixel).
    #[arg(long, default_value_t = 4)]
    pub(crate) supersample: u32,
    #[arg(long, value_enum, default_value = "png16")]
    pub(crate) format: FormatArg,
    #[arg(long, default_value_t = 95)]
    pub(crate) jpeg_quality: u8,
    /// Camera-to-sphere distance in mm (default: framed automatically).
    #[arg(long)]
    pub(crate) distance: Option<f64>,
    /// What session.json's "intrinsics" points to; without it the true camera is written as
    /// intrinsics.json in the output folder.
    #[arg(long)]
    pub(crate) intrinsics_ref: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Also write the first image as an 8-bit sRGB PNG here, for looking at.
    #[arg(long)]
    pub(crate) preview: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct CalibrateArgs {
    /// Folder of chessboard photos (JPEG, PNG, TIFF).
    pub(crate) dir: PathBuf,
    /// Inner corners COLSxROWS (default: detected).
    #[arg(long)]
    pub(crate) pattern: Option<String>,
    /// Square size, e.g. 25mm or 25.
    #[arg(long, default_value = "25mm")]
    pub(crate) square: String,
    /// Where intrinsics.json goes (default: in the folder); the OpenCV YAML goes beside it.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Folder for the diagnostic plots (default: plots/ beside the output).
    #[arg(long)]
    pub(crate) plots: Option<PathBuf>,
    /// auto: classic everywhere, the slower sector-based detector where the classic one fails
    /// or gives a view whose error stands out; or classic, sb, both.
    #[arg(long, value_enum, default_value = "auto")]
    pub(crate) detector: DetectorArg,
    /// cornerSubPix half-window in px (default: a third of the corner spacing, 3 to 25).
    #[arg(long)]
    pub(crate) subpix_window: Option<u32>,
    /// Also write the camera for other tools, beside intrinsics.json: ros (camera_info.yaml),
    /// colmap (cameras.txt); opencv (intrinsics.yml) is always written. Comma-separated.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub(crate) export: Vec<ExportArg>,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ExportArg {
    Opencv,
    Ros,
    Colmap,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum DetectorArg {
    Auto,
    Classic,
    Sb,
    Both,
}

#[derive(Args)]
pub(crate) struct CheckerArgs {
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Inner corners COLSxROWS.
    #[arg(long, default_value = "9x6")]
    pub(crate) pattern: String,
    /// Square size in mm.
    #[arg(long, default_value_t = 25.0)]
    pub(crate) square: f64,
    /// White margin in mm (default: one square).
    #[arg(long)]
    pub(crate) margin: Option<f64>,
    #[arg(long, default_value_t = 15)]
    pub(crate) views: u32,
    #[command(flatten)]
    pub(crate) camera: CameraArgs,
    /// Blur σ in pixels.
    #[arg(long, default_value_t = 0.7)]
    pub(crate) blur: f64,
    #[arg(long, default_value_t = 0.01)]
    pub(crate) noise: f64,
    #[arg(long, default_value_t = 2e-3)]
    pub(crate) read_noise: f64,
    /// Brightness loss at the frame corners (0..1).
    #[arg(long, default_value_t = 0.3)]
    pub(crate) vignetting: f64,
    #[arg(long, default_value_t = 4)]
    pub(crate) supersample: u32,
    /// png or jpeg.
    #[arg(long, default_value = "png")]
    pub(crate) format: String,
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
}

/// A parse error as one line: clap's message (its lines joined) without its usage block and
/// hints.
pub(crate) fn one_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let message: Vec<&str> = text
        .lines()
        .take_while(|l| !l.starts_with("Usage:") && !l.trim_start().starts_with("tip:"))
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    if message.is_empty() {
        "error: bad arguments".into()
    } else {
        message.join(" ")
    }
}

/// The longest line [`say`] prints whole (characters): a message quoting a huge field keeps its
/// start and its end.
const SAY_MAX: usize = 2000;

/// Print one line on stderr. A stderr that cannot be written (`2>/dev/full`, closed) is ignored:
/// the exit status still says what happened (eprintln! would panic, exit 101).
pub(crate) fn say(line: &str) {
    let n = line.chars().count();
    let line = if n > SAY_MAX {
        let head: String = line.chars().take(SAY_MAX / 2).collect();
        let tail: String = line.chars().skip(n - SAY_MAX / 2).collect();
        format!("{head} … ({} characters left out) … {tail}", n - SAY_MAX)
    } else {
        line.to_string()
    };
    let mut err = std::io::stderr().lock();
    let _ = std::io::Write::write_all(&mut err, format!("{line}\n").as_bytes())
        .and_then(|()| std::io::Write::flush(&mut err));
}
