//! Problem files: an experiment file whose `[problem]` table describes a problem of the user's
//! instead of naming one of the paper's. acps cannot simulate such a problem; `acps run` serves
//! its tasks through the worker fleet to workers the user provides (README, "Your own problem").
//!
//! The table is checked here, key by key, with the accepted ranges of its keys
//! ([`PROBLEM_KEYS`]), before anything starts.

use crate::keys::{FILE, Invalid, Key, out_of_range};
use crate::summary::UserProblem;
use acps_learner::creps::FeatureMap;
use acps_shared::{ContextSpace, EnvironmentSpec, Problem, ScoreAggregate};
use acps_wire::wire::{MAX_CONTEXT, MAX_THETA};
use serde::{Deserialize, Serialize};

/// Most points a context grid expands to.
pub const MAX_GRID_POINTS: u64 = 100_000;

/// Largest magnitude of a context coordinate or an initial parameter, in the problem's units:
/// the scale of `initial_sigma`'s standard deviations (at most 1e6). Quadratic features square a
/// coordinate and the C-REPS regression squares it again; rescale a problem beyond it.
const MAX_MAGNITUDE: f64 = 1e6;

/// Whether every value is a number of magnitude at most [`MAX_MAGNITUDE`] (NaN is not).
fn bounded(values: &[f64]) -> bool {
    values.iter().all(|x| x.abs() <= MAX_MAGNITUDE)
}

/// What a list of contexts accepts.
const CONTEXTS: &str = "a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box";
/// What a context grid accepts.
const GRID: &str = "a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions: low <= high in -1e6..=1e6, points >= 1 per dimension and at most 100000 in all, inside the context box";

/// A key of the `[problem]` table.
const fn problem_key(name: &'static str, accepted: &'static str) -> Key {
    Key {
        name,
        doc: "",
        default: "",
        accepted,
        why: "",
        applies: FILE,
        methods: &[],
        learner: None,
    }
}

/// Every key of the `[problem]` table and of its `[problem.environment]`, as `problem.KEY`.
pub const PROBLEM_KEYS: &[Key] = &[
    problem_key(
        "problem.name",
        "1 to 32 characters of ASCII letters, digits, '-', '_' and '.' (default: the file's name without .toml)",
    ),
    problem_key("problem.training_contexts", CONTEXTS),
    problem_key("problem.training_grid", GRID),
    problem_key("problem.test_contexts", CONTEXTS),
    problem_key("problem.test_grid", GRID),
    problem_key(
        "problem.context_low",
        "a list of 1 to 8 numbers in -1e6..=1e6, one per context dimension (default: the lower corner of the contexts' bounding box)",
    ),
    problem_key(
        "problem.context_high",
        "a list of numbers in -1e6..=1e6, one per context dimension, each above context_low's (default: the upper corner of the contexts' bounding box)",
    ),
    problem_key(
        "problem.theta0",
        "a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters)",
    ),
    problem_key(
        "problem.features",
        "one of affine, quadratic, polar (2-D contexts only)",
    ),
    problem_key("problem.score", "one of sum, mean, log-mean"),
    problem_key("problem.metric", "a text that is not blank"),
    problem_key("problem.unit", "a text"),
    problem_key("problem.lower_is_better", "true or false"),
    problem_key(
        "problem.environment",
        "a table with name, settings and optionally parameters",
    ),
    problem_key(
        "problem.environment.name",
        "1 to 32 characters of ASCII letters, digits, '-', '_' and '.'",
    ),
    problem_key(
        "problem.environment.settings",
        "a text (its FNV-1a 64-bit hash is the environment's settings identity)",
    ),
    problem_key("problem.environment.parameters", "three integers in 0..=2^63-1"),
];

/// A `[problem]` table as written; checking it (in `Plan::new`) says which keys must be set.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProblemFile {
    /// The problem's name (default: the file's stem).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The K training contexts ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_contexts: Option<Vec<Vec<f64>>>,
    /// ... or a grid of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_grid: Option<ContextGrid>,
    /// The test contexts (default: the training contexts) ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_contexts: Option<Vec<Vec<f64>>>,
    /// ... or a grid of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_grid: Option<ContextGrid>,
    /// Lower corner of the continuous context box (default: of the contexts' bounding box).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_low: Option<Vec<f64>>,
    /// Upper corner of the box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_high: Option<Vec<f64>>,
    /// The initial parameters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta0: Option<Vec<f64>>,
    /// The policy's context features (default affine).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<Features>,
    /// How the test contexts' scores aggregate (default mean).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<ScoreAggregate>,
    /// What the score means (default "score").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<String>,
    /// The score's unit (default none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Whether lower scores are better (default true).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lower_is_better: Option<bool>,
    /// The environment the problem is defined for (default: none named).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<EnvironmentTable>,
}

