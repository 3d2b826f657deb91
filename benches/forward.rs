//! Forward-model throughput: the CDRF kernel, the per-pixel model with its full gradient, and the
//! synthetic-session renderer (5 spheres, 1280×960, edge supersampling 4×4).
//!
//!     cargo bench --bench forward

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use nalgebra::Vector3;
use std::hint::black_box;
use workbench::model::cdrf::{self, Convolution};
use workbench::model::{Geometry, LightAngles, Model, Params};
use workbench::synth::session::{self, Layout, SessionConfig};

fn samples(n: usize) -> Vec<Geometry> {
    (0..n)
        .map(|i| {
            let u = (i as f64 + 0.5) / n as f64;
            let ct = 0.05 + 0.94 * (i as f64 * 0.618).fract();
            let st = (1.0 - ct * ct).sqrt();
            let ph = u * 60.0;
            Geometry {
                normal: Vector3::new(st * ph.cos(), st * ph.sin(), -ct),
                view: Vector3::new(0.01, -0.02, -1.0).normalize(),
                radius_mm: [15.0, 20.0, 25.0, 30.0, 35.0][i % 5],
            }
        })
        .collect()
}

/// The synthetic wax under a light from the upper right.
fn params() -> Params {
    Params {
        material: SessionConfig::default().material,
        light: LightAngles {
            azimuth: 1.2,
            elevation: 0.35,
        },
    }
}

fn bench_kernels(c: &mut Criterion) {
    let n = 10_000;
    let thetas: Vec<f64> = (0..n)
        .map(|i| std::f64::consts::PI * i as f64 / n as f64)
        .collect();
    let mut g = c.benchmark_group("kernels");
    g.throughput(Throughput::Elements(n as u64));
    for (name, sigma) in [
        ("cdrf_sigma0.1", 0.1),
        ("cdrf_sigma0.3", 0.3),
        ("cdrf_sigma1.5", 1.5),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                thetas
                    .iter()
                    .map(|&t| cdrf::eval(t, black_box(sigma), Convolution::Wrapped).value)
                    .sum::<f64>()
            })
        });
        // The same from the table (value and both derivatives, as the closed form gives).
        let table = workbench::model::table::Table::shared();
        g.bench_function(format!("{name}_table"), |b| {
            b.iter(|| {
                thetas
                    .iter()
                    .map(|&t| table.eval(t, black_box(sigma)).value)
                    .sum::<f64>()
            })
        });
        // The same from the table's slice at that width (what the fit evaluates).
        let slice = table.slice(sigma).expect("a tabulated width");
        g.bench_function(format!("{name}_slice"), |b| {
            b.iter(|| {
                thetas
                    .iter()
                    .map(|&t| black_box(&slice).eval(t).value)
                    .sum::<f64>()
            })
        });
    }
    let geo = samples(n);
    let model = Model::default();
    let params = params();
    g.bench_function("model_rgb", |b| {
        b.iter(|| {
            geo.iter()
                .map(|gm| model.radiance(black_box(&params), gm)[0])
                .sum::<f64>()
        })
    });
    // The fit's path: the model prepared at the parameters (the table's slices at each radius's
    // widths), on the points as above and sorted as a fit's are (by sphere, then across it).
    let prepared = model.prepare(&params, geo.iter().map(|g| g.radius_mm));
    let mut sorted = geo.clone();
    sorted.sort_by(|a, b| {
        (a.radius_mm, a.normal.z)
            .partial_cmp(&(b.radius_mm, b.normal.z))
            .unwrap()
    });
    for (name, pts) in [("", &geo), ("_sorted", &sorted)] {
        g.bench_function(format!("model_rgb_with_gradient{name}"), |b| {
            b.iter(|| {
                pts.iter()
                    .map(|gm| model.radiance_with_gradient(black_box(&params), gm).1[0][0])
                    .sum::<f64>()
            })
        });
        g.bench_function(format!("model_rgb_with_gradient_prepared{name}"), |b| {
            b.iter(|| {
                pts.iter()
                    .map(|gm| black_box(&prepared).radiance_with_gradient(gm).1[0][0])
                    .sum::<f64>()
            })
        });
    }
    let closed = Model {
        tabulated: false,
        ..Model::default()
    };
    g.bench_function("model_rgb_with_gradient_closed_form", |b| {
        b.iter(|| {
            geo.iter()
                .map(|gm| closed.radiance_with_gradient(black_box(&params), gm).1[0][0])
                .sum::<f64>()
        })
    });
    g.finish();
}

fn bench_synth(c: &mut Criterion) {
    let mut g = c.benchmark_group("synth_session_1280x960");
    g.sample_size(10);
    for (name, layout) in [
        ("separate_5_images", Layout::Separate),
        ("row_1_image", Layout::Row),
    ] {
        let cfg = SessionConfig {
            layout,
            ..SessionConfig::default()
        };
        g.bench_function(name, |b| {
            b.iter_batched(
                || tempfile::tempdir().unwrap(),
                |dir| session::generate(&cfg, dir.path(), None, true).unwrap(),
                BatchSize::PerIteration,
            )
        });
        let plans = session::plan(&cfg).unwrap();
        g.bench_function(format!("{name}_render_only"), |b| {
            b.iter(|| {
                plans
                    .iter()
                    .map(|p| session::render_linear(&cfg, &p.spheres)[0])
                    .sum::<f64>()
            })
        });
    }
    g.finish();
}

/// The solver's hot kernel: model + gradient for every observation, accumulated into JᵀJ and Jᵀr
/// (what one Levenberg–Marquardt evaluation costs), on one core and on all cores.
fn bench_normal_equations(c: &mut Criterion) {
    use workbench::fit::solver::{self, Obs};
    let n = 100_000;
    let model = Model::default();
    let params = params();
    // Sorted by radius, as a fit's observations are (sphere by sphere).
    let mut geometry = samples(n);
    geometry.sort_by(|a, b| a.radius_mm.total_cmp(&b.radius_mm));
    let obs: Vec<Obs> = geometry
        .into_iter()
        .map(|g| Obs {
            radiance: model.radiance(&params, &g),
            geometry: g,
            weight: [1.0; 3],
        })
        .collect();
    let mut free = [true; workbench::model::N_PARAMS];
    free[workbench::model::idx::SIGMA_EXPONENT] = false;
    free[workbench::model::idx::ALBEDO_CURVATURE] = false;
    let mut g = c.benchmark_group("normal_equations_100k");
    g.throughput(Throughput::Elements(n as u64));
    g.sample_size(20);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // The table (the default) on one core and on all; the closed-form CDRF on one core: the
    // table's gain on the hot path.
    let closed = Model {
        tabulated: false,
        ..model
    };
    for (threads, model, suffix) in [
        (1, model, ""),
        (cores, model, ""),
        (1, closed, "_closed_form"),
    ] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        g.bench_function(format!("{threads}_threads{suffix}"), |b| {
            b.iter(|| {
                pool.install(|| black_box(solver::normal_equations(model, &obs, &params, free)))
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_kernels, bench_synth, bench_normal_equations);
criterion_main!(benches);
