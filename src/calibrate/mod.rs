//! Camera calibration from chessboard views: everything that is not OpenCV. The detector and the
//! solver behind [`Backend`] come from OpenCV ([`crate::calibrate::cv`]); this module decides what to
//! trust: the distortion model by held-out error, outlier views, standard deviations from the
//! Jacobian (OpenCV 4.6's own formula is known to be wrong, opencv issue 19803), k-fold
//! cross-validation, frame coverage, tilt range and the EXIF sanity checks.

#[cfg(feature = "opencv")]
pub mod cv;
pub mod plots;
pub mod run;

use crate::camera::{Camera, Distortion};
use crate::formats::intrinsics::{IntrinsicsStd, ViewReport};
use crate::stats::{mad_sigma, median};
use nalgebra::{DMatrix, Matrix2x3, Matrix3, Rotation3, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Inner corners of a chessboard: `cols` along a row, `rows` rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pattern {
    pub cols: u32,
    pub rows: u32,
}

impl Pattern {
    pub fn count(&self) -> usize {
        (self.cols * self.rows) as usize
    }

    /// The most inner corners along a side (a printed board with more is not a camera target;
    /// the bound keeps the corner count and the detector's work small).
    pub const MAX_SIDE: u32 = 100;

    /// Parse "9x6": each side 2 to [`Pattern::MAX_SIDE`].
    pub fn parse(s: &str) -> Option<Pattern> {
        let (c, r) = s.split_once(['x', 'X'])?;
        let p = Pattern {
            cols: c.trim().parse().ok()?,
            rows: r.trim().parse().ok()?,
        };
        let side = 2..=Self::MAX_SIDE;
        (side.contains(&p.cols) && side.contains(&p.rows)).then_some(p)
    }

    /// Board-frame corner positions (mm), row by row, as OpenCV orders detected corners.
    pub fn object_points(&self, square_mm: f64) -> Vec<Vector3<f64>> {
        let mut v = Vec::with_capacity(self.count());
        for j in 0..self.rows {
            for i in 0..self.cols {
                v.push(Vector3::new(
                    i as f64 * square_mm,
                    j as f64 * square_mm,
                    0.0,
                ));
            }
        }
        v
    }
}

impl std::fmt::Display for Pattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.cols, self.rows)
    }
}

/// Which chessboard detector found a set of corners.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Detector {
    /// `findChessboardCorners` + `cornerSubPix`.
    Classic,
    /// `findChessboardCornersSB` (exhaustive, accuracy): more accurate, 20–100× slower.
    SectorBased,
}

impl Detector {
    pub fn name(&self) -> &'static str {
        match self {
            Detector::Classic => "classic",
            Detector::SectorBased => "sb",
        }
    }
}

/// Which detectors a calibration runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DetectorChoice {
    /// Classic everywhere; the sector-based detector where the classic one found nothing or gave
    /// a view whose error stands out (> 1.5× the median), keeping whichever the camera explains
    /// better.
    Auto,
    Classic,
    SectorBased,
    /// Both on every view, keeping the better.
    Both,
}

/// Board pose: Rodrigues rotation vector and translation (mm), board → camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub rvec: Vector3<f64>,
    pub tvec: Vector3<f64>,
}

impl Pose {
    pub fn rotation(&self) -> Rotation3<f64> {
        Rotation3::from_scaled_axis(self.rvec)
    }

    /// Angle between the board normal and the optical axis (radians).
    pub(crate) fn tilt(&self) -> f64 {
        (self.rotation() * Vector3::z())
            .z
            .abs()
            .clamp(0.0, 1.0)
            .acos()
    }
}

/// Distortion models offered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DistortionModel {
    /// k1 k2 p1 p2 (k3 fixed at 0).
    K1K2P1P2,
    /// k1 k2 p1 p2 k3.
    K1K2P1P2K3,
}

impl DistortionModel {
    pub(crate) fn n_intrinsics(&self) -> usize {
        match self {
            DistortionModel::K1K2P1P2 => 8,
            DistortionModel::K1K2P1P2K3 => 9,
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            DistortionModel::K1K2P1P2 => "k1 k2 p1 p2",
            DistortionModel::K1K2P1P2K3 => "k1 k2 p1 p2 k3",
        }
    }
}

