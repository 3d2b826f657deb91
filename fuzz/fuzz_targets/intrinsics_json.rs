//! intrinsics.json as every command reads it (`Intrinsics::load`: parse and the bounds), then the
//! camera used: a pixel's ray and back, and a sphere's silhouette. Must never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("workbench-fuzz-{}.json", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let Ok(f) = workbench::formats::intrinsics::IntrinsicsFile::load(&path) else {
        return;
    };
    let cam = f.camera();
    let proj = workbench::camera::outline::Projection::Perspective(cam);
    for px in [[0.0, 0.0], [cam.cx, cam.cy], [f.image_size[0] as f64, f.image_size[1] as f64]] {
        if let Some(ray) = proj.point(nalgebra::Vector2::from(px)) {
            let _ = proj.pixel(&(ray * 500.0));
        }
    }
    let sphere = workbench::camera::sphere::Sphere {
        center: nalgebra::Vector3::new(10.0, -5.0, 400.0),
        radius: 20.0,
    };
    let _ = sphere.image_ellipse(&cam);
});
