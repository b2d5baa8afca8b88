//! A checked request ([`Plan`]): an experiment file's values overridden by command-line options,
//! checked once, and the experiments it runs ([`Job`]s) with their output directories and
//! resolved files.

use crate::experiment::{Experiment, Instance, InstanceFactory};
use crate::file::{LoadedFile, describe};
use crate::keys::{ConfigError, Kind};
use crate::paper::{self, Sim};
use crate::problem_file::CheckedProblem;
use crate::settings::{ExperimentFile, ExperimentName, Memory, Resolving, SimName};
use acps_learner::creps::CRepsConfig;
use acps_learner::selection::DUcbConfig;
use acps_learner::{LearnerConfig, Method, SelectorConfig};
use acps_models::benchmark::Objective;
use serde_json::json;
use std::path::{Path, PathBuf};

/// A problem file's methods unless set.
const PROBLEM_METHODS: [Method; 2] = [Method::MonotonicProgress, Method::Random];

/// A problem file's C-REPS memory unless set: BOLeRo's window of the last 100 rollouts.
const MEMORY: usize = 100;

/// A problem file's evaluations of the greedy policy on the test contexts happen every this
/// many training episodes (or once at the end of shorter runs), as in the paper's Section 5.1.2.
const EVAL_EVERY: u64 = 50;

/// A checked request: the experiment file's values overridden by command-line options.
pub struct Plan {
    settings: ExperimentFile,
    subject: Subject,
}

/// What a plan runs: one of the paper's experiments or a problem file's problem.
enum Subject {
    Paper(ExperimentName),
    File(Box<CheckedProblem>),
}

/// One experiment to run, where its results go, and its resolved experiment file.
pub struct Job {
    /// The experiment.
    pub experiment: Experiment,
    /// Its output directory.
    pub dir: PathBuf,
    /// Every setting of the job, the experiment's defaults filled in: re-runs it bit for bit.
    pub config: ExperimentFile,
}

impl Plan {
    /// Check `file`'s values overridden by the options set in `cli`. Errors name the option for
    /// values given on the command line and the file and line for values from the file.
    pub fn new(file: Option<&LoadedFile>, cli: &ExperimentFile) -> Result<Self, ConfigError> {
        let base = file.map(|f| f.values.clone()).unwrap_or_default();
        let settings = cli.over(base);
        let stem = file.and_then(|f| f.path().file_stem()).and_then(|s| s.to_str());
        let describe = |invalid| describe(invalid, file, cli);
        let subject = match (settings.check().map_err(describe)?, &settings.problem) {
            (Kind::File, Some(problem)) => {
                // Only methods that choose among the training contexts need them.
                let methods = paper::methods(&settings, &PROBLEM_METHODS, |_| DUcbConfig::default());
                let box_only = methods.iter().all(SelectorConfig::draws_from_space);
                Subject::File(Box::new(problem.check(stem, box_only).map_err(describe)?))
            }
            (Kind::Paper(name), _) => Subject::Paper(name),
            (Kind::File, None) => unreachable!("a file's kind is that of its [problem] table"),
        };
        Ok(Self { settings, subject })
    }

    /// The experiment's name, or the problem's.
    pub fn name(&self) -> &str {
        match &self.subject {
            Subject::Paper(name) => name.name(),
            Subject::File(checked) => &checked.problem.name,
        }
    }