/// What a calibration backend (OpenCV) returns.
#[derive(Clone, Debug)]
pub struct Solution {
    pub camera: Camera,
    pub poses: Vec<Pose>,
    pub rms_px: f64,
}

/// The solver a calibration needs: a full calibration and a single-view pose.
pub trait Backend: Sync {
    fn calibrate(
        &self,
        views: &[&[Vector2<f64>]],
        object: &[Vector3<f64>],
        image_size: [u32; 2],
        model: DistortionModel,
    ) -> crate::Result<Solution>;
    fn pose(
        &self,
        camera: &Camera,
        corners: &[Vector2<f64>],
        object: &[Vector3<f64>],
    ) -> crate::Result<Pose>;
}

/// Pixel projection of a board point with its Jacobians: with respect to the intrinsics
/// [fx, fy, cx, cy, k1, k2, p1, p2, k3] and to the pose as [δ, t], where δ is a small rotation
/// applied on the left (R ← exp([δ]×) R).
pub fn project_with_jacobian(
    cam: &Camera,
    pose: &Pose,
    x: &Vector3<f64>,
) -> (Vector2<f64>, SMatrix<f64, 2, 9>, SMatrix<f64, 2, 6>) {
    let rx = pose.rotation() * x;
    let p = rx + pose.tvec;
    let (iz, n) = (1.0 / p.z, Vector2::new(p.x / p.z, p.y / p.z));
    let dn_dp = Matrix2x3::new(iz, 0.0, -p.x * iz * iz, 0.0, iz, -p.y * iz * iz);
    let (d, jd) = cam.distortion.apply_with_jacobian(n);
    let (xx, yy) = (n.x, n.y);
    let r2 = xx * xx + yy * yy;
    let f = nalgebra::Matrix2::new(cam.fx, 0.0, 0.0, cam.fy);
    let dd_dk = SMatrix::<f64, 2, 5>::new(
        xx * r2,
        xx * r2 * r2,
        2.0 * xx * yy,
        r2 + 2.0 * xx * xx,
        xx * r2 * r2 * r2,
        yy * r2,
        yy * r2 * r2,
        r2 + 2.0 * yy * yy,
        2.0 * xx * yy,
        yy * r2 * r2 * r2,
    );
    let mut ji = SMatrix::<f64, 2, 9>::zeros();
    ji[(0, 0)] = d.x;
    ji[(1, 1)] = d.y;
    ji[(0, 2)] = 1.0;
    ji[(1, 3)] = 1.0;
    ji.fixed_view_mut::<2, 5>(0, 4).copy_from(&(f * dd_dk));
    let du_dp = f * jd * dn_dp;
    let skew = Matrix3::new(0.0, -rx.z, rx.y, rx.z, 0.0, -rx.x, -rx.y, rx.x, 0.0);
    let mut jp = SMatrix::<f64, 2, 6>::zeros();
    jp.fixed_view_mut::<2, 3>(0, 0).copy_from(&(-du_dp * skew));
    jp.fixed_view_mut::<2, 3>(0, 3).copy_from(&du_dp);
    (cam.to_pixel(d), ji, jp)
}

/// Corner residuals (observed − projected) of one view.
pub(crate) fn view_residuals(
    cam: &Camera,
    pose: &Pose,
    corners: &[Vector2<f64>],
    object: &[Vector3<f64>],
) -> Vec<Vector2<f64>> {
    corners
        .iter()
        .zip(object)
        .map(|(c, x)| {
            let p = pose.rotation() * x + pose.tvec;
            c - cam.project(&p).unwrap_or(Vector2::new(f64::NAN, f64::NAN))
        })
        .collect()
}

/// RMS of residual vectors (√ of the mean squared length — a true RMS, not a mean of norms).
pub fn rms(res: &[Vector2<f64>]) -> f64 {
    (res.iter().map(|r| r.norm_squared()).sum::<f64>() / res.len().max(1) as f64).sqrt()
}

