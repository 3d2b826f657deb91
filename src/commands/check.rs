//! `workbench check`: a session folder against its files.

use anyhow::Result;
use std::path::PathBuf;

pub(crate) fn check(session: PathBuf) -> Result<()> {
    let r = workbench::formats::session::inspect(&session)?;
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
