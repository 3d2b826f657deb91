//! The integration tests as one crate, a module per area: the suite links the OpenCV-backed
//! library once instead of once per file (docs/measurements/speed.md, "Build and suite time").

mod common;

mod calibration;
mod cdrf;
mod cli;
mod curvature;
mod detect;
mod docs;
mod engine;
mod exif;
mod export;
mod geometry;
mod hostile;
mod layout;
mod medium;
mod model;
mod pbr;
mod photo;
mod reliability;
mod render;
mod shaders;
mod solve;
mod solver;
mod stress;
mod synth;
mod uncertainty;
mod view;
