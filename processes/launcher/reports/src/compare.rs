//! `acps compare`: every method of a run directory against a baseline, paired over runs with the
//! same seed, on the final score, the area under the learning curve and the episodes to reach
//! score levels; mean +- SEM, the paired difference and two-sided p-values of the Wilcoxon
//! signed-rank test and the paired t-test.
//!
//! The t and normal tails come from `statrs`; the exact distribution of Wilcoxon's W+ is counted
//! here ([`signed_rank_counts`]).

use acps_experiments::records::RUNS_CSV_HEADER;
use acps_experiments::settings::LearnerName;
use acps_experiments::summary::{UserProblem, lower_is_better, scores_are_distances};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, StudentsT};
use statrs::function::gamma::gamma_ur;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The baselines of the paper's problems; the default baseline is the best of those present.
pub const BASELINES: [&str; 4] = ["round-robin", "random", "random-continuous", "corners"];

/// Largest number of nonzero differences for which the Wilcoxon test is exact (without ties).
pub const WILCOXON_EXACT_MAX: usize = 25;

/// Why a comparison could not be made.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// A file of the run directory could not be read.
    #[error("cannot read {}: {reason} (a run directory written by `acps experiment` or `acps run` holds summary.json and runs.csv)", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why (shown in the message; not a source, which would say it twice).
        reason: std::io::Error,
    },
    /// A directory of several panels (`acps experiment toy`, `dims`), each a run directory.
    #[error("{} holds no run of its own but {} panels, each a run directory ({}): compare one, e.g. `acps compare {}`", dir.display(), panels.len(), panels.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "), panels[0].display())]
    Panels {
        /// The directory given.
        dir: PathBuf,
        /// Its run directories (at least one).
        panels: Vec<PathBuf>,
    },
    /// A file of the run directory is not what acps writes.
    #[error("{}: {detail}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong (with the line, for runs.csv).
        detail: String,
    },
    /// The baseline asked for is not in the run directory.
    #[error("method '{method}' is not in {dir}: it holds {available}")]
    UnknownMethod {
        /// The method asked for.
        method: String,
        /// The run directories.
        dir: String,
        /// The methods present.
        available: String,
    },
    /// No baseline was given and none of the usual ones is present.
    #[error("none of the baselines ({}) is in {dir}; name one with --baseline (present: {available})", BASELINES.join(", "))]
    NoBaseline {
        /// The run directories.
        dir: String,
        /// The methods present.
        available: String,
    },
    /// A level that no score can mean.
    #[error("--levels {level}: {why}")]
    BadLevel {
        /// The level as given.
        level: String,
        /// Why it is refused.
        why: String,
    },
    /// A second run directory that does not pair with the first.
    #[error("{} does not pair with {}: {what} differs ({theirs} vs {ours})", other.display(), first.display())]
    Mismatch {
        /// The first run directory.
        first: PathBuf,
        /// The other one.
        other: PathBuf,
        /// The setting that differs.
        what: &'static str,
        /// The first directory's value.
        ours: String,
        /// The other's value.
        theirs: String,
    },
    /// A method appears in two run directories under the same name.
    #[error("method '{method}' is in both {} and {}: pair only directories with different methods, with retire = true in the second (its methods are named METHOD+retire) or with the other learner (METHOD+c-cmaes)", first.display(), other.display())]
    Duplicate {
        /// The method.
        method: String,
        /// The first directory holding it.
        first: PathBuf,
        /// The other.
        other: PathBuf,
    },
    /// A run whose evaluations all failed, so it has no score to compare.
    #[error("{method} run with seed {seed} has no evaluation with a score")]
    NoScores {
        /// The method.
        method: String,
        /// The run's seed.
        seed: u64,
    },
}

/// What `acps compare` reads of summary.json.
#[derive(Debug, Deserialize)]
struct SummaryHead {
    experiment: String,
    metric: String,
    #[serde(default)]
    user_problem: Option<UserProblem>,
    base_seed: u64,
    training_episodes: u64,
    #[serde(default)]
    settings: serde_json::Value,
}

/// One run's evaluations: (episode, score), failed evaluations left out.
type Curve = Vec<(u64, f64)>;

/// A run directory's runs: method -> seed -> evaluations.
type Runs = BTreeMap<String, BTreeMap<u64, Curve>>;

/// One metric of a method's runs and of the baseline's runs with the same seeds, in pairs.
type Values = (Vec<f64>, Vec<f64>);