/// Standard deviations of the intrinsics: σ²(JᵀJ)⁻¹ over all intrinsics and poses, with
/// σ² = Σr² / (m − n), marginalised over the poses by the Schur complement. Returns the standard
/// deviations and the intrinsics' covariance (order fx fy cx cy k1 k2 p1 p2 [k3]).
pub fn intrinsic_uncertainty(
    cam: &Camera,
    poses: &[Pose],
    views: &[&[Vector2<f64>]],
    object: &[Vector3<f64>],
    model: DistortionModel,
) -> Option<(IntrinsicsStd, DMatrix<f64>)> {
    let ni = model.n_intrinsics();
    let mut a = DMatrix::<f64>::zeros(ni, ni);
    let mut ss = 0.0;
    let mut m = 0usize;
    for (pose, corners) in poses.iter().zip(views) {
        let mut b = DMatrix::<f64>::zeros(ni, 6);
        let mut c = SMatrix::<f64, 6, 6>::zeros();
        for (obs, x) in corners.iter().zip(object) {
            let (px, ji, jp) = project_with_jacobian(cam, pose, x);
            let r = obs - px;
            ss += r.norm_squared();
            m += 2;
            let ji = ji.columns(0, ni).into_owned();
            a += ji.transpose() * &ji;
            b += ji.transpose() * jp;
            c += jp.transpose() * jp;
        }
        let cinv = c.try_inverse()?;
        let cinv = DMatrix::from_iterator(6, 6, cinv.iter().cloned());
        a -= &b * cinv * b.transpose();
    }
    let n = ni + 6 * poses.len();
    if m <= n {
        return None;
    }
    let sigma2 = ss / (m - n) as f64;
    let cov = a.try_inverse()? * sigma2;
    let sd = |i: usize| {
        if i < ni {
            cov[(i, i)].max(0.0).sqrt()
        } else {
            0.0
        }
    };
    Some((
        IntrinsicsStd {
            fx: sd(0),
            fy: sd(1),
            cx: sd(2),
            cy: sd(3),
            distortion: Distortion {
                k1: sd(4),
                k2: sd(5),
                p1: sd(6),
                p2: sd(7),
                k3: sd(8),
            },
        },
        cov,
    ))
}

/// Views whose RMS error is an outlier: above both twice the median and the median plus 4
/// robust standard deviations (1.4826 · MAD). Returns their indices.
pub(crate) fn outlier_views(per_view_rms: &[f64]) -> Vec<usize> {
    if per_view_rms.len() < 4 {
        return vec![];
    }
    let limit = outlier_limit(median(per_view_rms), mad_sigma(per_view_rms));
    (0..per_view_rms.len())
        .filter(|&i| per_view_rms[i] > limit)
        .collect()
}

/// The threshold [`outlier_views`] applies.
pub(crate) fn outlier_limit(median: f64, robust_sd: f64) -> f64 {
    (2.0 * median).max(median + 4.0 * robust_sd)
}

/// Corner coverage of the frame on a grid of `gx × gy` cells: counts per cell, row-major.
pub fn coverage(corners: &[Vector2<f64>], size: [u32; 2], gx: usize, gy: usize) -> Vec<usize> {
    let mut cells = vec![0; gx * gy];
    for c in corners {
        let i = (c.x / size[0] as f64 * gx as f64).floor();
        let j = (c.y / size[1] as f64 * gy as f64).floor();
        if i >= 0.0 && j >= 0.0 && (i as usize) < gx && (j as usize) < gy {
            cells[j as usize * gx + i as usize] += 1;
        }
    }
    cells
}

/// Cross-validation of a calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CrossValidation {
    pub folds: usize,
    pub model: DistortionModel,
    /// RMS of held-out views' corners, each view's pose fitted with the intrinsics of the other
    /// folds.
    pub heldout_rms_px: f64,
    /// fx, fy, cx, cy of each fold's calibration.
    pub fold_intrinsics: Vec<[f64; 4]>,
    /// Grouped-jackknife standard error of fx, fy, cx, cy: √((K−1)/K · Σ(θ_k − θ̄)²).
    pub jackknife_std: [f64; 4],
}

