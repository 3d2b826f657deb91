//! Calibration benchmark, run by hand (`cargo bench --bench calibration [-- --quick]`):
//! 1. synthetic checkerboards at several noise levels: intrinsics against truth;
//! 2. OpenCV's sample photos (../shared/data/opencv-left): workbench against OpenCV's own Python
//!    bindings with the same flags (benches/cv2_calibrate.py, needs python3-opencv), same run;
//! 3. 20 synthetic views of 24 MP: time of detection and of calibration.
//!
//! Prints Markdown tables.

use std::path::Path;
use std::time::Instant;
use workbench::calibrate::cv::{OpenCv, OpenCvDetect};
use workbench::calibrate::run::{run, Options};
use workbench::calibrate::DetectorChoice;
use workbench::synth::checkerboard::{generate, CheckerConfig};
use workbench::synth::session::default_camera;

fn opts(dir: &Path, out: &Path, detector: DetectorChoice) -> Options {
    Options {
        dir: dir.into(),
        pattern: None,
        square_mm: 25.0,
        out: Some(out.join("intrinsics.json")),
        plots: None,
        detector,
        subpix_window: None,
        exports: vec![],
        quiet: true,
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    workbench::calibrate::cv::set_threads(1);
    let tmp = tempfile::tempdir().unwrap();
    synthetic(quick, tmp.path());
    opencv_left(tmp.path());
    if !quick {
        large(tmp.path());
    }
}

/// Synthetic checkerboards at four noise levels against their truth.
fn synthetic(quick: bool, tmp: &Path) {
    println!("\n### Synthetic checkerboards (1280×960, 15 views, blur 0.7 px, vignetting 0.3, 8-bit PNG)\n");
    println!("| shot noise | read noise | seeds | fx err % | fy err % | cx err px | cy err px | k1 err | k2 err | RMS px |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let seeds: Vec<u64> = if quick { vec![1] } else { vec![1, 2, 3] };
    for (noise, read) in [(0.005, 0.001), (0.01, 0.002), (0.02, 0.004), (0.05, 0.01)] {
        let mut worst = [0.0f64; 6];
        let mut rms = 0.0;
        for &seed in &seeds {
            let cfg = CheckerConfig {
                noise,
                read_noise: read,
                seed,
                ..CheckerConfig::default()
            };
            let d = tmp.join(format!("n{noise}-{seed}"));
            let t = generate(&cfg, &d, true).unwrap().truth.intrinsics;
            let r = run(&opts(&d, &d, DetectorChoice::Auto), &OpenCvDetect, &OpenCv).unwrap();
            let c = r.calibration.camera;
            let e = [
                100.0 * (c.fx / t.fx - 1.0),
                100.0 * (c.fy / t.fy - 1.0),
                c.cx - t.cx,
                c.cy - t.cy,
                c.distortion.k1 - t.distortion.k1,
                c.distortion.k2 - t.distortion.k2,
            ];
            for k in 0..6 {
                if e[k].abs() > worst[k].abs() {
                    worst[k] = e[k];
                }
            }
            rms += r.calibration.rms_px / seeds.len() as f64;
        }
        println!(
            "| {noise} | {read} | {} | {:+.3} | {:+.3} | {:+.2} | {:+.2} | {:+.4} | {:+.4} | {rms:.3} |",
            seeds.len(), worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]
        );
    }
    println!(
        "\n(worst over the seeds; truth fx = fy = 1400, cx 643.2, cy 478.5, k1 −0.12, k2 0.08)"
    );
}

/// OpenCV's sample photos, each detector, and cv2 from Python with the same flags.
fn opencv_left(tmp: &Path) {
    let left = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/opencv-left");
    if left.is_dir() {
        println!("\n### OpenCV's sample photos (opencv-left, 13 views 640×480), same run\n");
        println!("| method | views | fx | fy | cx | cy | k1 | RMS px | time s |");
        println!("|---|---|---|---|---|---|---|---|---|");
        for (name, det) in [
            ("workbench, classic detector", DetectorChoice::Classic),
            ("workbench, auto (default)", DetectorChoice::Auto),
            ("workbench, both detectors", DetectorChoice::Both),
        ] {
            let out = tmp.join(format!("left-{name}").replace([' ', ','], "_"));
            let t0 = Instant::now();
            let r = run(&opts(&left, &out, det), &OpenCvDetect, &OpenCv).unwrap();
            let dt = t0.elapsed().as_secs_f64();
            let c = &r.calibration;
            let s = c.std.unwrap_or_default();
            println!(
                "| {name} | {} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.4} | {:.4} | {dt:.2} (all of it: {:.2} s detection + model choice, CV, plots) |",
                c.used.len(), c.camera.fx, s.fx, c.camera.fy, s.fy, c.camera.cx, s.cx, c.camera.cy, s.cy, c.camera.distortion.k1, c.rms_px, r.detection_s
            );
        }
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/cv2_calibrate.py");
        match std::process::Command::new("/usr/bin/python3")
            .arg(&script)
            .arg(&left)
            .args(["9", "6", "25"])
            .output()
        {
            Ok(o) if o.status.success() => {
                let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
                let f = |k: &str| j[k].as_f64().unwrap();
                println!(
                    "| cv2 (Python), same flags | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.4} | {:.4} | {:.2} ({:.2} detection + {:.2} calibrateCamera, {} threads) |",
                    j["views"], f("fx"), f("fy"), f("cx"), f("cy"), f("k1"), f("rms"), f("detect_s") + f("calibrate_s"), f("detect_s"), f("calibrate_s"), j["threads"]
                );
            }
            _ => println!(
                "\n(cv2 comparison skipped: /usr/bin/python3 with python3-opencv not available)"
            ),
        }
    } else {
        println!(
            "\n(opencv-left comparison skipped: {} is absent)",
            left.display()
        );
    }
}

/// 20 views of 24 MP: the time of each step.
fn large(tmp: &Path) {
    println!("\n### 20 views of 24 MP (6000×4000), synthetic\n");
    let mut cam = default_camera();
    let s = 6000.0 / 1280.0;
    cam.fx *= s;
    cam.fy *= s;
    cam.cx = 3001.5;
    cam.cy = 1998.0;
    cam.image_size = [6000, 4000];
    let cfg = CheckerConfig {
        camera: cam,
        views: 20,
        blur_px: 1.5,
        ..CheckerConfig::default()
    };
    let d = tmp.join("24mp");
    let t0 = Instant::now();
    let truth = generate(&cfg, &d, true).unwrap().truth.intrinsics;
    let gen = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let r = run(&opts(&d, &d, DetectorChoice::Auto), &OpenCvDetect, &OpenCv).unwrap();
    let total = t0.elapsed().as_secs_f64();
    let c = r.calibration.camera;
    println!("| views used | decode + detect s | calibrate s (model choice, CV, std) | total s | fx err % | cx err px | RMS px | (rendering the views: {gen:.0} s) |");
    println!("|---|---|---|---|---|---|---|---|");
    println!(
        "| {} | {:.2} | {:.2} | {total:.2} | {:+.3} | {:+.2} | {:.3} | |",
        r.calibration.used.len(),
        r.detection_s,
        r.calibration_s,
        100.0 * (c.fx / truth.fx - 1.0),
        c.cx - truth.cx,
        r.calibration.rms_px
    );
}
