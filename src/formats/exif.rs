//! EXIF as cameras and tools write it: read tolerantly, every field that parses is used, and what
//! was lost or substituted is said in one line each (`ExifInfo::notes`).
//!
//! The exposure convention (README, "Conventions"): a linear pixel value (full scale 1) is
//! scene radiance times the *relative exposure*
//!
//!     exposure = ExposureTime[s] · (ISO / 100) · (8 / FNumber)² · 30
//!
//! i.e. exposure 1 is 1/30 s at f/8 and ISO 100. The time comes from ExposureTime, else from the
//! APEX ShutterSpeedValue (t = 2^−Tv); the f-number from FNumber, else from the APEX ApertureValue
//! (N = 2^(Av/2)). A photo without ISO or f-number is compared at the value the session's other
//! photos share (`crate::formats::session::inspect` decides, and refuses when they differ).

use crate::error::{Error, Result};
use exif::{experimental::Writer, Field, In, Rational, Tag, Value};
use std::path::Path;

/// The photographic settings and camera identity a photo's EXIF carries.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExifInfo {
    pub make: String,
    pub model: String,
    pub exposure_time_s: Option<f64>,
    pub iso: Option<u32>,
    pub f_number: Option<f64>,
    pub focal_length_mm: Option<f64>,
    pub focal_length_35mm: Option<u32>,
    /// The Orientation tag (1–8), when present.
    pub orientation: Option<u16>,
    /// What was lost, substituted or ignored while reading, one line each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Why there is no exposure time, when there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_exposure: Option<String>,
}

/// ISO and f-number at which the relative exposure is 1 (with 1/30 s).
pub(crate) const REFERENCE_ISO: f64 = 100.0;
pub(crate) const REFERENCE_F_NUMBER: f64 = 8.0;

/// The relative exposure of the convention above.
pub fn relative_exposure(exposure_time_s: f64, iso: f64, f_number: f64) -> f64 {
    exposure_time_s * (iso / REFERENCE_ISO) * (REFERENCE_F_NUMBER / f_number).powi(2) * 30.0
}

// Tag numbers, looked up in whichever directory holds them: dcraw and some TIFF writers put
// ExposureTime and its kin in IFD0 rather than in the Exif sub-IFD.
const EXPOSURE_TIME: u16 = 0x829a;
const F_NUMBER: u16 = 0x829d;
const ISO: u16 = 0x8827;
const SHUTTER_SPEED: u16 = 0x9201;
const APERTURE: u16 = 0x9202;
const FOCAL_LENGTH: u16 = 0x920a;
const FOCAL_35MM: u16 = 0xa405;
const ORIENTATION: u16 = 0x0112;
const MAKE: u16 = 0x010f;
const MODEL: u16 = 0x0110;

/// The first value of a rational field, signed or not, as (numerator, denominator).
fn ratio(v: &Value) -> Option<(f64, f64)> {
    match v {
        Value::Rational(r) => r.first().map(|q| (q.num as f64, q.denom as f64)),
        Value::SRational(r) => r.first().map(|q| (q.num as f64, q.denom as f64)),
        _ => None,
    }
}

/// How a decoder turns a photo of each Orientation upright (EXIF 2.3, table of Orientation).
fn orientation_words(o: u16) -> &'static str {
    match o {
        2 => "mirrored left–right",
        3 => "turned 180°",
        4 => "mirrored top–bottom",
        5 => "mirrored and turned 90°",
        6 => "turned 90° clockwise",
        7 => "mirrored and turned 90° anticlockwise",
        8 => "turned 90° anticlockwise",
        _ => "not a valid orientation",
    }
}

impl ExifInfo {
    /// The relative exposure, with `iso` and `f_number` standing in for missing tags; `None`
    /// without an exposure time.
    pub(crate) fn relative_exposure_with(&self, iso: f64, f_number: f64) -> Option<f64> {
        Some(relative_exposure(
            self.exposure_time_s?,
            self.iso.map_or(iso, |v| v as f64),
            self.f_number.unwrap_or(f_number),
        ))
    }

    /// The relative exposure, missing ISO and f-number taken at the reference (100, f/8).
    pub fn relative_exposure(&self) -> Option<f64> {
        self.relative_exposure_with(REFERENCE_ISO, REFERENCE_F_NUMBER)
    }

