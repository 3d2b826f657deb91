//! Photo loading: EXIF orientation honoured, 16-bit input, bad files named.

use image::codecs::jpeg::JpegEncoder;
use image::{ExtendedColorType, ImageEncoder};

fn jpeg_with_orientation(path: &std::path::Path, orientation: u16) {
    // 40×20: left half black, right half white.
    let data: Vec<u8> = (0..20)
        .flat_map(|_| (0..40).map(|x| if x < 20 { 0u8 } else { 255 }))
        .collect();
    let field = exif::Field {
        tag: exif::Tag::Orientation,
        ifd_num: exif::In::PRIMARY,
        value: exif::Value::Short(vec![orientation]),
    };
    let mut w = exif::experimental::Writer::new();
    w.push_field(&field);
    let mut tiff = std::io::Cursor::new(Vec::new());
    w.write(&mut tiff, false).unwrap();
    let mut out = Vec::new();
    let mut enc = JpegEncoder::new_with_quality(&mut out, 95);
    enc.set_exif_metadata(tiff.into_inner()).unwrap();
    enc.write_image(&data, 40, 20, ExtendedColorType::L8)
        .unwrap();
    std::fs::write(path, out).unwrap();
}

#[test]
fn exif_orientation_is_applied() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("o.jpg");
    jpeg_with_orientation(&p, 1);
    let g = workbench::formats::photo::load_gray8(&p).unwrap();
    assert_eq!((g.width, g.height), (40, 20));
    assert!(g.data[20 * 40 / 2 + 2] < 40 && g.data[20 * 40 / 2 + 37] > 215);
    // 6: rotate 90° clockwise to display — the left (black) half becomes the top.
    jpeg_with_orientation(&p, 6);
    let g = workbench::formats::photo::load_gray8(&p).unwrap();
    assert_eq!((g.width, g.height), (20, 40));
    assert!(g.data[2 * 20 + 10] < 40, "top is black");
    assert!(g.data[37 * 20 + 10] > 215, "bottom is white");
}

#[test]
fn sixteen_bit_png_loads_as_grey() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.png");
    let rgb: Vec<u16> = (0..8 * 8)
        .flat_map(|i| {
            let v = if i % 8 < 4 { 0 } else { 65535 };
            [v, v, v]
        })
        .collect();
    workbench::formats::photo::write_png16_rgb(&p, 8, 8, &rgb).unwrap();
    let g = workbench::formats::photo::load_gray8(&p).unwrap();
    assert_eq!((g.width, g.height), (8, 8));
    assert_eq!((g.data[0], g.data[7]), (0, 255));
}

#[test]
fn bad_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("notes.jpg");
    std::fs::write(&p, "plain text, not a photo").unwrap();
    let e = workbench::formats::photo::load_gray8(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("notes.jpg") && !e.contains('\n'), "{e}");
    let e = workbench::formats::photo::load_gray8(&dir.path().join("missing.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.png: No such file"), "{e}");
}

#[test]
fn linear_loading_decodes_srgb_and_flags_saturation() {
    let dir = tempfile::tempdir().unwrap();
    // 8-bit sRGB JPEG-free path: an 8-bit PNG with codes 0, 128, 255.
    let p = dir.path().join("s.png");
    let data: Vec<u8> = [0u8, 128, 255].iter().flat_map(|&v| [v, v, v]).collect();
    workbench::formats::photo::write_8bit(&p, 3, 1, 3, &data, 0, None).unwrap();
    let img = workbench::formats::photo::load_linear_rgb(&p, None).unwrap();
    assert_eq!(img.bits, 8);
    let expect = workbench::formats::photo::srgb_decode(128.0 / 255.0) as f32;
    assert!((img.data[3] - expect).abs() < 1e-6 && img.data[0] == 0.0 && img.data[6] == 1.0);
    assert_eq!(img.saturated, [false, false, true]);
    // Declared linear: no transfer curve.
    let img = workbench::formats::photo::load_linear_rgb(&p, Some(true)).unwrap();
    assert!((img.data[3] - 128.0 / 255.0).abs() < 1e-6);
    // 16-bit: linear by default.
    let q = dir.path().join("l.png");
    workbench::formats::photo::write_png16_rgb(&q, 2, 1, &[0, 0, 0, 32768, 65535, 65535]).unwrap();
    let img = workbench::formats::photo::load_linear_rgb(&q, None).unwrap();
    assert_eq!(img.bits, 16);
    assert!((img.data[3] - 0.5).abs() < 1e-4 && img.data[5] == 1.0);
    assert_eq!(img.saturated, [false, true]);
    assert!((img.luminance(1, 0) - (0.2126 * 0.5 + 0.7152 + 0.0722)).abs() < 1e-4);
}
