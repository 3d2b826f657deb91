//! `workbench check`: a session folder against its files.

use super::Report;
use anyhow::Result;
use std::fmt;
use std::path::PathBuf;
use workbench::formats::session::{inspect, Session, SessionReport};

/// The session's files checked as the other commands read them: session.json, the intrinsics,
/// each photo's header and EXIF, and then every photo decoded in full (a file cut short is found
/// here, not by `detect`).
pub(crate) fn check(session: PathBuf) -> Result<Checked> {
    let report = inspect(&session)?;
    let (sess, _) = Session::load(&session)?;
    report.decode(&sess)?;
    Ok(Checked(report))
}

/// What the session holds, as checked.
pub(crate) struct Checked(SessionReport);

impl fmt::Display for Checked {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let r = &self.0;
        writeln!(f, "session  {}", r.session_file.display())?;
        if let Some(m) = &r.material {
            writeln!(f, "material {m}")?;
        }
        match (&r.intrinsics_file, &r.camera) {
            (Some(file), Some(c)) => writeln!(
                f,
                "camera   {} — {}×{}, fx {:.1} fy {:.1} cx {:.1} cy {:.1}, k1 {:+.4} k2 {:+.4}",
                file.display(),
                c.image_size[0],
                c.image_size[1],
                c.fx,
                c.fy,
                c.cx,
                c.cy,
                c.distortion.k1,
                c.distortion.k2
            )?,
            _ => writeln!(f, "camera   none given: orthographic")?,
        }
        for im in &r.images {
            let exposure = match (im.exposure, im.exposure_source) {
                (Some(e), Some(src)) => format!("exposure {e:.4} ({src})"),
                _ => "exposure unknown".into(),
            };
            let radii: Vec<String> = im.radii_mm.iter().map(|r| format!("{r}")).collect();
            writeln!(
                f,
                "image    {:<12} {}×{} {}-bit {} {}, {exposure}, spheres {} mm",
                im.file,
                im.width,
                im.height,
                im.bits,
                if im.channels >= 3 { "RGB" } else { "grey" },
                if im.linear { "linear" } else { "sRGB" },
                radii.join(" ")
            )?;
            for n in &im.exif_notes {
                writeln!(f, "exif     {:<12} {n}", im.file)?;
            }
        }
        let radii: std::collections::BTreeSet<String> = r
            .images
            .iter()
            .flat_map(|i| i.radii_mm.iter().map(|r| format!("{r}")))
            .collect();
        writeln!(
            f,
            "ok: {} image(s), {} distinct radii",
            r.images.len(),
            radii.len()
        )
    }
}

impl Report for Checked {}
