//! Environments by spec: a worker receives an [`EnvironmentSpec`] with every task and builds
//! (and caches) the environment it names from its name and parameters; in-process runs build
//! theirs with the same constructors. The spec of what was built then says whether it is the
//! environment asked for: a build with other settings builds another one.

use crate::benchmark::{self, BenchmarkCreateError, ContextualBenchmark, Objective};
use crate::contextual_function::{self, ContextualFunction, ContextualFunctionCreateError};
use crate::rapier_sim::{RapierArm, RapierArmCreateError, RapierConfig};
use crate::robot::Robot;
use crate::targets;
use crate::throw::{
    DARTBOARD_ENVIRONMENT, GRID_ENVIRONMENT, PARAMS, Simulator, SpeedLimits, Targets, ThrowDesign, ThrowPolicy,
    ThrowPolicyCreateError, ThrowingEnvironment,
};
use acps_shared::{Environment, EnvironmentSpec, Outcome, Task};

pub use crate::throw::Sim;

/// The name of the [`TrivialEnvironment`].
pub const TRIVIAL_ENVIRONMENT: &str = "trivial";

/// The analytic backend needs only the release state, which the DMPs' 1 ms Euler substeps fix
/// whatever the control period, so each DMP is sampled at its two end points only.
const ANALYTIC_CONTROL_DT: f64 = 0.5;
/// The rapier arm interpolates the commanded samples between its own steps; 4 ms samples keep
/// that interpolation far below the motors' tracking error.
const RAPIER_CONTROL_DT: f64 = 0.004;

/// The dartboard's fields, centred where theta_0 lands with the analytic model.
pub fn dartboard_fields() -> Vec<targets::Field> {
    let mut analytic = throwing_environment(Sim::Analytic, Targets::Grid).expect("the shipped PA-10 throws");
    targets::dartboard(analytic.landing(&[0.0; PARAMS]).expect("theta_0 lands"))
}

