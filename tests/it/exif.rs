//! EXIF as cameras and tools write it: hand-built blobs with the quirks found in the wild, each
//! either loaded (with a note for what was lost) or refused with one line naming the photo and the
//! field.

use std::path::{Path, PathBuf};
use workbench::formats::photo::ExifInfo;

// ---- a little-endian TIFF/EXIF writer that can be told to be wrong ----

const ASCII: u16 = 2;
const SHORT: u16 = 3;
const LONG: u16 = 4;
const RATIONAL: u16 = 5;
const UNDEFINED: u16 = 7;
const SRATIONAL: u16 = 10;

struct Entry {
    tag: u16,
    typ: u16,
    count: u32,
    bytes: Vec<u8>,
    /// Write this as the value offset instead of where the bytes are (a garbage offset).
    bad_offset: Option<u32>,
}

fn entry(tag: u16, typ: u16, count: u32, bytes: Vec<u8>) -> Entry {
    Entry {
        tag,
        typ,
        count,
        bytes,
        bad_offset: None,
    }
}
fn short(tag: u16, v: u16) -> Entry {
    entry(tag, SHORT, 1, v.to_le_bytes().to_vec())
}
fn rational(tag: u16, num: u32, den: u32) -> Entry {
    entry(
        tag,
        RATIONAL,
        1,
        [num.to_le_bytes(), den.to_le_bytes()].concat(),
    )
}
fn srational(tag: u16, num: i32, den: i32) -> Entry {
    entry(
        tag,
        SRATIONAL,
        1,
        [num.to_le_bytes(), den.to_le_bytes()].concat(),
    )
}
fn ascii(tag: u16, s: &str) -> Entry {
    let mut b = s.as_bytes().to_vec();
    b.push(0);
    entry(tag, ASCII, b.len() as u32, b)
}

const MAKE: u16 = 0x010f;
const MODEL: u16 = 0x0110;
const ORIENTATION: u16 = 0x0112;
const EXIF_IFD: u16 = 0x8769;
const EXPOSURE_TIME: u16 = 0x829a;
const F_NUMBER: u16 = 0x829d;
const ISO: u16 = 0x8827;
const SHUTTER_SPEED: u16 = 0x9201;
const APERTURE: u16 = 0x9202;
const FOCAL_LENGTH: u16 = 0x920a;
const MAKER_NOTE: u16 = 0x927c;

/// A TIFF block: header, the values longer than 4 bytes, IFD0 (with a pointer to the Exif IFD when
/// `exif` is not empty), the Exif IFD with `exif_next` as its next-IFD offset.
fn tiff(ifd0: Vec<Entry>, exif: Vec<Entry>, exif_next: u32) -> Vec<u8> {
    let mut out = b"II*\0".to_vec();
    out.extend(0u32.to_le_bytes()); // IFD0 offset, patched below
                                    // Values longer than 4 bytes first, so that a cut through an IFD keeps them.
    let place = |es: &[Entry], out: &mut Vec<u8>| -> Vec<u32> {
        es.iter()
            .map(|e| {
                if e.bytes.len() <= 4 {
                    return 0;
                }
                if out.len() % 2 == 1 {
                    out.push(0);
                }
                let at = out.len() as u32;
                out.extend(&e.bytes);
                at
            })
            .collect()
    };
    let at0 = place(&ifd0, &mut out);
    let at1 = place(&exif, &mut out);
    if out.len() % 2 == 1 {
        out.push(0);
    }
    let n0 = ifd0.len() + usize::from(!exif.is_empty());
    let ifd0_at = out.len() as u32;
    let exif_at = ifd0_at + 2 + 12 * n0 as u32 + 4;
    out[4..8].copy_from_slice(&ifd0_at.to_le_bytes());
    let write = |out: &mut Vec<u8>, e: &Entry, at: u32| {
        out.extend(e.tag.to_le_bytes());
        out.extend(e.typ.to_le_bytes());
        out.extend(e.count.to_le_bytes());
        let mut v = [0u8; 4];
        if let Some(o) = e.bad_offset {
            v = o.to_le_bytes();
        } else if e.bytes.len() <= 4 {
            v[..e.bytes.len()].copy_from_slice(&e.bytes);
        } else {
            v = at.to_le_bytes();
        }
        out.extend(v);
    };
    out.extend((n0 as u16).to_le_bytes());
    for (e, &at) in ifd0.iter().zip(&at0) {
        write(&mut out, e, at);
    }
    if !exif.is_empty() {
        write(
            &mut out,
            &entry(EXIF_IFD, LONG, 1, exif_at.to_le_bytes().to_vec()),
            0,
        );
    }
    out.extend(0u32.to_le_bytes());
    if !exif.is_empty() {
        assert_eq!(out.len() as u32, exif_at);
        out.extend((exif.len() as u16).to_le_bytes());
        for (e, &at) in exif.iter().zip(&at1) {
            write(&mut out, e, at);
        }
        out.extend(exif_next.to_le_bytes());
    }
    out
}

