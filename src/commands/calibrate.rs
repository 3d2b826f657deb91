//! `workbench calibrate`: the camera from chessboard photos (OpenCV).

use super::Report;
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;

#[cfg(feature = "opencv")]
pub(crate) fn calibrate(a: CalibrateArgs, quiet: bool) -> Result<Calibrated> {
    use workbench::calibrate::{run, Pattern};
    let pattern = match &a.pattern {
        Some(p) => Some(Pattern::parse(p).with_context(|| {
            format!(
                "--pattern {p:?}: expected COLSxROWS inner corners, 2 to {} a side, e.g. 9x6",
                Pattern::MAX_SIDE
            )
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
    workbench::calibrate::cv::set_threads(1);
    use workbench::calibrate::DetectorChoice;
    use workbench::formats::camera_export::ExportFormat;
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
        exports: a
            .export
            .iter()
            .map(|e| match e {
                ExportArg::Opencv => ExportFormat::OpenCv,
                ExportArg::Ros => ExportFormat::Ros,
                ExportArg::Colmap => ExportFormat::Colmap,
            })
            .collect(),
        quiet,
    };
    let r = run::run(
        &opts,
        &workbench::calibrate::cv::OpenCvDetect,
        &workbench::calibrate::cv::OpenCv,
    )?;
    Ok(Calibrated { r, square_mm })
}

/// The camera calibrated: the model, its parameters with their errors, what was left out.
#[cfg(feature = "opencv")]
pub(crate) struct Calibrated {
    r: workbench::calibrate::run::Report,
    square_mm: f64,
}

#[cfg(feature = "opencv")]
impl fmt::Display for Calibrated {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let (r, square_mm) = (&self.r, self.square_mm);
        let c = &r.calibration;
        let cam = &c.camera;
        writeln!(
            f,
            "pattern  {} inner corners, {square_mm} mm squares",
            r.pattern
        )?;
        writeln!(
            f,
            "views    {} used, {} rejected as outliers, {} unusable, of {} image(s) read",
            c.used.len(),
            c.rejected.len(),
            r.unusable.len(),
            r.images_read
        )?;
        for (file, why) in &r.unusable {
            writeln!(f, "         {file}: {why}")?;
        }
        for n in &c.notes {
            writeln!(f, "note     {n}")?;
        }
        let sd = c.std.unwrap_or_default();
        writeln!(f, "model    {}", c.model.name())?;
        writeln!(f, "fx       {:10.3} ± {:.3} px", cam.fx, sd.fx)?;
        writeln!(f, "fy       {:10.3} ± {:.3} px", cam.fy, sd.fy)?;
        writeln!(f, "cx       {:10.3} ± {:.3} px", cam.cx, sd.cx)?;
        writeln!(f, "cy       {:10.3} ± {:.3} px", cam.cy, sd.cy)?;
        let d = cam.distortion;
        let e = sd.distortion;
        writeln!(
            f,
            "k1 k2    {:+.5} ± {:.5}   {:+.5} ± {:.5}",
            d.k1, e.k1, d.k2, e.k2
        )?;
        writeln!(
            f,
            "p1 p2 k3 {:+.6} ± {:.6}   {:+.6} ± {:.6}   {:+.5} ± {:.5}",
            d.p1, e.p1, d.p2, e.p2, d.k3, e.k3
        )?;
        writeln!(f, "RMS      {:.4} px over the used views", c.rms_px)?;
        if let Some(cv) = c.cross_validation.iter().find(|v| v.model == c.model) {
            let j = cv.jackknife_std;
            writeln!(
                f,
                "cross-validation ({}-fold): held-out RMS {:.4} px; jackknife std fx {:.2} fy {:.2} cx {:.2} cy {:.2} px",
                cv.folds, cv.heldout_rms_px, j[0], j[1], j[2], j[3]
            )?;
        }
        for n in r.exif_notes.iter().filter(|n| !n.starts_with("warning: ")) {
            writeln!(f, "exif     {n}")?;
        }
        for w in &c.warnings {
            writeln!(f, "warning  {w}")?;
        }
        writeln!(
            f,
            "wrote    {} and {}",
            r.intrinsics_file.display(),
            r.yaml_file.display()
        )?;
        for (path, note) in &r.exports {
            writeln!(f, "wrote    {} ({note})", path.display())?;
        }
        if let Some(dir) = r.plot_files.first().and_then(|p| p.parent()) {
            writeln!(
                f,
                "plots    {} ({} files)",
                dir.display(),
                r.plot_files.len()
            )?;
        }
        writeln!(
            f,
            "time     detection {:.2} s, calibration {:.2} s",
            r.detection_s, r.calibration_s
        )?;
        Ok(())
    }
}

#[cfg(feature = "opencv")]
impl Report for Calibrated {}
