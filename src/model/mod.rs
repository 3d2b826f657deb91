//! The forward model, a pixel's radiance from the material, the light and the surface under it:
//! the CDRF's blur ([`cdrf`], tabulated for the fit in [`table`]), the Fresnel transmissions ([`fresnel`], [`entry`]), the specular
//! lobe ([`specular`]) and their sum with its gradient ([`radiance`], whose items are re-exported
//! here).

pub mod boundary;
pub mod cdrf;
pub mod dipole;
pub mod entry;
pub mod exit_tilt;
pub mod fresnel;
pub mod lanes;
pub mod mixture;
pub mod normalized_diffusion;
pub mod quadrature;
mod radiance;
pub mod rough_level;
pub mod specular;
pub mod sphere_atlas;
pub mod sphere_diffusion;
pub mod sphere_profile;
pub mod table;
pub mod tangential_flux;

pub use radiance::*;
