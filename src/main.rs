//! The `workbench` command line, shaped like ripgrep's: parse the arguments ([`cli`]), run the
//! command ([`commands`]), print its report or its error once, as one line, and exit non-zero on
//! error. A reader that stops early (`| head`) ends the printing quietly, as for grep; the exit
//! status stays the command's.

mod cli;
mod commands;

use clap::Parser;
use std::io::Write;
use std::process::ExitCode;

fn main() -> ExitCode {
    cli::signals::clean_up_on_signals();
    let cli = match cli::Cli::try_parse() {
        Ok(cli) => cli,
        // --help, --version, and no subcommand at all: clap's full text.
        Err(e)
            if !e.use_stderr()
                || e.kind() == clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand =>
        {
            e.exit()
        }
        Err(e) => {
            cli::say(&cli::one_line(&e));
            return ExitCode::from(2);
        }
    };
    let report = match commands::run(cli.command, cli.quiet) {
        Ok(r) => r,
        Err(e) => {
            cli::say(&format!("error: {e:#}"));
            return ExitCode::FAILURE;
        }
    };
    let mut out = std::io::stdout().lock();
    if let Err(e) = write!(out, "{report}").and_then(|()| out.flush()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            cli::say(&format!("error: writing the report: {e}"));
            return ExitCode::FAILURE;
        }
    }
    match report.failure() {
        Some(why) => {
            cli::say(&format!("error: {why}"));
            ExitCode::from(3)
        }
        None => ExitCode::SUCCESS,
    }
}
