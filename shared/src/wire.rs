//! The fixed-size payloads that cross shared memory between the learner and its workers.
//!
//! Both are `#[repr(C)]`, free of pointers and `Drop`, and carry a stable type name, so that every
//! process of one build agrees on them. A worker announces the protocol version and the run's
//! identity in every message; the learner refuses mismatches instead of mixing them in.

use crate::{Outcome, OutcomeStatus, Task, TaskKind};
use iceoryx2::prelude::ZeroCopySend;

/// Version of this wire format; bump on any change to the payloads or their meaning.
pub const PROTOCOL_VERSION: u32 = 1;
/// Largest context a task can carry.
pub const MAX_CONTEXT: usize = 8;
/// Largest parameter vector a task can carry.
pub const MAX_THETA: usize = 64;
/// Largest diagnostics vector an outcome can carry.
pub const MAX_DIAGNOSTICS: usize = 4;

/// Which environment a task needs: workers build environments from this and cache them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[repr(C)]
pub struct EnvironmentSpec {
    /// The model (see `acps_models::environment`).
    pub model: u32,
    /// Model-specific small integers (for example the simulator, context dimension, n_theta).
    pub options: [u32; 3],
    /// Seed of the problem instance (for example the contextual function's matrix A).
    pub problem_seed: u64,
}

/// What a response to a worker means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Response {
    /// A task to perform.
    Task = 1,
    /// The run is over: stop.
    Stop = 2,
    /// The worker belongs to another run or build: stop and say why.
    Refused = 3,
}

/// The learner's answer to a worker's request.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WireTask")]
pub struct WireTask {
    /// A [`Response`].
    pub response: u32,
    /// The learner's [`TaskKind`] (0 train, 1 evaluate, 2 baseline).
    pub kind: u32,
    /// Which learner (method x run) of the experiment the task belongs to.
    pub job: u32,
    /// Number of valid entries of `context`.
    pub context_len: u32,
    /// The task's id within its job.
    pub task_id: u64,
    /// Seed of everything random inside the rollout.
    pub seed: u64,
    /// The environment to perform it in.
    pub environment: EnvironmentSpec,
    /// Number of valid entries of `theta`.
    pub theta_len: u32,
    /// With `Refused`: the learner's protocol version.
    pub protocol: u32,
    /// With `Refused`: the learner's run identity.
    pub run: u64,
    /// The context.
    pub context: [f64; MAX_CONTEXT],
    /// The parameters.
    pub theta: [f64; MAX_THETA],
}

/// What a worker sends: a request for work, carrying the outcome of its previous task if any.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WorkerMessage")]
pub struct WorkerMessage {
    /// The worker's [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// 1 when the outcome fields are valid.
    pub has_outcome: u32,
    /// The run the worker means to join.
    pub run: u64,
    /// The outcome's job.
    pub job: u32,
    /// 1 for an ok outcome, 0 for a failed one.
    pub ok: u32,
    /// The outcome's task id.
    pub task_id: u64,
    /// The return.
    pub reward: f64,
    /// The score.
    pub score: f64,
    /// Number of valid entries of `diagnostics`.
    pub diagnostics_len: u32,
    /// Padding, always 0.
    pub reserved: u32,
    /// The diagnostics.
    pub diagnostics: [f64; MAX_DIAGNOSTICS],
}

/// A task or outcome that does not fit the fixed capacities.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} has {len} values, the wire carries at most {max}")]
pub struct CapacityError {
    /// What overflowed.
    pub what: &'static str,
    /// Its length.
    pub len: usize,
    /// The capacity.
    pub max: usize,
}

fn fit<const N: usize>(what: &'static str, values: &[f64]) -> Result<([f64; N], u32), CapacityError> {
    if values.len() > N {
        return Err(CapacityError {
            what,
            len: values.len(),
            max: N,
        });
    }
    let mut array = [0.0; N];
    array[..values.len()].copy_from_slice(values);
    Ok((array, values.len() as u32))
}

fn kind_code(kind: TaskKind) -> u32 {
    match kind {
        TaskKind::Train => 0,
        TaskKind::Evaluate => 1,
        TaskKind::Baseline => 2,
    }
}

impl WireTask {
    /// A task of `job` to perform in `environment`.
    pub fn task(job: u32, task: &Task, environment: EnvironmentSpec) -> Result<Self, CapacityError> {
        let (context, context_len) = fit::<MAX_CONTEXT>("a task's context", &task.context)?;
        let (theta, theta_len) = fit::<MAX_THETA>("a task's theta", &task.theta)?;
        Ok(Self {
            response: Response::Task as u32,
            kind: kind_code(task.kind),
            job,
            context_len,
            task_id: task.id,
            seed: task.seed,
            environment,
            theta_len,
            protocol: PROTOCOL_VERSION,
            run: 0,
            context,
            theta,
        })
    }