/// The run directories being compared, merged.
#[derive(Debug)]
pub struct RunData {
    head: SummaryHead,
    runs: Runs,
    dirs: Vec<PathBuf>,
}

fn read(path: &Path) -> Result<String, CompareError> {
    std::fs::read_to_string(path).map_err(|reason| CompareError::Read {
        path: path.to_path_buf(),
        reason,
    })
}

fn read_head(dir: &Path) -> Result<SummaryHead, CompareError> {
    let path = dir.join("summary.json");
    if !path.exists() {
        let mut panels: Vec<PathBuf> = std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .map(|entry| entry.path())
            .filter(|panel| panel.join("summary.json").is_file())
            .collect();
        panels.sort();
        if !panels.is_empty() {
            return Err(CompareError::Panels {
                dir: dir.to_path_buf(),
                panels,
            });
        }
    }
    serde_json::from_str(&read(&path)?).map_err(|e| CompareError::Malformed {
        path,
        detail: e.to_string(),
    })
}

fn read_runs(dir: &Path) -> Result<Runs, CompareError> {
    let path = dir.join("runs.csv");
    let text = read(&path)?;
    let bad = |line: usize, detail: String| CompareError::Malformed {
        path: path.clone(),
        detail: format!("line {line}: {detail}"),
    };
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    if header != RUNS_CSV_HEADER {
        return Err(bad(1, format!("header '{header}', expected '{RUNS_CSV_HEADER}'")));
    }
    let mut runs = Runs::new();
    for (i, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let [method, _run, seed, episode, score] = fields[..] else {
            return Err(bad(i + 2, format!("{} fields, expected 5", fields.len())));
        };
        let seed: u64 = seed.parse().map_err(|_| bad(i + 2, format!("seed '{seed}'")))?;
        let episode: u64 = episode
            .parse()
            .map_err(|_| bad(i + 2, format!("episode '{episode}'")))?;
        let curve = runs.entry(method.to_string()).or_default().entry(seed).or_default();
        // An empty score is an evaluation whose rollouts all failed: no point of the curve.
        if !score.is_empty() {
            let score: f64 = score.parse().map_err(|_| bad(i + 2, format!("score '{score}'")))?;
            if !score.is_finite() {
                return Err(bad(i + 2, format!("score '{score}'")));
            }
            curve.push((episode, score));
        }
    }
    Ok(runs)
}

impl RunData {
    /// Reads `first` and any further directories that pair with it (same experiment, metric,
    /// seeds and length). A directory run with `retire = true` names its methods METHOD+retire,
    /// and one run with the other learner than the first's METHOD+LEARNER (`+c-cmaes`).
    pub fn load(first: &Path, others: &[PathBuf]) -> Result<Self, CompareError> {
        let head = read_head(first)?;
        let mut runs = read_runs(first)?;
        let mut origin: BTreeMap<String, PathBuf> = runs.keys().map(|m| (m.clone(), first.to_path_buf())).collect();
        for other in others {
            let theirs = read_head(other)?;
            let mismatch = |what, ours: String, theirs: String| CompareError::Mismatch {
                first: first.to_path_buf(),
                other: other.clone(),
                what,
                ours,
                theirs,
            };
            if theirs.experiment != head.experiment {
                return Err(mismatch("experiment", head.experiment.clone(), theirs.experiment));
            }
            if theirs.metric != head.metric {
                return Err(mismatch("metric", head.metric.clone(), theirs.metric));
            }
            if theirs.base_seed != head.base_seed {
                return Err(mismatch(
                    "base_seed",
                    head.base_seed.to_string(),
                    theirs.base_seed.to_string(),
                ));
            }
            if theirs.training_episodes != head.training_episodes {
                let (a, b) = (head.training_episodes, theirs.training_episodes);
                return Err(mismatch("training_episodes", a.to_string(), b.to_string()));
            }
            let retired = !theirs.settings["retire"].is_null();
            let learner = LearnerName::recorded(&theirs.settings);
            let other_learner = (learner != LearnerName::recorded(&head.settings)).then_some(learner.name());
            for (method, seeds) in read_runs(other)? {
                let mut name = if retired { format!("{method}+retire") } else { method };
                if let Some(learner) = other_learner {
                    name = format!("{name}+{learner}");
                }
                if let Some(first) = origin.get(&name) {
                    return Err(CompareError::Duplicate {
                        method: name,
                        first: first.clone(),
                        other: other.clone(),
                    });
                }
                origin.insert(name.clone(), other.clone());
                runs.insert(name, seeds);
            }
        }
        let mut dirs = vec![first.to_path_buf()];
        dirs.extend(others.iter().cloned());
        Ok(RunData { head, runs, dirs })
    }

