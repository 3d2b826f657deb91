//! `workbench calibrate <dir>/`: a folder of chessboard photos → `intrinsics.json`, the same
//! calibration as OpenCV FileStorage YAML, and diagnostic plots.

use super::{calibrate, Backend, Calibration, Detector, DetectorChoice, Pattern, View};
use crate::error::{one_line, Error, Result};
use crate::formats::intrinsics::{IntrinsicsFile, ViewReport, SCHEMA};
use crate::formats::photo::{self, ExifInfo, Gray8};
use nalgebra::Vector2;
use rayon::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};

/// What the command was asked.
#[derive(Clone, Debug)]
pub struct Options {
    pub dir: PathBuf,
    pub pattern: Option<Pattern>,
    pub square_mm: f64,
    /// intrinsics.json path (default `<dir>/intrinsics.json`); the YAML goes beside it.
    pub out: Option<PathBuf>,
    /// Plot folder (default `<out's folder>/plots`).
    pub plots: Option<PathBuf>,
    pub detector: DetectorChoice,
    /// cornerSubPix half-window (px); default: a third of the corner spacing, within [3, 25].
    pub subpix_window: Option<u32>,
    /// Formats written beside intrinsics.json besides the OpenCV YAML, which is always written.
    pub exports: Vec<crate::formats::camera_export::ExportFormat>,
    pub quiet: bool,
}

/// What the command produced.
#[derive(Debug)]
pub struct Report {
    pub calibration: Calibration,
    pub pattern: Pattern,
    pub images_read: usize,
    /// Images that gave no view, with the reason.
    pub unusable: Vec<(String, String)>,
    pub exif_notes: Vec<String>,
    pub intrinsics_file: PathBuf,
    pub yaml_file: PathBuf,
    /// The other formats written (ROS, COLMAP), with a note on each.
    pub exports: Vec<(PathBuf, String)>,
    pub plot_files: Vec<PathBuf>,
    pub detection_s: f64,
    pub calibration_s: f64,
}

/// Detectors a calibration can use (implemented by OpenCV in [`crate::calibrate::cv`]).
pub trait Detect: Sync {
    /// The chessboard's inner corners by one detector; `None` when it finds no board.
    fn detect(
        &self,
        img: &Gray8,
        pattern: Pattern,
        detector: Detector,
        window: Option<u32>,
    ) -> Result<Option<Vec<Vector2<f64>>>>;
    fn guess_pattern(&self, img: &Gray8) -> Result<Option<Pattern>>;
    /// YAML text of the calibration in OpenCV FileStorage format.
    fn yaml(&self, cam: &crate::camera::Camera) -> Result<String>;
}

/// A view's corners, when a detector found the board.
type Corners = Option<Vec<Vector2<f64>>>;
/// A decoded image with its EXIF, or why it could not be read.
type Loaded = Result<(Gray8, Option<ExifInfo>)>;

const IMAGE_EXTENSIONS: [&str; 5] = ["jpg", "jpeg", "png", "tif", "tiff"];

/// The image files of a folder (not recursive), sorted by name.
pub(crate) fn image_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files: Vec<PathBuf> = rd
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    Ok(files)
}

fn name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The readable images of the folder (all of one size), with their EXIF, and those that could
/// not be read.
struct Images {
    list: Vec<(String, Gray8, Option<ExifInfo>)>,
    /// Image files found.
    read: usize,
    size: [u32; 2],
    /// Images that gave no view, with the reason.
    unusable: Vec<(String, String)>,
}

/// A detector's result on one image: not run (`None`), no board (`Some(None)`) or corners.
type Found = Option<Corners>;

/// Per image: the classic and the sector-based detector's results, and a detector's error.
struct Detected {
    found: Vec<[Found; 2]>,
    errors: Vec<Option<String>>,
}

