//! `session.json` (schema `workbench.session/1`): what a user writes by hand to describe a photo
//! session of spheres. Relative paths are relative to the session file.

use crate::error::{Error, Result};
use crate::formats::output::read_json;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(crate) const SCHEMA: &str = "workbench.session/1";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionSphere {
    pub radius_mm: f64,
    /// Where to look (optional, pixels of the photo as decoded upright): the outline's centre and
    /// radius, roughly (within a fifth of the radius). Given for every sphere of a photo, the
    /// spheres are searched there instead of among the bright blobs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_px: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_px: Option<f64>,
}

impl SessionSphere {
    pub fn new(radius_mm: f64) -> Self {
        SessionSphere {
            radius_mm,
            center_px: None,
            radius_px: None,
        }
    }

    /// The hint (centre, radius in pixels), when given.
    pub fn hint(&self) -> Option<([f64; 2], f64)> {
        Some((self.center_px?, self.radius_px?))
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionImage {
    pub file: String,
    /// Spheres in the photo, left to right.
    pub spheres: Vec<SessionSphere>,
    /// Relative exposure (see [`crate::formats::exif`]); overrides EXIF.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure: Option<f64>,
    /// The light's intensity in this photo per channel (r, g, b), relative to the session's
    /// other photos: a photometric-stereo set's lamps differ (DiLiGenT's
    /// `light_intensities.txt`). The photo's radiance is divided by it, as by the exposure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_intensity: Option<[f64; 3]>,
    /// Whether pixel values are linear; default: 16-bit/float linear, 8-bit sRGB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear: Option<bool>,
}

/// One light for the whole session (default) or one per photo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightMode {
    #[default]
    Shared,
    PerImage,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Session {
    pub schema: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
    /// Path of an `intrinsics.json`; without it the camera is treated as orthographic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intrinsics: Option<String>,
    #[serde(default, skip_serializing_if = "is_shared")]
    pub light: LightMode,
    /// The camera's dark floor (pixel value, full scale 1: black level and stray light, e.g. the
    /// mean of a photo with the lens capped), subtracted from every photo; without it the floor is
    /// measured where the photo around the spheres is dark, and before a lit backdrop the joint
    /// fit fits it (docs/pipeline.md, "The dark floor").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<f64>,
    pub images: Vec<SessionImage>,
    /// A diffuse reference of known reflectance in one of the photos (a grey card, a
    /// reflectance standard): it gives the light's irradiance when `solve --irradiance` does not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<SessionReference>,
}

/// A matte card of known reflectance under the session's light, in one of its photos.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionReference {
    /// The photo it is in: one of `images`.
    pub image: String,
    /// The pixels to average, [x0, y0, x1, y1] with x0 ≤ x < x1, y0 ≤ y < y1 (the photo as
    /// decoded upright): inside the card, clear of its edges and of the spheres.
    pub box_px: [u32; 4],
    /// Its diffuse reflectance (0–1; a grey card 0.18, a reflectance standard as calibrated).
    pub reflectance: f64,
    /// Which way it faces: the light (default) or the camera.
    #[serde(default)]
    pub facing: Facing,
}

/// The reference card's normal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Facing {
    /// Toward the light: its radiance is ρE/π.
    #[default]
    Light,
    /// Toward the camera: ρE cos θ/π, θ between the camera's axis and the light.
    Camera,
}

fn is_shared(m: &LightMode) -> bool {
    *m == LightMode::Shared
}

impl Session {
    /// Read and validate a session file (a folder means its `session.json`).
    pub fn load(path: &Path) -> Result<(Session, PathBuf)> {
        let file = if path.is_dir() {
            path.join("session.json")
        } else {
            path.to_path_buf()
        };
        let s: Session = read_json(&file)?;
        s.validate(&file)?;
        Ok((s, file))
    }

