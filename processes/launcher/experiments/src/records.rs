//! The tables and learned policies of a run directory, next to summary.json:
//! - `curves.csv`: `method,episode,mean,sem`, one row per method and evaluation (the curves of
//!   summary.json in long format);
//! - `runs.csv`: `method,run,seed,episode,score`, one row per method, run and evaluation;
//! - `selections.csv`: `method,episode,arm,s0,..,reward`, one row per training episode of run 0
//!   of every method (arm empty for contexts drawn from the continuous space, reward empty for a
//!   failed rollout);
//! - `updates.csv`: `method,run,update,episode,samples,eta,eta_at_bound,kl,epsilon,ess,dual,
//!   optimality,iterations,logdet_sigma,trace_sigma,rejected,alpha,context_eta,context_kl,
//!   context_ess,nu`, one row per C-REPS update of every run (the fields of
//!   [`UpdateReport`](acps_learner::creps::UpdateReport); `episode` is the training episodes
//!   consumed when it ran, `rejected` the reason's name or empty when the update was applied; the
//!   last five are its [`ContextReport`](acps_learner::creps::ContextReport), empty but for
//!   self-paced; only the header for problems without a policy);
//! - `policies/METHOD-runR.json`: the final C-REPS policy of every run with what `acps evaluate`
//!   needs to rebuild its problem and environment.
//!
//! Empty CSV fields mean "no value" (an evaluation whose rollouts all failed).

use crate::regular::{self, Unread};
use crate::settings::LearnerName;
use crate::summary::{RunResult, Summary, UserProblem};
use acps_learner::SearchReport;
use acps_learner::creps::{PolicySnapshot, PolicySnapshotRestoreError, Rejection, RestoredPolicy};
use acps_shared::Problem;
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// The header of `runs.csv`, which `acps compare` reads back.
pub const RUNS_CSV_HEADER: &str = "method,run,seed,episode,score";