/// Why [`build`] cannot build the environment a spec names.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvironmentBuildError {
    /// A name that names none of the project's models.
    #[error(
        "environment spec: name must be contextual-function, contextual-sphere, contextual-rosenbrock, throw-grid, throw-dartboard or trivial, got {0}"
    )]
    UnknownName(String),
    /// A simulator code (a throwing spec's parameter 0) that names no simulator.
    #[error("environment spec: simulator (parameter 0) must be 0 (analytic) or 1 (rapier), got {0}")]
    UnknownSimulator(u64),
    /// The contextual function refuses the spec's dimensions.
    #[error(transparent)]
    ContextualFunction(#[from] ContextualFunctionCreateError),
    /// A benchmark function's sizes are out of range.
    #[error(transparent)]
    Benchmark(#[from] BenchmarkCreateError),
    /// The rapier arm cannot be built.
    #[error(transparent)]
    Rapier(#[from] RapierArmCreateError),
    /// The throw design does not roll out with the simulator's control period.
    #[error("throw: the design does not roll out: {0}")]
    Throw(#[from] ThrowPolicyCreateError),
}

fn throwing_environment(sim: Sim, targets: Targets) -> Result<ThrowingEnvironment, EnvironmentBuildError> {
    let robot = Robot::pa10();
    let (simulator, control_dt) = match sim {
        Sim::Analytic => (Simulator::Analytic, ANALYTIC_CONTROL_DT),
        Sim::Rapier => (
            Simulator::Rapier(Box::new(RapierArm::new(&robot, RapierConfig::default())?)),
            RAPIER_CONTROL_DT,
        ),
    };
    let policy = ThrowPolicy::new(ThrowDesign::pa10(), control_dt)?;
    Ok(ThrowingEnvironment::new(
        robot,
        policy,
        simulator,
        targets,
        SpeedLimits::Ignore,
    ))
}

/// The PA-10 throwing at the grid problem's targets.
pub fn grid(sim: Sim) -> Result<ThrowingEnvironment, EnvironmentBuildError> {
    throwing_environment(sim, Targets::Grid)
}

/// The PA-10 throwing at the dartboard's fields.
pub fn dartboard(sim: Sim) -> Result<ThrowingEnvironment, EnvironmentBuildError> {
    throwing_environment(sim, Targets::Dartboard(dartboard_fields()))
}

/// The simulator a throwing environment's spec names (its first parameter).
fn sim_of(spec: &EnvironmentSpec) -> Result<Sim, EnvironmentBuildError> {
    let [parameter, ..] = spec.parameters();
    Sim::from_parameter(parameter).ok_or(EnvironmentBuildError::UnknownSimulator(parameter))
}

/// Build the environment `spec` names from its name and parameters; the settings hash is for the
/// caller to compare with the built environment's.
pub fn build(spec: &EnvironmentSpec) -> Result<Box<dyn Environment>, EnvironmentBuildError> {
    Ok(match spec.name() {
        contextual_function::ENVIRONMENT => {
            let [n_s, n_theta, problem_seed] = spec.parameters();
            let size = |n: u64| usize::try_from(n).unwrap_or(usize::MAX);
            Box::new(ContextualFunction::new(size(n_s), size(n_theta), problem_seed)?)
        }
        name @ (benchmark::SPHERE_ENVIRONMENT | benchmark::ROSENBROCK_ENVIRONMENT) => {
            let [n_s, n_theta, problem_seed] = spec.parameters();
            let size = |n: u64| usize::try_from(n).unwrap_or(usize::MAX);
            let objective = if name == benchmark::SPHERE_ENVIRONMENT {
                Objective::Sphere
            } else {
                Objective::Rosenbrock
            };
            Box::new(ContextualBenchmark::new(
                objective,
                size(n_s),
                size(n_theta),
                problem_seed,
            )?)
        }
        GRID_ENVIRONMENT => Box::new(grid(sim_of(spec)?)?),
        DARTBOARD_ENVIRONMENT => Box::new(dartboard(sim_of(spec)?)?),
        TRIVIAL_ENVIRONMENT => Box::new(TrivialEnvironment::new()),
        other => return Err(EnvironmentBuildError::UnknownName(other.to_string())),
    })
}

/// For a dartboard spec, the same throws scored against any target as on the grid (reward
/// -||s - b||^2): the dartboard's reward is defined at field centres only. `None` for other
/// specs.
pub fn free_targets(spec: &EnvironmentSpec) -> Result<Option<ThrowingEnvironment>, EnvironmentBuildError> {
    if spec.name() == DARTBOARD_ENVIRONMENT {
        grid(sim_of(spec)?).map(Some)
    } else {
        Ok(None)
    }
}

/// A rollout that costs nothing: reward -||theta||^2, score ||theta||^2.
pub struct TrivialEnvironment {
    spec: EnvironmentSpec,
}

impl TrivialEnvironment {
    /// The trivial environment; it has no settings.
    pub fn new() -> Self {
        Self {
            spec: EnvironmentSpec::new(TRIVIAL_ENVIRONMENT, [0; 3], &()).expect("a valid name"),
        }
    }

    /// A problem for it, as the benchmarks pose it: one training context, 0 in [-1, 1], one
    /// parameter starting at 1, and `test_contexts` (none: no evaluation costs).
    pub fn problem(&self, test_contexts: Vec<Vec<f64>>) -> acps_shared::Problem {
        acps_shared::Problem {
            name: "trivial".into(),
            training_contexts: vec![vec![0.0]],
            test_contexts,
            space: acps_shared::ContextSpace::new_box(vec![-1.0], vec![1.0]).expect("a valid box"),
            theta0: vec![1.0],
            score: acps_shared::ScoreAggregate::Mean,
            metric: "none".into(),
            environment: self.spec,
        }
    }
}

impl Default for TrivialEnvironment {
    fn default() -> Self {
        Self::new()
    }
}

impl Environment for TrivialEnvironment {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        1
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let norm2: f64 = task.theta.iter().map(|x| x * x).sum();
        Outcome::new(task.id, -norm2, norm2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use acps_shared::TaskKind;

    fn task(theta: Vec<f64>, context: Vec<f64>) -> Task {
        Task {
            id: 3,
            kind: TaskKind::Train,
            seed: 1,
            context,
            theta,
        }
    }

    #[test]
    fn specs_build_the_environments_that_declare_them() {
        let direct = ContextualFunction::new(2, 20, 5).unwrap();
        let mut function = build(&direct.spec()).unwrap();
        assert_eq!(function.spec(), direct.spec());
        let t = task(vec![0.1; 20], vec![0.5, -0.5]);
        assert_eq!(
            function.rollout(&t).reward,
            direct.evaluate(&t.theta, &t.context).unwrap().0
        );
        for objective in [Objective::Sphere, Objective::Rosenbrock] {
            let direct = ContextualBenchmark::new(objective, 1, 20, 5).unwrap();
            let mut built = build(&direct.spec()).unwrap();
            assert_eq!(built.spec(), direct.spec());
            let t = task(vec![0.1; 20], vec![1.5]);
            assert_eq!(built.rollout(&t).score, direct.cost(&t.theta, &t.context).unwrap());
        }
        let analytic = grid(Sim::Analytic).unwrap();
        let mut built = build(&analytic.spec()).unwrap();
        assert_eq!(built.spec(), analytic.spec());
        assert!(built.rollout(&task(vec![0.0; PARAMS], vec![-3.5, -3.5])).is_ok());
        let board = dartboard(Sim::Analytic).unwrap();
        let mut built = build(&board.spec()).unwrap();
        assert_eq!(built.spec(), board.spec());
        let bull = dartboard_fields()[0].centre;
        assert_eq!(built.rollout(&task(vec![0.0; PARAMS], bull.to_vec())).reward, 0.0);
        let trivial = TrivialEnvironment::new().spec();
        assert_eq!(
            build(&trivial)
                .unwrap()
                .rollout(&task(vec![3.0, 4.0], vec![0.0]))
                .reward,
            -25.0
        );
    }

    #[test]
    fn the_dartboards_free_targets_are_the_grids_throws() {
        let free = free_targets(&dartboard(Sim::Analytic).unwrap().spec())
            .unwrap()
            .unwrap();
        assert_eq!(free.spec(), grid(Sim::Analytic).unwrap().spec());
        assert!(free_targets(&grid(Sim::Analytic).unwrap().spec()).unwrap().is_none());
    }

    #[test]
    fn bad_specs_name_the_field() {
        let spec = |name: &str, parameters| EnvironmentSpec::from_parts(name.as_bytes(), 0, parameters).unwrap();
        let error = build(&spec("learning-model", [0; 3])).err().unwrap().to_string();
        assert!(
            error.contains(
                "name must be contextual-function, contextual-sphere, contextual-rosenbrock, throw-grid, throw-dartboard or trivial, got learning-model"
            ),
            "{error}"
        );
        let error = build(&spec(GRID_ENVIRONMENT, [7, 0, 0])).err().unwrap().to_string();
        assert!(
            error.contains("simulator (parameter 0) must be 0 (analytic) or 1 (rapier), got 7"),
            "{error}"
        );
        let function = spec(contextual_function::ENVIRONMENT, [3, 2, 0]);
        assert!(build(&function).is_err(), "n_theta must exceed n_s");
        let sphere = spec(benchmark::SPHERE_ENVIRONMENT, [0, 20, 0]);
        assert!(build(&sphere).is_err(), "n_s must be at least 1");
    }
}
