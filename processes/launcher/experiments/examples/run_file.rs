//! Run an experiment file from a Rust program, as `acps experiment --config FILE` does, and read
//! the run directory it wrote: `summary.json`, the tables, the policies and the pictures.
//!
//! ```sh
//! cargo run --release -p acps-experiments --example run_file -- experiments/function-fig4.toml runs/mine
//! ```
//!
//! Settings given in the program override the file's, like options on the command line: here
//! two runs of 500 episodes, so that it takes seconds.

use acps_experiments::run_dir::RunDir;
use acps_experiments::settings::ExperimentFile;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args_os().skip(1).map(PathBuf::from);
    let (Some(file), Some(out)) = (args.next(), args.next()) else {
        return Err("usage: run_file EXPERIMENT_FILE OUTPUT_DIR".into());
    };
    let shorter = ExperimentFile {
        runs: Some(2),
        episodes: Some(500),
        ..Default::default()
    };
    let run = RunDir::plan(Some(&file), &shorter, Some(out))?;
    run.prepare()?;
    let summaries = run.in_process(true, &AtomicBool::new(false), &|summary, dir| {
        acps_reports::plot::write_all(summary, dir)
    })?;
    for (job, summary) in run.jobs.iter().zip(&summaries) {
        println!("{} -> {}", summary.experiment, job.dir.display());
        for (method, result) in &summary.methods {
            let last = result.final_mean.map_or("none".to_string(), |m| format!("{m:.4}"));
            println!("  {method}: final mean score {last} over {} runs", summary.runs);
        }
    }
    Ok(())
}