/// K-fold cross-validation over views (round-robin folds).
pub(crate) fn cross_validate(
    backend: &dyn Backend,
    views: &[&[Vector2<f64>]],
    object: &[Vector3<f64>],
    size: [u32; 2],
    model: DistortionModel,
    folds: usize,
) -> crate::Result<CrossValidation> {
    use rayon::prelude::*;
    let k = folds.min(views.len()).max(2);
    let results: Vec<crate::Result<(f64, usize, [f64; 4])>> = (0..k)
        .into_par_iter()
        .map(|f| {
            let train: Vec<&[Vector2<f64>]> = views
                .iter()
                .enumerate()
                .filter(|(i, _)| i % k != f)
                .map(|(_, v)| *v)
                .collect();
            let sol = backend.calibrate(&train, object, size, model)?;
            let mut ss = 0.0;
            let mut n = 0;
            for (_, v) in views.iter().enumerate().filter(|(i, _)| i % k == f) {
                let pose = backend.pose(&sol.camera, v, object)?;
                let r = view_residuals(&sol.camera, &pose, v, object);
                ss += r.iter().map(|e| e.norm_squared()).sum::<f64>();
                n += r.len();
            }
            let c = &sol.camera;
            Ok((ss, n, [c.fx, c.fy, c.cx, c.cy]))
        })
        .collect();
    let mut ss = 0.0;
    let mut n = 0;
    let mut fold_intrinsics = vec![];
    for r in results {
        let (s, m, p) = r?;
        ss += s;
        n += m;
        fold_intrinsics.push(p);
    }
    let kf = fold_intrinsics.len() as f64;
    let mut jackknife_std = [0.0; 4];
    for (q, js) in jackknife_std.iter_mut().enumerate() {
        let mean = fold_intrinsics.iter().map(|p| p[q]).sum::<f64>() / kf;
        let s2: f64 = fold_intrinsics.iter().map(|p| (p[q] - mean).powi(2)).sum();
        *js = ((kf - 1.0) / kf * s2).sqrt();
    }
    Ok(CrossValidation {
        folds: k,
        model,
        heldout_rms_px: (ss / n.max(1) as f64).sqrt(),
        fold_intrinsics,
        jackknife_std,
    })
}

/// A view's detected corners.
#[derive(Clone, Debug)]
pub struct View {
    pub file: String,
    pub corners: Vec<Vector2<f64>>,
    /// Which detector found them ("classic" or "sb").
    pub detector: &'static str,
}

/// The whole calibration result.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub camera: Camera,
    pub model: DistortionModel,
    pub rms_px: f64,
    pub std: Option<IntrinsicsStd>,
    /// Views used in the final solve, with their poses and RMS.
    pub used: Vec<(View, Pose, f64)>,
    /// Views dropped as outliers, with the RMS that condemned them.
    pub rejected: Vec<(View, f64, String)>,
    /// The per-view RMS above which a view counts as an outlier (px), from the rejection rounds.
    pub outlier_limit_px: f64,
    pub cross_validation: Vec<CrossValidation>,
    pub notes: Vec<String>,
    pub warnings: Vec<String>,
    pub reports: Vec<ViewReport>,
}