    pub fn validate(&self, file: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::invalid(file, msg));
        if self.schema != SCHEMA {
            return bad(format!("schema is {:?}, expected {SCHEMA:?}", self.schema));
        }
        if self.images.is_empty() {
            return bad("no images listed".into());
        }
        if let Some(f) = self.floor {
            if !(f.is_finite() && (0.0..0.5).contains(&f)) {
                return bad(format!("floor must lie in [0, 0.5) of full scale, got {f}"));
            }
        }
        for (i, im) in self.images.iter().enumerate() {
            if im.file.trim().is_empty() {
                return bad(format!("images[{i}] has an empty file name"));
            }
            if !inside(&im.file) {
                return bad(format!(
                    "images[{i}] ({}) lies outside the session folder: photos must be in it or below it",
                    im.file
                ));
            }
            if im.spheres.is_empty() {
                return bad(format!("images[{i}] ({}) lists no spheres", im.file));
            }
            for (j, s) in im.spheres.iter().enumerate() {
                if !RADIUS_RANGE_MM.contains(&s.radius_mm) {
                    return bad(format!(
                        "images[{i}] ({}) sphere {j}: radius_mm must be a positive number of mm ({} to {}), got {}",
                        im.file, RADIUS_RANGE_MM.start, RADIUS_RANGE_MM.end, s.radius_mm
                    ));
                }
                if s.center_px.is_some() != s.radius_px.is_some() {
                    return bad(format!(
                        "images[{i}] ({}) sphere {j}: give center_px and radius_px together",
                        im.file
                    ));
                }
                if let (Some(c), Some(r)) = (s.center_px, s.radius_px) {
                    if !(c.iter().all(|v| v.is_finite()) && r.is_finite() && r >= 4.0) {
                        return bad(format!(
                            "images[{i}] ({}) sphere {j}: center_px must be finite and radius_px at least 4 px",
                            im.file
                        ));
                    }
                }
            }
            if let Some(j) = self.images[..i]
                .iter()
                .position(|o| same_file(&o.file, &im.file))
            {
                return bad(format!(
                    "images[{i}] ({}) is images[{j}] again: a photo listed twice would be fitted twice and shrink every error",
                    im.file
                ));
            }
            let hinted = im.spheres.iter().filter(|s| s.center_px.is_some()).count();
            if hinted != 0 && hinted != im.spheres.len() {
                return bad(format!(
                    "images[{i}] ({}): center_px/radius_px for {hinted} of its {} spheres: give them for all or none",
                    im.file,
                    im.spheres.len()
                ));
            }
            if let Some(e) = im.exposure {
                if !(e.is_finite() && e > 1e-9 && e < 1e9) {
                    return bad(format!(
                        "images[{i}] ({}): exposure must lie between 1e-9 and 1e9, got {e:e}",
                        im.file
                    ));
                }
            }
            if let Some(l) = im.light_intensity {
                if let Some(v) = l
                    .iter()
                    .find(|v| !(v.is_finite() && **v > 1e-9 && **v < 1e9))
                {
                    return bad(format!(
                        "images[{i}] ({}): light_intensity must lie between 1e-9 and 1e9 in each channel, got {v:e}",
                        im.file
                    ));
                }
            }
        }
        if let Some(r) = &self.reference {
            if !self.images.iter().any(|im| same_file(&im.file, &r.image)) {
                return bad(format!(
                    "reference: image {:?} is not one of the session's images",
                    r.image
                ));
            }
            if !(r.reflectance.is_finite() && r.reflectance > 0.0 && r.reflectance <= 1.0) {
                return bad(format!(
                    "reference: reflectance must lie in (0, 1], got {}",
                    r.reflectance
                ));
            }
            let [x0, y0, x1, y1] = r.box_px;
            if !(x0 < x1 && y0 < y1) {
                return bad(format!(
                    "reference: box_px [{x0}, {y0}, {x1}, {y1}] is empty (x0 < x1 and y0 < y1)"
                ));
            }
        }
        let lamps = self
            .images
            .iter()
            .filter(|im| im.light_intensity.is_some())
            .count();
        // One lamp per photo: all given, or none (then each is fitted). Under one light a photo
        // without it keeps the lamp at 1.
        if self.light == LightMode::PerImage && lamps != 0 && lamps != self.images.len() {
            return bad(format!(
                "light_intensity for {lamps} of the {} photos: with \"light\": \"per-image\" give it for all or none (none: each photo's is fitted)",
                self.images.len()
            ));
        }
        Ok(())
    }

    /// Resolve a path written in the session file.
    pub fn resolve(session_file: &Path, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            session_file.parent().unwrap_or(Path::new(".")).join(p)
        }
    }
}

/// The sphere radii a session may give and a fit may hold (mm): a micrometre to 100 m. Beyond, the
/// blur σ0/r and the curvature 1/r leave what the tables and the renderer keep finite.
pub const RADIUS_RANGE_MM: std::ops::Range<f64> = 1e-3..1e5;