    /// The experiments to run into `out`: toy without a panel and dims without n_s expand to
    /// their four panels or dimensions in subdirectories.
    pub fn jobs(&self, out: &Path) -> Vec<Job> {
        let s = &self.settings;
        let sim = match s.sim.unwrap_or(SimName::Analytic) {
            SimName::Analytic => Sim::Analytic,
            SimName::Rapier => Sim::Rapier,
        };
        let job = |experiment: Experiment, dir: PathBuf, panel, n_s| {
            let paper = match &self.subject {
                Subject::Paper(name) => Some(*name),
                Subject::File(_) => None,
            };
            let mut config = ExperimentFile::resolved(&Resolving {
                experiment: &experiment,
                request: s,
                paper,
                panel,
                n_s,
            });
            if let Subject::File(checked) = &self.subject {
                config.problem = Some(checked.resolved.clone());
            }
            Job {
                experiment,
                dir,
                config,
            }
        };
        let name = match &self.subject {
            Subject::Paper(name) => *name,
            Subject::File(checked) => {
                return vec![job(problem_experiment(checked, s), out.to_path_buf(), None, None)];
            }
        };
        match name {
            ExperimentName::Toy => {
                let panels: Vec<(char, PathBuf)> = match s.panel {
                    Some(panel) => vec![(panel, out.to_path_buf())],
                    None => "abcd".chars().map(|p| (p, out.join(p.to_string()))).collect(),
                };
                panels
                    .into_iter()
                    .map(|(panel, dir)| {
                        let model = paper::toy_panel(panel).expect("the panel was checked");
                        job(paper::toy(model, s), dir, Some(panel), None)
                    })
                    .collect()
            }
            ExperimentName::Function => vec![job(paper::function(s), out.to_path_buf(), None, None)],
            ExperimentName::Dims => {
                let dims: Vec<(usize, PathBuf)> = match s.n_s {
                    Some(n_s) => vec![(n_s, out.to_path_buf())],
                    None => (1..=4).map(|n| (n, out.join(format!("ns-{n}")))).collect(),
                };
                dims.into_iter()
                    .map(|(n_s, dir)| job(paper::dims(n_s, s), dir, None, Some(n_s)))
                    .collect()
            }
            ExperimentName::Grid => vec![job(paper::grid(sim, s), out.to_path_buf(), None, None)],
            ExperimentName::Dartboard => vec![job(paper::dartboard(sim, s), out.to_path_buf(), None, None)],
            ExperimentName::Sphere => vec![job(
                paper::benchmark(Objective::Sphere, s),
                out.to_path_buf(),
                None,
                None,
            )],
            ExperimentName::Rosenbrock => vec![job(
                paper::benchmark(Objective::Rosenbrock, s),
                out.to_path_buf(),
                None,
                None,
            )],
        }
    }

    /// The request with the experiment's defaults filled in: every setting its jobs share. The
    /// panel or n_s stays unset when it was, meaning all four, and so does a default that differs
    /// between them (dims' memory and update interval grow with n_s), so that the file re-runs
    /// every job as it was.
    pub fn resolved(&self) -> ExperimentFile {
        let configs: Vec<serde_json::Value> = self
            .jobs(Path::new(""))
            .iter()
            .map(|job| serde_json::to_value(&job.config).expect("settings serialise"))
            .collect();
        let (first, others) = configs.split_first().expect("a plan has at least one job");
        let mut shared = first.as_object().expect("settings serialise to an object").clone();
        shared.retain(|key, value| others.iter().all(|other| other.get(key) == Some(value)));
        let shared: ExperimentFile =
            serde_json::from_value(serde_json::Value::Object(shared)).expect("settings deserialise");
        ExperimentFile {
            panel: self.settings.panel,
            n_s: self.settings.n_s,
            ..shared
        }
    }
}

/// The experiment of a checked problem file: C-REPS with BOLeRo's defaults but for its memory
/// (an update every 25 rollouts on the best 100/K per training context, or with `memory =
/// "window"` the last 100) and the file's features,
/// D-UCB with [`DUcbConfig::default`] (docs/DUCB-PARAMETERS.md), monotonic progress against
/// random selection by default. No environment: the user's workers perform every rollout.
fn problem_experiment(checked: &CheckedProblem, s: &ExperimentFile) -> Experiment {
    let problem = checked.problem.clone();
    let preset = CRepsConfig {
        features: checked.features.map(),
        ..CRepsConfig::default()
    };
    let tasks = problem.training_contexts.len();
    // The best N/K per training context, not the last N: with a window, C-REPS lost its best
    // policy on users' problems (docs/RESULTS.md, "Learning that does not undo itself").
    let creps = paper::creps(preset, s, Memory::BestPerTask, MEMORY, tasks);
    let ducb = paper::ducb(DUcbConfig::default(), s);
    let episodes = s.episodes.unwrap_or(LearnerConfig::default().episodes);
    let learner = paper::learner(s, episodes, EVAL_EVERY.min(episodes), Some(creps));
    let features = serde_json::to_value(checked.features).expect("a unit variant serialises");
    let settings = paper::with_search(
        json!({
            "problem": checked.resolved,
            "ducb": ducb,
            "first_visit": paper::first_visit(s),
            "eval_every": learner.eval_every,
        }),
        &learner,
        features.as_str().unwrap_or_default(),
        "theta0",
    );
    let methods = paper::methods(s, &PROBLEM_METHODS, |_| ducb.clone());
    let name = problem.name.clone();
    let instance: InstanceFactory = Box::new(move |_| Instance {
        problem: problem.clone(),
        environment: None,
        optimal_score: None,
        keeps_state: false,
    });
    Experiment {
        selection_window: 250.min(episodes as usize),
        user_problem: Some(checked.user.clone()),
        ..paper::experiment(&name, s, settings, methods, learner, instance)
    }
}