/// Calibrate from detected views: reject outlier views (judged with the simpler model), choose
/// the distortion model by held-out error, solve, then compute uncertainties and quality
/// warnings.
pub fn calibrate(
    backend: &dyn Backend,
    views: Vec<View>,
    object: &[Vector3<f64>],
    size: [u32; 2],
) -> crate::Result<Calibration> {
    let min_views = 3;
    if views.len() < min_views {
        return Err(crate::Error::Argument(format!(
            "{} usable view(s); at least {min_views} are needed",
            views.len()
        )));
    }
    let mut notes = vec![];
    let (active, rejected, limit_used) =
        reject_outliers(backend, views, object, size, min_views, &mut notes)?;
    let refs: Vec<&[Vector2<f64>]> = active.iter().map(|v| v.corners.as_slice()).collect();
    let (model, cvs) = distortion_model(backend, &refs, object, size, &mut notes)?;
    let sol = backend.calibrate(&refs, object, size, model)?;
    let std = intrinsic_uncertainty(&sol.camera, &sol.poses, &refs, object, model).map(|s| s.0);
    let mut used = vec![];
    let mut all_res = vec![];
    for (v, p) in active.into_iter().zip(sol.poses.iter()) {
        let r = view_residuals(&sol.camera, p, &v.corners, object);
        all_res.extend(r.iter().cloned());
        let e = rms(&r);
        used.push((v, *p, e));
    }
    let rms_px = rms(&all_res);
    let mut warnings = quality_warnings(&sol.camera, &used, size);
    if let (Some(s), Some(cv)) = (&std, cvs.iter().find(|c| c.model == model)) {
        let ratio = cv.jackknife_std[0] / s.fx.max(1e-12);
        if ratio > 3.0 {
            warnings.push(format!(
                "cross-validation spread of fx ({:.2} px) is {ratio:.1}× the formal standard deviation ({:.2} px): the formal figure is optimistic",
                cv.jackknife_std[0], s.fx
            ));
        }
    }
    let mut reports: Vec<ViewReport> = used
        .iter()
        .map(|(v, _, e)| ViewReport {
            file: v.file.clone(),
            rms_px: Some(*e),
            status: format!("used ({})", v.detector),
        })
        .collect();
    reports.extend(rejected.iter().map(|(v, e, why)| ViewReport {
        file: v.file.clone(),
        rms_px: Some(*e),
        status: why.clone(),
    }));
    Ok(Calibration {
        camera: sol.camera,
        model,
        rms_px,
        std,
        used,
        rejected,
        outlier_limit_px: limit_used,
        cross_validation: cvs,
        notes,
        warnings,
        reports,
    })
}

/// Views whose RMS is beyond the outlier limit, rejected round by round (up to a fifth of the
/// views, at most 3 rounds) under the simpler model. Returns the views kept, those rejected
/// (with their RMS and why) and the limit last used.
#[allow(clippy::type_complexity)]
fn reject_outliers(
    backend: &dyn Backend,
    views: Vec<View>,
    object: &[Vector3<f64>],
    size: [u32; 2],
    min_views: usize,
    notes: &mut Vec<String>,
) -> crate::Result<(Vec<View>, Vec<(View, f64, String)>, f64)> {
    let model_fixed = DistortionModel::K1K2P1P2;
    let mut active = views;
    let mut rejected: Vec<(View, f64, String)> = vec![];
    let mut limit_used = f64::NAN;
    // Outlier views, judged with the simpler model (up to a fifth of the views, at most 3 rounds).
    for _ in 0..3 {
        let refs: Vec<&[Vector2<f64>]> = active.iter().map(|v| v.corners.as_slice()).collect();
        let sol = backend.calibrate(&refs, object, size, model_fixed)?;
        let per_view: Vec<f64> = active
            .iter()
            .zip(&sol.poses)
            .map(|(v, p)| rms(&view_residuals(&sol.camera, p, &v.corners, object)))
            .collect();
        let out = outlier_views(&per_view);
        {
            if limit_used.is_nan() || !out.is_empty() {
                limit_used = outlier_limit(median(&per_view), mad_sigma(&per_view));
            }
        }
        let budget = (active.len() + rejected.len()) / 5;
        if out.is_empty()
            || rejected.len() + out.len() > budget
            || active.len() - out.len() < min_views
        {
            if !out.is_empty() {
                notes.push(format!(
                    "{} view(s) look like outliers but rejecting them would drop more than a fifth of the views: kept",
                    out.len()
                ));
            }
            break;
        }
        let med = median(&per_view);
        let limit = outlier_limit(med, mad_sigma(&per_view));
        for &i in out.iter().rev() {
            let v = active.remove(i);
            let why = format!(
                "rejected: {:.3} px RMS, above the outlier limit {:.3} px (median {:.3} px)",
                per_view[i], limit, med
            );
            notes.push(format!("{}: {why}", v.file));
            rejected.push((v, per_view[i], why));
        }
    }
    Ok((active, rejected, limit_used))
}

