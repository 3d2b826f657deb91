//! Rendering with a measured material: the CDRF's look-up table ([`lut`]), meshes ([`mesh`]), the
//! rasterizer ([`raster`]), the check against the fit's own spheres ([`check`]), and the `lut` and
//! `render` commands as library calls ([`job`]).

pub mod check;
pub mod job;
pub mod lut;
pub mod mesh;
pub mod preset;
pub mod raster;
pub mod view;
