//! The measured CDRF as a look-up table over N·L and curvature (pre-integrated shading).
//!
//! The table holds the fitted diffuse term without exit transmission, per colour channel,
//!
//!     D_c(N·L, κ) = a_c(κ) · f(acos(N·L); σ_c(κ))        (see [`Model::diffuse`])
//!
//! on a grid of nodes: column i is N·L = −1 + 2i / (n_cos − 1), row j is κ = κ_max · j /
//! (n_kappa − 1) in 1/mm (row 0 a flat surface). Between nodes it is interpolated bilinearly;
//! outside it is clamped (N·L to [−1, 1], κ to [0, κ_max]). Both axes are linear: the clamped
//! cosine is linear in N·L (an odd n_cos puts its kink N·L = 0 on a node) and the blur
//! σ = σ0 · κ is linear in κ. κ_max is [`KAPPA_MAX_FACTOR`] times the highest curvature the fit
//! measured (its smallest sphere).
//!
//! [`interpolation_error`] measures the table against the closed form at every cell's centre and
//! edge midpoints; [`choose`] picks the smallest size of [`SIZES`] within a tolerance.

use crate::error::{Error, Result};
use crate::formats::fit::FitFile;
use crate::formats::output::{write_bytes, write_json};
use crate::formats::photo::write_png16_rgb;
use crate::model::{Material, Model, Rgb};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(crate) const SCHEMA: &str = "workbench.lut/1";

/// κ_max over the highest measured curvature 1 / r_min: the table reaches three times the smallest
/// sphere's blur (beyond it a render clamps).
pub(crate) const KAPPA_MAX_FACTOR: f64 = 3.0;

/// Table sizes (n_cos × n_kappa nodes) [`choose`] tries, smallest first.
pub(crate) const SIZES: [(usize, usize); 6] = [
    (33, 17),
    (65, 33),
    (129, 65),
    (257, 129),
    (513, 257),
    (1025, 513),
];

/// Default tolerance of [`choose`]: the largest interpolation error over the table, as a fraction
/// of the table's peak value.
pub const DEFAULT_TOLERANCE: f64 = 1e-3;

/// The table.
#[derive(Clone, Debug, PartialEq)]
pub struct Lut {
    pub n_cos: usize,
    pub n_kappa: usize,
    /// Curvature of the last row (1/mm).
    pub kappa_max: f64,
    /// Row-major: `values[j * n_cos + i]` at N·L of column i and κ of row j.
    pub values: Vec<[f32; 3]>,
}

impl Lut {
    /// Tabulate `model`'s diffuse term for `material`.
    pub fn build(
        model: &Model,
        material: &Material,
        n_cos: usize,
        n_kappa: usize,
        kappa_max: f64,
    ) -> Lut {
        assert!(n_cos >= 2 && n_kappa >= 2 && kappa_max > 0.0);
        let mut lut = Lut {
            n_cos,
            n_kappa,
            kappa_max,
            values: vec![[0.0; 3]; n_cos * n_kappa],
        };
        let (cos, kap): (Vec<f64>, Vec<f64>) = (
            (0..n_cos).map(|i| lut.cos_at(i)).collect(),
            (0..n_kappa).map(|j| lut.kappa_at(j)).collect(),
        );
        lut.values
            .par_chunks_mut(n_cos)
            .zip(kap.par_iter())
            .for_each(|(row, &k)| {
                for (v, &c) in row.iter_mut().zip(&cos) {
                    let d = model.diffuse(material, c, k);
                    *v = [d[0] as f32, d[1] as f32, d[2] as f32];
                }
            });
        lut
    }

    /// N·L of column i.
    pub(crate) fn cos_at(&self, i: usize) -> f64 {
        -1.0 + 2.0 * i as f64 / (self.n_cos - 1) as f64
    }

    /// κ of row j (1/mm).
    pub(crate) fn kappa_at(&self, j: usize) -> f64 {
        self.kappa_max * j as f64 / (self.n_kappa - 1) as f64
    }