/// The distortion model by held-out error: k3 only when it predicts unseen views better by
/// more than 2%. Returns the model and the cross-validations.
fn distortion_model(
    backend: &dyn Backend,
    refs: &[&[Vector2<f64>]],
    object: &[Vector3<f64>],
    size: [u32; 2],
    notes: &mut Vec<String>,
) -> crate::Result<(DistortionModel, Vec<CrossValidation>)> {
    let model_fixed = DistortionModel::K1K2P1P2;
    // Distortion model by held-out error: k3 only when it predicts unseen views better by > 2%.
    let folds = 5.min(refs.len());
    let mut cvs = vec![];
    let mut model = model_fixed;
    if refs.len() >= 4 {
        let cv4 = cross_validate(
            backend,
            refs,
            object,
            size,
            DistortionModel::K1K2P1P2,
            folds,
        )?;
        let cv5 = cross_validate(
            backend,
            refs,
            object,
            size,
            DistortionModel::K1K2P1P2K3,
            folds,
        )?;
        if cv5.heldout_rms_px < 0.98 * cv4.heldout_rms_px {
            model = DistortionModel::K1K2P1P2K3;
        }
        notes.push(format!(
            "distortion model: held-out RMS {:.4} px with k1 k2 p1 p2, {:.4} px with k3 too ({}-fold): using {}",
            cv4.heldout_rms_px,
            cv5.heldout_rms_px,
            cv4.folds,
            model.name()
        ));
        cvs.push(cv4);
        cvs.push(cv5);
    } else {
        notes.push("too few views to cross-validate: k3 fixed at 0".into());
    }
    Ok((model, cvs))
}

/// Coverage and tilt warnings.
pub(crate) fn quality_warnings(
    _cam: &Camera,
    used: &[(View, Pose, f64)],
    size: [u32; 2],
) -> Vec<String> {
    let mut w = vec![];
    let corners: Vec<Vector2<f64>> = used
        .iter()
        .flat_map(|(v, _, _)| v.corners.iter().cloned())
        .collect();
    let (gx, gy) = (8, 6);
    let cells = coverage(&corners, size, gx, gy);
    let covered = cells.iter().filter(|&&c| c > 0).count() as f64 / cells.len() as f64;
    let corner_cells = [0, gx - 1, gx * (gy - 1), gx * gy - 1];
    let empty_corners = corner_cells.iter().filter(|&&i| cells[i] == 0).count();
    if covered < 0.7 || empty_corners > 0 {
        w.push(format!(
            "the views cover {:.0}% of the frame ({}×{} grid){}: distortion is unconstrained where no corner fell — add views there",
            100.0 * covered,
            gx,
            gy,
            if empty_corners > 0 { format!(", and {empty_corners} of the 4 frame corners have no corner") } else { String::new() }
        ));
    }
    let tilts: Vec<f64> = used.iter().map(|(_, p, _)| p.tilt().to_degrees()).collect();
    let max_tilt = tilts.iter().cloned().fold(0.0, f64::max);
    let min_tilt = tilts.iter().cloned().fold(f64::INFINITY, f64::min);
    if max_tilt < 20.0 || max_tilt - min_tilt < 15.0 {
        w.push(format!(
            "board tilts range over {min_tilt:.0}°–{max_tilt:.0}°: too little to separate focal length from distance — add views tilted 30–45°"
        ));
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outlier_rule() {
        let v = [0.21, 0.25, 0.23, 0.3, 1.2, 0.26, 0.22, 0.28];
        assert_eq!(outlier_views(&v), vec![4]);
        assert!(outlier_views(&[0.2, 0.21, 0.22, 0.25, 0.24]).is_empty());
    }

    #[test]
    fn pattern_parsing() {
        assert_eq!(Pattern::parse("9x6"), Some(Pattern { cols: 9, rows: 6 }));
        assert_eq!(Pattern::parse("1x6"), None);
        assert_eq!(
            Pattern::parse("100x100"),
            Some(Pattern {
                cols: 100,
                rows: 100
            })
        );
        assert_eq!(Pattern::parse("70000x70000"), None);
        assert_eq!(Pattern::parse("nine"), None);
    }
}