/// A run directory's records that could not be written, or a policy file or run directory
/// `acps evaluate` cannot use. Each message names the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordsError {
    /// Reading, writing or creating a file or directory failed.
    #[error("{action} {}", path.display())]
    Io {
        /// "reading", "writing" or "creating".
        action: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// A policy could not be serialised (it holds a value JSON cannot).
    #[error("serialising the policy of {}", path.display())]
    Serialise {
        /// The file it was for.
        path: PathBuf,
        /// serde_json's reason.
        #[source]
        source: serde_json::Error,
    },
    /// The file is not JSON of a policy file's shape.
    #[error("{}: not an acps policy file", path.display())]
    NotAPolicy {
        /// The file.
        path: PathBuf,
        /// serde_json's reason.
        #[source]
        source: serde_json::Error,
    },
    /// A field of a policy file is out of its range.
    #[error("{}: {field} {reason}", path.display())]
    Field {
        /// The file.
        path: PathBuf,
        /// The field, such as `problem.theta0`.
        field: &'static str,
        /// What it must be and what it is.
        reason: String,
    },
    /// The saved policy does not restore (its shapes or values).
    #[error("{}: {error}{hint}", path.display())]
    Policy {
        /// The file.
        path: PathBuf,
        /// Why.
        error: PolicySnapshotRestoreError,
        /// Where its size comes from, for a shape error.
        hint: String,
    },
    /// A policy file of a run directory whose method or run is not the one its name says.
    #[error(
        "{}: method {method:?} and run {run} are not the ones the file's name says (they would be in {named}); was the file relabelled?",
        path.display()
    )]
    Relabelled {
        /// The file.
        path: PathBuf,
        /// The method it holds.
        method: String,
        /// The run it holds.
        run: usize,
        /// The name it would have.
        named: String,
    },
    /// Not a regular file (a FIFO, a device, a directory ...).
    #[error("{} is a {kind}, not a {expected}", path.display())]
    Special {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
        /// What was expected there.
        expected: &'static str,
    },
    /// Larger than any policy file.
    #[error("{}: {len} bytes is more than a policy file holds (at most {MAX_POLICY_BYTES} bytes)", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size in bytes.
        len: u64,
    },
    /// `acps evaluate`'s path does not exist.
    #[error(
        "{} does not exist; give a run directory (the --out of `acps experiment` or `acps run`) or one of its policies/METHOD-runR.json files",
        path.display()
    )]
    Missing {
        /// The path.
        path: PathBuf,
    },
    /// `--method` or `--run` with a policy file instead of a run directory.
    #[error("--method and --run choose a file in a run directory; {} is a policy file", path.display())]
    ChoiceOnFile {
        /// The policy file.
        path: PathBuf,
    },
    /// A run directory without `policies/`.
    #[error(
        "{} has no {POLICY_DIR}/ directory: the run directory of an experiment with a learned policy holds one (toy's Section 4 model has no policy)",
        dir.display()
    )]
    NoPolicyDir {
        /// The run directory.
        dir: PathBuf,
    },
    /// `policies/` holds no policy file.
    #[error("{} holds no policy file (METHOD-runR.json)", dir.display())]
    NoPolicies {
        /// The `policies/` directory.
        dir: PathBuf,
    },
    /// No policy file of the run asked for.
    #[error("{} holds no policy file of run {run} (--run); --run must be one of {runs:?}", dir.display())]
    NoRun {
        /// The `policies/` directory.
        dir: PathBuf,
        /// The run asked for.
        run: usize,
        /// The runs it holds.
        runs: Vec<usize>,
    },
    /// No policy file of the method asked for.
    #[error(
        "--method {method}: {} holds no policy file of that method for run {run}; --method must be one of [{}]",
        dir.display(),
        methods.join(", ")
    )]
    NoMethod {
        /// The method asked for.
        method: String,
        /// The `policies/` directory.
        dir: PathBuf,
        /// The run.
        run: usize,
        /// The methods it holds for that run.
        methods: Vec<String>,
    },
}

fn io<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> RecordsError + 'a {
    move |source| RecordsError::Io {
        action,
        path: path.to_path_buf(),
        source,
    }
}

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

    /// Read and check a policy file: its format, the problem's space, contexts and theta_0, the
    /// policy's shapes and values, and that the policy fits the problem (context dimension,
    /// n_theta). Errors name the file and the field.
    pub fn load(path: &Path) -> Result<(Self, RestoredPolicy), RecordsError> {
        let text = read_regular(path)?;
        let not_a_policy = |source| RecordsError::NotAPolicy {
            path: path.to_path_buf(),
            source,
        };
        let json: serde_json::Value = serde_json::from_str(&text).map_err(not_a_policy)?;
        let bad = |field: &'static str, reason: String| RecordsError::Field {
            path: path.to_path_buf(),
            field,
            reason,
        };
        // The format first: a file of another format need not have this one's fields.
        let format = json.get("format").and_then(|f| f.as_str());
        if format != Some(POLICY_FORMAT) {
            let got = format.map_or("none".to_string(), |f| format!("{f:?}"));
            return Err(bad("format", format!("must be {POLICY_FORMAT:?}, got {got}")));
        }
        let saved: SavedPolicy = serde_json::from_value(json).map_err(not_a_policy)?;
        let problem = &saved.problem;
        check_problem(problem).map_err(|(field, reason)| bad(field, reason))?;
        let n_theta = problem.theta0.len();
        let restored = saved.policy.restore(n_theta).map_err(|error| RecordsError::Policy {
            path: path.to_path_buf(),
            hint: match error.field {
                "weights" | "covariance" => format!(" (n_theta: problem.theta0 has {n_theta} entries)"),
                _ => String::new(),
            },
            error,
        })?;
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
        Ok((saved, restored))
    }

    /// Refuse a file of a run directory whose method or run is not the one its name says (a
    /// relabelled file would replay another run's policy under this one's name).
    pub fn check_name(&self, path: &Path) -> Result<(), RecordsError> {
        let named = format!("{}-run{}.json", self.method, self.run);
        if path.file_name() != Some(named.as_ref()) {
            return Err(RecordsError::Relabelled {
                path: path.to_path_buf(),
                method: self.method.clone(),
                run: self.run,
                named,
            });
        }
        Ok(())
    }
}

