//! Frame time of `workbench render`: the Stanford bunny (../shared/data/meshes, 69 451 triangles)
//! at 1280×720 with the synthetic wax's CDRF, after loading (mesh, curvature and table are built
//! once, outside the timing; the image buffers are reused frame to frame). Samples 1/4/16, CDRF against Lambert shading, 1 thread against all.
//!
//!     cargo bench --bench render

use criterion::{criterion_group, criterion_main, Criterion};
use std::path::Path;
use workbench::camera::Camera;
use workbench::model::{LightAngles, Model};
use workbench::render::job::{prepare, shader, table, TableSize};
use workbench::render::lut::FitMaterial;
use workbench::render::raster::{render, render_into, Samples, Scene, Shading, View};
use workbench::synth::session::SessionConfig;

fn bench_bunny(c: &mut Criterion) {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/meshes/stanford-bunny.obj");
    if !path.exists() {
        println!("skipped: {} absent", path.display());
        return;
    }
    let fm = FitMaterial {
        model: Model::default(),
        material: SessionConfig::default().material,
        light: LightAngles {
            azimuth: 70f64.to_radians(),
            elevation: 20f64.to_radians(),
        },
        measured_kappa: [1.0 / 35.0, 1.0 / 15.0],
    };
    let t = table(&fm, TableSize::default(), None).unwrap();
    let prep = prepare(&path, workbench::render::mesh::Unit::M, None).unwrap();
    let cam = Camera::from_fov(1280, 720, 30.0);
    let scene = Scene::framed(&prep.mesh, &prep.curvature, &View::default(), &cam);
    let mut g = c.benchmark_group("bunny_1280x720");
    g.sample_size(30);
    for (name, samples, shading) in [
        ("samples1_cdrf", Samples::One, Shading::Cdrf),
        ("samples4_cdrf", Samples::Four, Shading::Cdrf),
        ("samples4_lambert", Samples::Four, Shading::Lambert),
        ("samples16_cdrf", Samples::Sixteen, Shading::Cdrf),
    ] {
        let sh = shader(&fm, &t.lut, fm.light, shading);
        let mut img = render(&scene, &cam, &sh, samples);
        g.bench_function(name, |b| {
            b.iter(|| render_into(&scene, &cam, &sh, samples, &mut img))
        });
    }
    let sh = shader(&fm, &t.lut, fm.light, Shading::Cdrf);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    g.bench_function("samples4_cdrf_1thread", |b| {
        let mut img = render(&scene, &cam, &sh, Samples::Four);
        one.install(|| b.iter(|| render_into(&scene, &cam, &sh, Samples::Four, &mut img)))
    });
    g.finish();
}

criterion_group!(benches, bench_bunny);
criterion_main!(benches);
