//! Everything that touches OpenCV (crate `opencv`, system OpenCV 4.6), behind the default-on
//! `opencv` cargo feature. Inputs and outputs are plain Rust / nalgebra types: images arrive as
//! [`Gray8`], corners leave as `Vector2<f64>`, calibrations as [`Camera`] and [`Pose`].

use crate::calibrate::{Backend, Detector, DistortionModel, Pattern, Pose, Solution};
use crate::camera::{Camera, Distortion};
use crate::error::{Error, Result};
use crate::formats::photo::Gray8;
use nalgebra::{Vector2, Vector3};
use opencv::core::{self, Mat, Point2f, Point3f, Size, TermCriteria, Vector};
use opencv::prelude::*;
use opencv::{calib3d, imgproc};

fn cv(what: &str, e: opencv::Error) -> Error {
    Error::Argument(format!("OpenCV {what}: {}", e.message))
}

/// Limit OpenCV's own thread pool (callers parallelise over images with rayon).
pub fn set_threads(n: i32) {
    let _ = core::set_num_threads(n);
}

/// Longest side at which detection runs; larger images are searched downscaled and the corners
/// refined at full resolution.
const DETECT_MAX_SIDE: u32 = 1600;

fn mat_of(img: &Gray8) -> Result<Mat> {
    let m = Mat::new_rows_cols_with_data(img.height as i32, img.width as i32, &img.data)
        .map_err(|e| cv("image", e))?;
    m.try_clone().map_err(|e| cv("image", e))
}

fn downscaled(full: &Mat, img: &Gray8, max_side: u32) -> Result<(Mat, f64)> {
    let side = img.width.max(img.height);
    if side <= max_side {
        return Ok((full.clone(), 1.0));
    }
    let s = max_side as f64 / side as f64;
    let mut small = Mat::default();
    imgproc::resize(full, &mut small, Size::new(0, 0), s, s, imgproc::INTER_AREA)
        .map_err(|e| cv("resize", e))?;
    Ok((small, s))
}

/// Smallest distance between neighbouring corners along rows and columns (px).
fn corner_spacing(c: &[Vector2<f64>], p: Pattern) -> f64 {
    let (cols, rows) = (p.cols as usize, p.rows as usize);
    let mut best = f64::INFINITY;
    for j in 0..rows {
        for i in 0..cols {
            let k = j * cols + i;
            if i + 1 < cols {
                best = best.min((c[k + 1] - c[k]).norm());
            }
            if j + 1 < rows {
                best = best.min((c[k + cols] - c[k]).norm());
            }
        }
    }
    best
}

/// The cornerSubPix half-window: a third of the smallest corner spacing within [3, 25] px, unless
/// given. A fixed 11 (OpenCV's samples) reaches past the neighbouring corners on steep views.
fn refine(
    full: &Mat,
    corners: &mut Vector<Point2f>,
    spacing: f64,
    window: Option<u32>,
) -> Result<()> {
    let w = window
        .map(|w| w as i32)
        .unwrap_or_else(|| (spacing / 3.0).clamp(3.0, 25.0).round() as i32);
    let crit = TermCriteria::new(core::TermCriteria_COUNT + core::TermCriteria_EPS, 60, 1e-4)
        .map_err(|e| cv("criteria", e))?;
    imgproc::corner_sub_pix(full, corners, Size::new(w, w), Size::new(-1, -1), crit)
        .map_err(|e| cv("cornerSubPix", e))
}

fn to_rust(v: &Vector<Point2f>, scale: f64) -> Vec<Vector2<f64>> {
    v.iter()
        .map(|p| Vector2::new(p.x as f64 / scale, p.y as f64 / scale))
        .collect()
}

fn to_cv(v: &[Vector2<f64>]) -> Vector<Point2f> {
    v.iter()
        .map(|p| Point2f::new(p.x as f32, p.y as f32))
        .collect()
}

/// Find the chessboard's inner corners with one detector. `None` when the board is not found.
pub fn detect(
    img: &Gray8,
    pattern: Pattern,
    detector: Detector,
    window: Option<u32>,
) -> Result<Option<Vec<Vector2<f64>>>> {
    let full = mat_of(img)?;
    let size = Size::new(pattern.cols as i32, pattern.rows as i32);
    let (small, s) = downscaled(&full, img, DETECT_MAX_SIDE)?;
    let mut corners = Vector::<Point2f>::new();
    let found = match detector {
        Detector::Classic => calib3d::find_chessboard_corners(
            &small,
            size,
            &mut corners,
            calib3d::CALIB_CB_ADAPTIVE_THRESH
                | calib3d::CALIB_CB_NORMALIZE_IMAGE
                | calib3d::CALIB_CB_FAST_CHECK,
        ),
        Detector::SectorBased => calib3d::find_chessboard_corners_sb(
            &small,
            size,
            &mut corners,
            calib3d::CALIB_CB_EXHAUSTIVE | calib3d::CALIB_CB_ACCURACY,
        ),
    }
    .map_err(|e| cv("findChessboardCorners", e))?;
    if !found || corners.len() != pattern.count() {
        return Ok(None);
    }
    let approx = to_rust(&corners, s);
    if detector == Detector::Classic || s < 1.0 {
        let mut c = to_cv(&approx);
        refine(&full, &mut c, corner_spacing(&approx, pattern), window)?;
        return Ok(Some(to_rust(&c, 1.0)));
    }
    Ok(Some(approx))
}