/// The problem of a policy file as any problem must be: a valid context space, at least one
/// training and one test context, each finite with the space's dimension, and a finite theta_0
/// of at least one parameter. The error is the field and what it accepts.
fn check_problem(problem: &Problem) -> Result<(), (&'static str, String)> {
    problem
        .space
        .validate()
        .map_err(|e| ("problem.space", format!("is not a context space: {e}")))?;
    let dim = problem.context_dim();
    for (field, contexts) in [
        ("problem.training_contexts", &problem.training_contexts),
        ("problem.test_contexts", &problem.test_contexts),
    ] {
        if contexts.is_empty() {
            return Err((field, "must hold at least one context, got none".into()));
        }
        if let Some((i, context)) = contexts
            .iter()
            .enumerate()
            .find(|(_, s)| s.len() != dim || s.iter().any(|x| !x.is_finite()))
        {
            return Err((
                field,
                format!("must be finite with {dim} entries (the space's dimension), got {context:?} at index {i}"),
            ));
        }
    }
    if problem.theta0.is_empty() || problem.theta0.iter().any(|x| !x.is_finite()) {
        return Err((
            "problem.theta0",
            format!(
                "must be at least one finite parameter, got {} entries{}",
                problem.theta0.len(),
                if problem.theta0.is_empty() {
                    ""
                } else {
                    " with a non-finite one"
                }
            ),
        ));
    }
    Ok(())
}

/// Policy files of this build are far smaller (a problem file's problem holds at most a few
/// hundred thousand contexts); a larger file is refused before it is read into memory.
const MAX_POLICY_BYTES: u64 = 256 << 20;

/// The text of the policy file `path` ([`regular::read_regular`]).
fn read_regular(path: &Path) -> Result<String, RecordsError> {
    regular::read_regular(path, MAX_POLICY_BYTES).map_err(|unread| match unread {
        Unread::Special(kind) => RecordsError::Special {
            path: path.to_path_buf(),
            kind,
            expected: "policy file",
        },
        Unread::TooLarge(len) => RecordsError::TooLarge {
            path: path.to_path_buf(),
            len,
        },
        Unread::Io(source) => io("reading", path)(source),
    })
}

/// Write the CSV tables and the policy files of `summary` into `dir` (which exists).
pub fn write(summary: &Summary, dir: &Path) -> Result<(), RecordsError> {
    // Streamed through a buffer: a long run's tables are far larger than its summary.
    let file = |name: &str, table: fn(&Summary, &mut dyn Write) -> std::io::Result<()>| {
        let path = dir.join(name);
        let written = File::create(&path).and_then(|file| {
            let mut out = BufWriter::new(file);
            table(summary, &mut out)?;
            out.flush()
        });
        written.map_err(io("writing", &path))
    };
    file("curves.csv", curves_csv)?;
    file("runs.csv", runs_csv)?;
    file("selections.csv", selections_csv)?;
    file("updates.csv", updates_csv)?;
    write_policies(summary, dir)
}

fn curves_csv(summary: &Summary, csv: &mut dyn Write) -> std::io::Result<()> {
    writeln!(csv, "method,episode,mean,sem")?;
    for (method, m) in &summary.methods {
        for ((episode, mean), sem) in m.episodes.iter().zip(&m.mean).zip(&m.sem) {
            writeln!(csv, "{method},{episode},{},{}", field(*mean), field(*sem))?;
        }
    }
    Ok(())
}