    fn dir_names(&self) -> String {
        self.dirs
            .iter()
            .map(|d| d.display().to_string())
            .collect::<Vec<_>>()
            .join(" + ")
    }

    fn methods(&self) -> String {
        self.runs.keys().cloned().collect::<Vec<_>>().join(", ")
    }

    /// Whether lower scores are better, as the problem says.
    pub fn lower_is_better(&self) -> bool {
        lower_is_better(&self.head.experiment, self.head.user_problem.as_ref())
    }
}

/// Mean and standard error of the mean (SEM 0 for fewer than two values).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct MeanSem {
    /// The mean.
    pub mean: f64,
    /// Its standard error: the sample standard deviation over sqrt(n).
    pub sem: f64,
}

/// Mean and SEM of `values` (not empty).
pub fn mean_sem(values: &[f64]) -> MeanSem {
    MeanSem {
        mean: acps_experiments::summary::mean(values),
        sem: acps_experiments::summary::standard_error(values),
    }
}

/// Two-sided p-value of Student's t with `df` degrees of freedom: P(|T| >= |t|) = I_x(df/2, 1/2)
/// at x = df / (df + t^2), the regularised incomplete beta function (statrs).
pub fn student_t_two_sided(t: f64, df: f64) -> f64 {
    let student = StudentsT::new(0.0, 1.0, df).expect("degrees of freedom above 0");
    2.0 * student.sf(t.abs())
}

/// Two-sided p-value of a standard normal z: P(|Z| >= |z|) = erfc(|z| / sqrt 2) = Q(1/2, z^2 / 2),
/// the regularised upper incomplete gamma function (statrs). Not statrs' `erfc`: up to 0.19.1 it
/// is off by up to 1e-10 relative (statrs#412), Q by 1e-14.
pub fn normal_two_sided(z: f64) -> f64 {
    if z == 0.0 { 1.0 } else { gamma_ur(0.5, z * z / 2.0) }
}

/// A paired test's result.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Test {
    /// Two-sided p-value (`None`: undefined, e.g. every difference the same nonzero value for t).
    pub p: Option<f64>,
    /// For Wilcoxon: whether p is exact (else the normal approximation with tie correction).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact: Option<bool>,
}

/// Ranks 1..=n of `values` (ascending), ties given their average rank.
fn average_ranks(values: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
    let mut ranks = vec![0.0; values.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && values[order[j + 1]] == values[order[i]] {
            j += 1;
        }
        let rank = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            ranks[k] = rank;
        }
        i = j + 1;
    }
    ranks
}

/// How many of the 2^n sign patterns of the ranks 1..=n give each rank sum 0..=n(n+1)/2.
pub fn signed_rank_counts(n: usize) -> Vec<f64> {
    let top = n * (n + 1) / 2;
    let mut counts = vec![0.0; top + 1];
    counts[0] = 1.0;
    for rank in 1..=n {
        for sum in (rank..=top).rev() {
            counts[sum] += counts[sum - rank];
        }
    }
    counts
}

