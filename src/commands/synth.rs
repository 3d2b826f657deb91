//! `workbench synth session|checkerboard|pbr`: render ground truth.

use super::Report;
use crate::cli::*;
use anyhow::{bail, Context, Result};
use std::fmt;
use std::path::PathBuf;
use workbench::model::{Material, SpecularParams};
use workbench::synth::checkerboard::{self, BoardFormat, CheckerConfig};
use workbench::synth::session::{self, Backdrop, Format, Layout, SessionConfig, Stand};
use workbench::synth::volpath;

pub(crate) fn synth_session(a: SessionArgs, quiet: bool) -> Result<SessionWritten> {
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
    if !(a.stand_radius > 0.0 && a.stand_radius <= 1e3) {
        bail!(
            "--stand-radius must lie in (0, 1000] mm, got {}",
            a.stand_radius
        );
    }
    if a.stand_level.is_some_and(|v| !(0.0..=1.0).contains(&v)) {
        bail!(
            "--stand-level must lie in [0, 1], got {}",
            a.stand_level.unwrap_or_default()
        );
    }
    if !(0.0..=1e3).contains(&a.stand_contact) {
        bail!(
            "--stand-contact must lie in [0, 1000] mm, got {}",
            a.stand_contact
        );
    }
    if a.stand_every == 0 {
        bail!("--stand-every must be 1 or more");
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
        stand: a.stand.then_some(Stand {
            radius_mm: a.stand_radius,
            level: a.stand_level,
            every: a.stand_every,
            contact_mm: a.stand_contact,
        }),
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
    Ok(SessionWritten {
        images: out.images.len(),
        session: out.session_file,
        truth: out.truth_file,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// A synthetic session written.
pub(crate) struct SessionWritten {
    images: usize,
    session: PathBuf,
    truth: PathBuf,
    seconds: f64,
}

impl fmt::Display for SessionWritten {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        writeln!(
            f,
            "wrote {} image(s), {} and {} in {:.2} s",
            self.images,
            self.session.display(),
            self.truth.display(),
            self.seconds
        )
    }
}

impl Report for SessionWritten {}

pub(crate) fn synth_pbr(a: PbrArgs, quiet: bool) -> Result<PbrWritten> {
    let cfg = volpath::PbrConfig {
        radii_mm: a.radii,
        camera: a.camera.camera()?,
        light: a.light.angles(),
        medium: volpath::Medium::grey(a.sigma_t, a.albedo),
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
    Ok(PbrWritten {
        images: out.images.len(),
        dir: a.out,
        seconds: t0.elapsed().as_secs_f64(),
        noise: out
            .truth
            .images
            .iter()
            .map(|p| p.noise_rel_median_lit)
            .collect(),
        irradiance: out.truth.irradiance_in_png_units,
    })
}

/// A physically based session written.
pub(crate) struct PbrWritten {
    images: usize,
    dir: PathBuf,
    seconds: f64,
    /// Each photo's median relative noise of a lit pixel.
    noise: Vec<f64>,
    irradiance: f64,
}

impl fmt::Display for PbrWritten {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let noise: Vec<String> = self
            .noise
            .iter()
            .map(|n| format!("{:.1}%", 100.0 * n))
            .collect();
        writeln!(
            f,
            "wrote {} photo(s), session.json and truth.json into {} in {:.1} s (noise per lit pixel {}; irradiance {:.4} in PNG units)",
            self.images,
            self.dir.display(),
            self.seconds,
            noise.join(" "),
            self.irradiance
        )
    }
}

impl Report for PbrWritten {}

pub(crate) fn synth_checkerboard(a: CheckerArgs, quiet: bool) -> Result<BoardsWritten> {
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
    Ok(BoardsWritten {
        views: out.images.len(),
        truth: out.truth_file,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Synthetic checkerboard views written.
pub(crate) struct BoardsWritten {
    views: usize,
    truth: PathBuf,
    seconds: f64,
}

impl fmt::Display for BoardsWritten {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        writeln!(
            f,
            "wrote {} view(s) and {} in {:.2} s",
            self.views,
            self.truth.display(),
            self.seconds
        )
    }
}

impl Report for BoardsWritten {}
