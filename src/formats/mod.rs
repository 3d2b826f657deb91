//! Files the stages exchange with the outside world and with each other.

pub mod exif;
