//! Files the stages exchange with the outside world and with each other: the session a user
//! writes ([`session`]), the camera's calibration ([`intrinsics`]), photos ([`photo`]) and their EXIF
//! ([`exif`]), and atomic output ([`output`]).

pub mod exif;
pub mod intrinsics;
pub mod output;
pub mod photo;
pub mod session;
