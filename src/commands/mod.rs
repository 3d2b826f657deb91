//! One module per command: each takes its parsed arguments, calls the library and prints the
//! result.

mod bench;
#[cfg(feature = "opencv")]
mod calibrate;
mod check;
mod detect;
mod lut;
mod plot;
mod render;
mod solve;
mod synth;

use crate::cli::{Command, Synth};
use anyhow::Result;
use std::path::PathBuf;

/// Run one parsed command.
pub(crate) fn run(command: Command, quiet: bool) -> Result<()> {
    match command {
        Command::Synth(Synth::Session(a)) => synth::synth_session(a, quiet),
        Command::Synth(Synth::Checkerboard(a)) => synth::synth_checkerboard(a, quiet),
        Command::Synth(Synth::Pbr(a)) => synth::synth_pbr(a, quiet),
        Command::Detect(a) => detect::detect(a, quiet),
        Command::Solve(a) => solve::solve(a, quiet),
        Command::Plot(a) => plot::plot(a, quiet),
        Command::Bench(a) => bench::bench(a, quiet),
        Command::Lut(a) => lut::lut(a),
        Command::Render(a) => render::render(a),
        Command::Check { session } => check::check(session),
        #[cfg(feature = "opencv")]
        Command::Calibrate(a) => calibrate::calibrate(a, quiet),
    }
}

/// `name` in the folder of `file`.
pub(crate) fn beside(file: &std::path::Path, name: &str) -> PathBuf {
    file.parent()
        .unwrap_or(std::path::Path::new("."))
        .join(name)
}