/// `{ low = [...], high = [...], points = [...] }`: `points[d]` evenly spaced values from
/// `low[d]` to `high[d]` in every dimension (one point: the midpoint), the first dimension
/// slowest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContextGrid {
    /// Lowest value per dimension.
    pub low: Vec<f64>,
    /// Highest value per dimension.
    pub high: Vec<f64>,
    /// Points per dimension.
    pub points: Vec<u64>,
}

/// The policy's context features, as a problem file names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Features {
    /// [`FeatureMap::Affine`].
    Affine,
    /// [`FeatureMap::Quadratic`].
    Quadratic,
    /// [`FeatureMap::PolarQuadratic`], 2-D contexts only.
    Polar,
}

impl Features {
    /// The feature map it names.
    pub fn map(self) -> FeatureMap {
        match self {
            Self::Affine => FeatureMap::Affine,
            Self::Quadratic => FeatureMap::Quadratic,
            Self::Polar => FeatureMap::PolarQuadratic,
        }
    }
}

/// `[problem.environment]`: the identity workers must declare,
/// `EnvironmentSpec::from_text(name, parameters, settings)`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentTable {
    /// The environment's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Free text; its FNV-1a hash is the spec's settings hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<String>,
    /// Three numbers (default `[0, 0, 0]`).
    #[serde(default, skip_serializing_if = "Option::is_none", deserialize_with = "three")]
    pub parameters: Option<[u64; 3]>,
}

/// Exactly three numbers: TOML's reader fills an array of three from a longer list and drops
/// the rest, which would make `[0, 0, 0, 7]` the identity `[0, 0, 0]` unseen.
fn three<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Option<[u64; 3]>, D::Error> {
    let numbers = Vec::<u64>::deserialize(deserializer)?;
    let len = numbers.len();
    <[u64; 3]>::try_from(numbers)
        .map(Some)
        .map_err(|_| serde::de::Error::invalid_length(len, &"three integers"))
}

/// A checked problem file: the problem the learner sees, and the table with its defaults
/// filled in (what `config.toml` records).
#[derive(Debug, Clone)]
pub struct CheckedProblem {
    /// The table with every default filled in.
    pub resolved: ProblemFile,
    /// The problem.
    pub problem: Problem,
    /// The policy's context features.
    pub features: Features,
    /// How its scores read.
    pub user: UserProblem,
}

/// The name of a context key and its points, once expanded.
struct Contexts {
    key: &'static str,
    points: Vec<Vec<f64>>,
}

