//! The `acps` command line and the worker fleet end to end, in one test binary: one link of the
//! whole workspace instead of one per file.

mod cli;
mod config;
mod fleet;
mod run_dir;
