//! The camera for other tools (`calibrate --export`), read back the way those tools read it: the
//! ROS YAML with a YAML parser against `sensor_msgs/CameraInfo`'s fields, COLMAP's cameras.txt by
//! its documented grammar; each then projects points with that tool's own camera model (written
//! out here from its documentation, independent of workbench's) and must land where workbench's
//! camera puts them.

use nalgebra::Vector3;
use workbench::camera::{Camera, Distortion};
use workbench::formats::camera_export::{colmap_cameras, ros_camera_info};
use yaml_rust2::{Yaml, YamlLoader};

/// A camera with every coefficient non-zero (k3 too) or with k3 = 0.
fn camera(k3: f64) -> Camera {
    Camera {
        fx: 1402.25,
        fy: 1398.5,
        cx: 641.3,
        cy: 478.9,
        distortion: Distortion {
            k1: -0.12,
            k2: 0.081,
            p1: 4.6e-4,
            p2: -3.1e-4,
            k3,
        },
        image_size: [1280, 960],
    }
}

/// Points in front of the camera across the image (its corners included).
fn points() -> Vec<Vector3<f64>> {
    let mut v = vec![];
    for i in 0..=8 {
        for j in 0..=6 {
            let (x, y) = (-0.45 + 0.9 * i as f64 / 8.0, -0.34 + 0.68 * j as f64 / 6.0);
            v.push(Vector3::new(x * 2.0, y * 2.0, 2.0));
        }
    }
    v
}

/// A ROS CameraInfo YAML read back: K, D (plumb_bob), R, P and the image size. Panics with the
/// field at fault.
pub(crate) struct RosCamera {
    pub width: i64,
    pub height: i64,
    pub k: Vec<f64>,
    pub d: Vec<f64>,
    pub r: Vec<f64>,
    pub p: Vec<f64>,
}

pub(crate) fn read_ros(text: &str) -> RosCamera {
    let docs = YamlLoader::load_from_str(text).expect("YAML");
    assert_eq!(docs.len(), 1);
    let y = &docs[0];
    let int = |k: &str| y[k].as_i64().unwrap_or_else(|| panic!("{k}: an integer"));
    assert!(y["camera_name"].as_str().is_some(), "camera_name: a string");
    assert_eq!(y["distortion_model"].as_str(), Some("plumb_bob"));
    // Each matrix: rows × cols floats, as camera_calibration_parsers reads them.
    let matrix = |k: &str, rows: i64, cols: i64| -> Vec<f64> {
        let m = &y[k];
        assert_eq!(m["rows"].as_i64(), Some(rows), "{k}.rows");
        assert_eq!(m["cols"].as_i64(), Some(cols), "{k}.cols");
        let data: Vec<f64> = match &m["data"] {
            Yaml::Array(a) => a
                .iter()
                .map(|v| v.as_f64().unwrap_or_else(|| panic!("{k}.data: floats")))
                .collect(),
            other => panic!("{k}.data: {other:?}"),
        };
        assert_eq!(data.len() as i64, rows * cols, "{k}.data");
        data
    };
    RosCamera {
        width: int("image_width"),
        height: int("image_height"),
        k: matrix("camera_matrix", 3, 3),
        d: matrix("distortion_coefficients", 1, 5),
        r: matrix("rectification_matrix", 3, 3),
        p: matrix("projection_matrix", 3, 4),
    }
}

/// plumb_bob (OpenCV's five-coefficient model, as ROS documents it) with K: a point to pixels.
fn plumb_bob(k: &[f64], d: &[f64], p: &Vector3<f64>) -> [f64; 2] {
    let (x, y) = (p.x / p.z, p.y / p.z);
    let r2 = x * x + y * y;
    let radial = 1.0 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2;
    let xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
    let yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
    [k[0] * xd + k[1] * yd + k[2], k[4] * yd + k[5]]
}