/// Find the size of the chessboard an image shows: the sector-based detector with
/// `CALIB_CB_LARGER` accepts any board of at least 4×3 inner corners and reports the grid it
/// found (on a copy downscaled to 1000 px). About 0.1–0.3 s; trying the classic detector with
/// wrong sizes instead can take seconds per size. Returned as the longer side × the shorter.
pub(crate) fn guess_pattern(img: &Gray8) -> Result<Option<Pattern>> {
    let full = mat_of(img)?;
    let (small, _) = downscaled(&full, img, 1000)?;
    let mut corners = Vector::<Point2f>::new();
    let mut meta = Mat::default();
    let found = calib3d::find_chessboard_corners_sb_with_meta(
        &small,
        Size::new(4, 3),
        &mut corners,
        calib3d::CALIB_CB_LARGER | calib3d::CALIB_CB_NORMALIZE_IMAGE,
        &mut meta,
    )
    .map_err(|e| cv("findChessboardCornersSB", e))?;
    if !found
        || meta.rows() < 2
        || meta.cols() < 2
        || corners.len() != (meta.rows() * meta.cols()) as usize
    {
        return Ok(None);
    }
    let (a, b) = (meta.rows() as u32, meta.cols() as u32);
    Ok(Some(Pattern {
        cols: a.max(b),
        rows: a.min(b),
    }))
}

fn camera_mats(cam: &Camera) -> Result<(Mat, Mat)> {
    let k = Mat::from_slice_2d(&[
        [cam.fx, 0.0, cam.cx],
        [0.0, cam.fy, cam.cy],
        [0.0, 0.0, 1.0],
    ])
    .map_err(|e| cv("matrix", e))?;
    let d = cam.distortion;
    let dist = Mat::from_slice(&[d.k1, d.k2, d.p1, d.p2, d.k3])
        .map_err(|e| cv("matrix", e))?
        .try_clone()
        .map_err(|e| cv("matrix", e))?;
    Ok((k, dist))
}

/// A [`Camera`] from OpenCV's camera matrix and distortion vector (missing coefficients are 0).
fn camera_from_mats(k: &Mat, dist: &Mat, image_size: [u32; 2]) -> Result<Camera> {
    let at = |r: i32, c: i32| {
        k.at_2d::<f64>(r, c)
            .copied()
            .map_err(|e| cv("camera matrix", e))
    };
    let d = |i: i32| -> Result<f64> {
        if (i as usize) < dist.total() {
            dist.at::<f64>(i).copied().map_err(|e| cv("distortion", e))
        } else {
            Ok(0.0)
        }
    };
    Ok(Camera {
        fx: at(0, 0)?,
        fy: at(1, 1)?,
        cx: at(0, 2)?,
        cy: at(1, 2)?,
        distortion: Distortion {
            k1: d(0)?,
            k2: d(1)?,
            p1: d(2)?,
            p2: d(3)?,
            k3: d(4)?,
        },
        image_size,
    })
}

fn vec3_of(m: &Mat) -> Result<Vector3<f64>> {
    let v: Vec<f64> = (0..3)
        .map(|i| m.at::<f64>(i).copied())
        .collect::<opencv::Result<_>>()
        .map_err(|e| cv("vector", e))?;
    Ok(Vector3::new(v[0], v[1], v[2]))
}

/// The OpenCV calibration backend (`calibrateCameraExtended`, `solvePnP`).
pub struct OpenCv;

