//! `workbench synth checkerboard`: views of a planar chessboard with known camera and poses.
//!
//! Board frame (OpenCV's object points): inner corner (i, j) at (i·s, j·s, 0) mm, i along the
//! `cols` direction, z into the board; camera point P = R·X + t. The board has (cols+1)×(rows+1)
//! squares, the square touching the origin corner's (−, −) side is black, and a white margin
//! surrounds the squares. Pixels whose neighbourhood sees more than one colour are supersampled;
//! then the image is blurred, vignetted, given shot and read noise, sRGB-encoded and written as
//! 8-bit greyscale.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::formats::intrinsics::IntrinsicsFile;
use crate::formats::output::write_json;
use crate::formats::photo;
use nalgebra::{Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BoardFormat {
    Png,
    Jpeg,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckerConfig {
    /// Inner corners [cols, rows].
    pub inner: [u32; 2],
    pub square_mm: f64,
    /// White margin around the squares (mm).
    pub margin_mm: f64,
    pub views: u32,
    pub camera: Camera,
    /// Gaussian blur σ (px) of lens and sensor.
    pub blur_px: f64,
    pub noise: f64,
    pub read_noise: f64,
    /// Relative brightness loss at the frame corners (cos⁴-like falloff, 0 = none).
    pub vignetting: f64,
    pub supersample: u32,
    pub format: BoardFormat,
    pub jpeg_quality: u8,
    pub seed: u64,
}

impl Default for CheckerConfig {
    fn default() -> Self {
        CheckerConfig {
            inner: [9, 6],
            square_mm: 25.0,
            margin_mm: 25.0,
            views: 15,
            camera: super::session::default_camera(),
            blur_px: 0.7,
            noise: 0.01,
            read_noise: 2e-3,
            vignetting: 0.3,
            supersample: 4,
            format: BoardFormat::Png,
            jpeg_quality: 92,
            seed: 1,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewTruth {
    pub file: String,
    /// Rodrigues rotation vector board → camera.
    pub rvec: [f64; 3],
    /// Translation (mm): the board origin in the camera frame.
    pub tvec: [f64; 3],
    /// Inner corners in (distorted) pixel coordinates, row by row: j = 0..rows, i = 0..cols.
    pub corners_px: Vec<[f64; 2]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckerTruth {
    pub schema: String,
    pub kind: String,
    /// Inner corners [cols, rows].
    pub pattern: [u32; 2],
    pub square_mm: f64,
    pub margin_mm: f64,
    pub intrinsics: IntrinsicsFile,
    pub views: Vec<ViewTruth>,
    pub blur_px: f64,
    pub noise: f64,
    pub read_noise: f64,
    pub vignetting: f64,
    pub seed: u64,
}

const WHITE: f64 = 0.80;
const BLACK: f64 = 0.04;
const BACKGROUND: f64 = 0.12;

/// A board pose.
#[derive(Clone, Copy, Debug)]
pub struct Pose {
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

impl CheckerConfig {
    fn squares_extent(&self) -> (f64, f64) {
        let s = self.square_mm;
        (self.inner[0] as f64 * s + s, self.inner[1] as f64 * s + s)
    }

    /// The board's outer corners (margin included), board frame.
    fn outline(&self) -> [Vector3<f64>; 4] {
        let (s, m) = (self.square_mm, self.margin_mm);
        let (x0, y0) = (-s - m, -s - m);
        let x1 = self.inner[0] as f64 * s + m;
        let y1 = self.inner[1] as f64 * s + m;
        [
            Vector3::new(x0, y0, 0.0),
            Vector3::new(x1, y0, 0.0),
            Vector3::new(x1, y1, 0.0),
            Vector3::new(x0, y1, 0.0),
        ]
    }

    /// Colour of a board-frame point, `None` off the board.
    fn colour(&self, u: f64, v: f64) -> Option<f64> {
        let s = self.square_mm;
        let (w, h) = self.squares_extent();
        let (m, x0, y0) = (self.margin_mm, -s, -s);
        if u < x0 - m || v < y0 - m || u > x0 + w + m || v > y0 + h + m {
            return None;
        }
        if u < x0 || v < y0 || u >= x0 + w || v >= y0 + h {
            return Some(WHITE);
        }
        let (iu, iv) = (((u - x0) / s).floor() as i64, ((v - y0) / s).floor() as i64);
        Some(if (iu + iv) % 2 == 0 { BLACK } else { WHITE })
    }
}

fn check(cfg: &CheckerConfig) -> Result<()> {
    let arg = |m: &str| Err(Error::Argument(m.into()));
    if cfg.inner[0] < 2 || cfg.inner[1] < 2 {
        return arg("the pattern needs at least 2×2 inner corners");
    }
    if !(cfg.square_mm > 0.0) || !(cfg.margin_mm >= 0.0) {
        return arg("square size must be positive and margin ≥ 0");
    }
    if cfg.views == 0 || cfg.views > 200 {
        return arg("views must be between 1 and 200");
    }
    let size = cfg.camera.image_size;
    if let Some(why) = photo::size_problem(size[0], size[1]) {
        return Err(Error::Argument(why));
    }
    if cfg.supersample == 0 || cfg.supersample > 16 {
        return arg("supersample must be between 1 and 16");
    }
    let nums = [cfg.blur_px, cfg.noise, cfg.read_noise, cfg.vignetting];
    if !nums.iter().all(|v| v.is_finite() && *v >= 0.0) || cfg.vignetting >= 1.0 {
        return arg("blur, noise and read noise must be ≥ 0, vignetting in [0, 1)");
    }
    Ok(())
}

/// Poses that spread the board over the frame: its centre cycles through a 3×3 grid of image
/// positions (plus jitter), tilted 15–45° about alternating axes with some roll, at a distance
/// where the board spans about half the frame width; a pose whose outline leaves the frame is
/// pulled toward the centre, then pushed back.
pub fn poses(cfg: &CheckerConfig) -> Result<Vec<Pose>> {
    check(cfg)?;
    let cam = &cfg.camera;
    let (w, h) = (cam.width() as f64, cam.height() as f64);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0xC4EC_B0A2_D000_0000);
    let (sw, sh) = cfg.squares_extent();
    let centre_b = Vector3::new(0.5 * sw - cfg.square_mm, 0.5 * sh - cfg.square_mm, 0.0);
    let board_w = sw + 2.0 * cfg.margin_mm;
    // Aim at the frame's edges and corners; a pose that does not fit is pulled toward the centre
    // just far enough, so the board ends up touching the edge it was aimed at.
    let grid = [
        (0.5, 0.5),
        (0.05, 0.05),
        (0.95, 0.05),
        (0.05, 0.95),
        (0.95, 0.95),
        (0.5, 0.05),
        (0.5, 0.95),
        (0.05, 0.5),
        (0.95, 0.5),
    ];
    let mut out = Vec::new();
    for k in 0..cfg.views as usize {
        let (gx, gy) = grid[k % grid.len()];
        let sign = |b: bool| if b { 1.0 } else { -1.0 };
        let tilt = |rng: &mut ChaCha8Rng| rng.random_range(15f64..45f64).to_radians();
        let (pitch, yaw) = match k % 3 {
            0 => (
                sign(k % 2 == 0) * tilt(&mut rng),
                rng.random_range(-10f64..10f64).to_radians(),
            ),
            1 => (
                rng.random_range(-10f64..10f64).to_radians(),
                sign(k % 4 < 2) * tilt(&mut rng),
            ),
            _ => (
                sign(k % 2 == 1) * tilt(&mut rng) * 0.8,
                sign(k % 4 >= 2) * tilt(&mut rng) * 0.8,
            ),
        };
        // Views aimed at the centre fill more of the frame; those aimed at edges are smaller, and
        // those aimed at the frame's corners smaller still and hardly rolled, so that their inner
        // corners reach into the frame's corners.
        let at_corner = (1..=4).contains(&(k % grid.len()));
        let roll_max = if at_corner { 5f64 } else { 20f64 };
        let roll = rng.random_range(-roll_max..roll_max).to_radians();
        let rotation = Rotation3::from_euler_angles(pitch, yaw, roll);
        let frac = if k % grid.len() == 0 {
            rng.random_range(0.6..0.75)
        } else if at_corner {
            rng.random_range(0.28..0.38)
        } else {
            rng.random_range(0.35..0.5)
        };
        let mut z = cam.fx * board_w / (frac * w);
        let mut target = Vector2::new(gx * w, gy * h)
            + Vector2::new(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0));
        let mut found = None;
        'search: for _ in 0..20 {
            for _ in 0..25 {
                let n = cam.undistort_pixel(target).unwrap_or(Vector2::zeros());
                let translation = Vector3::new(n.x * z, n.y * z, z) - rotation * centre_b;
                let inside = cfg.outline().iter().all(|p| {
                    let pc = rotation * p + translation;
                    pc.z > 1.0
                        && cam.project(&pc).is_some_and(|q| {
                            q.x > 8.0 && q.y > 8.0 && q.x < w - 8.0 && q.y < h - 8.0
                        })
                });
                if inside {
                    found = Some(Pose {
                        rotation,
                        translation,
                    });
                    break 'search;
                }
                target += (Vector2::new(0.5 * w, 0.5 * h) - target) * 0.08;
            }
            z *= 1.1;
        }
        out.push(found.ok_or_else(|| {
            Error::Argument(format!("cannot place view {} inside the frame", k + 1))
        })?);
    }
    Ok(out)
}

/// Render one view to linear grey (noise-free), given the unit rays of all pixel centres.
fn render_view(cfg: &CheckerConfig, pose: &Pose, rays: &[Option<Vector3<f64>>]) -> Vec<f64> {
    let cam = &cfg.camera;
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let normal = pose.rotation * Vector3::z();
    let nt = normal.dot(&pose.translation);
    let rinv = pose.rotation.inverse();
    let value = |d: &Vector3<f64>| -> f64 {
        let nd = normal.dot(d);
        if nd.abs() < 1e-12 {
            return BACKGROUND;
        }
        let s = nt / nd;
        if s <= 0.0 {
            return BACKGROUND;
        }
        let b = rinv * (d * s - pose.translation);
        cfg.colour(b.x, b.y).unwrap_or(BACKGROUND)
    };
    let mut img: Vec<f64> = rays
        .par_iter()
        .map(|r| r.as_ref().map_or(BACKGROUND, &value))
        .collect();
    let n = cfg.supersample as usize;
    if n > 1 {
        let base = img.clone();
        img.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for x in 0..w {
                let c = base[y * w + x];
                let mut edge = false;
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                        if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                            edge |= base[yy as usize * w + xx as usize] != c;
                        }
                    }
                }
                if !edge {
                    continue;
                }
                let mut acc = 0.0;
                for j in 0..n {
                    for i in 0..n {
                        let sub = Vector2::new(
                            x as f64 + (i as f64 + 0.5) / n as f64 - 0.5,
                            y as f64 + (j as f64 + 0.5) / n as f64 - 0.5,
                        );
                        acc += cam.ray_for_pixel(sub).as_ref().map_or(BACKGROUND, &value);
                    }
                }
                row[x] = acc / (n * n) as f64;
            }
        });
    }
    img
}