    /// Settings at ISO 100 and f/8 that give a relative exposure (only the time varies).
    pub(crate) fn for_exposure(
        exposure: f64,
        make: &str,
        model: &str,
        focal_mm: f64,
        f35: u32,
    ) -> Self {
        ExifInfo {
            make: make.into(),
            model: model.into(),
            exposure_time_s: Some(exposure / 30.0),
            iso: Some(REFERENCE_ISO as u32),
            f_number: Some(REFERENCE_F_NUMBER),
            focal_length_mm: Some(focal_mm),
            focal_length_35mm: Some(f35),
            ..Default::default()
        }
    }

    /// Encode as a TIFF/Exif block (the payload of a JPEG APP1 "Exif" segment).
    pub(crate) fn to_tiff(&self) -> Result<Vec<u8>> {
        // Rationals with a fixed denominator (ExposureTime keeps a power-of-ten denominator so that
        // 1/30 s survives with 9 significant digits).
        let rational = |v: f64, denom: u32| Rational {
            num: (v * denom as f64).round() as u32,
            denom,
        };
        let field = |tag, value| Field {
            tag,
            ifd_num: In::PRIMARY,
            value,
        };
        let mut fields = vec![
            field(
                Tag::Make,
                Value::Ascii(vec![self.make.clone().into_bytes()]),
            ),
            field(
                Tag::Model,
                Value::Ascii(vec![self.model.clone().into_bytes()]),
            ),
        ];
        if let Some(t) = self.exposure_time_s {
            fields.push(field(
                Tag::ExposureTime,
                Value::Rational(vec![rational(t, 1_000_000_000)]),
            ));
        }
        if let Some(n) = self.f_number {
            fields.push(field(
                Tag::FNumber,
                Value::Rational(vec![rational(n, 1000)]),
            ));
        }
        if let Some(iso) = self.iso {
            fields.push(field(
                Tag::PhotographicSensitivity,
                Value::Short(vec![iso.min(65535) as u16]),
            ));
        }
        if let Some(f) = self.focal_length_mm {
            fields.push(field(
                Tag::FocalLength,
                Value::Rational(vec![rational(f, 1000)]),
            ));
        }
        if let Some(f35) = self.focal_length_35mm {
            fields.push(field(
                Tag::FocalLengthIn35mmFilm,
                Value::Short(vec![f35.min(65535) as u16]),
            ));
        }
        let mut w = Writer::new();
        for f in &fields {
            w.push_field(f);
        }
        let mut buf = std::io::Cursor::new(Vec::new());
        w.write(&mut buf, false)
            .map_err(|e| Error::Argument(format!("cannot encode EXIF: {e}")))?;
        Ok(buf.into_inner())
    }

    /// Read the EXIF of a JPEG, TIFF or PNG file; `None` when it has none. A damaged block is read
    /// as far as it parses, with a note for what was skipped.
    pub fn read(path: &Path) -> Result<Option<ExifInfo>> {
        crate::formats::input::regular_file(path)?;
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut r = std::io::BufReader::new(file);
        let (ex, errors) = match exif::Reader::new()
            .continue_on_error(true)
            .read_from_container(&mut r)
        {
            Ok(ex) => (ex, vec![]),
            Err(exif::Error::PartialResult(p)) => p.into_inner(),
            Err(exif::Error::NotFound(_)) => return Ok(None),
            Err(exif::Error::Io(e)) => return Err(Error::io(path, e)),
            // The block is there but not even its header parses: the photo loads without it.
            Err(e) => {
                return Ok(Some(ExifInfo {
                    notes: vec![format!("EXIF unreadable ({e}): no camera settings from it")],
                    no_exposure: Some(format!("its EXIF is unreadable ({e})")),
                    ..Default::default()
                }))
            }
        };
        Ok(Some(Self::from_fields(ex.fields(), &errors)))
    }

