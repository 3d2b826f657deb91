//! Files the stages exchange with the outside world and with each other: the session a user
//! writes ([`session`]), the camera's calibration ([`intrinsics`], and for other tools [`camera_export`]), photos ([`photo`]) and their EXIF
//! ([`exif`]), what the detector found ([`detections`]), a fit ([`fit`]), a mesh with its curvature for engines ([`glb`]), atomic output
//! ([`output`]), inputs read only from regular files ([`input`]) and what an output was made from ([`fingerprint`]).

pub mod camera_export;
pub mod detections;
pub mod exif;
pub mod fingerprint;
pub mod fit;
pub mod glb;
pub mod input;
pub mod intrinsics;
pub mod material_export;
pub mod output;
pub mod photo;
pub mod session;
