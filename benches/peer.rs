//! The solve's kernel against a peer in one run: workbench's least squares and SciPy's
//! `least_squares` (method 'trf', analytic Jacobian; `benches/scipy_peer.py`) fit the same
//! observations — every pixel of the default synthetic session outside the specular lobe — with
//! the same diffuse model from the same start; the ratio of their times is the figure, and their
//! parameters are compared in workbench's standard errors. Also timed: decoding the session's
//! photos. Run by hand (needs python3 with numpy and scipy): `cargo bench --bench peer`.

use std::path::Path;
use std::time::Instant;
use workbench::fit::solver::{self, Obs};
use workbench::model::{idx, Model, Params, N_PARAMS, PARAM_NAMES};
use workbench::solve::{self, Options};
use workbench::synth::session::{self, SessionConfig};

/// The best of `n` runs of `f`, and its last result.
fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let t = Instant::now();
        out = Some(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    (best, out.expect("n ≥ 1"))
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/bench-peer");
    let _ = std::fs::remove_dir_all(&dir);
    session::generate(&SessionConfig::default(), &dir, None, true).expect("synthetic session");
    let mut o = Options::new(&dir);
    o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
    let fitted = solve::run(&o).expect("solve");
    let l = solve::load(&o).expect("load");
    let fit_params = fitted.params();
    let light = fit_params.light.direction();
    // Every pixel outside 30° of the mirror direction: the diffuse model alone describes them.
    let obs: Vec<Obs> = l
        .spheres
        .iter()
        .flat_map(|s| s.obs.iter())
        .filter(|o| {
            let h = (light + o.geometry.view).normalize();
            o.geometry.normal.dot(&h) < 30f64.to_radians().cos()
        })
        .cloned()
        .collect();
    let v = start_values(&fit_params);
    let start = Params::from_vec(&v);
    let mut free = [false; N_PARAMS];
    for k in (0..7).chain([idx::AZIMUTH, idx::ELEVATION]) {
        free[k] = true;
    }
    let model = Model {
        entry_fresnel: false,
        ..Model::default()
    };
    workbench::model::table::Table::shared(); // built before the clock starts
    let (t_wb, wb) = best_of(3, || solver::fit(model, &obs, &start, free, &[]));
    let closed = Model {
        tabulated: false,
        ..model
    };
    let (t_closed, _) = best_of(3, || solver::fit(closed, &obs, &start, free, &[]));
    // Decoding the session's photos, in the same run.
    let photos: Vec<_> = l
        .report
        .images
        .iter()
        .map(|im| dir.join(&im.file))
        .collect();
    let (t_decode, _) = best_of(3, || {
        photos
            .iter()
            .map(|p| {
                workbench::formats::photo::load_linear_rgb(p, None)
                    .expect("photo")
                    .width
            })
            .sum::<u32>()
    });
    let (t_peer, peer, peer_v) = scipy(&dir, &obs, &v);
    let ours = wb.params.to_vec();
    println!(
        "observations: {} pixels × 3 channels, 9 parameters (σ0, albedo, η, light), plain least squares",
        obs.len()
    );
    println!("| solver | seconds | evaluations | ratio to workbench |");
    println!("|---|---:|---:|---:|");
    println!(
        "| workbench (tabulated CDRF) | {t_wb:.3} | {} | 1 |",
        wb.evaluations
    );
    println!(
        "| workbench (closed-form CDRF) | {t_closed:.3} | | {:.1}× |",
        t_closed / t_wb
    );
    println!(
        "| SciPy {} least_squares trf | {t_peer:.3} | {} (+{} Jacobians) | {:.1}× |",
        peer["scipy"].as_str().unwrap_or("?"),
        peer["evaluations"],
        peer["jacobians"],
        t_peer / t_wb
    );
    println!(
        "| decoding the {} photos | {t_decode:.3} | | {:.2}× |",
        photos.len(),
        t_decode / t_wb
    );
    println!(
        "cost: workbench {:.6e}, SciPy {:.6e}",
        wb.cost,
        peer["cost"].as_f64().unwrap_or(f64::NAN)
    );
    let mut worst = (0.0f64, "");
    for (k, val) in peer_v {
        let d = (val - ours[k]).abs() / wb.std[k].max(1e-300);
        if d > worst.0 {
            worst = (d, PARAM_NAMES[k]);
        }
    }
    println!(
        "parameters: SciPy's within {:.2e} of workbench's standard errors ({})",
        worst.0, worst.1
    );
}

/// The same start for both: the fit moved off (σ0 ×1.3, albedo ×0.8, η 1.45, the light 1°).
fn start_values(fit: &Params) -> [f64; N_PARAMS] {
    let mut v = fit.to_vec();
    for c in 0..3 {
        v[idx::SIGMA0 + c] *= 1.3;
        v[idx::ALBEDO + c] *= 0.8;
    }
    v[idx::ETA] = 1.45;
    v[idx::KS] = 0.0;
    v[idx::AZIMUTH] += 1f64.to_radians();
    v[idx::ELEVATION] -= 1f64.to_radians();
    for k in [
        idx::SIGMA_EXPONENT,
        idx::ALBEDO_CURVATURE,
        idx::KERNEL_WEIGHT,
        idx::KERNEL_RATIO,
    ] {
        v[k] = 0.0;
    }
    v
}

/// SciPy on the same observations and start (`benches/scipy_peer.py`): its seconds, its JSON
/// line, and its parameters by model index.
fn scipy(
    dir: &Path,
    obs: &[Obs],
    v: &[f64; N_PARAMS],
) -> (f64, serde_json::Value, Vec<(usize, f64)>) {
    let rows: Vec<[f64; 13]> = obs
        .iter()
        .map(|o| {
            let g = &o.geometry;
            [
                g.normal.x,
                g.normal.y,
                g.normal.z,
                g.view.x,
                g.view.y,
                g.view.z,
                g.radius_mm,
                o.radiance[0],
                o.radiance[1],
                o.radiance[2],
                o.weight[0],
                o.weight[1],
                o.weight[2],
            ]
        })
        .collect();
    let x0: Vec<f64> = (0..3)
        .map(|c| v[idx::SIGMA0 + c].ln())
        .chain((0..3).map(|c| v[idx::ALBEDO + c].ln()))
        .chain([v[idx::ETA], v[idx::AZIMUTH], v[idx::ELEVATION]])
        .collect();
    let input = dir.join("peer-observations.json");
    std::fs::write(
        &input,
        serde_json::to_string(
            &serde_json::json!({"observations": rows, "start": x0, "loss": "linear"}),
        )
        .expect("json"),
    )
    .expect("write");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/scipy_peer.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(&input)
        .output()
        .expect("python3");
    if !out.status.success() {
        eprintln!(
            "SciPy peer failed (needs python3 with numpy and scipy): {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::process::exit(1);
    }
    let peer: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("the peer's JSON line");
    let t_peer = peer["seconds"].as_f64().expect("seconds");
    let x: Vec<f64> = peer["x"]
        .as_array()
        .expect("x")
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect();
    let peer_v: Vec<(usize, f64)> = (0..3)
        .map(|c| (idx::SIGMA0 + c, x[c].exp()))
        .chain((0..3).map(|c| (idx::ALBEDO + c, x[3 + c].exp())))
        .chain([
            (idx::ETA, x[6]),
            (idx::AZIMUTH, x[7]),
            (idx::ELEVATION, x[8]),
        ])
        .collect();
    (t_peer, peer, peer_v)
}
