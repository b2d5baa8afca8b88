//! The `acps` command line and the worker fleet end to end, in one test binary: one link of the
//! whole workspace instead of one per file.

use std::process::{Command, Output};

mod cli;
mod config;
mod fleet;
mod python;
mod run_dir;

/// `acps args`, run to its end.
fn acps(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_acps"))
        .args(args)
        .output()
        .expect("acps runs")
}