/// The Wilcoxon signed-rank test of the paired differences `d` against a median of 0, two-sided.
/// Zero differences are dropped (Wilcoxon's rule). Exact for at most
/// [`WILCOXON_EXACT_MAX`] nonzero differences without ties; otherwise the normal approximation of
/// W+ with the variance corrected for ties and without continuity correction.
pub fn wilcoxon(d: &[f64]) -> Test {
    let nonzero: Vec<f64> = d.iter().copied().filter(|v| *v != 0.0).collect();
    let n = nonzero.len();
    if n == 0 {
        return Test {
            p: Some(1.0),
            exact: Some(true),
        };
    }
    let magnitudes: Vec<f64> = nonzero.iter().map(|v| v.abs()).collect();
    let ranks = average_ranks(&magnitudes);
    let w_plus: f64 = nonzero
        .iter()
        .zip(&ranks)
        .filter(|(v, _)| **v > 0.0)
        .map(|(_, r)| r)
        .sum();
    let mut sorted = magnitudes.clone();
    sorted.sort_by(f64::total_cmp);
    let mut tie_sum = 0.0;
    let mut ties = false;
    for group in sorted.chunk_by(|a, b| a == b) {
        let t = group.len() as f64;
        tie_sum += t * t * t - t;
        ties |= group.len() > 1;
    }
    let nf = n as f64;
    if n <= WILCOXON_EXACT_MAX && !ties {
        let counts = signed_rank_counts(n);
        let total = 2f64.powi(n as i32);
        let w = w_plus.round() as usize;
        let below: f64 = counts[..=w].iter().sum();
        let above: f64 = counts[w..].iter().sum();
        let p = (2.0 * below.min(above) / total).min(1.0);
        return Test {
            p: Some(p),
            exact: Some(true),
        };
    }
    let mean = nf * (nf + 1.0) / 4.0;
    let variance = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - tie_sum / 48.0;
    let p = if variance > 0.0 {
        normal_two_sided((w_plus - mean) / variance.sqrt())
    } else {
        1.0
    };
    Test {
        p: Some(p),
        exact: Some(false),
    }
}

/// The paired t-test of the differences `d` against a mean of 0, two-sided.
pub fn paired_t(d: &[f64]) -> Test {
    let stats = mean_sem(d);
    let p = if d.len() < 2 {
        None
    } else if stats.sem == 0.0 {
        (stats.mean == 0.0).then_some(1.0)
    } else {
        Some(student_t_two_sided(stats.mean / stats.sem, d.len() as f64 - 1.0))
    };
    Test { p, exact: None }
}

/// Area under a run's learning curve divided by its span: the trapezoid rule's mean score.
pub fn mean_over_curve(curve: &[(u64, f64)]) -> f64 {
    match curve {
        [] => f64::NAN,
        [(_, only)] => *only,
        _ => {
            let area: f64 = curve
                .windows(2)
                .map(|w| (w[1].0 - w[0].0) as f64 * (w[0].1 + w[1].1) / 2.0)
                .sum();
            area / (curve[curve.len() - 1].0 - curve[0].0) as f64
        }
    }
}

/// The first evaluation at or better than `level`, or `None`.
pub fn episodes_to(curve: &[(u64, f64)], level: f64, lower_is_better: bool) -> Option<u64> {
    curve
        .iter()
        .find(|(_, s)| if lower_is_better { *s <= level } else { *s >= level })
        .map(|(e, _)| *e)
}

/// One metric of one method, paired with the baseline.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// The method.
    pub method: String,
    /// The metric: `final`, `auc` or `episodes to LEVEL`.
    pub metric: String,
    /// Pairs (runs with a seed in both).
    pub n: usize,
    /// The method's mean +- SEM over those runs.
    pub value: MeanSem,
    /// For episodes to a level: the runs that never reached it (counted as the run length plus
    /// one evaluation interval).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_reached: Option<usize>,
    /// Method minus baseline, mean +- SEM (absent for the baseline itself).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub difference: Option<MeanSem>,
    /// The Wilcoxon signed-rank test of the differences.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wilcoxon: Option<Test>,
    /// The paired t-test of the differences.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub t_test: Option<Test>,
}

/// The whole comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The run directories.
    pub dirs: Vec<String>,
    /// The experiment.
    pub experiment: String,
    /// What the scores mean.
    pub metric: String,
    /// Whether lower scores are better.
    pub lower_is_better: bool,
    /// The baseline every method is paired with.
    pub baseline: String,
    /// Training episodes per run.
    pub episodes: u64,
    /// The rows: for the baseline and then every other method by name, final, AUC and each level.
    pub rows: Vec<Row>,
}

/// Parses `--levels`: finite numbers, and positive where the scores are distances (the throws).
pub fn parse_levels(text: &str, distances: bool) -> Result<Vec<f64>, CompareError> {
    text.split(',')
        .map(|item| {
            let bad = |why: &str| CompareError::BadLevel {
                level: item.to_string(),
                why: why.to_string(),
            };
            let level: f64 = item.trim().parse().map_err(|_| bad("not a number"))?;
            if !level.is_finite() {
                return Err(bad("not a finite number"));
            }
            if distances && level <= 0.0 {
                return Err(bad("the scores are distances in cm, so a level must be above 0"));
            }
            Ok(level)
        })
        .collect()
}