#[derive(Debug)]
pub struct CheckerOutput {
    pub truth_file: PathBuf,
    pub images: Vec<PathBuf>,
    pub truth: CheckerTruth,
}

/// Render the views into `out` with `truth.json`.
pub fn generate(cfg: &CheckerConfig, out: &Path, quiet: bool) -> Result<CheckerOutput> {
    let poses = poses(cfg)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // One set: the views with their truth.json, or the folder as it was.
    let set = crate::formats::output::OutputSet::begin(&[out])?;
    let cam = &cfg.camera;
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    let rays: Vec<Option<Vector3<f64>>> = (0..w * h)
        .into_par_iter()
        .map(|i| cam.ray_for_pixel(Vector2::new((i % w) as f64, (i / w) as f64)))
        .collect();
    let rho_max = Vector2::new(cam.cx.max(w as f64 - cam.cx), cam.cy.max(h as f64 - cam.cy)).norm();
    let ext = match cfg.format {
        BoardFormat::Png => "png",
        BoardFormat::Jpeg => "jpg",
    };
    let pb = crate::progress::bar(poses.len() as u64, "rendering", quiet);
    // EXIF (JPEG only): the lens as a 23.5 mm wide sensor would see it.
    let sensor_w = 23.5;
    let focal_mm = cam.fx * sensor_w / cam.width() as f64;
    let f35 = photo::focal_35mm_equivalent(focal_mm, sensor_w, cam.image_size).round() as u32;
    let exif = photo::ExifInfo::for_exposure(1.0, "workbench", "synthetic camera", focal_mm, f35);
    let mut views = Vec::new();
    let mut images = Vec::new();
    for (k, pose) in poses.iter().enumerate() {
        let mut img = render_view(cfg, pose, &rays);
        super::gaussian_blur(&mut img, w, h, cfg.blur_px);
        let data: Vec<u8> = img
            .par_chunks(w)
            .enumerate()
            .flat_map_iter(|(y, row)| {
                let mut rng = super::row_rng(cfg.seed, k as u64, y as u64);
                row.iter()
                    .enumerate()
                    .map(|(x, v)| {
                        let rho =
                            Vector2::new(x as f64 - cam.cx, y as f64 - cam.cy).norm() / rho_max;
                        let vig = 1.0 - cfg.vignetting * rho * rho;
                        let s = super::sensor(v * vig, cfg.noise, cfg.read_noise, &mut rng);
                        (photo::srgb_encode(s) * 255.0).round() as u8
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let file = format!("view{:02}.{ext}", k + 1);
        let path = out.join(&file);
        photo::write_8bit(
            &path,
            w as u32,
            h as u32,
            1,
            &data,
            cfg.jpeg_quality,
            Some(&exif),
        )?;
        let mut corners = Vec::new();
        for j in 0..cfg.inner[1] {
            for i in 0..cfg.inner[0] {
                let p = Vector3::new(i as f64 * cfg.square_mm, j as f64 * cfg.square_mm, 0.0);
                let q = cam
                    .project(&(pose.rotation * p + pose.translation))
                    .expect("board in front of the camera");
                corners.push([q.x, q.y]);
            }
        }
        let rv = pose.rotation.scaled_axis();
        let t = pose.translation;
        views.push(ViewTruth {
            file,
            rvec: [rv.x, rv.y, rv.z],
            tvec: [t.x, t.y, t.z],
            corners_px: corners,
        });
        images.push(path);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let truth = CheckerTruth {
        schema: super::session::TRUTH_SCHEMA.into(),
        kind: "checkerboard".into(),
        pattern: cfg.inner,
        square_mm: cfg.square_mm,
        margin_mm: cfg.margin_mm,
        intrinsics: IntrinsicsFile::from_truth(cam),
        views,
        blur_px: cfg.blur_px,
        noise: cfg.noise,
        read_noise: cfg.read_noise,
        vignetting: cfg.vignetting,
        seed: cfg.seed,
    };
    let truth_file = out.join("truth.json");
    write_json(&truth_file, &truth)?;
    set.commit()?;
    Ok(CheckerOutput {
        truth_file,
        images,
        truth,
    })
}