fn runs_csv(summary: &Summary, csv: &mut dyn Write) -> std::io::Result<()> {
    writeln!(csv, "{RUNS_CSV_HEADER}")?;
    for (method, runs) in &summary.run_results {
        for (index, run) in runs.iter().enumerate() {
            for (episode, score) in run.eval_episodes.iter().zip(&run.scores) {
                writeln!(csv, "{method},{index},{},{episode},{}", run.seed, field(*score))?;
            }
        }
    }
    Ok(())
}

fn selections_csv(summary: &Summary, csv: &mut dyn Write) -> std::io::Result<()> {
    let dim = summary.training_contexts.first().map_or(0, Vec::len);
    write!(csv, "method,episode,arm")?;
    for d in 0..dim {
        write!(csv, ",s{d}")?;
    }
    writeln!(csv, ",reward")?;
    for (method, runs) in &summary.run_results {
        for (episode, e) in runs[0].episodes.iter().enumerate() {
            write!(
                csv,
                "{method},{episode},{}",
                e.arm.map(|a| a.to_string()).unwrap_or_default()
            )?;
            for s in &e.context {
                write!(csv, ",{s}")?;
            }
            let reward = Some(e.reward).filter(|r| r.is_finite());
            writeln!(csv, ",{}", field(reward))?;
        }
    }
    Ok(())
}

/// The header of `updates.csv` for C-REPS.
pub const UPDATES_HEADER: &str = "method,run,update,episode,samples,eta,eta_at_bound,kl,epsilon,ess,dual,optimality,iterations,logdet_sigma,trace_sigma,rejected,alpha,context_eta,context_kl,context_ess,nu";

/// The header of `updates.csv` for C-CMA-ES: its step size, the lengths of its evolution paths
/// (`p_sigma` relative to its length under random selection), the stall test, the mean's shift
/// in sigma and the condition number of C.
pub const CCMAES_UPDATES_HEADER: &str = "method,run,update,episode,samples,sigma,p_sigma,p_c,h_sigma,mean_shift,condition,logdet_sigma,trace_sigma,rejected";

fn updates_csv(summary: &Summary, csv: &mut dyn Write) -> std::io::Result<()> {
    let header = match LearnerName::recorded(&summary.settings) {
        LearnerName::CReps => UPDATES_HEADER,
        LearnerName::CCmaes => CCMAES_UPDATES_HEADER,
    };
    writeln!(csv, "{header}")?;
    for (method, runs) in &summary.run_results {
        for (index, run) in runs.iter().enumerate() {
            for (update, record) in run.updates.iter().enumerate() {
                write!(csv, "{method},{index},{update},{}", record.episode)?;
                match &record.report {
                    SearchReport::CReps(r) => {
                        let c = r.context.as_ref();
                        writeln!(
                            csv,
                            ",{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
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
                            r.rejected.map_or("", Rejection::name),
                            field(c.map(|c| c.alpha)),
                            field(c.map(|c| c.eta)),
                            field(c.map(|c| c.kl)),
                            field(c.map(|c| c.ess)),
                            field(c.and_then(|c| c.nu)),
                        )?;
                    }
                    SearchReport::CCmaes(r) => writeln!(
                        csv,
                        ",{},{},{},{},{},{},{},{},{},{}",
                        r.samples,
                        r.sigma,
                        r.p_sigma,
                        r.p_c,
                        r.h_sigma,
                        r.mean_shift,
                        r.condition,
                        r.logdet_sigma,
                        r.trace_sigma,
                        r.rejected.map_or("", Rejection::name),
                    )?,
                }
            }
        }
    }
    Ok(())
}

/// A CSV field: the shortest text that parses back to the same f64, or empty.
fn field(value: Option<f64>) -> String {
    value.map(|v| v.to_string()).unwrap_or_default()
}