/// Compares every method of `data` with `baseline` (default: the best of [`BASELINES`] by final
/// mean score) on the final score, the mean over the learning curve and the episodes to `levels`.
pub fn compare(data: &RunData, baseline: Option<&str>, levels: &[f64]) -> Result<Report, CompareError> {
    let lower = data.lower_is_better();
    for (method, seeds) in &data.runs {
        if let Some((seed, _)) = seeds.iter().find(|(_, c)| c.is_empty()) {
            return Err(CompareError::NoScores {
                method: method.clone(),
                seed: *seed,
            });
        }
    }
    let final_mean = |method: &str| {
        let finals: Vec<f64> = data.runs[method].values().map(|c| c[c.len() - 1].1).collect();
        mean_sem(&finals).mean
    };
    let baseline = match baseline {
        Some(name) if data.runs.contains_key(name) => name.to_string(),
        Some(name) => {
            return Err(CompareError::UnknownMethod {
                method: name.to_string(),
                dir: data.dir_names(),
                available: data.methods(),
            });
        }
        None => BASELINES
            .iter()
            .filter(|b| data.runs.contains_key(**b))
            .map(|b| (b.to_string(), final_mean(b)))
            .reduce(|best, next| {
                let better = if lower { next.1 < best.1 } else { next.1 > best.1 };
                if better { next } else { best }
            })
            .map(|(name, _)| name)
            .ok_or_else(|| CompareError::NoBaseline {
                dir: data.dir_names(),
                available: data.methods(),
            })?,
    };
    let base_runs = &data.runs[&baseline];
    // A run that never reaches a level counts as its length plus one evaluation interval.
    let never = |curve: &Curve| {
        let interval = match curve.len() {
            0 | 1 => data.head.training_episodes,
            n => curve[n - 1].0 - curve[n - 2].0,
        };
        data.head.training_episodes + interval
    };
    let mut order: Vec<&String> = vec![&baseline];
    order.extend(data.runs.keys().filter(|m| **m != baseline));
    let mut rows = Vec::new();
    for method in order {
        let paired: Vec<(&Curve, &Curve)> = data.runs[method]
            .iter()
            .filter_map(|(seed, curve)| base_runs.get(seed).map(|b| (curve, b)))
            .collect();
        let n = paired.len();
        let is_baseline = *method == baseline;
        // A metric of every run of the method and of the baseline's run with the same seed.
        let both = |of: &dyn Fn(&Curve) -> f64| -> Values {
            (
                paired.iter().map(|(c, _)| of(c)).collect(),
                paired.iter().map(|(_, b)| of(b)).collect(),
            )
        };
        // Every curve has a score (checked above), so `last` is some.
        let last = |curve: &Curve| curve.last().map_or(f64::NAN, |p| p.1);
        let mut metric_rows: Vec<(String, Values, Option<usize>)> = vec![
            ("final".to_string(), both(&last), None),
            ("auc".to_string(), both(&|c| mean_over_curve(c)), None),
        ];
        for &level in levels {
            let to = |curve: &Curve| episodes_to(curve, level, lower).unwrap_or_else(|| never(curve)) as f64;
            let missed = paired
                .iter()
                .filter(|(c, _)| episodes_to(c, level, lower).is_none())
                .count();
            metric_rows.push((format!("episodes to {level}"), both(&to), Some(missed)));
        }
        for (metric, (a, b), not_reached) in metric_rows {
            let d: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
            let compared = !is_baseline && n > 0;
            rows.push(Row {
                method: method.clone(),
                metric,
                n,
                value: if n > 0 {
                    mean_sem(&a)
                } else {
                    MeanSem {
                        mean: f64::NAN,
                        sem: f64::NAN,
                    }
                },
                not_reached,
                difference: compared.then(|| mean_sem(&d)),
                wilcoxon: compared.then(|| wilcoxon(&d)),
                t_test: compared.then(|| paired_t(&d)),
            });
        }
    }
    Ok(Report {
        dirs: data.dirs.iter().map(|d| d.display().to_string()).collect(),
        experiment: data.head.experiment.clone(),
        metric: data.head.metric.clone(),
        lower_is_better: lower,
        baseline,
        episodes: data.head.training_episodes,
        rows,
    })
}

/// A number for the table: two or three significant figures, no exponent above 0.001.
fn num(value: f64) -> String {
    let magnitude = value.abs();
    if magnitude >= 100.0 {
        format!("{value:.0}")
    } else if magnitude >= 10.0 {
        format!("{value:.1}")
    } else if magnitude >= 1.0 {
        format!("{value:.2}")
    } else if magnitude >= 1e-3 || magnitude == 0.0 {
        format!("{value:.3}")
    } else {
        format!("{value:.1e}")
    }
}