impl ProblemFile {
    /// Check every key and build the problem; `stem` (the file's name without `.toml`) is the
    /// default name.
    ///
    /// When every method draws its contexts from the continuous box (`box_only`), the training
    /// contexts may be left out: the test contexts then stand in for them where the learner
    /// needs points (the cells of a best-per-task memory).
    pub(crate) fn check(&self, stem: Option<&str>, box_only: bool) -> Result<CheckedProblem, Invalid> {
        let theta0 = self.theta0.clone().ok_or(Invalid::missing("problem.theta0"))?;
        if !(1..=MAX_THETA).contains(&theta0.len()) || !bounded(&theta0) {
            return Err(out_of_range("problem.theta0", format!("{theta0:?}")));
        }
        let training = contexts(
            ("problem.training_contexts", &self.training_contexts),
            ("problem.training_grid", &self.training_grid),
        )?;
        let given_test = contexts(
            ("problem.test_contexts", &self.test_contexts),
            ("problem.test_grid", &self.test_grid),
        )?;
        let training = match (training, &given_test) {
            (Some(training), _) => training,
            (None, Some(test)) if box_only => Contexts {
                key: test.key,
                points: test.points.clone(),
            },
            (None, _) => return Err(Invalid::missing("problem.training_contexts")),
        };
        let dim = match &self.context_low {
            Some(low) => low.len(),
            None => training.points[0].len(),
        };
        if !(1..=MAX_CONTEXT).contains(&dim) {
            let key = if self.context_low.is_some() {
                "problem.context_low"
            } else {
                training.key
            };
            return Err(Invalid::element(key, format!("{dim}-D contexts")));
        }
        let test = given_test;
        for set in std::iter::once(&training).chain(&test) {
            if let Some((i, point)) = set.points.iter().enumerate().find(|(_, p)| p.len() != dim) {
                return Err(Invalid::element(
                    set.key,
                    format!("point {i} {point:?} of {} coordinates, not {dim}", point.len()),
                ));
            }
        }
        let test = test.unwrap_or(Contexts {
            key: training.key,
            points: training.points.clone(),
        });
        let (low, high) = self.context_box(dim, &training, &test)?;
        let space = ContextSpace::new_box(low.clone(), high.clone())
            .map_err(|_| out_of_range("problem.context_low", format!("{low:?}")))?;
        for set in [&training, &test] {
            if let Some((i, point)) = set.points.iter().enumerate().find(|(_, p)| !space.contains(p)) {
                return Err(Invalid::element(
                    set.key,
                    format!("point {i} {point:?}, outside the context box {low:?} .. {high:?}"),
                ));
            }
        }
        let features = self.features.unwrap_or(Features::Affine);
        if features == Features::Polar && dim != 2 {
            return Err(Invalid::element(
                "problem.features",
                format!("\"polar\" for {dim}-D contexts"),
            ));
        }
        let metric = self.metric.clone().unwrap_or_else(|| "score".into());
        if metric.trim().is_empty() {
            return Err(out_of_range("problem.metric", format!("{metric:?}")));
        }
        let environment = match &self.environment {
            None => EnvironmentSpec::unnamed(),
            Some(table) => table.spec()?,
        };
        let name = match (&self.name, stem) {
            (Some(name), _) => name.clone(),
            (None, Some(stem)) => stem.to_string(),
            (None, None) => return Err(Invalid::missing("problem.name")),
        };
        if EnvironmentSpec::from_text(&name, [0; 3], "").is_err() {
            let got = match &self.name {
                Some(_) => format!("{name:?}"),
                None => format!("{name:?} (the file's name: set problem.name)"),
            };
            return Err(out_of_range("problem.name", got));
        }
        let user = UserProblem {
            unit: self.unit.clone().unwrap_or_default(),
            lower_is_better: self.lower_is_better.unwrap_or(true),
        };
        let score = self.score.unwrap_or(ScoreAggregate::Mean);
        // What config.toml records: every default filled in, the test contexts as written for
        // the training ones when they were left to default.
        let (test_contexts, test_grid) = match (&self.test_contexts, &self.test_grid) {
            (None, None) => (self.training_contexts.clone(), self.training_grid.clone()),
            given => (given.0.clone(), given.1.clone()),
        };
        let resolved = ProblemFile {
            name: Some(name.clone()),
            training_contexts: self.training_contexts.clone(),
            training_grid: self.training_grid.clone(),
            test_contexts,
            test_grid,
            context_low: Some(low),
            context_high: Some(high),
            theta0: Some(theta0.clone()),
            features: Some(features),
            score: Some(score),
            metric: Some(metric.clone()),
            unit: Some(user.unit.clone()),
            lower_is_better: Some(user.lower_is_better),
            environment: self.environment.as_ref().map(|table| EnvironmentTable {
                parameters: Some(table.parameters.unwrap_or_default()),
                ..table.clone()
            }),
        };
        Ok(CheckedProblem {
            resolved,
            problem: Problem {
                name,
                training_contexts: training.points,
                test_contexts: test.points,
                space,
                theta0,
                score,
                metric,
                environment,
            },
            features,
            user,
        })
    }

    /// The context box: as given, or the bounding box of the contexts.
    fn context_box(&self, dim: usize, training: &Contexts, test: &Contexts) -> Result<(Vec<f64>, Vec<f64>), Invalid> {
        let valid = |corner: &[f64]| corner.len() == dim && bounded(corner);
        match (&self.context_low, &self.context_high) {
            (Some(low), Some(high)) => {
                if !valid(low) {
                    return Err(out_of_range("problem.context_low", format!("{low:?}")));
                }
                if !valid(high) || low.iter().zip(high).any(|(l, h)| l >= h) {
                    return Err(out_of_range("problem.context_high", format!("{high:?}")));
                }
                Ok((low.clone(), high.clone()))
            }
            (Some(_), None) => Err(Invalid::missing("problem.context_high")),
            (None, Some(_)) => Err(Invalid::missing("problem.context_low")),
            (None, None) => {
                let all = || training.points.iter().chain(&test.points);
                let low: Vec<f64> = (0..dim).map(|d| all().map(|p| p[d]).fold(f64::MAX, f64::min)).collect();
                let high: Vec<f64> = (0..dim).map(|d| all().map(|p| p[d]).fold(f64::MIN, f64::max)).collect();
                match (0..dim).find(|&d| low[d] >= high[d]) {
                    Some(d) => Err(Invalid::element(
                        "problem.context_low",
                        format!(
                            "nothing, and every context has coordinate {d} = {}: set context_low and context_high",
                            low[d]
                        ),
                    )),
                    None => Ok((low, high)),
                }
            }
        }
    }
}