/// Run the whole calibration: read the images, the pattern, the corners by each detector, the
/// views (each with the detector the first camera explains better), the calibration and its
/// EXIF checks, then the outputs as one set.
pub fn run(opts: &Options, detect: &dyn Detect, backend: &dyn Backend) -> Result<Report> {
    let t0 = std::time::Instant::now();
    if !(opts.square_mm.is_finite() && opts.square_mm > 0.0) {
        return Err(Error::Argument(format!(
            "square size must be positive, got {} mm",
            opts.square_mm
        )));
    }
    let mut images = read_images(opts)?;
    let pattern = pattern_of(opts, detect, &images)?;
    let object = pattern.object_points(opts.square_mm);
    let found = detect_corners(opts, detect, backend, &images, pattern, &object)?;
    let detection_s = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let runs = |d: Detector| {
        found
            .found
            .iter()
            .filter(|f| f[d as usize].is_some())
            .count()
    };
    let detector_note = format!(
        "detectors: classic run on {} image(s), sector-based on {}",
        runs(Detector::Classic),
        runs(Detector::SectorBased)
    );
    let candidates = candidates(&mut images, &found, pattern);
    if candidates.len() < 3 {
        return Err(no_view(&opts.dir, images.read, &images.unusable));
    }
    let views = choose_views(backend, candidates, &object, images.size)?;
    let mut cal = calibrate(backend, views, &object, images.size)?;
    cal.notes.insert(0, detector_note);
    for (f, why) in &images.unusable {
        cal.reports.push(ViewReport {
            file: f.clone(),
            rms_px: None,
            status: why.clone(),
        });
    }
    cal.reports.sort_by(|a, b| a.file.cmp(&b.file));
    let exif_notes = exif_checks(
        &images
            .list
            .iter()
            .map(|(f, _, e)| (f.clone(), e.clone()))
            .collect::<Vec<_>>(),
        cal.camera.fx,
        images.size,
    );
    cal.warnings.extend(
        exif_notes
            .iter()
            .filter(|n| n.starts_with("warning: "))
            .map(|n| n[9..].to_string()),
    );
    let calibration_s = t1.elapsed().as_secs_f64();
    let written = write_outputs(opts, detect, &cal, pattern, &object, &images, &exif_notes)?;
    Ok(Report {
        calibration: cal,
        pattern,
        images_read: images.read,
        unusable: images.unusable,
        exif_notes,
        intrinsics_file: written.intrinsics_file,
        yaml_file: written.yaml_file,
        exports: written.exports,
        plot_files: written.plot_files,
        detection_s,
        calibration_s,
    })
}

/// Decode every image of the folder (in parallel) with its EXIF; one size for all.
fn read_images(opts: &Options) -> Result<Images> {
    let files = image_files(&opts.dir)?;
    if files.is_empty() {
        return Err(Error::invalid(
            &opts.dir,
            "no JPEG, PNG or TIFF images in this folder",
        ));
    }
    let pb = crate::progress::bar(files.len() as u64, "reading", opts.quiet);
    let loaded: Vec<(PathBuf, Loaded)> = files
        .par_iter()
        .map(|p| {
            let r = photo::load_gray8(p).map(|g| (g, ExifInfo::read(p).unwrap_or(None)));
            pb.inc(1);
            (p.clone(), r)
        })
        .collect();
    pb.finish_and_clear();
    let mut unusable: Vec<(String, String)> = vec![];
    let mut list: Vec<(String, Gray8, Option<ExifInfo>)> = vec![];
    for (p, r) in loaded {
        match r {
            Ok((g, e)) => list.push((name(&p), g, e)),
            Err(e) => unusable.push((
                name(&p),
                format!("unreadable: {}", one_line(&e.to_string())),
            )),
        }
    }
    let read = files.len();
    let size = match list.first() {
        Some((_, g, _)) => [g.width, g.height],
        None => return Err(no_view(&opts.dir, read, &unusable)),
    };
    if let Some((f, g, _)) = list.iter().find(|(_, g, _)| [g.width, g.height] != size) {
        return Err(Error::invalid(
            opts.dir.join(f),
            format!(
                "image is {}×{} but {} is {}×{}: one calibration needs one image size",
                g.width, g.height, list[0].0, size[0], size[1]
            ),
        ));
    }
    Ok(Images {
        list,
        read,
        size,
        unusable,
    })
}

/// The pattern given, or the first one found in the first eight images.
fn pattern_of(opts: &Options, detect: &dyn Detect, images: &Images) -> Result<Pattern> {
    if let Some(p) = opts.pattern {
        return Ok(p);
    }
    for (_, g, _) in images.list.iter().take(8) {
        if let Some(p) = detect.guess_pattern(g)? {
            return Ok(p);
        }
    }
    Err(Error::invalid(
        &opts.dir,
        "no chessboard of a common size found in the first images: give --pattern COLSxROWS (inner corners)",
    ))
}

impl Detected {
    /// One detector on the images `todo`, in parallel.
    fn pass(
        &mut self,
        which: Detector,
        todo: &[usize],
        opts: &Options,
        detect: &dyn Detect,
        images: &Images,
        pattern: Pattern,
    ) {
        let pb = crate::progress::bar(
            todo.len() as u64,
            &format!("{} detector", which.name()),
            opts.quiet,
        );
        let res: Vec<(usize, Result<Corners>)> = todo
            .par_iter()
            .map(|&i| {
                let r = detect.detect(&images.list[i].1, pattern, which, opts.subpix_window);
                pb.inc(1);
                (i, r)
            })
            .collect();
        pb.finish_and_clear();
        for (i, r) in res {
            match r {
                Ok(c) => self.found[i][which as usize] = Some(c),
                Err(e) => self.errors[i] = Some(e.to_string()),
            }
        }
    }

