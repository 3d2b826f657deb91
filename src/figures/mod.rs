//! A fit's figures ([`fitplot`]) and its page ([`report`]), drawn with [`crate::plot`].

pub mod fitplot;
pub mod report;
