//! The tables and learned policies of a run directory, next to summary.json:
//! - `curves.csv`: `method,episode,mean,sem`, one row per method and evaluation (the curves of
//!   summary.json in long format);
//! - `runs.csv`: `method,run,seed,episode,score`, one row per method, run and evaluation;
//! - `selections.csv`: `method,episode,arm,s0,..,reward`, one row per training episode of run 0
//!   of every method (arm empty for contexts drawn from the continuous space, reward empty for a
//!   failed rollout);
//! - `updates.csv`: `method,run,update,episode,samples,eta,eta_at_bound,kl,epsilon,ess,dual,
//!   optimality,iterations,logdet_sigma,trace_sigma,rejected`, one row per C-REPS update of every
//!   run (the fields of [`UpdateReport`](acps_learner::creps::UpdateReport); `episode` is the
//!   training episodes consumed when it ran, `rejected` the reason's name or empty when the update
//!   was applied; only the header for problems without a policy);
//! - `policies/METHOD-runR.json`: the final C-REPS policy of every run with what `acps evaluate`
//!   needs to rebuild its problem and environment.
//!
//! Empty CSV fields mean "no value" (an evaluation whose rollouts all failed).

use crate::experiment::{RunResult, Summary, UserProblem};
use acps_learner::creps::{PolicySnapshot, Rejection, RestoredPolicy};
use acps_shared::Problem;
use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The `format` of policy files this build writes and reads.
pub const POLICY_FORMAT: &str = "acps-policy-2";

/// The directory of the policy files inside a run directory.
pub const POLICY_DIR: &str = "policies";

/// A learned policy with everything needed to replay it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedPolicy {
    /// Always [`POLICY_FORMAT`].
    pub format: String,
    /// The experiment's name.
    pub experiment: String,
    /// The context-selection method that trained the policy.
    pub method: String,
    /// The run's index within the method.
    pub run: usize,
    /// The run's seed (problem instance and learner).
    pub seed: u64,
    /// Training episodes consumed.
    pub training_episodes: u64,
    /// The score of the learner's last evaluation on the test contexts.
    pub final_score: Option<f64>,
    /// The problem: training and test contexts, context space, theta_0, score aggregate, and the
    /// environment it is defined for.
    pub problem: Problem,
    /// For a problem file's problem: the scores' unit and direction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub user_problem: Option<UserProblem>,
    /// The upper-level policy.
    pub policy: PolicySnapshot,
}

impl SavedPolicy {
    /// The file of `method`'s run `run` in the run directory `dir`.
    pub fn path(dir: &Path, method: &str, run: usize) -> PathBuf {
        dir.join(POLICY_DIR).join(format!("{method}-run{run}.json"))
    }

    /// Read and check a policy file: its format, the policy's shapes and values, and that the
    /// policy fits the problem (context dimension, n_theta). Errors name the file and the field.
    pub fn load(path: &Path) -> anyhow::Result<(Self, RestoredPolicy)> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let not_a_policy = || format!("{}: not an acps policy file", path.display());
        let json: serde_json::Value = serde_json::from_str(&text).with_context(not_a_policy)?;
        let bad = |field: &str, reason: String| anyhow::anyhow!("{}: {field} {reason}", path.display());
        // The format first: a file of another format need not have this one's fields.
        let format = json.get("format").and_then(|f| f.as_str());
        if format != Some(POLICY_FORMAT) {
            let got = format.map_or("none".to_string(), |f| format!("{f:?}"));
            return Err(bad("format", format!("must be {POLICY_FORMAT:?}, got {got}")));
        }
        let saved: SavedPolicy = serde_json::from_value(json).with_context(not_a_policy)?;
        let restored = saved
            .policy
            .restore()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let problem = &saved.problem;
        if restored.context_dim() != problem.context_dim() {
            return Err(bad(
                "policy.context_dim",
                format!(
                    "must equal the problem's context dimension {}, got {}",
                    problem.context_dim(),
                    restored.context_dim()
                ),
            ));
        }
        if restored.n_params() != problem.theta0.len() {
            return Err(bad(
                "policy.weights",
                format!(
                    "must have {} columns (the problem's n_theta), got {}",
                    problem.theta0.len(),
                    restored.n_params()
                ),
            ));
        }
        if let Some(context) = problem
            .test_contexts
            .iter()
            .chain(&problem.training_contexts)
            .find(|s| s.len() != problem.context_dim() || s.iter().any(|x| !x.is_finite()))
        {
            return Err(bad(
                "problem contexts",
                format!("must be finite with {} entries, got {context:?}", problem.context_dim()),
            ));
        }
        Ok((saved, restored))
    }
}