    /// Bilinear look-up, clamped to the table's ranges.
    #[inline]
    pub fn sample(&self, cos: f32, kappa: f32) -> [f32; 3] {
        let u = ((cos + 1.0) * 0.5).clamp(0.0, 1.0) * (self.n_cos - 1) as f32;
        let v = (kappa / self.kappa_max as f32).clamp(0.0, 1.0) * (self.n_kappa - 1) as f32;
        let i = (u as usize).min(self.n_cos - 2);
        let j = (v as usize).min(self.n_kappa - 2);
        let (fu, fv) = (u - i as f32, v - j as f32);
        let r0 = j * self.n_cos + i;
        let r1 = r0 + self.n_cos;
        let (a, b, c, d) = (
            self.values[r0],
            self.values[r0 + 1],
            self.values[r1],
            self.values[r1 + 1],
        );
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * fu;
            let bottom = c[k] + (d[k] - c[k]) * fu;
            top + (bottom - top) * fv
        })
    }

    /// The largest value in the table.
    pub fn peak(&self) -> f64 {
        self.values
            .iter()
            .flat_map(|v| v.iter())
            .fold(0.0f32, |a, &b| a.max(b)) as f64
    }

    /// The table as 16-bit values, `value / scale · 65535` rounded, rows top (κ = 0) to bottom.
    pub(crate) fn to_u16(&self, scale: f64) -> Vec<u16> {
        self.values
            .iter()
            .flat_map(|v| v.iter())
            .map(|&x| ((x as f64 / scale).clamp(0.0, 1.0) * 65535.0).round() as u16)
            .collect()
    }
}

/// How far the bilinear table is from the closed form.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct InterpolationError {
    /// Largest absolute error over every channel and point (table units).
    pub max_abs: f64,
    /// Root mean square over every channel and point.
    pub rms: f64,
    /// `max_abs` over the table's peak value.
    pub max_rel: f64,
    /// Where the largest error is (N·L, κ in 1/mm).
    pub at_cos: f64,
    pub at_kappa_per_mm: f64,
    /// Points compared (three per cell: its centre and two edge midpoints).
    pub points: usize,
}

/// Compare the table with the closed form at every cell's centre and the midpoints of its lower
/// and left edges, where bilinear interpolation is furthest from its nodes.
pub(crate) fn interpolation_error(
    lut: &Lut,
    model: &Model,
    material: &Material,
) -> InterpolationError {
    let du = 1.0 / (lut.n_cos - 1) as f64;
    let dv = 1.0 / (lut.n_kappa - 1) as f64;
    let per_row: Vec<(f64, f64, f64, f64, usize)> = (0..lut.n_kappa - 1)
        .into_par_iter()
        .map(|j| {
            let mut worst = (0.0f64, 0.0, 0.0);
            let mut sq = 0.0;
            let mut n = 0;
            for i in 0..lut.n_cos - 1 {
                for (a, b) in [(0.5, 0.5), (0.5, 0.0), (0.0, 0.5)] {
                    let cos = -1.0 + 2.0 * (i as f64 + a) * du;
                    let kappa = lut.kappa_max * (j as f64 + b) * dv;
                    let exact = model.diffuse(material, cos, kappa);
                    let got = lut.sample(cos as f32, kappa as f32);
                    for c in 0..3 {
                        let e = (got[c] as f64 - exact[c]).abs();
                        sq += e * e;
                        n += 1;
                        if e > worst.0 {
                            worst = (e, cos, kappa);
                        }
                    }
                }
            }
            (worst.0, worst.1, worst.2, sq, n)
        })
        .collect();
    let (mut max_abs, mut at_cos, mut at_kappa, mut sq, mut n) = (0.0, 0.0, 0.0, 0.0, 0);
    for (e, c, k, s, m) in per_row {
        if e > max_abs {
            (max_abs, at_cos, at_kappa) = (e, c, k);
        }
        sq += s;
        n += m;
    }
    let peak = lut.peak();
    InterpolationError {
        max_abs,
        rms: (sq / n.max(1) as f64).sqrt(),
        max_rel: if peak > 0.0 { max_abs / peak } else { 0.0 },
        at_cos,
        at_kappa_per_mm: at_kappa,
        points: n / 3,
    }
}

/// A size tried by [`choose`] and its largest error over the peak.
pub type Tried = ((usize, usize), f64);

