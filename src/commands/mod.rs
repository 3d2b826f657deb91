//! One module per command: each takes its parsed arguments, calls the library and returns a
//! [`Report`] — what it has to say, written by its `Display` in one place; `main` prints it.

mod bench;
#[cfg(feature = "opencv")]
mod calibrate;
mod check;
mod close_loop;
mod detect;
mod export;
mod lut;
mod plot;
mod render;
mod solve;
mod synth;
mod view;

use crate::cli::{Command, Synth};
use anyhow::Result;
use std::fmt;
use std::path::PathBuf;

/// What a command that ran has to say: its lines for standard output (`Display`) and, for a
/// result written but not to be trusted (a fit that did not converge), the line for standard
/// error that makes the exit status 3.
pub(crate) trait Report: fmt::Display {
    fn failure(&self) -> Option<String> {
        None
    }
}

/// Run one parsed command.
pub(crate) fn run(command: Command, quiet: bool) -> Result<Box<dyn Report>> {
    fn boxed<R: Report + 'static>(r: Result<R>) -> Result<Box<dyn Report>> {
        r.map(|r| Box::new(r) as Box<dyn Report>)
    }
    match command {
        Command::Synth(Synth::Session(a)) => boxed(synth::synth_session(a, quiet)),
        Command::Synth(Synth::Checkerboard(a)) => boxed(synth::synth_checkerboard(a, quiet)),
        Command::Synth(Synth::Pbr(a)) => boxed(synth::synth_pbr(a, quiet)),
        Command::Detect(a) => boxed(detect::detect(a, quiet)),
        Command::Solve(a) => boxed(solve::solve(a, quiet)),
        Command::Plot(a) => boxed(plot::plot(a, quiet)),
        Command::Bench(a) => boxed(bench::bench(a, quiet)),
        Command::Lut(a) => lut::lut(a),
        Command::Render(a) => boxed(render::render(a)),
        Command::View(a) => boxed(view::view(a)),
        Command::Export(a) => boxed(export::export(a)),
        Command::CloseLoop(a) => boxed(close_loop::close_loop(a, quiet)),
        Command::Check { session } => boxed(check::check(session)),
        #[cfg(feature = "opencv")]
        Command::Calibrate(a) => boxed(calibrate::calibrate(a, quiet)),
    }
}

/// `name` in the folder of `file`.
pub(crate) fn beside(file: &std::path::Path, name: &str) -> PathBuf {
    file.parent()
        .unwrap_or(std::path::Path::new("."))
        .join(name)
}
