use workbench::outline::{Outline, Projection};
use workbench::photo::LinearRgb;
use workbench::synth::session::{self, SessionConfig};

#[test]
fn debug_bias() {
    let exposure: f64 = std::env::var("EXPO")
        .map(|v| v.parse().unwrap())
        .unwrap_or(1.2);
    let cfg = SessionConfig {
        radii_mm: vec![35.0, 15.0],
        noise: 0.0,
        read_noise: 0.0,
        exposure,
        ..SessionConfig::default()
    };
    let plans = session::plan(&cfg).unwrap();
    let l = cfg.light.direction();
    for p in &plans {
        let lin = session::render_linear(&cfg, &p.spheres);
        let (w, h) = (cfg.camera.image_size[0], cfg.camera.image_size[1]);
        let img = LinearRgb {
            width: w,
            height: h,
            data: lin.iter().map(|&v| v.min(1.0) as f32).collect(),
            saturated: lin.chunks(3).map(|c| c.iter().any(|&v| v >= 1.0)).collect(),
            bits: 16,
        };
        let proj = Projection::Perspective(cfg.camera);
        let truth = Outline::of_sphere(&p.spheres[0].1).unwrap();
        let lum = workbench::detect::luminance(&img);
        let hl = workbench::highlight::find(&lum, &img.saturated, &proj, &truth, 1e-4).unwrap();
        println!(
            "{}: true outline: light err {:.4}° alpha {:?} sat {}",
            p.file,
            hl.light.angle(&l).to_degrees(),
            hl.alpha,
            hl.saturated
        );
        let f = workbench::detect::find_spheres(
            &img,
            &proj,
            &[p.spheres[0].0],
            std::path::Path::new("x"),
        )
        .unwrap();
        let o = f[0].outline;
        if let (
            Outline::Cone {
                axis: a1,
                half_angle: h1,
            },
            Outline::Cone {
                axis: a2,
                half_angle: h2,
            },
        ) = (o, truth)
        {
            let r = o.radius_px(&proj);
            println!(
                "   detected: axis err {:.4} px, half-angle err {:.4} px",
                a1.angle(&a2) * r / h1.tan() * h1.tan(),
                (h1 - h2) / h2 * r
            );
        }
        println!("   blur {:.3}", f[0].blur_px);
        println!(
            "   detected light err {:.4}°",
            f[0].highlight
                .as_ref()
                .unwrap()
                .light
                .angle(&l)
                .to_degrees()
        );
    }
}

#[test]
fn debug_refine_from_truth() {
    let az: f64 = std::env::var("AZ")
        .map(|v| v.parse().unwrap())
        .unwrap_or(70.0);
    let mut cfg = SessionConfig {
        radii_mm: vec![35.0],
        noise: 0.0,
        read_noise: 0.0,
        exposure: 0.3,
        ..SessionConfig::default()
    };
    cfg.light.azimuth = az.to_radians();
    cfg.light.elevation = 0.0;
    if std::env::var("NODIST").is_ok() {
        cfg.camera.distortion = Default::default();
    }
    let plans = session::plan(&cfg).unwrap();
    let p = &plans[0];
    let lin = session::render_linear(&cfg, &p.spheres);
    let (w, h) = (cfg.camera.image_size[0], cfg.camera.image_size[1]);
    let img = LinearRgb {
        width: w,
        height: h,
        data: lin.iter().map(|&v| v.min(1.0) as f32).collect(),
        saturated: lin.chunks(3).map(|c| c.iter().any(|&v| v >= 1.0)).collect(),
        bits: 16,
    };
    let proj = Projection::Perspective(cfg.camera);
    let truth = Outline::of_sphere(&p.spheres[0].1).unwrap();
    let lum = workbench::detect::luminance(&img);
    for inner in [2.0, 4.0] {
        let r = workbench::silhouette::refine(&[(&lum, None)], &proj, &truth, inner, 3.0).unwrap();
        if let (
            Outline::Cone {
                axis: a1,
                half_angle: h1,
            },
            Outline::Cone {
                axis: a2,
                half_angle: h2,
            },
        ) = (r.outline, truth)
        {
            let rp = truth.radius_px(&proj);
            println!("inner {inner}: axis err {:.4} px, half-angle err {:.4} px blur {:.3} rms {:.2e} iters {}", a1.angle(&a2)*rp/h2.tan()*h2.tan()/h2*h2, (h1-h2)/h2*rp, r.blur_px, r.rms, r.iterations);
        }
    }
}
