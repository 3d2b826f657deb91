//! `workbench bench`: time and error of every stage, over the library's public API ([`run`]).

use super::Report;
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;
use std::path::PathBuf;

mod end_to_end;
mod run;
use run as bench;

pub(crate) fn bench(a: BenchArgs, quiet: bool) -> Result<Benched> {
    let out = a.out.unwrap_or_else(bench::default_out);
    let report = bench::run(&bench::BenchOptions {
        out: out.clone(),
        quick: a.quick,
        quiet,
    })
    .with_context(|| format!("bench into {}", out.display()))?;
    Ok(Benched { report, out })
}

/// The benchmark's tables and where they were written.
pub(crate) struct Benched {
    report: bench::BenchReport,
    out: PathBuf,
}

impl fmt::Display for Benched {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}", bench::markdown(&self.report))?;
        writeln!(f, "wrote    {}", self.out.join("report.md").display())
    }
}

impl Report for Benched {}
