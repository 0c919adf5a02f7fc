//! The `oxicat` binary.
#![forbid(unsafe_code)]

use clap::Parser;

fn main() -> std::process::ExitCode {
    match oxicat::run(oxicat::Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // Standard output closed by its reader (`oxicat sdos | head -1`): end quietly.
        Err(e) if e.is_broken_pipe() => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("oxicat: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