/// The smallest of [`SIZES`] whose table (`build` makes it and measures its error) is within
/// `tolerance` of its peak (the largest size when none is), with its measured error and every size
/// tried with its relative error. The node table and the engine presets' texel table both choose
/// their size with it.
pub(crate) fn choose<T>(
    tolerance: f64,
    build: impl Fn(usize, usize) -> (T, InterpolationError),
) -> (T, InterpolationError, Vec<Tried>) {
    let mut tried = Vec::new();
    for &(nc, nk) in &SIZES {
        let (table, err) = build(nc, nk);
        tried.push(((nc, nk), err.max_rel));
        if err.max_rel <= tolerance || (nc, nk) == SIZES[SIZES.len() - 1] {
            return (table, err, tried);
        }
    }
    unreachable!("the last size always returns")
}

/// The model and material a fit describes, and the range of curvature it measured (1/mm).
pub struct FitMaterial {
    pub model: Model,
    pub material: Material,
    pub light: crate::model::LightAngles,
    /// [1 / r_max, 1 / r_min] over the fit's spheres.
    pub measured_kappa: [f64; 2],
}

impl FitMaterial {
    pub(crate) fn from_fit(fit: &FitFile, file: &Path) -> Result<FitMaterial> {
        fit.validate(file)?;
        let radii: Vec<f64> = fit.rmse.spheres.iter().map(|s| s.radius_mm).collect();
        let (lo, hi) = radii
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &r| (a.min(r), b.max(r)));
        if !(lo > 0.0) || !hi.is_finite() {
            return Err(Error::invalid(file, "no sphere radii in rmse.spheres"));
        }
        let p = fit.params();
        let m = &p.material;
        if m.sigma0_mm.iter().chain(&m.albedo).any(|&x| !(x >= 0.0)) || !(m.eta >= 1.0) {
            return Err(Error::invalid(
                file,
                "σ0 and albedo must be ≥ 0 and η ≥ 1 to tabulate",
            ));
        }
        if !(fit.reference_radius_mm > 0.0) {
            return Err(Error::invalid(file, "reference_radius_mm must be > 0"));
        }
        Ok(FitMaterial {
            model: fit.model(),
            material: p.material,
            light: p.light,
            measured_kappa: [1.0 / hi, 1.0 / lo],
        })
    }

    /// The default κ_max: [`KAPPA_MAX_FACTOR`] / r_min.
    pub fn kappa_max(&self) -> f64 {
        KAPPA_MAX_FACTOR * self.measured_kappa[1]
    }

    /// The exact diffuse term (table units), for checks.
    pub fn diffuse(&self, cos: f64, kappa: f64) -> Rgb {
        self.model.diffuse(&self.material, cos, kappa)
    }
}

/// Read and check `fit.json`.
pub(crate) fn read_fit(path: &Path) -> Result<(FitFile, FitMaterial)> {
    let fit: FitFile = crate::formats::output::read_json(path)?;
    let fm = FitMaterial::from_fit(&fit, path)?;
    Ok((fit, fm))
}

/// The JSON sidecar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LutJson {
    pub schema: String,
    /// The fit tabulated.
    pub fit: String,
    /// The images beside this file.
    pub png: String,
    pub exr: String,
    pub n_cos: usize,
    pub n_kappa: usize,
    pub cos_range: [f64; 2],
    pub kappa_range_per_mm: [f64; 2],
    /// The curvatures the fit measured, [1 / r_max, 1 / r_min].
    pub measured_kappa_per_mm: [f64; 2],
    pub mapping: String,
    /// PNG pixel p (16-bit) holds the value p / 65535 · png_scale (linear, no transfer curve).
    pub png_scale: f64,
    pub content: String,
    pub convolution: crate::model::cdrf::Convolution,
    pub reference_radius_mm: f64,
    pub material: Material,
    pub interpolation_error: InterpolationError,
    /// The tolerance the size was chosen for (null: the size was given).
    pub tolerance: Option<f64>,
}

/// The stem of `--out` (an extension .png/.exr/.json given with it is dropped).
pub fn stem_of(out: &Path) -> PathBuf {
    match out.extension().and_then(|e| e.to_str()) {
        Some("png" | "exr" | "json") => out.with_extension(""),
        _ => out.to_path_buf(),
    }
}