/// A signed number for a difference.
fn signed(value: f64) -> String {
    if value > 0.0 {
        format!("+{}", num(value))
    } else {
        num(value)
    }
}

fn p_text(test: &Option<Test>) -> String {
    match test {
        None => String::new(),
        Some(Test { p: None, .. }) => "n/a".into(),
        Some(Test { p: Some(p), exact }) => {
            let p = if *p < 1e-4 {
                "<1e-4".to_string()
            } else {
                format!("{p:.4}")
            };
            if *exact == Some(false) {
                format!("{p} (normal)")
            } else {
                p
            }
        }
    }
}

impl Report {
    /// The line saying what the table compares.
    fn caption(&self) -> String {
        let direction = if self.lower_is_better { "lower" } else { "higher" };
        format!(
            "{} ({}): {}, {direction} is better; {} episodes per run. Every method paired with {} over runs of the same seed; difference = method - {}; p two-sided (Wilcoxon signed-rank; paired t). auc: the area under the learning curve over its span, a mean score. episodes to L: the first evaluation at or better than L, runs that never reach it counted as the run length plus one evaluation interval (how many: never).\n",
            self.experiment,
            self.dirs.join(" + "),
            self.metric,
            self.episodes,
            self.baseline,
            self.baseline
        )
    }

    /// One row per method, one column per metric: mean +- SEM, and for the methods other than
    /// the baseline the paired difference and both p-values beneath.
    pub fn wide(&self) -> String {
        let mut out = self.caption();
        let mut metrics: Vec<&str> = Vec::new();
        for row in &self.rows {
            if !metrics.contains(&row.metric.as_str()) {
                metrics.push(&row.metric);
            }
        }
        let _ = writeln!(out, "| method | {} |", metrics.join(" | "));
        let _ = writeln!(out, "|---|{}", "---|".repeat(metrics.len()));
        for chunk in self.rows.chunk_by(|a, b| a.method == b.method) {
            let cells: Vec<String> = chunk
                .iter()
                .map(|row| {
                    let missed = match row.not_reached {
                        Some(0) | None => String::new(),
                        Some(k) => format!(" ({k} never)"),
                    };
                    let mut cell = format!("{} ± {}{missed}", num(row.value.mean), num(row.value.sem));
                    if let Some(d) = row.difference {
                        let _ = write!(
                            cell,
                            "<br>{}, p {} / {}",
                            signed(d.mean),
                            p_text(&row.wilcoxon),
                            p_text(&row.t_test)
                        );
                    }
                    cell
                })
                .collect();
            let name = if chunk[0].method == self.baseline {
                format!("**{}** (baseline)", chunk[0].method)
            } else {
                chunk[0].method.clone()
            };
            let _ = writeln!(out, "| {name} | {} |", cells.join(" | "));
        }
        out
    }

    /// The report as a markdown table, one row per method and metric, with a line saying what it
    /// compares.
    pub fn markdown(&self) -> String {
        let mut out = self.caption();
        out.push_str("| method | metric | n | mean ± SEM | difference ± SEM | p Wilcoxon | p t-test |\n");
        out.push_str("|---|---|---|---|---|---|---|\n");
        for row in &self.rows {
            let missed = match row.not_reached {
                Some(0) | None => String::new(),
                Some(k) => format!(" ({k} never)"),
            };
            let difference = row
                .difference
                .map_or(String::new(), |d| format!("{} ± {}", signed(d.mean), num(d.sem)));
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} ± {}{missed} | {difference} | {} | {} |",
                row.method,
                row.metric,
                row.n,
                num(row.value.mean),
                num(row.value.sem),
                p_text(&row.wilcoxon),
                p_text(&row.t_test)
            );
        }
        out
    }
}

/// How `acps compare` prints its report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// A markdown row per method and metric.
    Long,
    /// A markdown row per method, a column per metric.
    Wide,
    /// The [`Report`] as JSON.
    Json,
}