/// Write the CSV tables and the policy files of `summary` into `dir` (which exists).
pub fn write(summary: &Summary, dir: &Path) -> anyhow::Result<()> {
    let file = |name: &str, text: String| {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    file("curves.csv", curves_csv(summary))?;
    file("runs.csv", runs_csv(summary))?;
    file("selections.csv", selections_csv(summary))?;
    file("updates.csv", updates_csv(summary))?;
    write_policies(summary, dir)
}

fn curves_csv(summary: &Summary) -> String {
    let mut csv = String::from("method,episode,mean,sem\n");
    for (method, m) in &summary.methods {
        for ((episode, mean), sem) in m.episodes.iter().zip(&m.mean).zip(&m.sem) {
            writeln!(csv, "{method},{episode},{},{}", field(*mean), field(*sem)).expect("writing to a string");
        }
    }
    csv
}

fn runs_csv(summary: &Summary) -> String {
    let mut csv = String::from("method,run,seed,episode,score\n");
    for (method, runs) in &summary.run_results {
        for (index, run) in runs.iter().enumerate() {
            for (episode, score) in run.eval_episodes.iter().zip(&run.scores) {
                writeln!(csv, "{method},{index},{},{episode},{}", run.seed, field(*score))
                    .expect("writing to a string");
            }
        }
    }
    csv
}

fn selections_csv(summary: &Summary) -> String {
    let dim = summary.training_contexts.first().map_or(0, Vec::len);
    let mut csv = String::from("method,episode,arm");
    for d in 0..dim {
        write!(csv, ",s{d}").expect("writing to a string");
    }
    csv.push_str(",reward\n");
    for (method, runs) in &summary.run_results {
        for (episode, e) in runs[0].episodes.iter().enumerate() {
            write!(
                csv,
                "{method},{episode},{}",
                e.arm.map(|a| a.to_string()).unwrap_or_default()
            )
            .expect("writing to a string");
            for s in &e.context {
                write!(csv, ",{s}").expect("writing to a string");
            }
            let reward = Some(e.reward).filter(|r| r.is_finite());
            writeln!(csv, ",{}", field(reward)).expect("writing to a string");
        }
    }
    csv
}

/// The header of `updates.csv`.
pub const UPDATES_HEADER: &str = "method,run,update,episode,samples,eta,eta_at_bound,kl,epsilon,ess,dual,optimality,iterations,logdet_sigma,trace_sigma,rejected";

fn updates_csv(summary: &Summary) -> String {
    let mut csv = format!("{UPDATES_HEADER}\n");
    for (method, runs) in &summary.run_results {
        for (index, run) in runs.iter().enumerate() {
            for (update, record) in run.updates.iter().enumerate() {
                let r = &record.report;
                writeln!(
                    csv,
                    "{method},{index},{update},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                    record.episode,
                    r.samples,
                    r.eta,
                    r.eta_at_bound,
                    r.kl,
                    r.epsilon,
                    r.ess,
                    r.dual,
                    r.optimality,
                    r.iterations,
                    r.logdet_sigma,
                    r.trace_sigma,
                    r.rejected.map_or("", Rejection::name)
                )
                .expect("writing to a string");
            }
        }
    }
    csv
}

/// A CSV field: the shortest text that parses back to the same f64, or empty.
fn field(value: Option<f64>) -> String {
    value.map(|v| v.to_string()).unwrap_or_default()
}

fn write_policies(summary: &Summary, dir: &Path) -> anyhow::Result<()> {
    let saved: Vec<SavedPolicy> = summary
        .run_results
        .iter()
        .flat_map(|(method, runs)| runs.iter().enumerate().map(move |(index, run)| (method, index, run)))
        .filter_map(|(method, index, run)| saved_policy(summary, method, index, run))
        .collect();
    if saved.is_empty() {
        return Ok(());
    }
    std::fs::create_dir_all(dir.join(POLICY_DIR))
        .with_context(|| format!("creating {}", dir.join(POLICY_DIR).display()))?;
    for policy in saved {
        let path = SavedPolicy::path(dir, &policy.method, policy.run);
        let json = serde_json::to_string_pretty(&policy)?;
        std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn saved_policy(summary: &Summary, method: &str, run: usize, result: &RunResult) -> Option<SavedPolicy> {
    Some(SavedPolicy {
        format: POLICY_FORMAT.into(),
        experiment: summary.experiment.clone(),
        method: method.into(),
        run,
        seed: result.seed,
        training_episodes: result.episodes.len() as u64,
        final_score: result.scores.last().copied().flatten(),
        problem: result.problem.clone(),
        user_problem: summary.user_problem.clone(),
        policy: result.policy.clone()?,
    })
}

/// The policy file `acps evaluate DIR` uses: `--method` (default: the first method with a
/// policy file, by name) and `--run` (default 0). `dir` may also be a policy file itself.
pub fn policy_file(dir: &Path, method: Option<&str>, run: Option<usize>) -> anyhow::Result<PathBuf> {
    if dir.is_file() {
        if method.is_some() || run.is_some() {
            bail!(
                "--method and --run choose a file in a run directory; {} is a policy file",
                dir.display()
            );
        }
        return Ok(dir.to_path_buf());
    }
    let run = run.unwrap_or(0);
    let method = match method {
        Some(method) => method.to_string(),
        None => first_method(dir, run)?,
    };
    let path = SavedPolicy::path(dir, &method, run);
    if !path.is_file() {
        let available = saved_methods(dir, run).unwrap_or_default();
        bail!(
            "{} does not exist; --method must be one of [{}] and --run within the runs of the experiment",
            path.display(),
            available.join(", ")
        );
    }
    Ok(path)
}

fn first_method(dir: &Path, run: usize) -> anyhow::Result<String> {
    let methods = saved_methods(dir, run)?;
    match methods.into_iter().next() {
        Some(method) => Ok(method),
        None => bail!(
            "{} holds no policy file of run {run} (--run)",
            dir.join(POLICY_DIR).display()
        ),
    }
}

/// The methods with a policy file for `run`, sorted.
fn saved_methods(dir: &Path, run: usize) -> anyhow::Result<Vec<String>> {
    if !dir.is_dir() {
        bail!("{} is not a run directory: it does not exist", dir.display());
    }
    let policies = dir.join(POLICY_DIR);
    if !policies.is_dir() {
        bail!(
            "{} has no {POLICY_DIR}/ directory: the run directory of an experiment with a learned policy holds one (toy's Section 4 model has no policy)",
            dir.display()
        );
    }
    let entries = std::fs::read_dir(&policies).with_context(|| format!("reading {}", policies.display()))?;
    let suffix = format!("-run{run}.json");
    let mut methods: Vec<String> = entries
        .filter_map(|entry| {
            entry
                .ok()?
                .file_name()
                .to_str()?
                .strip_suffix(&suffix)
                .map(str::to_string)
        })
        .collect();
    methods.sort();
    Ok(methods)
}
