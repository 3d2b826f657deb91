//! workbench: camera calibration and inverse rendering of translucent spheres, measuring a
//! curvature-dependent reflectance function (CDRF).
//!
//! Conventions: millimetres; radians inside (degrees only in human-facing output); the OpenCV
//! camera frame (x right, y down, z forward); light and view vectors point away from the surface.

// `!(x > 0.0)` is how the argument checks reject NaN along with the out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod calibrate;
pub mod camera;
pub mod detect;
pub mod error;
pub mod figures;
pub mod fit;
pub mod formats;
pub mod lm;
pub mod model;
pub mod plot;
pub mod progress;
pub mod render;
pub mod solve;
pub mod stats;
pub mod synth;

pub use error::{Error, Result};