fn write_policies(summary: &Summary, dir: &Path) -> Result<(), RecordsError> {
    let saved: Vec<SavedPolicy> = summary
        .run_results
        .iter()
        .flat_map(|(method, runs)| runs.iter().enumerate().map(move |(index, run)| (method, index, run)))
        .filter_map(|(method, index, run)| saved_policy(summary, method, index, run))
        .collect();
    if saved.is_empty() {
        return Ok(());
    }
    let policies = dir.join(POLICY_DIR);
    std::fs::create_dir_all(&policies).map_err(io("creating", &policies))?;
    for policy in saved {
        let path = SavedPolicy::path(dir, &policy.method, policy.run);
        let json = serde_json::to_string_pretty(&policy).map_err(|source| RecordsError::Serialise {
            path: path.clone(),
            source,
        })?;
        std::fs::write(&path, json).map_err(io("writing", &path))?;
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
/// policy file of the run, by name) and `--run` (default 0), both among the files that
/// `DIR/policies` holds. `dir` may also be a policy file itself.
pub fn policy_file(dir: &Path, method: Option<&str>, run: Option<usize>) -> Result<PathBuf, RecordsError> {
    let metadata = match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(RecordsError::Missing {
                path: dir.to_path_buf(),
            });
        }
        metadata => metadata.map_err(io("reading", dir))?,
    };
    if metadata.is_file() {
        if method.is_some() || run.is_some() {
            return Err(RecordsError::ChoiceOnFile {
                path: dir.to_path_buf(),
            });
        }
        return Ok(dir.to_path_buf());
    }
    if !metadata.is_dir() {
        return Err(RecordsError::Special {
            path: dir.to_path_buf(),
            kind: regular::special_kind(&metadata.file_type()),
            expected: "run directory or a policy file",
        });
    }
    let saved = saved_policies(dir)?;
    let run = run.unwrap_or(0);
    let policies = dir.join(POLICY_DIR);
    let methods: Vec<&str> = saved
        .iter()
        .filter(|(_, r)| *r == run)
        .map(|(m, _)| m.as_str())
        .collect();
    if saved.is_empty() {
        return Err(RecordsError::NoPolicies { dir: policies });
    }
    if methods.is_empty() {
        let mut runs: Vec<usize> = saved.iter().map(|(_, r)| *r).collect();
        runs.dedup();
        return Err(RecordsError::NoRun {
            dir: policies,
            run,
            runs,
        });
    }
    // Only a name the directory lists: a --method such as ../x must not reach a file elsewhere.
    let method = match method {
        None => methods[0],
        Some(method) if methods.contains(&method) => method,
        Some(method) => {
            return Err(RecordsError::NoMethod {
                method: method.to_string(),
                dir: policies,
                run,
                methods: methods.iter().map(|m| m.to_string()).collect(),
            });
        }
    };
    Ok(SavedPolicy::path(dir, method, run))
}

/// The (method, run) of every policy file in `dir/policies`, sorted by run, then method.
fn saved_policies(dir: &Path) -> Result<Vec<(String, usize)>, RecordsError> {
    let policies = dir.join(POLICY_DIR);
    if !policies.is_dir() {
        return Err(RecordsError::NoPolicyDir { dir: dir.to_path_buf() });
    }
    let entries = std::fs::read_dir(&policies).map_err(io("reading", &policies))?;
    let mut saved: Vec<(String, usize)> = entries
        .filter_map(|entry| {
            let name = entry.ok()?.file_name().into_string().ok()?;
            let (method, run) = name.strip_suffix(".json")?.rsplit_once("-run")?;
            let run: usize = run.parse().ok()?;
            // As SavedPolicy::path names it ("run01" is not run 1's file).
            (name == format!("{method}-run{run}.json")).then(|| (method.to_string(), run))
        })
        .collect();
    saved.sort_by(|a, b| (a.1, &a.0).cmp(&(b.1, &b.0)));
    Ok(saved)
}