    /// A response without a task: `Stop`, or `Refused` carrying the learner's identity.
    pub fn control(response: Response, run: u64) -> Self {
        Self {
            response: response as u32,
            kind: 0,
            job: 0,
            context_len: 0,
            task_id: 0,
            seed: 0,
            environment: EnvironmentSpec {
                model: 0,
                options: [0; 3],
                problem_seed: 0,
            },
            theta_len: 0,
            protocol: PROTOCOL_VERSION,
            run,
            context: [0.0; MAX_CONTEXT],
            theta: [0.0; MAX_THETA],
        }
    }

    /// The response kind, `None` for an unknown code.
    pub fn response(&self) -> Option<Response> {
        match self.response {
            1 => Some(Response::Task),
            2 => Some(Response::Stop),
            3 => Some(Response::Refused),
            _ => None,
        }
    }

    /// The task it carries (lengths are clamped to the capacities, so a corrupt message cannot
    /// make the worker read out of bounds).
    pub fn to_task(&self) -> Task {
        let kind = match self.kind {
            1 => TaskKind::Evaluate,
            2 => TaskKind::Baseline,
            _ => TaskKind::Train,
        };
        Task {
            id: self.task_id,
            kind,
            seed: self.seed,
            context: self.context[..(self.context_len as usize).min(MAX_CONTEXT)].to_vec(),
            theta: self.theta[..(self.theta_len as usize).min(MAX_THETA)].to_vec(),
        }
    }
}

impl WorkerMessage {
    /// A request for work without an outcome.
    pub fn hello(run: u64) -> Self {
        Self {
            protocol: PROTOCOL_VERSION,
            has_outcome: 0,
            run,
            job: 0,
            ok: 0,
            task_id: 0,
            reward: 0.0,
            score: 0.0,
            diagnostics_len: 0,
            reserved: 0,
            diagnostics: [0.0; MAX_DIAGNOSTICS],
        }
    }

    /// A request for work carrying the outcome of `job`'s task. Diagnostics beyond the capacity
    /// are an error rather than silently cut.
    pub fn with_outcome(run: u64, job: u32, outcome: &Outcome) -> Result<Self, CapacityError> {
        let (diagnostics, diagnostics_len) = fit::<MAX_DIAGNOSTICS>("an outcome's diagnostics", &outcome.diagnostics)?;
        Ok(Self {
            has_outcome: 1,
            job,
            ok: u32::from(outcome.is_ok()),
            task_id: outcome.task_id,
            reward: outcome.reward,
            score: outcome.score,
            diagnostics_len,
            diagnostics,
            ..Self::hello(run)
        })
    }

    /// The outcome it carries, if any. A message marked ok with non-finite numbers becomes a
    /// failed outcome (`Outcome::new` checks), so a NaN cannot sneak in through the wire.
    pub fn outcome(&self) -> Option<(u32, Outcome)> {
        if self.has_outcome != 1 {
            return None;
        }
        let diagnostics = self.diagnostics[..(self.diagnostics_len as usize).min(MAX_DIAGNOSTICS)].to_vec();
        let outcome = if self.ok == 1 {
            Outcome::new(self.task_id, self.reward, self.score).with_diagnostics(diagnostics)
        } else {
            Outcome {
                status: OutcomeStatus::Failed,
                ..Outcome::failed(self.task_id)
            }
        };
        Some((self.job, outcome))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tasks_and_outcomes_survive_the_wire() {
        let task = Task {
            id: 42,
            kind: TaskKind::Evaluate,
            seed: 7,
            context: vec![-3.5, -4.0],
            theta: (0..21).map(f64::from).collect(),
        };
        let spec = EnvironmentSpec {
            model: 3,
            options: [1, 0, 0],
            problem_seed: 9,
        };
        let wire = WireTask::task(5, &task, spec).unwrap();
        assert_eq!(wire.response(), Some(Response::Task));
        assert_eq!((wire.job, wire.environment), (5, spec));
        assert_eq!(wire.to_task(), task);
        let outcome = Outcome::new(42, -1.5, 12.0).with_diagnostics(vec![-3.4, -4.1]);
        let message = WorkerMessage::with_outcome(11, 5, &outcome).unwrap();
        assert_eq!(message.outcome(), Some((5, outcome)));
        assert_eq!(WorkerMessage::hello(11).outcome(), None);
    }

    #[test]
    fn overflow_is_an_error_and_nan_stays_failed() {
        let task = Task {
            id: 0,
            kind: TaskKind::Train,
            seed: 0,
            context: vec![0.0; MAX_CONTEXT + 1],
            theta: vec![],
        };
        let error = WireTask::task(
            0,
            &task,
            EnvironmentSpec {
                model: 0,
                options: [0; 3],
                problem_seed: 0,
            },
        )
        .unwrap_err();
        assert_eq!(
            error.to_string(),
            "a task's context has 9 values, the wire carries at most 8"
        );
        let mut message = WorkerMessage::with_outcome(1, 0, &Outcome::new(3, 1.0, 1.0)).unwrap();
        message.reward = f64::NAN;
        assert!(!message.outcome().unwrap().1.is_ok());
        let failed = WorkerMessage::with_outcome(1, 0, &Outcome::failed(4)).unwrap();
        assert!(!failed.outcome().unwrap().1.is_ok());
    }
}
