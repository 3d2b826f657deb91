//! detections.json as `solve` consumes it: parse, then each sphere's outline turned into its pixel
//! box and its samples on a small grey photo, through an orthographic camera and a perspective
//! one. Must never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use workbench::camera::outline::Projection;
use workbench::camera::Camera;
use workbench::formats::detections::Detections;
use workbench::formats::photo::LinearRgb;

fuzz_target!(|data: &[u8]| {
    let Ok(d) = serde_json::from_slice::<Detections>(data) else {
        return;
    };
    let img = LinearRgb {
        width: 64,
        height: 48,
        data: vec![0.25f32; 3 * 64 * 48],
        saturated: vec![false; 64 * 48],
        bits: 16,
    };
    let cameras = [
        Projection::Orthographic,
        Projection::Perspective(Camera::from_fov(64, 48, 60.0)),
    ];
    for image in &d.images {
        for s in &image.spheres {
            let outline = s.outline.outline();
            for proj in &cameras {
                let _ = outline.ellipse(proj);
                let _ = outline.center_mm(s.radius_mm);
                let light = d.light_direction.map(nalgebra::Vector3::from);
                let _ = workbench::detect::samples::sphere_samples(
                    &img,
                    image.exposure.unwrap_or(1.0),
                    proj,
                    &outline,
                    s.radius_mm,
                    light.as_ref(),
                    s.highlight.as_ref().map(|h| h.radius_deg.to_radians()),
                );
            }
        }
    }
});