/// `<stem>.<ext>` (the stem's own dots kept).
pub(crate) fn with_extension(stem: &Path, ext: &str) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

/// A path's file name, as a sidecar names the files beside it.
pub(crate) fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The three output paths of `--out <stem>` (an extension .png/.exr/.json is dropped).
pub(crate) fn output_paths(out: &Path) -> [PathBuf; 3] {
    let stem = stem_of(out);
    ["png", "exr", "json"].map(|e| with_extension(&stem, e))
}

/// Write the table as a 16-bit PNG, an OpenEXR float image and the JSON sidecar. Returns the paths.
pub fn write(
    out: &Path,
    lut: &Lut,
    fm: &FitMaterial,
    fit_path: &Path,
    err: &InterpolationError,
    tolerance: Option<f64>,
) -> Result<[PathBuf; 3]> {
    let paths = output_paths(out);
    let [png, exr, json] = &paths;
    // A table of inf or NaN is no table: said, not written (issue 33).
    if !lut.values.iter().flatten().all(|v| v.is_finite()) {
        return Err(Error::invalid(
            fit_path,
            "the table of this fit is not finite everywhere: its material is beyond what the model evaluates",
        ));
    }
    // One set: the PNG and the EXR, then the sidecar that describes them last.
    let set = crate::formats::output::OutputSet::begin(&[png, exr, json])?;
    let scale = lut.peak().max(f64::MIN_POSITIVE);
    write_png16_rgb(
        png,
        lut.n_cos as u32,
        lut.n_kappa as u32,
        &lut.to_u16(scale),
    )?;
    let floats: Vec<f32> = lut.values.iter().flat_map(|v| v.iter().copied()).collect();
    let img = image::Rgb32FImage::from_raw(lut.n_cos as u32, lut.n_kappa as u32, floats)
        .expect("buffer matches the size");
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::OpenExr)
        .map_err(|e| Error::Image {
            path: exr.clone(),
            err: e,
        })?;
    write_bytes(exr, bytes.get_ref())?;
    let sidecar = LutJson {
        schema: SCHEMA.into(),
        fit: fit_path.display().to_string(),
        png: file_name(png),
        exr: file_name(exr),
        n_cos: lut.n_cos,
        n_kappa: lut.n_kappa,
        cos_range: [-1.0, 1.0],
        kappa_range_per_mm: [0.0, lut.kappa_max],
        measured_kappa_per_mm: fm.measured_kappa,
        mapping: format!(
            "column i: N·L = -1 + 2 i / {}; row j (top = 0): kappa = {} / mm · j / {}; linear in both, \
             bilinear between nodes, clamped outside",
            lut.n_cos - 1,
            lut.kappa_max,
            lut.n_kappa - 1
        ),
        png_scale: scale,
        content: format!(
            "diffuse term a_c(kappa) · f(acos(N·L); sigma_c(kappa)) per channel (R, G, B), \
             linear radiance, without the exit Fresnel transmission or the specular lobe; f blurs {}",
            if fm.model.entry_fresnel {
                "the irradiance transmitted into the medium, max(N·L, 0) · (1 − F(N·L; eta))"
            } else {
                "the clamped cosine max(N·L, 0)"
            }
        ),
        convolution: fm.model.convolution,
        reference_radius_mm: fm.model.reference_radius_mm,
        material: fm.material,
        interpolation_error: *err,
        tolerance,
    };
    write_json(json, &sidecar)?;
    set.commit()?;
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Geometry, LightAngles, Params};
    use nalgebra::Vector3;

    fn material() -> Material {
        let mut p = Params::diffuse(
            [4.0, 3.0, 2.2],
            [0.8, 0.62, 0.45],
            1.44,
            LightAngles {
                azimuth: 0.0,
                elevation: 0.0,
            },
        );
        p.material.sigma_exponent = 0.3;
        p.material.albedo_curvature = 0.1;
        p.material
    }

    /// The table's content is the radiance model's diffuse part: with the lobe off, radiance over
    /// the exit transmission equals `Model::diffuse` at κ = 1/r.
    #[test]
    fn diffuse_is_the_models_diffuse_part() {
        let model = Model::default();
        let m = material();
        for (az, r) in [(0.3, 15.0), (1.2, 35.0), (2.0, 20.0)] {
            let light = LightAngles {
                azimuth: az,
                elevation: 0.1,
            };
            let p = Params { material: m, light };
            let n = Vector3::new(0.3, -0.2, -0.9).normalize();
            let v = Vector3::new(0.0, 0.0, -1.0);
            let g = Geometry {
                normal: n,
                view: v,
                radius_mm: r,
            };
            let rad = model.radiance(&p, &g);
            let t = crate::model::fresnel::transmission(n.dot(&v), m.eta);
            let d = model.diffuse(&m, n.dot(&light.direction()), 1.0 / r);
            for c in 0..3 {
                assert!(
                    (rad[c] - t * d[c]).abs() < 1e-12,
                    "{c}: {} vs {}",
                    rad[c],
                    t * d[c]
                );
            }
        }
        // κ = 0 is the unblurred source — the transmitted cosine max(N·L, 0)·T(N·L; η), to the
        // series' 1.1e-5 (crate::model::entry) — times the flat albedo a · exp(−b); without the entry
        // transmission the bare clamped cosine.
        let entered = Model {
            entry_fresnel: true,
            ..model
        };
        let d = entered.diffuse(&m, 0.6, 0.0);
        let t = crate::model::fresnel::transmission(0.6, m.eta);
        assert!((d[0] - 0.8 * (-0.1f64).exp() * 0.6 * t).abs() < 3e-5);
        let d = model.diffuse(&m, 0.6, 0.0);
        assert!((d[0] - 0.8 * (-0.1f64).exp() * 0.6).abs() < 1e-12);
        assert_eq!(model.diffuse(&m, -0.3, 0.0), [0.0; 3]);
    }

    #[test]
    fn nodes_are_exact_and_error_shrinks_with_size() {
        let model = Model::default();
        let m = material();
        let lut = Lut::build(&model, &m, 65, 33, 0.2);
        for (i, j) in [(0, 0), (32, 5), (64, 32), (40, 17)] {
            let exact = model.diffuse(&m, lut.cos_at(i), lut.kappa_at(j));
            let got = lut.sample(lut.cos_at(i) as f32, lut.kappa_at(j) as f32);
            for c in 0..3 {
                assert!((got[c] as f64 - exact[c]).abs() < 2e-6, "{i},{j}");
            }
        }
        let e1 = interpolation_error(&lut, &model, &m);
        let e2 = interpolation_error(&Lut::build(&model, &m, 129, 65, 0.2), &model, &m);
        // Bilinear interpolation of a smooth function: error ∝ h² away from the terminator's kink
        // at κ = 0, ∝ h at it; doubling the resolution must at least halve the largest error.
        assert!(e2.max_abs < 0.55 * e1.max_abs, "{e1:?} {e2:?}");
        assert!(e2.rms < 0.4 * e1.rms, "{e1:?} {e2:?}");
        // Clamping outside the ranges.
        assert_eq!(lut.sample(-3.0, 10.0), lut.sample(-1.0, 0.2));
    }

    #[test]
    fn choose_meets_the_tolerance() {
        let model = Model::default();
        let m = material();
        let (lut, err, _) = choose(2e-3, |nc, nk| {
            let l = Lut::build(&model, &m, nc, nk, 0.2);
            let e = interpolation_error(&l, &model, &m);
            (l, e)
        });
        assert!(err.max_rel <= 2e-3);
        // The size before it would not have met it.
        let k = SIZES
            .iter()
            .position(|&s| s == (lut.n_cos, lut.n_kappa))
            .unwrap();
        if k > 0 {
            let (nc, nk) = SIZES[k - 1];
            let smaller = interpolation_error(&Lut::build(&model, &m, nc, nk, 0.2), &model, &m);
            assert!(smaller.max_rel > 2e-3);
        }
    }

    #[test]
    fn output_paths_drop_a_known_extension() {
        let [a, b, c] = output_paths(Path::new("x/lut.png"));
        assert_eq!(
            (a.to_str(), b.to_str(), c.to_str()),
            (Some("x/lut.png"), Some("x/lut.exr"), Some("x/lut.json"))
        );
        let [a, _, _] = output_paths(Path::new("x/wax.v2"));
        assert_eq!(a.to_str(), Some("x/wax.v2.png"));
    }
}
