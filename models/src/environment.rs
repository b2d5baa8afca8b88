//! Environments by specification: a worker receives an [`EnvironmentSpec`] with every task and
//! builds (and caches) the environment it names; in-process runs build theirs the same way, so
//! both perform identical rollouts.

use crate::contextual_function::{ContextualFunction, ContextualFunctionCreateError};
use crate::rapier_sim::{RapierArm, RapierArmCreateError, RapierConfig};
use crate::robot::Robot;
use crate::targets;
use crate::throw::{
    PARAMS, Simulator, SpeedLimits, Targets, ThrowDesign, ThrowPolicy, ThrowPolicyCreateError, ThrowingEnvironment,
};

use acps_shared::EnvironmentSpec;
use acps_shared::{Environment, Outcome, Task};

/// The environments a spec can name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// The Section 5.1 contextual function: options = [n_s, n_theta, 0].
    ContextualFunction,
    /// The PA-10 grid problem: options = [simulator, 0, 0].
    Grid,
    /// The PA-10 dartboard problem: options = [simulator, 0, 0].
    Dartboard,
    /// A rollout that costs nothing (reward -||theta||^2), for measuring transport.
    Trivial,
}

/// How a throwing environment simulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sim {
    /// Forward kinematics at release and closed-form flight.
    Analytic,
    /// The rapier3d multibody arm with the default configuration.
    Rapier,
}

impl Model {
    fn code(self) -> u32 {
        match self {
            Model::ContextualFunction => 1,
            Model::Grid => 2,
            Model::Dartboard => 3,
            Model::Trivial => 4,
        }
    }

    fn from_code(code: u32) -> Option<Self> {
        [Model::ContextualFunction, Model::Grid, Model::Dartboard, Model::Trivial]
            .into_iter()
            .find(|m| m.code() == code)
    }
}

/// The spec of the contextual function with `n_s` context and `n_theta` parameter dimensions
/// whose matrix A comes from `problem_seed`.
pub fn contextual_function(n_s: usize, n_theta: usize, problem_seed: u64) -> EnvironmentSpec {
    EnvironmentSpec {
        model: Model::ContextualFunction.code(),
        options: [n_s as u32, n_theta as u32, 0],
        problem_seed,
    }
}

/// The spec of a throwing problem.
pub fn throwing(model: Model, sim: Sim) -> EnvironmentSpec {
    let sim = match sim {
        Sim::Analytic => 0,
        Sim::Rapier => 1,
    };
    EnvironmentSpec {
        model: model.code(),
        options: [sim, 0, 0],
        problem_seed: 0,
    }
}

/// For a dartboard spec, the same throws scored against any target as on the grid (reward
/// -||s - b||^2): the dartboard's reward is defined at field centres only. `None` for other
/// specs.
pub fn free_targets(spec: &EnvironmentSpec) -> Option<EnvironmentSpec> {
    (Model::from_code(spec.model) == Some(Model::Dartboard)).then_some(EnvironmentSpec {
        model: Model::Grid.code(),
        ..*spec
    })
}

/// The spec of the trivial environment.
pub fn trivial() -> EnvironmentSpec {
    EnvironmentSpec {
        model: Model::Trivial.code(),
        options: [0; 3],
        problem_seed: 0,
    }
}

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
    /// A model code that names no model.
    #[error("environment spec: model must be 1 (function), 2 (grid), 3 (dartboard) or 4 (trivial), got {0}")]
    UnknownModel(u32),
    /// A simulator code that names no simulator.
    #[error("environment spec: simulator must be 0 (analytic) or 1 (rapier), got {0}")]
    UnknownSimulator(u32),
    /// The contextual function refuses the spec's dimensions.
    #[error(transparent)]
    ContextualFunction(#[from] ContextualFunctionCreateError),
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

/// Build the environment `spec` names.
pub fn build(spec: &EnvironmentSpec) -> Result<Box<dyn Environment>, EnvironmentBuildError> {
    let model = Model::from_code(spec.model).ok_or(EnvironmentBuildError::UnknownModel(spec.model))?;
    let sim = || match spec.options[0] {
        0 => Ok(Sim::Analytic),
        1 => Ok(Sim::Rapier),
        other => Err(EnvironmentBuildError::UnknownSimulator(other)),
    };
    Ok(match model {
        Model::ContextualFunction => {
            let [n_s, n_theta, _] = spec.options;
            Box::new(ContextualFunction::new(
                n_s as usize,
                n_theta as usize,
                spec.problem_seed,
            )?)
        }
        Model::Grid => Box::new(throwing_environment(sim()?, Targets::Grid)?),
        Model::Dartboard => Box::new(throwing_environment(sim()?, Targets::Dartboard(dartboard_fields()))?),
        Model::Trivial => Box::new(TrivialEnvironment),
    })
}

/// A rollout that costs nothing: reward -||theta||^2, score ||theta||^2.
pub struct TrivialEnvironment;

impl Environment for TrivialEnvironment {
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

    #[test]
    fn specs_build_the_environments_they_name() {
        let task = |theta: Vec<f64>, context: Vec<f64>| Task {
            id: 3,
            kind: TaskKind::Train,
            seed: 1,
            context,
            theta,
        };
        let mut function = build(&contextual_function(2, 20, 5)).unwrap();
        let direct = ContextualFunction::new(2, 20, 5).unwrap();
        let t = task(vec![0.1; 20], vec![0.5, -0.5]);
        assert_eq!(
            function.rollout(&t).reward,
            direct.evaluate(&t.theta, &t.context).unwrap().0
        );
        let mut grid = build(&throwing(Model::Grid, Sim::Analytic)).unwrap();
        assert!(grid.rollout(&task(vec![0.0; PARAMS], vec![-3.5, -3.5])).is_ok());
        let mut board = build(&throwing(Model::Dartboard, Sim::Analytic)).unwrap();
        let free = free_targets(&throwing(Model::Dartboard, Sim::Rapier)).unwrap();
        assert_eq!(free, throwing(Model::Grid, Sim::Rapier));
        assert_eq!(free_targets(&throwing(Model::Grid, Sim::Analytic)), None);
        let bull = dartboard_fields()[0].centre;
        assert_eq!(board.rollout(&task(vec![0.0; PARAMS], bull.to_vec())).reward, 0.0);
        assert_eq!(
            build(&trivial())
                .unwrap()
                .rollout(&task(vec![3.0, 4.0], vec![0.0]))
                .reward,
            -25.0
        );
    }

    #[test]
    fn bad_specs_name_the_field() {
        let error = build(&EnvironmentSpec {
            model: 9,
            options: [0; 3],
            problem_seed: 0,
        })
        .err()
        .unwrap()
        .to_string();
        assert!(error.contains("model must be 1 (function)"), "{error}");
        let error = build(&EnvironmentSpec {
            model: 2,
            options: [7, 0, 0],
            problem_seed: 0,
        })
        .err()
        .unwrap()
        .to_string();
        assert!(
            error.contains("simulator must be 0 (analytic) or 1 (rapier), got 7"),
            "{error}"
        );
        assert!(build(&contextual_function(3, 2, 0)).is_err(), "n_theta must exceed n_s");
    }
}