/// Whether two photo paths of session.json name the same file, `./` components aside.
pub(crate) fn same_file(a: &str, b: &str) -> bool {
    let norm = |p: &str| -> PathBuf {
        Path::new(p)
            .components()
            .filter(|c| !matches!(c, std::path::Component::CurDir))
            .collect()
    };
    norm(a) == norm(b)
}

/// Whether a path written in session.json stays inside the session folder: relative, and never
/// climbing above its start with `..`.
fn inside(p: &str) -> bool {
    use std::path::Component;
    let mut depth = 0i32;
    for c in Path::new(p).components() {
        match c {
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return false;
                }
            }
            Component::RootDir | Component::Prefix(_) => return false,
        }
    }
    true
}

/// How a photo's pixel values are to be normalised, as found by [`inspect`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImageInfo {
    pub file: String,
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub bits: u8,
    pub channels: u8,
    /// Relative exposure, and where it came from ("session.json" or "EXIF").
    pub exposure: Option<f64>,
    pub exposure_source: Option<&'static str>,
    /// The light's relative intensity per channel in this photo, where session.json gives it.
    pub light_intensity: Option<[f64; 3]>,
    /// What the EXIF reader lost, substituted or ignored, one line each.
    pub exif_notes: Vec<String>,
    pub linear: bool,
    pub radii_mm: Vec<f64>,
}

/// A session checked against its files.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SessionReport {
    pub session_file: PathBuf,
    pub material: Option<String>,
    pub intrinsics_file: Option<PathBuf>,
    pub camera: Option<crate::camera::Camera>,
    pub images: Vec<ImageInfo>,
    /// Whether session.json names a diffuse reference (`reference`: a grey card in one photo).
    #[serde(skip)]
    pub has_reference: bool,
}

impl SessionReport {
    /// Every photo decoded ([`crate::formats::photo::decode_all`]), with `sess`'s linear flags.
    pub fn decode(&self, sess: &Session) -> Result<crate::formats::photo::Decoded> {
        let photos: Vec<(&Path, Option<bool>)> = self
            .images
            .iter()
            .zip(&sess.images)
            .map(|(info, si)| (info.path.as_path(), si.linear))
            .collect();
        crate::formats::photo::decode_all(&photos)
    }

    /// The files a session's results depend on: session.json, the photos, the intrinsics.
    pub fn input_files(&self) -> Vec<PathBuf> {
        let mut v = vec![self.session_file.clone()];
        v.extend(self.images.iter().map(|i| i.path.clone()));
        v.extend(self.intrinsics_file.clone());
        v
    }
}

/// The EXIF exposures of the photos without one in session.json. A photo lacking ISO or f-number
/// is compared at the value the other photos share (100 and f/8 when none has it); when the others
/// differ in it, the photo is refused, naming the field.
fn exif_exposures(
    session_file: &Path,
    images: &mut [ImageInfo],
    exifs: &[Option<crate::formats::photo::ExifInfo>],
) -> Result<()> {
    use crate::formats::exif::{REFERENCE_F_NUMBER, REFERENCE_ISO};
    let from_exif: Vec<usize> = (0..images.len())
        .filter(|&i| images[i].exposure.is_none())
        .filter(|&i| {
            exifs[i]
                .as_ref()
                .is_some_and(|e| e.exposure_time_s.is_some())
        })
        .collect();
    // The value the photos that have the field share, or `reference` when none has it.
    let shared = |field: &dyn Fn(&crate::formats::photo::ExifInfo) -> Option<f64>,
                  name: &str,
                  reference: f64|
     -> Result<f64> {
        let mut have: Vec<f64> = from_exif
            .iter()
            .filter_map(|&i| exifs[i].as_ref().and_then(field))
            .collect();
        have.sort_by(f64::total_cmp);
        have.dedup_by(|a, b| (*a - *b).abs() <= 1e-6 * b.abs());
        let lacking = from_exif
            .iter()
            .find(|&&i| exifs[i].as_ref().and_then(field).is_none());
        match (have.len(), lacking) {
            (0, _) => Ok(reference),
            (1, _) => Ok(have[0]),
            (_, Some(&i)) => Err(Error::invalid(
                &images[i].path,
                format!(
                    "EXIF has no {name} while the session's other photos differ in it ({}): its exposure cannot be compared (give \"exposure\" in {})",
                    have.iter().map(|v| format!("{v}")).collect::<Vec<_>>().join(", "),
                    session_file.display()
                ),
            )),
            (_, None) => Ok(reference),
        }
    };
    let iso = shared(
        &|e| e.iso.map(|v| v as f64),
        "ISO (PhotographicSensitivity)",
        REFERENCE_ISO,
    )?;
    let f_number = shared(
        &|e| e.f_number,
        "FNumber (nor ApertureValue)",
        REFERENCE_F_NUMBER,
    )?;
    for &i in &from_exif {
        let e = exifs[i].as_ref().expect("filtered above");
        images[i].exposure = e.relative_exposure_with(iso, f_number);
        images[i].exposure_source = Some("EXIF");
        if e.iso.is_none() {
            images[i].exif_notes.push(format!(
                "no ISO in EXIF: taken as {iso}, as the other photos"
            ));
        }
        if e.f_number.is_none() {
            images[i].exif_notes.push(format!(
                "no f-number in EXIF: taken as f/{f_number}, as the other photos"
            ));
        }
    }
    Ok(())
}