/// Memory a (method, run) job holds besides its episodes and evaluations: its learner and
/// problem instance (measured: 85 kB for the function, 235 kB for the rapier arm).
const JOB_BYTES: f64 = 256e3;
/// Memory per training episode of a job until its experiment is written: the episode's record,
/// its share of the updates and of the run directory's records (measured: 180 to 300 bytes for
/// toy, function, grid and dartboard), plus 8 per context coordinate.
const EPISODE_BYTES: f64 = 300.0;
/// Memory per test context of an evaluation: the outcome and its diagnostics.
const OUTCOME_BYTES: f64 = 80.0;

/// Refuse experiments whose records cannot fit the memory available now: every (method, run)
/// job of an experiment runs at once and keeps every episode and evaluation until the
/// experiment is written; experiments (toy's panels, dims' dimensions) run one after another.
pub fn check_memory(jobs: &[Job]) -> Result<(), ConfigError> {
    // Without /proc/meminfo (not Linux) there is nothing to compare with.
    let Some(available) = available_memory() else {
        return Ok(());
    };
    for Job { experiment, .. } in jobs {
        let problem = (experiment.instance)(experiment.base_seed).problem;
        let dim = problem.training_contexts.first().map_or(0, Vec::len) as f64;
        let episodes = experiment.learner.episodes;
        // At episode 0, every eval_every episodes, and after the last one.
        let evaluations = episodes / experiment.learner.eval_every.max(1) + 2;
        let tests = problem.test_contexts.len();
        let per_job = JOB_BYTES
            + episodes as f64 * (EPISODE_BYTES + 8.0 * dim)
            + evaluations as f64 * tests as f64 * OUTCOME_BYTES;
        let jobs = experiment.methods.len() * experiment.runs;
        let need = jobs as f64 * per_job;
        if need > available {
            return Err(ConfigError::Memory {
                message: format!(
                    "{}: {} methods x {} runs of {episodes} episodes ({evaluations} evaluations on {tests} test contexts each) would hold about {} in memory, more than the {} available now (MemAvailable in /proc/meminfo): lower runs (--runs), episodes (--episodes) or the number of methods (--method)",
                    experiment.name,
                    experiment.methods.len(),
                    experiment.runs,
                    bytes(need),
                    bytes(available)
                ),
            });
        }
    }
    Ok(())
}

/// The memory available for starting new programs without swapping, in bytes.
fn available_memory() -> Option<f64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find_map(|line| line.strip_prefix("MemAvailable:"))?;
    let kib: f64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    Some(kib * 1024.0)
}

/// `n` bytes in decimal units, such as "3.2 GB".
fn bytes(n: f64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let power = ((n.max(1.0).log10() / 3.0).floor() as usize).min(units.len() - 1);
    match power {
        0 => format!("{n:.0} bytes"),
        _ => format!("{:.1} {}", n / 1e3f64.powi(power as i32), units[power]),
    }
}

/// The default output directory: runs/STEM for an experiment file STEM.toml, else runs/NAME.
pub fn default_out(file: Option<&Path>, name: &str) -> PathBuf {
    let stem = file.and_then(|f| f.file_stem()).and_then(|s| s.to_str());
    Path::new("runs").join(stem.unwrap_or(name))
}
