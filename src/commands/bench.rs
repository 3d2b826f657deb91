//! `workbench bench`: time and error of every stage.

use crate::cli::*;
use anyhow::{Context, Result};

pub(crate) fn bench(a: BenchArgs, quiet: bool) -> Result<()> {
    use workbench::bench;
    let out = a.out.unwrap_or_else(bench::default_out);
    let r = bench::run(&bench::BenchOptions {
        out: out.clone(),
        quick: a.quick,
        quiet,
    })
    .with_context(|| format!("bench into {}", out.display()))?;
    print!("{}", bench::markdown(&r));
    println!("wrote    {}", out.join("report.md").display());
    Ok(())
}
