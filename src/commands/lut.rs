//! `workbench lut`: a fit's CDRF tabulated over N·L and curvature.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;
use std::path::PathBuf;

pub(crate) fn lut(a: LutArgs) -> Result<Box<dyn Report>> {
    if let Some(p) = a.preset {
        return Ok(Box::new(engine(a, p)?));
    }
    Ok(Box::new(tabulated(a)?))
}

fn tabulated(a: LutArgs) -> Result<Tabulated> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "lut"));
    let (t, fm, paths) = workbench::render::job::write_lut(
        &a.fit,
        &out,
        table_size(a.size, a.tolerance),
        a.kappa_max,
    )
    .with_context(|| format!("lut {}", a.fit.display()))?;
    Ok(Tabulated { t, fm, paths })
}

/// The table written, its size search and its error.
pub(crate) struct Tabulated {
    t: workbench::render::job::Table,
    fm: workbench::render::lut::FitMaterial,
    paths: [PathBuf; 3],
}

impl fmt::Display for Tabulated {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let (t, fm, paths) = (&self.t, &self.fm, &self.paths);
        for ((nc, nk), e) in &t.tried {
            writeln!(
                f,
                "size     {nc}x{nk}: largest interpolation error {:.2e} of the peak",
                e
            )?;
        }
        let e = &t.error;
        writeln!(
            f,
            "table    {}x{} nodes, N·L -1..1, curvature 0..{:.4}/mm (fit measured {:.4}..{:.4}/mm)",
            t.lut.n_cos, t.lut.n_kappa, t.lut.kappa_max, fm.measured_kappa[0], fm.measured_kappa[1]
        )?;
        writeln!(
            f,
            "error    largest {:.2e} ({:.2e} of the peak {:.4}) at N·L {:.3}, curvature {:.4}/mm; rms {:.2e}",
            e.max_abs,
            e.max_rel,
            t.lut.peak(),
            e.at_cos,
            e.at_kappa_per_mm,
            e.rms
        )?;
        for p in paths {
            writeln!(f, "wrote    {}", p.display())?;
        }
        Ok(())
    }
}

impl Report for Tabulated {}

/// `--preset`: the engine's table and sidecar.
fn engine(a: LutArgs, p: PresetArg) -> Result<Engine> {
    use workbench::render::preset::{Encoding, Preset};
    let preset = match p {
        PresetArg::Unity => Preset::Unity,
        PresetArg::Unreal => Preset::Unreal,
        PresetArg::Godot => Preset::Godot,
        PresetArg::Blender => Preset::Blender,
        PresetArg::Generic => Preset::Generic,
    };
    let encoding = match a.format {
        TextureArg::Exr => Encoding::ExrHalf,
        TextureArg::Png16 => Encoding::Png16,
        TextureArg::Png8Srgb => Encoding::Png8Srgb,
    };
    let stem = match &a.out {
        Some(o) => workbench::render::lut::stem_of(o),
        None => beside(&a.fit, &format!("lut-{}", preset.name())),
    };
    let mesh = match &a.mesh {
        Some(m) => Some(
            workbench::render::job::prepare(m, a.unit, a.object_size)
                .with_context(|| format!("lut --mesh {}", m.display()))?,
        ),
        None => None,
    };
    let e = workbench::render::job::write_engine_lut(
        &a.fit,
        &stem,
        preset,
        encoding,
        table_size(a.size, a.tolerance),
        a.kappa_max,
        mesh.as_ref(),
    )
    .with_context(|| format!("lut {}", a.fit.display()))?;
    Ok(Engine(e))
}

/// The engine table written.
struct Engine(workbench::render::job::EngineLut);

impl fmt::Display for Engine {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let (t, s) = (&self.0.table, &self.0.sidecar);
        for ((w, h), e) in &self.0.tried {
            writeln!(
                f,
                "size     {w}x{h}: largest sampled error {e:.2e} of the peak"
            )?;
        }
        writeln!(
            f,
            "texture  {}x{} texels, {}, origin {}",
            t.width,
            t.height,
            s.colour_space,
            s.origin.split(':').next().unwrap_or_default()
        )?;
        writeln!(f, "u        {}", s.u)?;
        writeln!(f, "v        {}", s.v)?;
        writeln!(
            f,
            "measured curvature {:.4}..{:.4} {} = v {:.4}..{:.4}; beyond it the model is extrapolated",
            s.measured_curvature[0],
            s.measured_curvature[1],
            s.curvature_unit,
            s.measured_v[0],
            s.measured_v[1]
        )?;
        let (e, q) = (&s.interpolation_error, &s.stored_error);
        writeln!(
            f,
            "error    as sampled {:.2e} of the peak {:.4}, as stored {:.2e} (at N·L {:.3}, curvature {:.4}/mm); {:.2e} in the outer half texel (clamped)",
            e.max_rel,
            t.peak(),
            q.max_rel,
            q.at_cos,
            q.at_kappa_per_mm,
            s.border_error
        )?;
        for line in &s.import_settings {
            writeln!(f, "import   {line}")?;
        }
        for p in &self.0.paths {
            writeln!(f, "wrote    {}", p.display())?;
        }
        Ok(())
    }
}

impl Report for Engine {}