/// A COLMAP cameras.txt read back by its grammar: `#` comments, then one camera a line,
/// `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`, separated by spaces.
pub(crate) fn read_colmap(text: &str) -> (u32, String, u32, u32, Vec<f64>) {
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    assert_eq!(lines.len(), 1, "one camera");
    let t: Vec<&str> = lines[0].split_whitespace().collect();
    let params: Vec<f64> = t[4..]
        .iter()
        .map(|v| v.parse().expect("a number"))
        .collect();
    let expected = match t[1] {
        "OPENCV" => 8,
        "FULL_OPENCV" => 12,
        m => panic!("model {m}"),
    };
    assert_eq!(params.len(), expected, "{} parameters", t[1]);
    (
        t[0].parse().unwrap(),
        t[1].to_string(),
        t[2].parse().unwrap(),
        t[3].parse().unwrap(),
        params,
    )
}

/// COLMAP's OPENCV / FULL_OPENCV models as its documentation writes them: the pixel of a point, in
/// COLMAP's image coordinates (the top-left pixel's centre at (0.5, 0.5)).
fn colmap_project(params: &[f64], p: &Vector3<f64>) -> [f64; 2] {
    let (u, v) = (p.x / p.z, p.y / p.z);
    let (k1, k2, p1, p2) = (params[4], params[5], params[6], params[7]);
    let (u2, v2, uv) = (u * u, v * v, u * v);
    let r2 = u2 + v2;
    let radial = if params.len() == 12 {
        let (k3, k4, k5, k6) = (params[8], params[9], params[10], params[11]);
        (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))) - 1.0
    } else {
        k1 * r2 + k2 * r2 * r2
    };
    let du = u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2);
    let dv = v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2);
    [
        params[0] * (u + du) + params[2],
        params[1] * (v + dv) + params[3],
    ]
}

/// The largest distance (px) between the exported model's pixels and workbench's.
fn worst(cam: &Camera, f: impl Fn(&Vector3<f64>) -> [f64; 2], shift: f64) -> f64 {
    points()
        .iter()
        .map(|p| {
            let ours = cam.project(p).expect("in front");
            let theirs = f(p);
            ((theirs[0] - shift - ours.x).powi(2) + (theirs[1] - shift - ours.y).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Check a ROS export of `cam`; returns the largest pixel difference.
pub(crate) fn check_ros(text: &str, cam: &Camera) -> f64 {
    let r = read_ros(text);
    assert_eq!(
        [r.width, r.height],
        [cam.image_size[0] as i64, cam.image_size[1] as i64]
    );
    assert_eq!(r.r, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    // P = [K | 0] for a monocular camera.
    for row in 0..3 {
        assert_eq!(&r.p[4 * row..4 * row + 3], &r.k[3 * row..3 * row + 3]);
        assert_eq!(r.p[4 * row + 3], 0.0);
    }
    worst(cam, |p| plumb_bob(&r.k, &r.d, p), 0.0)
}

/// Check a COLMAP export of `cam`; returns the model and the largest pixel difference.
pub(crate) fn check_colmap(text: &str, cam: &Camera) -> (String, f64) {
    let (id, model, w, h, params) = read_colmap(text);
    assert_eq!((id, w, h), (1, cam.image_size[0], cam.image_size[1]));
    (model, worst(cam, |p| colmap_project(&params, p), 0.5))
}

#[test]
fn ros_camera_info_projects_like_the_calibration() {
    for k3 in [0.0, 0.023] {
        let cam = camera(k3);
        let e = check_ros(&ros_camera_info(&cam), &cam);
        // Measured: 2.3e-13 px (rounding; the numbers are written to round-trip); the bound is about 4× that.
        println!("k3 {k3}: {e:.1e} px");
        assert!(e < 1e-12, "k3 {k3}: {e:e} px");
    }
}

#[test]
fn colmap_camera_projects_like_the_calibration_half_a_pixel_over() {
    for (k3, model) in [(0.0, "OPENCV"), (0.023, "FULL_OPENCV")] {
        let cam = camera(k3);
        let (text, named) = colmap_cameras(&cam);
        let (read, e) = check_colmap(&text, &cam);
        assert_eq!((named, read.as_str()), (model, model));
        // Measured: 2.5e-13 px.
        println!("{model}: {e:.1e} px");
        assert!(e < 1e-12, "{model}: {e:e} px");
        // Without the half-pixel shift the same file is half a pixel off in x and in y.
        let (_, _, _, _, params) = read_colmap(&text);
        let off = worst(&cam, |p| colmap_project(&params, p), 0.0);
        assert!((off - 0.5f64.hypot(0.5)).abs() < 1e-9, "{off}");
    }
}