/// `acps compare DIR [--with DIR2 ...] [--baseline METHOD] [--levels L1,L2] [--wide | --json]`.
pub fn run(
    dir: &Path,
    with: &[PathBuf],
    baseline: Option<&str>,
    levels: Option<&str>,
    layout: Layout,
) -> Result<String, CompareError> {
    let data = RunData::load(dir, with)?;
    let distances = scores_are_distances(&data.head.experiment, data.head.user_problem.as_ref());
    let levels = match levels {
        Some(text) => parse_levels(text, distances)?,
        None => Vec::new(),
    };
    let report = compare(&data, baseline, &levels)?;
    Ok(match layout {
        Layout::Json => serde_json::to_string_pretty(&report).expect("a report serialises") + "\n",
        Layout::Long => report.markdown(),
        Layout::Wide => report.wide(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tolerance: f64) -> bool {
        (a - b).abs() <= tolerance
    }

    #[test]
    fn student_t_matches_closed_forms_and_the_table() {
        for t in [0.0, 0.3, 1.0, 2.5, 12.7, 100.0] {
            // df 1 is Cauchy: P(|T| >= t) = 1 - 2 atan(t) / pi; df 2: 1 - t / sqrt(2 + t^2).
            let cauchy = 1.0 - 2.0 * f64::atan(t) / std::f64::consts::PI;
            assert!(close(student_t_two_sided(t, 1.0), cauchy, 1e-12), "t {t}");
            assert!(
                close(student_t_two_sided(-t, 2.0), 1.0 - t / (2.0 + t * t).sqrt(), 1e-12),
                "t {t}"
            );
        }
        // The tables' two-sided 5% points: t = 2.093 for df 19, 2.228 for df 10, 12.706 for df 1.
        assert!(close(student_t_two_sided(2.093, 19.0), 0.05, 2e-4));
        assert!(close(student_t_two_sided(2.228, 10.0), 0.05, 2e-4));
        assert!(close(student_t_two_sided(12.706, 1.0), 0.05, 1e-4));
        // Large df: the normal limit.
        assert!(close(student_t_two_sided(1.959964, 1e7), 0.05, 1e-5));
        // 2 * pt(-|t|, df) in R; here mpmath's betainc at 40 digits, rounded to f64: within 1e-12.
        for (t, df, p) in [
            (2.0, 10.0, 0.07338803477074037),
            (-2.5, 19.0, 0.021740411168397446),
            (1.0, 4.0, 0.37390096630005887),
            (5.0, 3.0, 0.015392438073302301),
            (0.5, 29.0, 0.6208480841937813),
        ] {
            assert!(close(student_t_two_sided(t, df), p, 1e-12 * p), "t {t} df {df}");
        }
    }

    #[test]
    fn normal_tail_matches_the_table_and_a_numerical_integral() {
        assert!(close(normal_two_sided(0.0), 1.0, 1e-15));
        assert!(close(normal_two_sided(1.959964), 0.05, 1e-6));
        assert!(close(normal_two_sided(-2.575829), 0.01, 1e-6));
        // 2 * pnorm(-|z|) in R; here mpmath's erfc at 40 digits, rounded to f64.
        for (z, p) in [
            (1.0, 0.3173105078629141),
            (-2.0, 0.04550026389635842),
            (3.5, 0.0004652581580710501),
        ] {
            assert!(close(normal_two_sided(z), p, 1e-13 * p), "z {z}");
        }
        // Simpson's rule of the density from 0 to z: p = 1 - 2 * integral.
        for z in [0.3, 1.0, 1.7, 2.4, 3.1] {
            let steps = 2000;
            let h = z / steps as f64;
            let density = |x: f64| (-x * x / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt();
            let mut integral = density(0.0) + density(z);
            for i in 1..steps {
                integral += density(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
            }
            integral *= h / 3.0;
            assert!(close(normal_two_sided(z), 1.0 - 2.0 * integral, 1e-10), "z {z}");
        }
    }

    /// The exact two-sided p of W+ by enumerating every sign pattern of the ranks.
    fn enumerated_p(n: usize, w: usize) -> f64 {
        let sums: Vec<usize> = (0u32..1 << n)
            .map(|signs| (0..n).filter(|i| signs >> i & 1 == 1).map(|i| i + 1).sum())
            .collect();
        let total = sums.len() as f64;
        let below = sums.iter().filter(|&&s| s <= w).count() as f64;
        let above = sums.iter().filter(|&&s| s >= w).count() as f64;
        (2.0 * below.min(above) / total).min(1.0)
    }

    #[test]
    fn exact_wilcoxon_matches_enumeration() {
        // All five positive: W+ = 15, the only pattern that extreme on each side: p = 2 / 32.
        let d = [1.0, 2.0, 3.0, 4.0, 5.0];
        let test = wilcoxon(&d);
        assert_eq!(test.exact, Some(true));
        assert!(close(test.p.unwrap(), 2.0 / 32.0, 1e-15));
        // A mixed sample: ranks of |d| are 1..8; positive ones sum to W+.
        let d = [0.4, -1.1, 2.5, 3.0, -0.2, 5.5, 6.1, -7.3, 0.0];
        let w = 2 + 4 + 5 + 6 + 7;
        let test = wilcoxon(&d);
        assert_eq!(test.exact, Some(true), "the zero is dropped, no ties");
        assert!(close(test.p.unwrap(), enumerated_p(8, w), 1e-15));
        for n in 1..=12 {
            let counts = signed_rank_counts(n);
            for (w, _) in counts.iter().enumerate() {
                let below: f64 = counts[..=w].iter().sum();
                let above: f64 = counts[w..].iter().sum();
                let p = (2.0 * below.min(above) / 2f64.powi(n as i32)).min(1.0);
                assert!(close(p, enumerated_p(n, w), 1e-15), "n {n} w {w}");
            }
        }
    }

    #[test]
    fn wilcoxon_with_ties_uses_the_corrected_normal_approximation() {
        // |d| = 1, 1, 2, 3, 3, 3: average ranks 1.5, 1.5, 3, 5, 5, 5; positive: 1.5 + 3 + 5 + 5.
        let d = [1.0, -1.0, 2.0, 3.0, 3.0, -3.0];
        let w_plus = 1.5 + 3.0 + 5.0 + 5.0;
        let n = 6.0;
        let variance = n * (n + 1.0) * (2.0 * n + 1.0) / 24.0 - ((8.0 - 2.0) + (27.0 - 3.0)) / 48.0;
        let z: f64 = (w_plus - n * (n + 1.0) / 4.0) / f64::sqrt(variance);
        let test = wilcoxon(&d);
        assert_eq!(test.exact, Some(false));
        assert!(close(test.p.unwrap(), normal_two_sided(z), 1e-15));
        // Above 25 differences the approximation too, without ties.
        let d: Vec<f64> = (1..=30)
            .map(|i| if i % 3 == 0 { -(i as f64) } else { i as f64 })
            .collect();
        assert_eq!(wilcoxon(&d).exact, Some(false));
        assert_eq!(wilcoxon(&[0.0, 0.0]).p, Some(1.0));
    }

    #[test]
    fn paired_t_is_the_mean_over_its_sem() {
        let d = [0.5, 1.5, -0.25, 2.0, 1.0];
        let mean = 4.75 / 5.0;
        let var = d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / 4.0;
        let t = mean / (var / 5.0).sqrt();
        assert!(close(paired_t(&d).p.unwrap(), student_t_two_sided(t, 4.0), 1e-15));
        assert_eq!(paired_t(&[1.0, 1.0]).p, None, "no spread: undefined");
        assert_eq!(paired_t(&[0.0, 0.0]).p, Some(1.0));
    }

    #[test]
    fn curve_metrics() {
        let curve = [(0, 4.0), (50, 2.0), (100, 1.0), (200, 3.0)];
        // Trapezoids: 50 * 3 + 50 * 1.5 + 100 * 2 = 425 over 200 episodes.
        assert!(close(mean_over_curve(&curve), 425.0 / 200.0, 1e-15));
        assert_eq!(episodes_to(&curve, 2.0, true), Some(50));
        assert_eq!(episodes_to(&curve, 0.5, true), None);
        assert_eq!(episodes_to(&curve, 3.0, false), Some(0));
        assert_eq!(episodes_to(&curve, 5.0, false), None);
    }

    #[test]
    fn levels_are_checked() {
        assert_eq!(parse_levels("10,5,3", true).unwrap(), vec![10.0, 5.0, 3.0]);
        assert_eq!(parse_levels("-1,-2.5", false).unwrap(), vec![-1.0, -2.5]);
        let error = parse_levels("10,0", true).unwrap_err().to_string();
        assert!(error.starts_with("--levels 0: the scores are distances"), "{error}");
        assert!(
            parse_levels("3,x", false)
                .unwrap_err()
                .to_string()
                .contains("--levels x: not a number")
        );
        assert!(parse_levels("inf", false).is_err());
    }
}