    /// The settings from parsed fields (IFD0 and its sub-IFDs), the parser's complaints as notes.
    fn from_fields<'a>(
        fields: impl Iterator<Item = &'a Field>,
        errors: &[exif::Error],
    ) -> ExifInfo {
        let fields: Vec<&Field> = fields.filter(|f| f.ifd_num == In::PRIMARY).collect();
        let get = |n: u16| {
            fields
                .iter()
                .find(|f| f.tag.number() == n)
                .map(|f| &f.value)
        };
        let mut info = ExifInfo::default();
        for e in errors {
            info.notes.push(match e.to_string().as_str() {
                "Unexpected next IFD" => "EXIF: a sub-IFD links to a next IFD (not allowed there, ignored; its fields kept)".into(),
                m => format!("EXIF damaged ({m}): that part skipped, every field that parsed used"),
            });
        }
        let ascii = |n| match get(n) {
            Some(Value::Ascii(v)) if !v.is_empty() => String::from_utf8_lossy(&v[0])
                .trim_end_matches('\0')
                .trim()
                .to_string(),
            _ => String::new(),
        };
        info.make = ascii(MAKE);
        info.model = ascii(MODEL);
        // A positive finite rational, or a note saying why the field was not used.
        let positive = |n: u16, name: &str, notes: &mut Vec<String>| -> Option<f64> {
            let Some((num, den)) = ratio(get(n)?) else {
                notes.push(format!("EXIF {name} is not a rational number: ignored"));
                return None;
            };
            if den == 0.0 {
                notes.push(format!(
                    "EXIF {name} is {num}/0 (zero denominator): ignored"
                ));
                return None;
            }
            let v = num / den;
            if !(v > 0.0) || !v.is_finite() {
                notes.push(format!("EXIF {name} is {v}: ignored"));
                return None;
            }
            Some(v)
        };
        let time = positive(EXPOSURE_TIME, "ExposureTime", &mut info.notes);
        let f_number = positive(F_NUMBER, "FNumber", &mut info.notes);
        let focal = positive(FOCAL_LENGTH, "FocalLength", &mut info.notes);
        // APEX values may be negative (Tv < 0: longer than 1 s), so they are read signed.
        let apex = |n: u16| {
            let (num, den) = ratio(get(n)?)?;
            (den != 0.0).then(|| num / den)
        };
        info.exposure_time_s = time.or_else(|| {
            let t = 2f64.powf(-apex(SHUTTER_SPEED)?);
            (t.is_finite() && t > 0.0).then(|| {
                info.notes.push(format!(
                    "exposure time {t:.4} s from ShutterSpeedValue (APEX), ExposureTime missing"
                ));
                t
            })
        });
        if info.exposure_time_s.is_none() {
            info.no_exposure = Some(
                match info.notes.iter().find(|n| n.contains("ExposureTime")) {
                    Some(n) => n.clone(),
                    None => "its EXIF has neither ExposureTime nor ShutterSpeedValue".into(),
                },
            );
        }
        info.f_number = f_number.or_else(|| {
            let n = 2f64.powf(apex(APERTURE)? / 2.0);
            (n.is_finite() && n > 0.0).then(|| {
                info.notes.push(format!(
                    "f-number f/{n:.1} from ApertureValue (APEX), FNumber missing"
                ));
                n
            })
        });
        info.iso = get(ISO).and_then(|v| v.get_uint(0)).filter(|&v| v > 0);
        info.focal_length_mm = focal;
        info.focal_length_35mm = get(FOCAL_35MM)
            .and_then(|v| v.get_uint(0))
            .filter(|&v| v > 0);
        info.orientation = get(ORIENTATION)
            .and_then(|v| v.get_uint(0))
            .map(|v| v.min(u16::MAX as u32) as u16);
        if let Some(o) = info.orientation.filter(|&o| o != 1) {
            info.notes.push(format!(
                "Orientation {o}: the pixels are {} as they are decoded (the calibration photos are too)",
                orientation_words(o)
            ));
        }
        info
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_exposure_is_one() {
        assert!((relative_exposure(1.0 / 30.0, 100.0, 8.0) - 1.0).abs() < 1e-12);
        assert!((relative_exposure(1.0 / 60.0, 400.0, 8.0) - 2.0).abs() < 1e-12);
        assert!((relative_exposure(1.0 / 30.0, 100.0, 4.0) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn written_settings_read_back() {
        let e = ExifInfo::for_exposure(2.0, "Maker", "Cam", 12.5, 35);
        let tiff = e.to_tiff().unwrap();
        let ex = exif::Reader::new().read_raw(tiff).unwrap();
        let back = ExifInfo::from_fields(ex.fields(), &[]);
        assert_eq!(back.make, "Maker");
        assert!((back.relative_exposure().unwrap() - 2.0).abs() < 1e-8);
        assert_eq!(back.iso, Some(100));
        assert_eq!(back.focal_length_35mm, Some(35));
        assert!(back.notes.is_empty(), "{:?}", back.notes);
    }
}
