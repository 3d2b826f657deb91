//! Figures: the plotting module ([`plot`]), a fit's figures ([`fitplot`]) and its page
//! ([`report`]).

pub mod fitplot;
pub mod plot;
pub mod report;
