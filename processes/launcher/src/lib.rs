//! The acps launcher: named experiments of the paper, run in-process over methods x seeds, and
//! problems of the user's from problem files, served to the user's workers.
#![warn(missing_docs)]

pub mod bench;
pub mod checkpoints;
pub mod cli;
pub mod commands;
pub mod compare;
pub mod config;
pub mod evaluate;
pub mod experiment;
pub mod paper;
pub mod plot;
pub mod problem_file;
pub mod progress;
pub mod records;
pub mod workers;