/// The settings a careful camera writes: 1/60 s, f/5.6, ISO 200, 35 mm.
fn camera_ifd0() -> Vec<Entry> {
    vec![ascii(MAKE, "Maker"), ascii(MODEL, "Model X")]
}
fn camera_exif(iso: u16) -> Vec<Entry> {
    vec![
        rational(EXPOSURE_TIME, 1, 60),
        rational(F_NUMBER, 56, 10),
        short(ISO, iso),
        rational(FOCAL_LENGTH, 35, 1),
    ]
}
fn exposure(t: f64, iso: f64, n: f64) -> f64 {
    t * (iso / 100.0) * (8.0 / n).powi(2) * 30.0
}

/// A fresh temporary folder of the test's own (removed when the guard drops).
fn dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("workbench-exif-{name}-"))
        .tempdir()
        .unwrap()
}

/// A 64×48 grey JPEG carrying `block` as its EXIF.
fn jpeg(path: &Path, block: Vec<u8>) {
    use image::ImageEncoder;
    let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(
        std::fs::File::create(path).unwrap(),
        90,
    );
    enc.set_exif_metadata(block).unwrap();
    enc.write_image(
        &[100u8; 64 * 48 * 3],
        64,
        48,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
}

fn read(name: &str, block: Vec<u8>) -> ExifInfo {
    let guard = dir(name);
    let d = guard.path();
    let p = d.join("a.jpg");
    jpeg(&p, block);
    ExifInfo::read(&p).unwrap().expect("the JPEG has EXIF")
}

fn session(d: &Path, files: &[&str]) -> PathBuf {
    let images: Vec<String> = files
        .iter()
        .map(|f| format!(r#"{{"file": "{f}", "spheres": [{{"radius_mm": 20}}]}}"#))
        .collect();
    let p = d.join("session.json");
    std::fs::write(
        &p,
        format!(
            r#"{{"schema": "workbench.session/1", "images": [{}]}}"#,
            images.join(", ")
        ),
    )
    .unwrap();
    p
}

#[test]
fn clean_block_reads_every_setting() {
    let e = read("clean", tiff(camera_ifd0(), camera_exif(200), 0));
    assert_eq!((e.make.as_str(), e.model.as_str()), ("Maker", "Model X"));
    let x = e.relative_exposure().unwrap();
    assert!((x - exposure(1.0 / 60.0, 200.0, 5.6)).abs() < 1e-12, "{x}");
    assert_eq!(e.focal_length_mm, Some(35.0));
    assert!(e.notes.is_empty(), "{:?}", e.notes);
}

#[test]
fn sub_ifd_with_a_next_ifd_loads_with_a_note() {
    // What a common Python EXIF library writes: the Exif IFD's next-IFD offset is not zero.
    let e = read("next", tiff(camera_ifd0(), camera_exif(200), 8));
    assert!((e.relative_exposure().unwrap() - exposure(1.0 / 60.0, 200.0, 5.6)).abs() < 1e-12);
    assert_eq!(e.notes.len(), 1, "{:?}", e.notes);
    assert!(e.notes[0].contains("next IFD"), "{:?}", e.notes);
}

#[test]
fn truncated_ifd_keeps_the_fields_before_the_cut() {
    let mut b = tiff(camera_ifd0(), camera_exif(200), 0);
    // Cut inside the Exif IFD's fourth entry (FocalLength): the first three survive.
    let cut = b.len() - 4 - 12 + 5;
    b.truncate(cut);
    let e = read("truncated", b);
    assert!((e.relative_exposure().unwrap() - exposure(1.0 / 60.0, 200.0, 5.6)).abs() < 1e-12);
    assert_eq!(e.focal_length_mm, None);
    assert!(
        e.notes.iter().any(|n| n.contains("Truncated IFD")),
        "{:?}",
        e.notes
    );
}

#[test]
fn maker_note_with_a_garbage_offset_is_skipped() {
    let mut exif = camera_exif(200);
    exif.push(Entry {
        bad_offset: Some(0xFFFF_FF00),
        ..entry(MAKER_NOTE, UNDEFINED, 64, vec![0; 64])
    });
    let e = read("makernote", tiff(camera_ifd0(), exif, 0));
    assert!((e.relative_exposure().unwrap() - exposure(1.0 / 60.0, 200.0, 5.6)).abs() < 1e-12);
    assert_eq!(e.notes.len(), 1, "{:?}", e.notes);
    assert!(e.notes[0].contains("damaged"), "{:?}", e.notes);
}

#[test]
fn zero_denominator_falls_back_to_apex_or_says_so() {
    // ExposureTime 1/0 with ShutterSpeedValue Tv = 6 (1/64 s) beside it: the APEX value is used.
    let mut exif = camera_exif(100);
    exif[0] = rational(EXPOSURE_TIME, 1, 0);
    exif.push(srational(SHUTTER_SPEED, 6, 1));
    let e = read("zero-apex", tiff(camera_ifd0(), exif, 0));
    let x = e.relative_exposure().unwrap();
    assert!((x - exposure(1.0 / 64.0, 100.0, 5.6)).abs() < 1e-12, "{x}");
    assert!(
        e.notes.iter().any(|n| n.contains("ExposureTime is 1/0")),
        "{:?}",
        e.notes
    );
    assert!(
        e.notes.iter().any(|n| n.contains("ShutterSpeedValue")),
        "{:?}",
        e.notes
    );
    // Without it the exposure is unknown, and says why.
    let mut exif = camera_exif(100);
    exif[0] = rational(EXPOSURE_TIME, 1, 0);
    let e = read("zero", tiff(camera_ifd0(), exif, 0));
    assert_eq!(e.exposure_time_s, None);
    assert!(e
        .no_exposure
        .as_deref()
        .unwrap()
        .contains("ExposureTime is 1/0"));
}

#[test]
fn apex_values_alone_give_the_exposure() {
    // Tv = 5 (1/32 s), Av = 6 (f/8), no ExposureTime or FNumber.
    let exif = vec![
        srational(SHUTTER_SPEED, 5, 1),
        rational(APERTURE, 6, 1),
        short(ISO, 400),
    ];
    let e = read("apex", tiff(camera_ifd0(), exif, 0));
    let x = e.relative_exposure().unwrap();
    assert!((x - exposure(1.0 / 32.0, 400.0, 8.0)).abs() < 1e-12, "{x}");
    assert_eq!(e.notes.len(), 2, "{:?}", e.notes);
}

#[test]
fn unreadable_block_loads_without_settings() {
    let e = read("garbage", b"XX*\0garbage that is not TIFF".to_vec());
    assert_eq!(e.exposure_time_s, None);
    assert!(e.notes[0].contains("unreadable"), "{:?}", e.notes);
}

#[test]
fn iso_and_f_number_enter_the_exposure_scale() {
    let guard = dir("iso");
    let d = guard.path();
    jpeg(&d.join("a.jpg"), tiff(camera_ifd0(), camera_exif(100), 0));
    jpeg(&d.join("b.jpg"), tiff(camera_ifd0(), camera_exif(200), 0));
    let mut exif = camera_exif(100);
    exif[1] = rational(F_NUMBER, 4, 1);
    jpeg(&d.join("c.jpg"), tiff(camera_ifd0(), exif, 0));
    let r =
        workbench::formats::session::inspect(&session(d, &["a.jpg", "b.jpg", "c.jpg"])).unwrap();
    let x: Vec<f64> = r.images.iter().map(|i| i.exposure.unwrap()).collect();
    // ISO 200 is twice ISO 100; f/4 is (5.6/4)² = 1.96 times f/5.6.
    assert!((x[1] / x[0] - 2.0).abs() < 1e-12, "{x:?}");
    assert!((x[2] / x[0] - 1.96).abs() < 1e-12, "{x:?}");
    assert!(r.images.iter().all(|i| i.exposure_source == Some("EXIF")));

    // A photo without ISO beside photos that differ in it: refused, naming the photo and field.
    let mut exif = camera_exif(100);
    exif.remove(2);
    jpeg(&d.join("n.jpg"), tiff(camera_ifd0(), exif, 0));
    let err = workbench::formats::session::inspect(&session(d, &["a.jpg", "b.jpg", "n.jpg"]))
        .unwrap_err()
        .to_string();
    assert!(err.contains("n.jpg") && err.contains("ISO"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    // Beside photos that agree (ISO 100): taken as theirs, with a note.
    let r = workbench::formats::session::inspect(&session(d, &["a.jpg", "n.jpg"])).unwrap();
    assert!((r.images[1].exposure.unwrap() - r.images[0].exposure.unwrap()).abs() < 1e-15);
    assert!(r.images[1].exif_notes.iter().any(|n| n.contains("no ISO")));

    // ExposureTime 1/0 beside photos with exposures: one line naming the photo and the field.
    let mut exif = camera_exif(100);
    exif[0] = rational(EXPOSURE_TIME, 1, 0);
    jpeg(&d.join("z.jpg"), tiff(camera_ifd0(), exif, 0));
    let err = workbench::formats::session::inspect(&session(d, &["a.jpg", "z.jpg"]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("z.jpg") && err.contains("ExposureTime is 1/0"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
}

#[test]
fn orientation_turns_the_photo_and_its_size() {
    let guard = dir("orientation");
    let d = guard.path();
    let mut ifd0 = camera_ifd0();
    ifd0.push(short(ORIENTATION, 6));
    jpeg(&d.join("a.jpg"), tiff(ifd0, camera_exif(100), 0));
    let r = workbench::formats::session::inspect(&session(d, &["a.jpg"])).unwrap();
    // Stored 64×48, shown (and decoded) 48×64.
    assert_eq!((r.images[0].width, r.images[0].height), (48, 64));
    let img = workbench::formats::photo::load_linear_rgb(&d.join("a.jpg"), None).unwrap();
    assert_eq!((img.width, img.height), (48, 64));
    assert!(r.images[0].exif_notes[0].contains("Orientation 6"));
}

/// A 16-bit RGB TIFF with its settings in an Exif sub-IFD, as dcraw -4 -T or LibRaw's dcraw_emu
/// write raw conversions.
fn tiff16(path: &Path, w: u32, h: u32, px: &[u16]) {
    use exif::{experimental::Writer, Field, In, Rational, Tag, Value};
    let f = |tag, value| Field {
        tag,
        ifd_num: In::PRIMARY,
        value,
    };
    let fields = [
        f(Tag::ImageWidth, Value::Long(vec![w])),
        f(Tag::ImageLength, Value::Long(vec![h])),
        f(Tag::BitsPerSample, Value::Short(vec![16, 16, 16])),
        f(Tag::Compression, Value::Short(vec![1])),
        f(Tag::PhotometricInterpretation, Value::Short(vec![2])),
        f(Tag::SamplesPerPixel, Value::Short(vec![3])),
        f(Tag::RowsPerStrip, Value::Long(vec![h])),
        f(Tag::PlanarConfiguration, Value::Short(vec![1])),
        f(Tag::Make, Value::Ascii(vec![b"Maker".to_vec()])),
        f(
            Tag::ExposureTime,
            Value::Rational(vec![Rational { num: 1, denom: 125 }]),
        ),
        f(
            Tag::FNumber,
            Value::Rational(vec![Rational { num: 11, denom: 1 }]),
        ),
        f(Tag::PhotographicSensitivity, Value::Short(vec![100])),
    ];
    let bytes: Vec<u8> = px.iter().flat_map(|v| v.to_le_bytes()).collect();
    let strips = [bytes.as_slice()];
    let mut wr = Writer::new();
    for x in &fields {
        wr.push_field(x);
    }
    wr.set_strips(&strips, In::PRIMARY);
    let mut buf = std::io::Cursor::new(Vec::new());
    wr.write(&mut buf, true).unwrap();
    std::fs::write(path, buf.into_inner()).unwrap();
}

#[test]
fn raw_conversion_tiff_loads_as_linear_with_its_exposure() {
    let guard = dir("tiff16");
    let d = guard.path();
    let (w, h) = (40u32, 36u32);
    let px: Vec<u16> = (0..w * h * 3).map(|i| (i * 37 % 65536) as u16).collect();
    tiff16(&d.join("a.tiff"), w, h, &px);
    let r = workbench::formats::session::inspect(&session(d, &["a.tiff"])).unwrap();
    let im = &r.images[0];
    assert_eq!((im.bits, im.linear, im.width, im.height), (16, true, w, h));
    let x = im.exposure.unwrap();
    assert!(
        (x - exposure(1.0 / 125.0, 100.0, 11.0)).abs() < 1e-12,
        "{x}"
    );
    assert!(im.exif_notes.is_empty(), "{:?}", im.exif_notes);
    // Linear: value / 65535, no transfer curve.
    let img = workbench::formats::photo::load_linear_rgb(&d.join("a.tiff"), None).unwrap();
    for (k, (&a, &b)) in img.data.iter().zip(&px).enumerate().step_by(97) {
        assert!(
            (a as f64 - b as f64 / 65535.0).abs() < 1e-6,
            "sample {k}: {a} vs {b}"
        );
    }
}
