//! The `zerovar` command: `render` a scene to EXR and PNG, or `check` that a scene loads.
//!
//! Raw arguments are turned into one validated configuration (`cli::Command`) before any work
//! starts; the library does the rest.

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    match cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