impl Backend for OpenCv {
    fn calibrate(
        &self,
        views: &[&[Vector2<f64>]],
        object: &[Vector3<f64>],
        image_size: [u32; 2],
        model: DistortionModel,
    ) -> Result<Solution> {
        let obj: Vector<Point3f> = object
            .iter()
            .map(|p| Point3f::new(p.x as f32, p.y as f32, p.z as f32))
            .collect();
        let mut objs = Vector::<Vector<Point3f>>::new();
        let mut imgs = Vector::<Vector<Point2f>>::new();
        for v in views {
            objs.push(obj.clone());
            imgs.push(to_cv(v));
        }
        let mut k = Mat::default();
        let mut dist = Mat::default();
        let mut rvecs = Vector::<Mat>::new();
        let mut tvecs = Vector::<Mat>::new();
        let (mut sdi, mut sde, mut pve) = (Mat::default(), Mat::default(), Mat::default());
        let flags = match model {
            DistortionModel::K1K2P1P2 => calib3d::CALIB_FIX_K3,
            DistortionModel::K1K2P1P2K3 => 0,
        };
        let crit = TermCriteria::new(
            core::TermCriteria_COUNT + core::TermCriteria_EPS,
            100,
            1e-12,
        )
        .map_err(|e| cv("criteria", e))?;
        let size = Size::new(image_size[0] as i32, image_size[1] as i32);
        let rms = calib3d::calibrate_camera_extended(
            &objs, &imgs, size, &mut k, &mut dist, &mut rvecs, &mut tvecs, &mut sdi, &mut sde,
            &mut pve, flags, crit,
        )
        .map_err(|e| cv("calibrateCamera", e))?;
        let camera = camera_from_mats(&k, &dist, image_size)?;
        let poses = rvecs
            .iter()
            .zip(tvecs.iter())
            .map(|(r, t)| {
                Ok(Pose {
                    rvec: vec3_of(&r)?,
                    tvec: vec3_of(&t)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Solution {
            camera,
            poses,
            rms_px: rms,
        })
    }

    fn pose(
        &self,
        camera: &Camera,
        corners: &[Vector2<f64>],
        object: &[Vector3<f64>],
    ) -> Result<Pose> {
        let obj: Vector<Point3f> = object
            .iter()
            .map(|p| Point3f::new(p.x as f32, p.y as f32, p.z as f32))
            .collect();
        let (k, dist) = camera_mats(camera)?;
        let (mut r, mut t) = (Mat::default(), Mat::default());
        let ok = calib3d::solve_pnp(
            &obj,
            &to_cv(corners),
            &k,
            &dist,
            &mut r,
            &mut t,
            false,
            calib3d::SOLVEPNP_ITERATIVE,
        )
        .map_err(|e| cv("solvePnP", e))?;
        if !ok {
            return Err(Error::Argument("solvePnP found no pose".into()));
        }
        Ok(Pose {
            rvec: vec3_of(&r)?,
            tvec: vec3_of(&t)?,
        })
    }
}

/// The calibration as OpenCV FileStorage YAML (`camera_matrix`, `distortion_coefficients`,
/// `image_width`, `image_height`), produced by cv::FileStorage itself.
pub(crate) fn filestorage_yaml(cam: &Camera) -> Result<String> {
    let mut fs = core::FileStorage::new(
        "intrinsics.yml",
        core::FileStorage_WRITE | core::FileStorage_MEMORY,
        "",
    )
    .map_err(|e| cv("FileStorage", e))?;
    let (k, dist) = camera_mats(cam)?;
    let dist = dist
        .reshape(1, 1)
        .map_err(|e| cv("reshape", e))?
        .try_clone()
        .map_err(|e| cv("reshape", e))?;
    core::write_i32(&mut fs, "image_width", cam.image_size[0] as i32)
        .map_err(|e| cv("FileStorage", e))?;
    core::write_i32(&mut fs, "image_height", cam.image_size[1] as i32)
        .map_err(|e| cv("FileStorage", e))?;
    core::write_mat(&mut fs, "camera_matrix", &k).map_err(|e| cv("FileStorage", e))?;
    core::write_mat(&mut fs, "distortion_coefficients", &dist).map_err(|e| cv("FileStorage", e))?;
    fs.release_and_get_string()
        .map_err(|e| cv("FileStorage", e))
}

/// Read a FileStorage calibration back (camera matrix, distortion, image size).
pub fn read_filestorage_yaml(text: &str) -> Result<Camera> {
    let fs = core::FileStorage::new(text, core::FileStorage_READ | core::FileStorage_MEMORY, "")
        .map_err(|e| cv("FileStorage", e))?;
    let node = |name: &str| fs.get(name).map_err(|e| cv("FileStorage", e));
    let k = node("camera_matrix")?
        .mat()
        .map_err(|e| cv("FileStorage", e))?;
    let d = node("distortion_coefficients")?
        .mat()
        .map_err(|e| cv("FileStorage", e))?;
    let w = node("image_width")?
        .to_i32()
        .map_err(|e| cv("FileStorage", e))?;
    let h = node("image_height")?
        .to_i32()
        .map_err(|e| cv("FileStorage", e))?;
    camera_from_mats(&k, &d, [w as u32, h as u32])
}

/// OpenCV's detectors for [`crate::calibrate::run`].
pub struct OpenCvDetect;

impl crate::calibrate::run::Detect for OpenCvDetect {
    fn detect(
        &self,
        img: &Gray8,
        pattern: Pattern,
        detector: Detector,
        window: Option<u32>,
    ) -> Result<Option<Vec<Vector2<f64>>>> {
        detect(img, pattern, detector, window)
    }

    fn guess_pattern(&self, img: &Gray8) -> Result<Option<Pattern>> {
        guess_pattern(img)
    }

    fn yaml(&self, cam: &Camera) -> Result<String> {
        filestorage_yaml(cam)
    }
}
