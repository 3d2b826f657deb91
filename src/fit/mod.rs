//! From photos to the material: observations from the detected spheres ([`observe`]),
//! pooled ([`reduce`]), fitted by least squares ([`solver`]) in the joint fit's stages ([`joint`]),
//! beside the paper's procedure ([`paper`]). The `solve` job that drives them is [`crate::solve`].

pub mod joint;
pub mod medium;
pub mod noise;
pub mod observe;
pub mod paper;
pub mod predict;
pub mod reduce;
pub mod sigma_grid;
pub mod solver;
pub mod wave;