    /// An image's corners by one detector, when it found the board.
    fn corners(&self, i: usize, d: Detector) -> Corners {
        self.found[i][d as usize].clone().flatten()
    }
}

/// The corners by the detectors `opts` chooses: classic, sector-based, both, or (auto) classic
/// with the sector-based detector where the classic one found no board or where the first
/// camera explains its corners badly.
fn detect_corners(
    opts: &Options,
    detect: &dyn Detect,
    backend: &dyn Backend,
    images: &Images,
    pattern: Pattern,
    object: &[nalgebra::Vector3<f64>],
) -> Result<Detected> {
    let n = images.list.len();
    let mut f = Detected {
        found: vec![[None, None]; n],
        errors: vec![None; n],
    };
    let all: Vec<usize> = (0..n).collect();
    if opts.detector != DetectorChoice::SectorBased {
        f.pass(Detector::Classic, &all, opts, detect, images, pattern);
    }
    let sb_todo: Vec<usize> = match opts.detector {
        DetectorChoice::Classic => vec![],
        DetectorChoice::SectorBased | DetectorChoice::Both => all.clone(),
        DetectorChoice::Auto => all
            .iter()
            .cloned()
            .filter(|&i| !matches!(f.found[i][0], Some(Some(_))))
            .collect(),
    };
    f.pass(
        Detector::SectorBased,
        &sb_todo,
        opts,
        detect,
        images,
        pattern,
    );
    let usable: Vec<usize> = all
        .iter()
        .cloned()
        .filter(|&i| f.found[i].iter().any(|x| matches!(x, Some(Some(_)))))
        .collect();
    if usable.len() >= 3 && opts.detector == DetectorChoice::Auto {
        // Views whose classic corners the first camera explains badly get the sector-based
        // detector too.
        let first: Vec<Vec<Vector2<f64>>> = usable
            .iter()
            .map(|&i| {
                f.corners(i, Detector::Classic)
                    .or_else(|| f.corners(i, Detector::SectorBased))
                    .unwrap_or_default()
            })
            .collect();
        let refs: Vec<&[Vector2<f64>]> = first.iter().map(|v| v.as_slice()).collect();
        let sol =
            backend.calibrate(&refs, object, images.size, super::DistortionModel::K1K2P1P2)?;
        let errs: Vec<f64> = refs
            .iter()
            .zip(&sol.poses)
            .map(|(v, p)| super::rms(&super::view_residuals(&sol.camera, p, v, object)))
            .collect();
        let med = crate::stats::median(&errs);
        let suspicious: Vec<usize> = usable
            .iter()
            .zip(&errs)
            .filter(|(&i, &e)| e > (1.5 * med).max(med + 0.1) && f.found[i][1].is_none())
            .map(|(&i, _)| i)
            .collect();
        f.pass(
            Detector::SectorBased,
            &suspicious,
            opts,
            detect,
            images,
            pattern,
        );
    }
    Ok(f)
}

/// The images with corners by either detector; the others join `images.unusable`, with why.
fn candidates(images: &mut Images, f: &Detected, pattern: Pattern) -> Vec<(String, [Corners; 2])> {
    let mut candidates = vec![];
    for (i, (name, _, _)) in images.list.iter().enumerate() {
        let both = [
            f.corners(i, Detector::Classic),
            f.corners(i, Detector::SectorBased),
        ];
        match (&f.errors[i], &both) {
            (Some(e), [None, None]) => images
                .unusable
                .push((name.clone(), format!("detection failed: {}", one_line(e)))),
            (_, [None, None]) => images
                .unusable
                .push((name.clone(), format!("no {pattern} chessboard found"))),
            _ => candidates.push((name.clone(), both)),
        }
    }
    candidates
}

