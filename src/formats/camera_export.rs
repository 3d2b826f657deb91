//! The calibrated camera in the formats the next tool reads (`workbench calibrate --export`):
//! ROS `CameraInfo` YAML (camera_calibration_parsers' layout) and COLMAP `cameras.txt`. The
//! OpenCV FileStorage YAML is written by OpenCV itself (`calibrate::cv`). Conventions, and how
//! each file is read back in the tests: docs/commands.md, "calibrate: outputs".
//!
//! Pixel origins differ: OpenCV and ROS put the centre of the top-left pixel at (0, 0), COLMAP at
//! (0.5, 0.5), so COLMAP's principal point is OpenCV's plus half a pixel.

use crate::camera::Camera;
use std::fmt::Write;

/// The formats `--export` knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExportFormat {
    /// OpenCV FileStorage YAML (`intrinsics.yml`).
    OpenCv,
    /// ROS `sensor_msgs/CameraInfo` as YAML (`camera_info.yaml`).
    Ros,
    /// COLMAP's text model (`cameras.txt`).
    Colmap,
}

impl ExportFormat {
    /// The file name written beside intrinsics.json.
    pub fn file_name(self) -> &'static str {
        match self {
            ExportFormat::OpenCv => "intrinsics.yml",
            ExportFormat::Ros => "camera_info.yaml",
            ExportFormat::Colmap => "cameras.txt",
        }
    }
}

/// A number as YAML and COLMAP read it back exactly (Rust's shortest round-trip form; `1` as
/// `1.0` so that YAML types it as a float).
fn num(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains(['.', 'e', 'E', 'i', 'N']) {
        s
    } else {
        format!("{s}.0")
    }
}

fn list(xs: &[f64]) -> String {
    xs.iter().map(|&x| num(x)).collect::<Vec<_>>().join(", ")
}

/// ROS `CameraInfo` YAML for a monocular camera: K, the plumb_bob distortion (k1, k2, p1, p2, k3),
/// R = I and P = [K | 0] (rectified images keep K; no stereo baseline). `camera_name` is
/// `camera`: ROS's camera_info_manager warns when it differs from the driver's name and loads the
/// file all the same.
pub fn ros_camera_info(cam: &Camera) -> String {
    let d = cam.distortion;
    let k = [cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0];
    let r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let p = [
        cam.fx, 0.0, cam.cx, 0.0, 0.0, cam.fy, cam.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
    ];
    let mut s = String::new();
    let _ = writeln!(s, "image_width: {}", cam.image_size[0]);
    let _ = writeln!(s, "image_height: {}", cam.image_size[1]);
    let _ = writeln!(s, "camera_name: camera");
    let matrix = |s: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]| {
        let _ = writeln!(s, "{key}:");
        let _ = writeln!(s, "  rows: {rows}");
        let _ = writeln!(s, "  cols: {cols}");
        let _ = writeln!(s, "  data: [{}]", list(data));
    };
    matrix(&mut s, "camera_matrix", 3, 3, &k);
    let _ = writeln!(s, "distortion_model: plumb_bob");
    matrix(
        &mut s,
        "distortion_coefficients",
        1,
        5,
        &[d.k1, d.k2, d.p1, d.p2, d.k3],
    );
    matrix(&mut s, "rectification_matrix", 3, 3, &r);
    matrix(&mut s, "projection_matrix", 3, 4, &p);
    s
}

/// COLMAP `cameras.txt` with one camera (id 1): the OPENCV model (fx, fy, cx, cy, k1, k2, p1, p2)
/// when k3 is 0, else FULL_OPENCV (… k3, k4, k5, k6 with k4 = k5 = k6 = 0), which holds the same
/// five coefficients exactly. The principal point moves by half a pixel (module doc). Returns the
/// text and the model's name.
pub fn colmap_cameras(cam: &Camera) -> (String, &'static str) {
    let d = cam.distortion;
    let (cx, cy) = (cam.cx + 0.5, cam.cy + 0.5);
    let mut params = vec![cam.fx, cam.fy, cx, cy, d.k1, d.k2, d.p1, d.p2];
    let model = if d.k3 == 0.0 {
        "OPENCV"
    } else {
        params.extend([d.k3, 0.0, 0.0, 0.0]);
        "FULL_OPENCV"
    };
    let mut s = String::new();
    let _ = writeln!(s, "# Camera list with one line of data per camera:");
    let _ = writeln!(s, "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]");
    let _ = writeln!(s, "# Number of cameras: 1");
    let _ = writeln!(
        s,
        "1 {model} {} {} {}",
        cam.image_size[0],
        cam.image_size[1],
        params.iter().map(|&x| num(x)).collect::<Vec<_>>().join(" ")
    );
    (s, model)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_trip_and_read_as_floats() {
        for x in [1.0, -0.0, 1400.25, 1e-300, -3.3e-7, 643.2] {
            let s = num(x);
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
            assert!(s.contains(['.', 'e']), "{s}");
        }
    }
}