impl EnvironmentTable {
    fn spec(&self) -> Result<EnvironmentSpec, Invalid> {
        let name = self.name.as_ref().ok_or(Invalid::missing("problem.environment.name"))?;
        let settings = self
            .settings
            .as_ref()
            .ok_or(Invalid::missing("problem.environment.settings"))?;
        EnvironmentSpec::from_text(name, self.parameters.unwrap_or_default(), settings)
            .map_err(|_| out_of_range("problem.environment.name", format!("{name:?}")))
    }
}

/// The contexts of a list key or a grid key, `None` when neither is set; both set is refused.
fn contexts(
    (list_key, list): (&'static str, &Option<Vec<Vec<f64>>>),
    (grid_key, grid): (&'static str, &Option<ContextGrid>),
) -> Result<Option<Contexts>, Invalid> {
    match (list, grid) {
        (Some(_), Some(_)) => Err(Invalid::conflict(grid_key, list_key)),
        (None, None) => Ok(None),
        (Some(points), None) => {
            if points.is_empty() {
                return Err(out_of_range(list_key, "[]"));
            }
            if points.len() as u64 > MAX_GRID_POINTS {
                return Err(Invalid::element(list_key, format!("{} points", points.len())));
            }
            if let Some((i, point)) = points.iter().enumerate().find(|(_, p)| p.is_empty() || !bounded(p)) {
                return Err(Invalid::element(list_key, format!("point {i} {point:?}")));
            }
            Ok(Some(Contexts {
                key: list_key,
                points: points.clone(),
            }))
        }
        (None, Some(grid)) => Ok(Some(Contexts {
            key: grid_key,
            points: grid
                .expand()
                .ok_or_else(|| out_of_range(grid_key, format!("{grid:?}")))?,
        })),
    }
}

impl ContextGrid {
    /// The grid's points, first dimension slowest; `None` for a grid out of range.
    fn expand(&self) -> Option<Vec<Vec<f64>>> {
        let dim = self.low.len();
        let valid = (1..=MAX_CONTEXT).contains(&dim)
            && self.high.len() == dim
            && self.points.len() == dim
            && self
                .low
                .iter()
                .zip(&self.high)
                .all(|(l, h)| bounded(&[*l, *h]) && l <= h)
            && self.points.iter().all(|&n| n >= 1);
        let total = self.points.iter().try_fold(1u64, |total, &n| total.checked_mul(n));
        if !valid || total.is_none_or(|total| total > MAX_GRID_POINTS) {
            return None;
        }
        let axis = |d: usize| -> Vec<f64> {
            let (low, high, n) = (self.low[d], self.high[d], self.points[d]);
            if n == 1 {
                return vec![low + (high - low) / 2.0];
            }
            // The last point is `high` itself: interpolated, it can round past it (-0.2 .. 0.4
            // in 4 points gave 0.4000000000000001), outside the box the file states.
            (0..n)
                .map(|i| {
                    if i + 1 == n {
                        high
                    } else {
                        low + (high - low) * i as f64 / (n - 1) as f64
                    }
                })
                .collect()
        };
        let mut points = vec![Vec::with_capacity(dim)];
        for d in 0..dim {
            let values = axis(d);
            let values = &values;
            points = points
                .into_iter()
                .flat_map(|point| {
                    values.iter().map(move |&x| {
                        let mut next = point.clone();
                        next.push(x);
                        next
                    })
                })
                .collect();
        }
        Some(points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_expand_first_dimension_slowest_and_one_point_is_the_midpoint() {
        let grid = ContextGrid {
            low: vec![-1.0, 0.0],
            high: vec![1.0, 2.0],
            points: vec![3, 1],
        };
        assert_eq!(
            grid.expand().unwrap(),
            vec![vec![-1.0, 1.0], vec![0.0, 1.0], vec![1.0, 1.0]]
        );
        let too_many = ContextGrid {
            low: vec![0.0; 2],
            high: vec![1.0; 2],
            points: vec![1000, 1000],
        };
        assert_eq!(too_many.expand(), None);
        let overflow = ContextGrid {
            points: vec![u64::MAX, 2],
            ..too_many
        };
        assert_eq!(overflow.expand(), None);
        let rounding = ContextGrid {
            low: vec![-0.2],
            high: vec![0.4],
            points: vec![4],
        };
        let axis: Vec<f64> = rounding.expand().unwrap().concat();
        assert_eq!((axis[0], axis[3]), (-0.2, 0.4), "the ends are the box's own");
        assert!(axis.windows(2).all(|w| w[0] < w[1]), "{axis:?}");
    }
}
