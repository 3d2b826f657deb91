//! Detection overlays: the photo (tone-mapped to sRGB), each fitted silhouette, the edge points
//! RANSAC kept, the highlight and an arrow toward the light.

use crate::camera::outline::Projection;
use crate::detect::found::Found;
use crate::error::{Error, Result};
use crate::formats::photo::{srgb_u8, LinearRgb};
use crate::model::LightAngles;
use crate::plot::{register_font, BLUE, GREEN, ORANGE, VERMILLION};
use nalgebra::{Vector2, Vector3};
use plotters::prelude::*;
use std::path::Path;

/// Largest overlay width; bigger photos are box-downscaled by an integer factor.
const MAX_WIDTH: u32 = 2000;

/// Draw and write the overlay of one photo (PNG): the photo tone-mapped, then each sphere's
/// marks.
pub fn write(
    path: &Path,
    img: &LinearRgb,
    proj: &Projection,
    found: &[Found],
    light: Option<&Vector3<f64>>,
) -> Result<()> {
    let k = img.width.div_ceil(MAX_WIDTH).max(1);
    let (w, h) = (img.width / k, img.height / k);
    let mut buf = tone_mapped(img, k);
    register_font();
    let pen = Pen {
        k,
        w,
        h,
        thick: (w / 800).max(1) + 1,
        font_px: (w as f64 / 55.0).max(13.0),
    };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        for (idx, f) in found.iter().enumerate() {
            pen.sphere(&root, path, proj, f, idx, light)?;
        }
        root.present()
            .map_err(|e| Error::invalid(path, format!("cannot draw: {e}")))?;
    }
    crate::formats::photo::write_8bit(path, w, h, 3, &buf, 0, None)
}

/// The photo box-downscaled by `k`, tone-mapped: the 99.5th percentile of luminance to 90%
/// white, then sRGB, 8 bits.
fn tone_mapped(img: &LinearRgb, k: u32) -> Vec<u8> {
    let (w, h) = (img.width / k, img.height / k);
    let mut lum: Vec<f32> = img
        .data
        .chunks_exact(3)
        .step_by(7)
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    let at = (lum.len() as f64 * 0.995) as usize;
    let white = ((*lum.select_nth_unstable_by(at, |a, b| a.total_cmp(b)).1).max(1e-6) / 0.9) as f64;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut s = 0.0;
                for dy in 0..k {
                    for dx in 0..k {
                        let i = ((y * k + dy) * img.width + x * k + dx) as usize;
                        s += img.data[3 * i + c] as f64;
                    }
                }
                let v = srgb_u8((s / (k * k) as f64 / white).clamp(0.0, 1.0));
                buf[((y * w + x) * 3 + c as u32) as usize] = v;
            }
        }
    }
    buf
}

/// The overlay's scale (`k`: photo pixels per overlay pixel), size and strokes.
struct Pen {
    k: u32,
    w: u32,
    h: u32,
    thick: u32,
    font_px: f64,
}

impl Pen {
    /// One sphere's marks: its silhouette, the edge points kept, the highlight, a label and an
    /// arrow toward the light.
    fn sphere(
        &self,
        root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
        path: &Path,
        proj: &Projection,
        f: &Found,
        idx: usize,
        light: Option<&Vector3<f64>>,
    ) -> Result<()> {
        let (k, w, h, thick, font_px) = (self.k, self.w, self.h, self.thick, self.font_px);
        let scale = |p: Vector2<f64>| ((p.x / k as f64) as i32, (p.y / k as f64) as i32);
        let err = |e: DrawingAreaErrorKind<_>| Error::invalid(path, format!("cannot draw: {e}"));
        let rim: Vec<(i32, i32)> = f
            .silhouette
            .outline
            .rim(720)
            .iter()
            .filter_map(|q| proj.pixel(q))
            .map(scale)
            .collect();
        let mut closed = rim.clone();
        if let Some(p) = rim.first() {
            closed.push(*p);
        }
        root.draw(&PathElement::new(closed, GREEN.stroke_width(thick)))
            .map_err(err)?;
        for p in f.silhouette.inlier_px.iter().step_by(3) {
            root.draw(&Circle::new(scale(*p), 1, BLUE.filled()))
                .map_err(err)?;
        }
        let Some(c) = proj.pixel(&f.silhouette.outline.center_point()) else {
            return Ok(());
        };
        let r = f.silhouette.outline.radius_px(proj) / k as f64;
        let (cx, cy) = scale(c);

        let text = match &f.highlight {
            Ok(hl) => {
                let (hx, hy) = scale(hl.px);
                let s = (r * 0.08).max(6.0) as i32;
                root.draw(&PathElement::new(
                    vec![(hx - s, hy), (hx + s, hy)],
                    VERMILLION.stroke_width(thick),
                ))
                .map_err(err)?;
                root.draw(&PathElement::new(
                    vec![(hx, hy - s), (hx, hy + s)],
                    VERMILLION.stroke_width(thick),
                ))
                .map_err(err)?;
                let a = LightAngles::from_direction(&hl.light);
                format!(
                    "{} mm: az {:.2}° el {:.2}°",
                    f.silhouette.radius_mm,
                    a.azimuth.to_degrees(),
                    a.elevation.to_degrees()
                )
            }
            Err(why) => format!(
                "{} mm: no highlight ({})",
                f.silhouette.radius_mm,
                short(why)
            ),
        };
        // Labels alternate below and above the spheres (a row of them does not collide),
        // kept inside the frame.
        let text_w = (text.chars().count() as f64 * font_px * 0.55) as i32;
        let x = (cx - text_w / 2).clamp(4, (w as i32 - text_w - 4).max(4));
        let y = if idx.is_multiple_of(2) {
            cy + (r * 1.05) as i32 + 4
        } else {
            cy - (r * 1.05) as i32 - font_px as i32 - 4
        };
        let label_at = (x, y.clamp(4, h as i32 - font_px as i32 - 4));
        root.draw(&Text::new(
            text,
            label_at,
            ("sans-serif", font_px).into_font().color(&WHITE),
        ))
        .map_err(err)?;
        // Arrow toward the light (its image-plane components, scaled to the radius).
        if let Some(l) = light {
            let d = Vector2::new(l.x, l.y) * r;
            if d.norm() > 2.0 {
                let tip = (cx + d.x as i32, cy + d.y as i32);
                root.draw(&PathElement::new(
                    vec![(cx, cy), tip],
                    ORANGE.stroke_width(thick + 1),
                ))
                .map_err(err)?;
                let u = d.normalize();
                let n = Vector2::new(-u.y, u.x);
                let hs = (r * 0.12).max(6.0);
                let back = Vector2::new(tip.0 as f64, tip.1 as f64) - u * hs;
                let a = back + n * hs * 0.5;
                let b = back - n * hs * 0.5;
                root.draw(&Polygon::new(
                    vec![tip, (a.x as i32, a.y as i32), (b.x as i32, b.y as i32)],
                    ORANGE.filled(),
                ))
                .map_err(err)?;
            }
        }
        Ok(())
    }
}

fn short(s: &str) -> String {
    s.split(" (").next().unwrap_or(s).chars().take(40).collect()
}