/// Load a session and check it against its files without decoding pixels: every image exists and
/// decodes its header, the sizes agree with each other and with the intrinsics, and the exposure
/// normalisation is known for all images or for none.
pub fn inspect(path: &Path) -> Result<SessionReport> {
    use image::ImageDecoder;
    let (s, file) = Session::load(path)?;
    let (intrinsics_file, camera) = match &s.intrinsics {
        Some(p) => {
            let ip = Session::resolve(&file, p);
            let cam = crate::formats::intrinsics::IntrinsicsFile::load(&ip)?.camera();
            (Some(ip), Some(cam))
        }
        None => (None, None),
    };
    let mut images = Vec::new();
    let mut exifs = Vec::new();
    for im in &s.images {
        let p = Session::resolve(&file, &im.file);
        crate::formats::input::regular_file(&p)?;
        let reader = image::ImageReader::open(&p)
            .map_err(|e| Error::io(&p, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(&p, e))?;
        let dec = reader.into_decoder().map_err(|e| Error::Image {
            path: p.clone(),
            err: e,
        })?;
        let (mut width, mut height) = dec.dimensions();
        crate::formats::photo::check_size(&p, width, height)?;
        let ct = dec.color_type();
        let channels = ct.channel_count();
        let bits = ct.bytes_per_pixel() / channels * 8;
        let exif = crate::formats::photo::ExifInfo::read(&p)?;
        // Photos are decoded upright (`photo::decode_oriented`): orientations 5–8 swap the sides.
        if exif
            .as_ref()
            .and_then(|e| e.orientation)
            .is_some_and(|o| (5..=8).contains(&o))
        {
            std::mem::swap(&mut width, &mut height);
        }
        if let Some(cam) = &camera {
            if cam.image_size != [width, height] {
                return Err(Error::invalid(
                    &p,
                    format!(
                        "image is {width}×{height} but the intrinsics are for {}×{}",
                        cam.image_size[0], cam.image_size[1]
                    ),
                ));
            }
        }
        images.push(ImageInfo {
            file: im.file.clone(),
            path: p,
            width,
            height,
            bits,
            channels,
            exposure: im.exposure,
            exposure_source: im.exposure.map(|_| "session.json"),
            light_intensity: im.light_intensity,
            exif_notes: exif.as_ref().map(|e| e.notes.clone()).unwrap_or_default(),
            linear: im.linear.unwrap_or(bits > 8),
            radii_mm: im.spheres.iter().map(|s| s.radius_mm).collect(),
        });
        exifs.push(exif);
    }
    exif_exposures(&file, &mut images, &exifs)?;
    let known = images.iter().filter(|i| i.exposure.is_some()).count();
    if known != 0 && known != images.len() {
        let missing: Vec<&str> = images
            .iter()
            .filter(|i| i.exposure.is_none())
            .map(|i| i.file.as_str())
            .collect();
        return Err(Error::invalid(
            &file,
            format!(
                "exposure unknown for {} (no \"exposure\" in session.json and {}): cannot compare with the other images",
                missing.join(", "),
                images
                    .iter()
                    .zip(&exifs)
                    .find(|(i, _)| i.exposure.is_none())
                    .map(|(_, e)| match e {
                        Some(e) => e.no_exposure.clone().unwrap_or_default(),
                        None => "no EXIF".into(),
                    })
                    .unwrap_or_default()
            ),
        ));
    }
    Ok(SessionReport {
        session_file: file,
        material: s.material.clone(),
        intrinsics_file,
        camera,
        images,
        has_reference: s.reference.is_some(),
    })
}