/// Per view, the detector whose corners an initial camera (from the first detector's corners
/// of every view) explains better.
fn choose_views(
    backend: &dyn Backend,
    candidates: Vec<(String, [Corners; 2])>,
    object: &[nalgebra::Vector3<f64>],
    size: [u32; 2],
) -> Result<Vec<View>> {
    let first: Vec<&[Vector2<f64>]> = candidates
        .iter()
        .map(|(_, b)| b[0].as_deref().or(b[1].as_deref()).unwrap_or(&[]))
        .collect();
    let initial = backend.calibrate(&first, object, size, super::DistortionModel::K1K2P1P2)?;
    let mut views = vec![];
    for (f, both) in candidates {
        let mut best: Option<(f64, Vec<Vector2<f64>>, &'static str)> = None;
        for (k, c) in both.into_iter().enumerate() {
            let Some(c) = c else { continue };
            let e = match backend.pose(&initial.camera, &c, object) {
                Ok(pose) => super::rms(&super::view_residuals(&initial.camera, &pose, &c, object)),
                Err(_) => f64::INFINITY,
            };
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, c, if k == 0 { "classic" } else { "sb" }));
            }
        }
        if let Some((_, corners, detector)) = best {
            views.push(View {
                file: f,
                corners,
                detector,
            });
        }
    }
    Ok(views)
}

/// The files a calibration wrote.
struct Written {
    intrinsics_file: PathBuf,
    yaml_file: PathBuf,
    exports: Vec<(PathBuf, String)>,
    plot_files: Vec<PathBuf>,
}

/// intrinsics.json, the OpenCV YAML, the exports asked for and the figures, as one set.
fn write_outputs(
    opts: &Options,
    detect: &dyn Detect,
    cal: &Calibration,
    pattern: Pattern,
    object: &[nalgebra::Vector3<f64>],
    images: &Images,
    exif_notes: &[String],
) -> Result<Written> {
    let size = images.size;
    let intrinsics_file = opts
        .out
        .clone()
        .unwrap_or_else(|| opts.dir.join("intrinsics.json"));
    let yaml_file = intrinsics_file.with_extension("yml");
    let out_dir = intrinsics_file
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let plot_dir = opts.plots.clone().unwrap_or_else(|| out_dir.join("plots"));
    let c = &cal.camera;
    let file = IntrinsicsFile {
        schema: SCHEMA.into(),
        image_size: size,
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        distortion: c.distortion,
        rms_px: Some(cal.rms_px),
        std: cal.std,
        views: cal.reports.clone(),
        source: Some(format!(
            "calibrated from {} view(s) of {}",
            cal.used.len(),
            opts.dir.display()
        )),
        details: Some(json!({
            "pattern": [pattern.cols, pattern.rows],
            "square_mm": opts.square_mm,
            "distortion_model": cal.model.name(),
            "cross_validation": cal.cross_validation,
            "notes": cal.notes,
            "warnings": cal.warnings,
            "exif": exif_notes,
            "images_read": images.read,
        })),
    };
    let exports = exports(opts, c, &out_dir);
    // One set: the YAML, the exports and the plots, then intrinsics.json (what the reuse check
    // trusts) last.
    let mut members: Vec<&Path> = vec![&intrinsics_file, &yaml_file, &plot_dir];
    members.extend(exports.iter().map(|(p, _, _)| p.as_path()));
    let set = crate::formats::output::OutputSet::begin(&members)?;
    crate::formats::output::write_bytes(&yaml_file, detect.yaml(c)?.as_bytes())?;
    for (path, text, _) in &exports {
        crate::formats::output::write_bytes(path, text.as_bytes())?;
    }
    let plot_files = super::plots::write_all(cal, object, size, &plot_dir)?;
    crate::formats::output::write_json(&intrinsics_file, &file)?;
    set.commit()?;
    Ok(Written {
        intrinsics_file,
        yaml_file,
        exports: exports.into_iter().map(|(p, _, n)| (p, n)).collect(),
        plot_files,
    })
}

/// The other tools' camera files asked for (path, text, a note on each), in `out_dir`.
fn exports(
    opts: &Options,
    c: &crate::camera::Camera,
    out_dir: &Path,
) -> Vec<(PathBuf, String, String)> {
    use crate::formats::camera_export::{self as export, ExportFormat};
    let mut exports: Vec<(PathBuf, String, String)> = vec![];
    for f in [ExportFormat::Ros, ExportFormat::Colmap] {
        if !opts.exports.contains(&f) {
            continue;
        }
        let path = out_dir.join(f.file_name());
        let (text, note) = match f {
            ExportFormat::Ros => (
                export::ros_camera_info(c),
                "ROS CameraInfo, plumb_bob, P = [K | 0]".to_string(),
            ),
            _ => {
                let (text, model) = export::colmap_cameras(c);
                (
                    text,
                    format!("COLMAP camera 1, {model}, principal point + 0.5 px (COLMAP's pixel origin)"),
                )
            }
        };
        exports.push((path, text, note));
    }
    exports
}

