//! `acps`: the command line of Active Contextual Policy Search.

use acps::experiment::{Experiment, progress_bar};
use acps::paper::{self, Options, Overrides};
use acps_learner::Method;
use acps_learner::selection::FirstVisit;
use anyhow::{Context, bail};
use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "acps",
    version,
    about = "Active contextual policy search (Fabisch & Metzen, JMLR 2014): C-REPS learns one policy over task contexts while D-UCB chooses which context to practise next."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run one of the paper's experiments in this process, for several methods x seeds in
    /// parallel, and write DIR/summary.json.
    Experiment(ExperimentArgs),
}

#[derive(Clone, Copy, ValueEnum)]
enum ExperimentName {
    /// Section 4's model of the learning process (Fig. 2 and 3).
    Toy,
    /// Section 5.1.2's contextual function on a 5x5 grid of contexts (Fig. 4 and 5).
    Function,
    /// Section 5.1.3: the contextual function for 1 to 4 context dimensions (Fig. 6).
    Dims,
    /// Section 5.2.3: the PA-10 throws at a 5x5 grid of targets, tested on a 4x4 grid (Fig. 8).
    Grid,
    /// Section 5.2.4: the PA-10 throws at the 81 fields of a dartboard on the ground (Fig. 10).
    Dartboard,
}

#[derive(Clone, Copy, ValueEnum)]
enum SimArg {
    /// Forward kinematics at release and closed-form flight (exact for perfect tracking).
    Analytic,
    /// The rapier3d multibody arm tracking the throw with joint motors (about 2 ms per throw).
    Rapier,
}

#[derive(clap::Args)]
struct ExperimentArgs {
    /// Which experiment.
    name: ExperimentName,
    /// Runs per method.
    #[arg(long, default_value_t = 20)]
    runs: usize,
    /// Training episodes per run (default: the paper's length: toy 1000, function 2500, dims 5000).
    #[arg(long)]
    episodes: Option<u64>,
    /// Seed of run 0; run r uses seed + r for the problem instance and the learner.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Training tasks in flight (P): task t is created after outcome t - P is consumed. 1 is the
    /// paper's sequential algorithm.
    #[arg(long, default_value_t = 1)]
    in_flight: usize,
    /// Run only this method (repeatable). Default: the methods of the paper's figure.
    #[arg(long = "method", value_name = "METHOD")]
    methods: Vec<String>,
    /// toy only: one panel of Fig. 2 (a: sigma_r 0, sigma_b 0; b: 0.01, 0; c: 0, 0.2; d: 0.01, 0.2)
    /// into DIR; without it all four go to DIR/a .. DIR/d.
    #[arg(long)]
    panel: Option<char>,
    /// dims only: one context dimension (1..=4) into DIR; without it all four go to DIR/ns-1 .. DIR/ns-4.
    #[arg(long)]
    n_s: Option<usize>,
    /// Number of low-level parameters n_theta of the contextual function (the paper does not say;
    /// default 20). Must exceed the context dimension.
    #[arg(long)]
    n_theta: Option<usize>,
    /// Baseline of a context's first visit for the progress heuristics: the initial greedy
    /// policy's return there (default), or none (the first visit scores 0).
    #[arg(long, value_enum)]
    first_visit: Option<FirstVisitArg>,
    /// C-REPS sample memory: the last N rollouts (default, as BOLeRo) or the paper's Section 5.2
    /// per-task memory of the best N/K rollouts.
    #[arg(long, value_enum)]
    memory: Option<MemoryArg>,
    /// Initial exploration covariance Sigma_0 = X I (default 1).
    #[arg(long, value_name = "X")]
    initial_sigma: Option<f64>,
    /// C-REPS KL bound epsilon (default: the experiment's).
    #[arg(long)]
    epsilon: Option<f64>,
    /// toy only: use the learning factors of the paper's Fig. 3 in every run instead of a random
    /// permutation per run.
    #[arg(long)]
    fig3_learning_factors: bool,
    /// D-UCB padding strength xi (default: the experiment's).
    #[arg(long)]
    xi: Option<f64>,
    /// grid and dartboard only: how throws are simulated.
    #[arg(long, value_enum, default_value = "analytic")]
    sim: SimArg,
    /// Output directory (default: runs/NAME).
    #[arg(long)]
    out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum FirstVisitArg {
    InitialReturn,
    Zero,
    Optimistic,
}

#[derive(Clone, Copy, ValueEnum)]
enum MemoryArg {
    Window,
    BestPerTask,
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Experiment(args) => experiment(args),
    }
}

fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    if args.runs == 0 {
        bail!("--runs must be >= 1, got 0");
    }
    let methods = args
        .methods
        .iter()
        .map(|name| name.parse::<Method>())
        .collect::<Result<Vec<_>, _>>()
        .context("--method")?;
    if let Some(n_theta) = args.n_theta
        && n_theta <= 4
    {
        bail!("--n-theta must be > the context dimension (up to 4), got {n_theta}");
    }
    let options = Options {
        runs: args.runs,
        episodes: args.episodes,
        seed: args.seed,
        in_flight: args.in_flight,
        methods: (!methods.is_empty()).then_some(methods),
        overrides: Overrides {
            n_theta: args.n_theta,
            first_visit: args.first_visit.map(|f| match f {
                FirstVisitArg::InitialReturn => FirstVisit::InitialReturn,
                FirstVisitArg::Zero => FirstVisit::Zero,
                FirstVisitArg::Optimistic => FirstVisit::Optimistic,
            }),
            best_per_task: args.memory.map(|m| matches!(m, MemoryArg::BestPerTask)),
            initial_sigma: args.initial_sigma,
            xi: args.xi,
            epsilon: args.epsilon,
            learning_factors: args.fig3_learning_factors.then_some(paper::FIG3_LEARNING_FACTORS),
        },
    };
    let (name, default_dir) = match args.name {
        ExperimentName::Toy => ("toy", "runs/toy"),
        ExperimentName::Function => ("function", "runs/function"),
        ExperimentName::Dims => ("dims", "runs/dims"),
        ExperimentName::Grid => ("grid", "runs/grid"),
        ExperimentName::Dartboard => ("dartboard", "runs/dartboard"),
    };
    let sim = match args.sim {
        SimArg::Analytic => paper::Sim::Analytic,
        SimArg::Rapier => paper::Sim::Rapier,
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(default_dir));
    let jobs: Vec<(Experiment, PathBuf)> = match args.name {
        ExperimentName::Toy => {
            if args.n_s.is_some() {
                bail!("--n-s belongs to the dims experiment, not {name}");
            }
            let panels = match args.panel {
                Some(panel) => vec![(panel, out.clone())],
                None => "abcd".chars().map(|p| (p, out.join(p.to_string()))).collect(),
            };
            panels
                .into_iter()
                .map(|(panel, dir)| match paper::toy_panel(panel) {
                    Some(model) => Ok((paper::toy(model, &options), dir)),
                    None => bail!("--panel must be one of a, b, c, d; got '{panel}'"),
                })
                .collect::<anyhow::Result<_>>()?
        }
        ExperimentName::Function => {
            if args.panel.is_some() || args.n_s.is_some() {
                bail!("--panel and --n-s do not apply to the function experiment");
            }
            vec![(paper::function(&options), out.clone())]
        }
        ExperimentName::Dims => {
            if args.panel.is_some() {
                bail!("--panel belongs to the toy experiment, not {name}");
            }
            match args.n_s {
                Some(n_s @ 1..=4) => vec![(paper::dims(n_s, &options), out.clone())],
                Some(n_s) => bail!("--n-s must be in 1..=4, got {n_s}"),
                None => (1..=4)
                    .map(|n_s| (paper::dims(n_s, &options), out.join(format!("ns-{n_s}"))))
                    .collect(),
            }
        }
        ExperimentName::Grid | ExperimentName::Dartboard => {
            if args.panel.is_some() || args.n_s.is_some() {
                bail!("--panel and --n-s do not apply to the {name} experiment");
            }
            let experiment = match args.name {
                ExperimentName::Grid => paper::grid(sim, &options),
                _ => paper::dartboard(sim, &options),
            };
            vec![(experiment, out.clone())]
        }
    };
    for (experiment, dir) in jobs {
        run_and_write(&experiment, &dir, args.quiet)?;
    }
    Ok(())
}

fn run_and_write(experiment: &Experiment, dir: &Path, quiet: bool) -> anyhow::Result<()> {
    let progress = progress_bar(quiet);
    let summary = experiment
        .run(&progress)
        .with_context(|| format!("experiment {}", experiment.name))?;
    progress.finish_and_clear();
    summary
        .write(dir)
        .with_context(|| format!("writing {}", dir.join("summary.json").display()))?;
    acps::plot::write_all(&summary, dir).map_err(|e| anyhow::anyhow!("plotting into {}: {e}", dir.display()))?;
    if !quiet {
        println!("{} -> {}", experiment.name, dir.join("summary.json").display());
        for (method, result) in &summary.methods {
            let fmt = |x: Option<f64>| x.map_or("n/a".to_string(), |x| format!("{x:.3}"));
            println!(
                "  {method:>20}: final {} +- {}",
                fmt(result.final_mean),
                fmt(result.final_sem)
            );
        }
    }
    Ok(())
}
