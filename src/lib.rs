//! workbench: camera calibration and inverse rendering of translucent spheres, measuring a
//! curvature-dependent reflectance function (CDRF).
//!
//! Conventions: millimetres; radians inside (degrees only in human-facing output); the OpenCV
//! camera frame (x right, y down, z forward); light and view vectors point away from the surface.

// `!(x > 0.0)` is how the argument checks reject NaN along with the out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod calibration;
pub mod camera;
pub mod cdrf;
#[cfg(feature = "opencv")]
pub mod cv;
pub mod detect;
pub mod entry;
pub mod error;
pub mod fitplot;
pub mod formats;
pub mod fresnel;
pub mod highlight;
pub mod intrinsics;
pub mod joint;
pub mod lut;
pub mod mesh;
pub mod model;
pub mod observe;
pub mod outline;
pub mod output;
pub mod overlay;
pub mod paper;
pub mod photo;
pub mod plot;
pub mod progress;
pub mod reduce;
pub mod render;
pub mod render_check;
pub mod render_job;
pub mod report;
pub mod samples;
pub mod session;
pub mod silhouette;
pub mod solve;
pub mod solver;
pub mod specular;
pub mod sphere;
pub mod stats;
pub mod synth;

pub use error::{Error, Result};