fn no_view(dir: &Path, read: usize, why: &[(String, String)]) -> Error {
    let reasons: Vec<String> = why.iter().map(|(f, w)| format!("{f}: {w}")).collect();
    Error::invalid(
        dir,
        format!(
            "no calibration possible: {read} image(s) read, {} usable (3 needed){}{}",
            read - why.len(),
            if reasons.is_empty() { "" } else { "; " },
            reasons.join("; ")
        ),
    )
}

/// EXIF sanity checks: one camera and one focal length across the set, and the fitted fx against
/// the lens's 35 mm equivalent focal length. Lines starting "warning: " are warnings.
pub(crate) fn exif_checks(
    exif: &[(String, Option<ExifInfo>)],
    fitted_fx: f64,
    size: [u32; 2],
) -> Vec<String> {
    let mut notes = vec![];
    let with: Vec<&ExifInfo> = exif.iter().filter_map(|(_, e)| e.as_ref()).collect();
    if with.is_empty() {
        notes.push("no EXIF camera settings in the images: fx not checked against the lens".into());
        return notes;
    }
    let mut cameras: Vec<String> = with
        .iter()
        .map(|e| format!("{} {}", e.make, e.model).trim().to_string())
        .collect();
    cameras.sort();
    cameras.dedup();
    if cameras.len() > 1 {
        notes.push(format!(
            "warning: the images come from different cameras: {}",
            cameras.join(", ")
        ));
    } else {
        notes.push(format!("camera: {}", cameras[0]));
    }
    let mut focals: Vec<String> = with
        .iter()
        .filter_map(|e| e.focal_length_mm.map(|f| format!("{f:.1} mm")))
        .collect();
    focals.sort();
    focals.dedup();
    if focals.len() > 1 {
        notes.push(format!(
            "warning: the images were taken at different focal lengths: {}",
            focals.join(", ")
        ));
    }
    let focal = match with.iter().find_map(|e| e.focal_length_mm) {
        Some(f) => format!("{f:.1} mm"),
        None => "focal length unknown".into(),
    };
    match with.iter().find_map(|e| e.focal_length_35mm) {
        Some(f35) => {
            let expected = photo::fx_from_35mm(f35 as f64, size);
            let ratio = fitted_fx / expected;
            let line = format!(
                "lens: {focal} ({f35} mm equivalent) implies fx ≈ {expected:.0} px; fitted fx = {:.1} px ({:+.1}%)",
                fitted_fx,
                100.0 * (ratio - 1.0)
            );
            if (ratio - 1.0).abs() > 0.10 {
                notes.push(format!("warning: {line}: more than 10% apart — check the pattern size, the square size and the images"));
            } else {
                notes.push(line);
            }
        }
        None => notes.push(format!(
            "lens: {focal}, but no 35 mm equivalent in EXIF: fx not checked against it"
        )),
    }
    notes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exif(model: &str, focal: f64, f35: u32) -> Option<ExifInfo> {
        Some(ExifInfo::for_exposure(1.0, "Maker", model, focal, f35))
    }

    #[test]
    fn exif_sanity_checks() {
        // 1280×960 and a 35 mm equivalent of 50 mm: fx ≈ 50 · 1600 / 43.27 = 1849 px.
        let size = [1280, 960];
        let same = vec![
            ("a".to_string(), exif("X1", 33.0, 50)),
            ("b".to_string(), exif("X1", 33.0, 50)),
        ];
        let notes = exif_checks(&same, 1849.0, size);
        assert!(
            notes.iter().all(|n| !n.starts_with("warning: ")),
            "{notes:?}"
        );
        assert!(
            notes
                .iter()
                .any(|n| n.starts_with("lens: 33.0 mm (50 mm equivalent)")),
            "{notes:?}"
        );
        // fx 15% off the lens: warned.
        let notes = exif_checks(&same, 1849.0 * 1.15, size);
        assert!(
            notes
                .iter()
                .any(|n| n.starts_with("warning: lens:") && n.contains("+15.0%")),
            "{notes:?}"
        );
        // Two cameras and two focal lengths: both warned.
        let mixed = vec![
            ("a".to_string(), exif("X1", 33.0, 50)),
            ("b".to_string(), exif("X2", 24.0, 36)),
        ];
        let notes = exif_checks(&mixed, 1849.0, size);
        assert!(
            notes
                .iter()
                .any(|n| n.contains("different cameras: Maker X1, Maker X2")),
            "{notes:?}"
        );
        assert!(
            notes
                .iter()
                .any(|n| n.contains("different focal lengths: 24.0 mm, 33.0 mm")),
            "{notes:?}"
        );
        // No EXIF at all: said, not guessed.
        let none = vec![("a".to_string(), None)];
        assert!(exif_checks(&none, 1849.0, size)[0].starts_with("no EXIF"));
    }
}
