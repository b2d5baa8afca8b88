//! The fixed-size payloads that cross shared memory between the learner and its workers.
//!
//! Both are `#[repr(C)]`, free of pointers and `Drop`, and carry a stable type name, so that every
//! process of one build agrees on them. A worker announces the protocol version and the run's
//! identity in every message; the learner refuses mismatches instead of mixing them in.
//!
//! Messages are batches: a worker's request carries the outcomes of up to [`MAX_BATCH`] tasks
//! and asks for up to as many new ones, and the learner answers with every ready task it may
//! give, so cheap rollouts pay the per-message cost (a shared-memory hand-over, a wake-up) once
//! per batch instead of once per task. An answer is an [`Answer`] header over a slice of exactly
//! the tasks it carries, written in place in shared memory.

use crate::secret::{RunSecret, SECRET_BYTES};
use acps_shared::{EnvironmentSpec, MAX_NAME, Outcome, OutcomeStatus, Serves, SpecBuildError, Task, TaskKind};
use iceoryx2::prelude::ZeroCopySend;
use std::time::Duration;

/// Version of this wire format; bump on any change to the payloads or their meaning.
pub const PROTOCOL_VERSION: u32 = 10;
/// Largest context a task can carry (docs/CHOICES.md: why 8).
pub const MAX_CONTEXT: usize = 8;
/// Largest parameter vector a task can carry.
pub const MAX_THETA: usize = 64;
/// Largest diagnostics vector an outcome can carry (docs/CHOICES.md: why 16).
pub const MAX_DIAGNOSTICS: usize = 16;
/// Most tasks one answer carries, and most outcomes one request carries.
pub const MAX_BATCH: usize = 64;
/// Most bytes of an environment's settings text a request or a refusal carries: enough to show
/// which setting differs, not a copy (the hash decides; the text is for people).
pub const MAX_SETTINGS_TEXT: usize = 256;

/// The settings text this process hashed into `spec` (none known: length 0), as a message
/// carries it: its length in bytes and its first [`MAX_SETTINGS_TEXT`] bytes, cut at a
/// character boundary.
fn settings_text(spec: Option<EnvironmentSpec>) -> (u32, [u8; MAX_SETTINGS_TEXT]) {
    let mut bytes = [0; MAX_SETTINGS_TEXT];
    let Some(text) = spec.and_then(|spec| spec.settings_text()) else {
        return (0, bytes);
    };
    let mut end = text.len().min(MAX_SETTINGS_TEXT);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    bytes[..end].copy_from_slice(&text.as_bytes()[..end]);
    (u32::try_from(text.len()).unwrap_or(u32::MAX), bytes)
}

/// `serves` in words, with the settings text this process knows for its environment: how a
/// worker names what it serves when it is refused.
pub fn serves_shown(serves: &Serves) -> String {
    match serves {
        Serves::One(spec) => {
            let (len, bytes) = settings_text(Some(*spec));
            format!("{serves}{}", shown_settings_text(len, &bytes))
        }
        Serves::Any => serves.to_string(),
    }
}

/// A settings text as a message carried it, for people: ` = "TEXT"`, or ` = "START..." (N
/// bytes)` when it was longer than the message holds; empty when the sender knew none.
fn shown_settings_text(len: u32, bytes: &[u8; MAX_SETTINGS_TEXT]) -> String {
    if len == 0 {
        return String::new();
    }
    let carried = bytes.iter().position(|&b| b == 0).unwrap_or(MAX_SETTINGS_TEXT);
    let text = String::from_utf8_lossy(&bytes[..carried.min(len as usize)]);
    if len as usize > carried {
        format!(" = {:?}... ({len} bytes)", text.as_ref())
    } else {
        format!(" = {:?}", text.as_ref())
    }
}

/// An [`EnvironmentSpec`] as it crosses the wire (all zeros: none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WireEnvironment")]
pub struct WireEnvironment {
    /// [`EnvironmentSpec::name`], padded with zeros.
    pub name: [u8; MAX_NAME],
    /// [`EnvironmentSpec::settings`].
    pub settings: u64,
    /// [`EnvironmentSpec::parameters`].
    pub parameters: [u64; 3],
}

impl From<EnvironmentSpec> for WireEnvironment {
    fn from(spec: EnvironmentSpec) -> Self {
        Self {
            name: spec.padded_name(),
            settings: spec.settings(),
            parameters: spec.parameters(),
        }
    }
}

impl TryFrom<WireEnvironment> for EnvironmentSpec {
    type Error = SpecBuildError;

    /// The spec, unless the name is not one (a corrupt message).
    fn try_from(wire: WireEnvironment) -> Result<Self, SpecBuildError> {
        EnvironmentSpec::from_parts(&wire.name, wire.settings, wire.parameters)
    }
}

/// What an answer to a worker means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Response {
    /// Tasks to perform.
    Task = 1,
    /// The run is over: stop.
    Stop = 2,
    /// The worker belongs to another run or build, or serves none of the run's environments:
    /// stop and say why.
    Refused = 3,
}

/// Why the learner refused a worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Refusal {
    /// Another protocol version: another build.
    Protocol = 1,
    /// Another run identity.
    Run = 2,
    /// The worker serves none of the environments the run's jobs need.
    Environment = 3,
    /// The worker declared context or parameter lengths other than its jobs'.
    Sizes = 4,
    /// The worker's messages do not carry the run's secret.
    Secret = 5,
}

/// The lengths of a problem's contexts and parameters: what a worker may declare it serves,
/// and what a job's tasks carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Sizes {
    /// Values of a context (n_s).
    pub context: usize,
    /// Values of the parameters (n_theta).
    pub theta: usize,
}

impl std::fmt::Display for Sizes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "contexts of {} and parameters of {} values",
            self.context, self.theta
        )
    }
}

/// One task of an answer.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WireTask")]
pub struct WireTask {
    /// The learner's [`TaskKind`] (0 train, 1 evaluate, 2 baseline).
    pub kind: u32,
    /// Which learner (method x run) of the experiment the task belongs to.
    pub job: u32,
    /// Number of valid entries of `context`.
    pub context_len: u32,
    /// Number of valid entries of `theta`.
    pub theta_len: u32,
    /// The task's id within its job.
    pub task_id: u64,
    /// Seed of everything random inside the rollout.
    pub seed: u64,
    /// The environment to perform it in.
    pub environment: WireEnvironment,
    /// The context.
    pub context: [f64; MAX_CONTEXT],
    /// The parameters.
    pub theta: [f64; MAX_THETA],
}

/// The header of the learner's answer to a worker's request; the answer's payload is the slice of
/// tasks it hands out (none for `Stop` and `Refused`). iceoryx2 starts a header from `Default`
/// (an unknown response) before the learner writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::Answer")]
pub struct Answer {
    /// A [`Response`].
    pub response: u32,
    /// The learner's protocol version.
    pub protocol: u32,
    /// The learner's run identity.
    pub run: u64,
    /// For `Refused`, a [`Refusal`]; else 0.
    pub refusal: u32,
    /// How many environments the learner's jobs need.
    pub environments: u32,
    /// For `Refused`, one of them: the first with the worker's environment's name, if any.
    pub environment: WireEnvironment,
    /// For a [`Refusal::Sizes`], the context length the worker's jobs need; else 0.
    pub context_len: u32,
    /// For a [`Refusal::Sizes`], the parameter length the worker's jobs need; else 0.
    pub theta_len: u32,
    /// For a refusal, the length in bytes of `environment`'s settings text, 0 when the learner
    /// knows none.
    pub settings_text_len: u32,
    /// Padding, always 0.
    pub reserved: u32,
    /// Its first bytes (UTF-8, zero-padded), for the worker to show beside its own.
    pub settings_text: [u8; MAX_SETTINGS_TEXT],
}

/// One outcome of a [`WorkerMessage`].
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WireOutcome")]
pub struct WireOutcome {
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

/// What a worker sends: a request for up to `want` tasks, carrying the outcomes of tasks it
/// performed.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("acps::WorkerMessage")]
pub struct WorkerMessage {
    /// The worker's [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// How many tasks the worker asks for, 0..=[`MAX_BATCH`]; 0 only delivers outcomes and is
    /// answered at once.
    pub want: u32,
    /// The run the worker means to join.
    pub run: u64,
    /// The run's secret ([`crate::secret`]); zeros when the worker has none.
    pub secret: [u8; SECRET_BYTES],
    /// Number of valid entries of `outcomes`.
    pub count: u32,
    /// The worker's slowest rollout so far, in microseconds (saturating): the learner waits at
    /// least a few times this long for a silent worker before it hands its tasks to others.
    pub slowest_rollout_us: u32,
    /// 1: the worker serves `environment` only; 0: any environment its factory builds.
    pub serves_one: u32,
    /// The context length the worker serves, 0 when it does not say (then `theta_len` is 0
    /// too): the learner refuses a worker whose declared lengths are not its jobs'.
    pub context_len: u32,
    /// The parameter length the worker serves (with a non-zero `context_len`).
    pub theta_len: u32,
    /// The length in bytes of `environment`'s settings text, 0 when the worker knows none (it
    /// was given only the hash) or serves any environment.
    pub settings_text_len: u32,
    /// The environment a worker that serves one serves (zeros otherwise).
    pub environment: WireEnvironment,
    /// The first bytes of its settings text (UTF-8, zero-padded), for the learner to show
    /// beside its own when it refuses the worker.
    pub settings_text: [u8; MAX_SETTINGS_TEXT],
    /// The outcomes.
    pub outcomes: [WireOutcome; MAX_BATCH],
}

/// A task or outcome that does not fit the fixed capacities.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} has {len} values, the wire carries at most {max} ({limit})")]
pub struct CapacityError {
    /// What overflowed.
    pub what: &'static str,
    /// Its length.
    pub len: usize,
    /// The capacity.
    pub max: usize,
    /// The capacity's name in this module.
    pub limit: &'static str,
}

/// A part of a task or an outcome with a capacity: what it is, and the capacity's name.
struct Part {
    what: &'static str,
    limit: &'static str,
}

const CONTEXT: Part = Part {
    what: "a task's context",
    limit: "MAX_CONTEXT",
};
const THETA: Part = Part {
    what: "a task's theta",
    limit: "MAX_THETA",
};
const DIAGNOSTICS: Part = Part {
    what: "an outcome's diagnostics",
    limit: "MAX_DIAGNOSTICS",
};

/// Refuse `len` values of `part` beyond its capacity `max`.
fn check_capacity(part: Part, len: usize, max: usize) -> Result<(), CapacityError> {
    if len > max {
        return Err(CapacityError {
            what: part.what,
            len,
            max,
            limit: part.limit,
        });
    }
    Ok(())
}

fn fit<const N: usize>(part: Part, values: &[f64]) -> Result<([f64; N], u32), CapacityError> {
    check_capacity(part, values.len(), N)?;
    let mut array = [0.0; N];
    array[..values.len()].copy_from_slice(values);
    Ok((array, values.len() as u32))
}

/// Refuse tasks with contexts of `context` values or parameters of `theta` values when the wire
/// cannot carry them: the check a learner's tasks pass before any is handed out.
pub fn check_task_sizes(context: usize, theta: usize) -> Result<(), CapacityError> {
    check_capacity(CONTEXT, context, MAX_CONTEXT)?;
    check_capacity(THETA, theta, MAX_THETA)
}

/// A task kind's code on the wire, also in the Python package's arrays: 0 train, 1 evaluate, 2
/// baseline.
pub fn kind_code(kind: TaskKind) -> u32 {
    match kind {
        TaskKind::Train => 0,
        TaskKind::Evaluate => 1,
        TaskKind::Baseline => 2,
    }
}

/// The batch is full (at most [`MAX_BATCH`] entries).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a batch carries at most {MAX_BATCH} entries")]
pub struct BatchFull;

impl WireTask {
    /// A task of `job` to perform in `environment`.
    pub fn new(job: u32, task: &Task, environment: EnvironmentSpec) -> Result<Self, CapacityError> {
        let (context, context_len) = fit::<MAX_CONTEXT>(CONTEXT, &task.context)?;
        let (theta, theta_len) = fit::<MAX_THETA>(THETA, &task.theta)?;
        Ok(Self {
            kind: kind_code(task.kind),
            job,
            context_len,
            theta_len,
            task_id: task.id,
            seed: task.seed,
            environment: environment.into(),
            context,
            theta,
        })
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

/// All zeros: an unknown response (a `Default` derive stops at arrays of 32).
impl Default for Answer {
    fn default() -> Self {
        Self {
            response: 0,
            protocol: 0,
            run: 0,
            refusal: 0,
            environments: 0,
            environment: WireEnvironment::default(),
            context_len: 0,
            theta_len: 0,
            settings_text_len: 0,
            reserved: 0,
            settings_text: [0; MAX_SETTINGS_TEXT],
        }
    }
}

impl Answer {
    /// A `response` of this build from the learner of run identity `run`.
    pub fn new(response: Response, run: u64) -> Self {
        Self {
            response: response as u32,
            protocol: PROTOCOL_VERSION,
            run,
            ..Self::default()
        }
    }

    /// A refusal for `refusal` by the learner of run identity `run`, whose jobs need
    /// `environments` environments, `environment` among them (`None` when they need none).
    pub fn refused(refusal: Refusal, run: u64, environment: Option<EnvironmentSpec>, environments: usize) -> Self {
        let (settings_text_len, settings_text) = settings_text(environment);
        Self {
            refusal: refusal as u32,
            environments: u32::try_from(environments).unwrap_or(u32::MAX),
            environment: environment.map(WireEnvironment::from).unwrap_or_default(),
            settings_text_len,
            settings_text,
            ..Self::new(Response::Refused, run)
        }
    }

    /// Why the learner refused, `None` for an unknown code (or no refusal).
    pub fn refusal(&self) -> Option<Refusal> {
        match self.refusal {
            1 => Some(Refusal::Protocol),
            2 => Some(Refusal::Run),
            3 => Some(Refusal::Environment),
            4 => Some(Refusal::Sizes),
            5 => Some(Refusal::Secret),
            _ => None,
        }
    }

    /// A sizes refusal for a worker whose jobs need `needed`, by the learner of run identity
    /// `run`.
    pub fn refused_sizes(run: u64, needed: Sizes) -> Self {
        Self {
            context_len: u32::try_from(needed.context).unwrap_or(u32::MAX),
            theta_len: u32::try_from(needed.theta).unwrap_or(u32::MAX),
            ..Self::refused(Refusal::Sizes, run, None, 0)
        }
    }

    /// The lengths a sizes refusal says the worker's jobs need.
    pub fn needed_sizes(&self) -> Sizes {
        Sizes {
            context: self.context_len as usize,
            theta: self.theta_len as usize,
        }
    }

    /// The environment a refusal names, `None` when the learner named none.
    pub fn environment(&self) -> Option<EnvironmentSpec> {
        EnvironmentSpec::try_from(self.environment).ok()
    }

    /// What a refusal says the learner's jobs need, in words: the environment it names and how
    /// many others.
    pub fn needs(&self) -> String {
        let text = shown_settings_text(self.settings_text_len, &self.settings_text);
        match (self.environment(), self.environments) {
            (None, _) => "no environment".to_string(),
            (Some(spec), 0 | 1) => format!("{spec}{text}"),
            (Some(spec), 2) => format!("{spec}{text} and 1 other"),
            (Some(spec), n) => format!("{spec}{text} and {} others", n - 1),
        }
    }

    /// The answer's kind, `None` for an unknown code.
    pub fn response(&self) -> Option<Response> {
        match self.response {
            1 => Some(Response::Task),
            2 => Some(Response::Stop),
            3 => Some(Response::Refused),
            _ => None,
        }
    }
}

impl WireOutcome {
    /// `job`'s outcome. Diagnostics beyond the capacity are an error rather than silently cut.
    pub fn new(job: u32, outcome: &Outcome) -> Result<Self, CapacityError> {
        let (diagnostics, diagnostics_len) = fit::<MAX_DIAGNOSTICS>(DIAGNOSTICS, &outcome.diagnostics)?;
        Ok(Self {
            job,
            ok: u32::from(outcome.is_ok()),
            task_id: outcome.task_id,
            reward: outcome.reward,
            score: outcome.score,
            diagnostics_len,
            reserved: 0,
            diagnostics,
        })
    }

    /// The job and the outcome. One marked ok with non-finite numbers becomes a failed outcome
    /// (`Outcome::new` checks), so a NaN cannot sneak in through the wire.
    pub fn to_outcome(&self) -> (u32, Outcome) {
        let diagnostics = self.diagnostics[..(self.diagnostics_len as usize).min(MAX_DIAGNOSTICS)].to_vec();
        let outcome = if self.ok == 1 {
            Outcome::new(self.task_id, self.reward, self.score).with_diagnostics(diagnostics)
        } else {
            Outcome {
                status: OutcomeStatus::Failed,
                ..Outcome::failed(self.task_id)
            }
        };
        (self.job, outcome)
    }
}

impl WorkerMessage {
    /// A request for `want` tasks (at most [`MAX_BATCH`]) without outcomes, from a worker that
    /// means to join `run` (0: whatever runs) and `serves` these environments.
    pub fn request(run: u64, want: usize, serves: Serves) -> Self {
        const EMPTY: WireOutcome = WireOutcome {
            job: 0,
            ok: 0,
            task_id: 0,
            reward: 0.0,
            score: 0.0,
            diagnostics_len: 0,
            reserved: 0,
            diagnostics: [0.0; MAX_DIAGNOSTICS],
        };
        let spec = match serves {
            Serves::One(spec) => Some(spec),
            Serves::Any => None,
        };
        let (settings_text_len, settings_text) = settings_text(spec);
        Self {
            protocol: PROTOCOL_VERSION,
            want: want.min(MAX_BATCH) as u32,
            run,
            secret: [0; SECRET_BYTES],
            count: 0,
            slowest_rollout_us: 0,
            serves_one: u32::from(spec.is_some()),
            context_len: 0,
            theta_len: 0,
            settings_text_len,
            environment: spec.map(WireEnvironment::from).unwrap_or_default(),
            settings_text,
            outcomes: [EMPTY; MAX_BATCH],
        }
    }

    /// The same request carrying the run's `secret`.
    pub fn carrying(mut self, secret: RunSecret) -> Self {
        self.secret = secret.bytes();
        self
    }

    /// The same request declaring that the worker serves `sizes` (contexts and parameters of
    /// these lengths).
    pub fn declaring(mut self, sizes: Sizes) -> Self {
        self.context_len = u32::try_from(sizes.context).unwrap_or(u32::MAX);
        self.theta_len = u32::try_from(sizes.theta).unwrap_or(u32::MAX);
        self
    }

    /// The lengths the worker declared it serves, `None` when it did not say.
    pub fn sizes(&self) -> Option<Sizes> {
        (self.context_len != 0).then_some(Sizes {
            context: self.context_len as usize,
            theta: self.theta_len as usize,
        })
    }

    /// What the worker serves in words: its environment with the settings text it sent.
    pub fn serves_shown(&self) -> String {
        match self.serves() {
            Ok(serves @ Serves::One(_)) => {
                format!(
                    "{serves}{}",
                    shown_settings_text(self.settings_text_len, &self.settings_text)
                )
            }
            Ok(serves) => serves.to_string(),
            Err(error) => error.to_string(),
        }
    }

    /// The environments the worker serves, or why its message does not say.
    pub fn serves(&self) -> Result<Serves, SpecBuildError> {
        match self.serves_one {
            0 => Ok(Serves::Any),
            _ => EnvironmentSpec::try_from(self.environment).map(Serves::One),
        }
    }

    /// Add an outcome.
    pub fn push(&mut self, outcome: WireOutcome) -> Result<(), BatchFull> {
        let slot = self.outcomes.get_mut(self.count as usize).ok_or(BatchFull)?;
        *slot = outcome;
        self.count += 1;
        Ok(())
    }

    /// The outcomes it carries (the count is clamped to the capacity).
    pub fn outcomes(&self) -> impl Iterator<Item = (u32, Outcome)> + '_ {
        self.outcomes[..(self.count as usize).min(MAX_BATCH)]
            .iter()
            .map(WireOutcome::to_outcome)
    }

    /// Tasks asked for, at most [`MAX_BATCH`].
    pub fn wanted(&self) -> usize {
        (self.want as usize).min(MAX_BATCH)
    }

    /// The worker's slowest rollout so far.
    pub fn slowest_rollout(&self) -> Duration {
        Duration::from_micros(self.slowest_rollout_us.into())
    }

    /// Record `rollout` if it is the slowest so far.
    pub fn observe_rollout(&mut self, rollout: Duration) {
        let us = u32::try_from(rollout.as_micros()).unwrap_or(u32::MAX);
        self.slowest_rollout_us = self.slowest_rollout_us.max(us);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> EnvironmentSpec {
        EnvironmentSpec::new("throw-grid", [1, 0, 0], &0.008).unwrap()
    }

    #[test]
    fn tasks_and_outcomes_survive_the_wire() {
        let task = Task {
            id: 42,
            kind: TaskKind::Evaluate,
            seed: 7,
            context: vec![-3.5, -4.0],
            theta: (0..21).map(f64::from).collect(),
        };
        let wire = WireTask::new(5, &task, spec()).unwrap();
        assert_eq!((wire.job, EnvironmentSpec::try_from(wire.environment)), (5, Ok(spec())));
        assert_eq!(wire.to_task(), task);
        let outcome = Outcome::new(42, -1.5, 12.0).with_diagnostics(vec![-3.4, -4.1]);
        let mut message = WorkerMessage::request(11, 4, Serves::One(spec()));
        assert_eq!(message.serves(), Ok(Serves::One(spec())));
        assert_eq!(message.outcomes().count(), 0);
        message.push(WireOutcome::new(5, &outcome).unwrap()).unwrap();
        message
            .push(WireOutcome::new(6, &Outcome::failed(43)).unwrap())
            .unwrap();
        let received: Vec<_> = message.outcomes().collect();
        assert_eq!(received[0], (5, outcome));
        assert_eq!(
            (received[1].0, received[1].1.task_id, received[1].1.is_ok()),
            (6, 43, false)
        );
        assert_eq!(message.wanted(), 4);
    }

    #[test]
    fn batches_are_bounded_and_clamped() {
        let mut message = WorkerMessage::request(0, 0, Serves::Any);
        assert_eq!(message.serves(), Ok(Serves::Any));
        assert_eq!(message.wanted(), 0, "a request may only deliver outcomes");
        assert_eq!(WorkerMessage::request(0, 1000, Serves::Any).wanted(), MAX_BATCH);
        for id in 0..MAX_BATCH as u64 {
            message
                .push(WireOutcome::new(0, &Outcome::new(id, 0.0, 0.0)).unwrap())
                .unwrap();
        }
        assert_eq!(
            message.push(WireOutcome::new(0, &Outcome::new(99, 0.0, 0.0)).unwrap()),
            Err(BatchFull)
        );
        // A corrupt count cannot make the learner read beyond the array.
        message.count = u32::MAX;
        assert_eq!(message.outcomes().count(), MAX_BATCH);
        for response in [Response::Task, Response::Stop, Response::Refused] {
            let answer = Answer::new(response, 7);
            assert_eq!(
                (answer.response(), answer.protocol, answer.run),
                (Some(response), PROTOCOL_VERSION, 7)
            );
        }
        let unknown = Answer {
            response: 9,
            ..Answer::new(Response::Task, 7)
        };
        assert_eq!(unknown.response(), None);
    }

    #[test]
    fn refusals_say_why_and_name_an_environment() {
        let answer = Answer::refused(Refusal::Environment, 7, Some(spec()), 3);
        assert_eq!(
            (
                answer.response(),
                answer.refusal(),
                answer.environment(),
                answer.environments
            ),
            (Some(Response::Refused), Some(Refusal::Environment), Some(spec()), 3)
        );
        assert_eq!(answer.needs(), format!("{} = \"0.008\" and 2 others", spec()));
        let none = Answer::refused(Refusal::Run, 7, None, 0);
        assert_eq!((none.refusal(), none.environment()), (Some(Refusal::Run), None));
        assert_eq!(none.needs(), "no environment");
        assert_eq!(Answer::new(Response::Task, 7).refusal(), None);
        // A name that is none (a corrupt message) is an error, not a spec.
        let mut message = WorkerMessage::request(0, 1, Serves::One(spec()));
        message.environment.name[0] = b' ';
        assert!(message.serves().is_err());
    }

    #[test]
    fn settings_texts_cross_in_requests_and_refusals_and_long_ones_are_shown_cut() {
        // A worker's text reaches the learner, and the learner's the worker.
        let worker = EnvironmentSpec::from_text("arm", [0; 3], "dt = 0.01").unwrap();
        let request = WorkerMessage::request(0, 1, Serves::One(worker));
        assert_eq!(request.serves_shown(), format!("{worker} = \"dt = 0.01\""));
        assert_eq!(serves_shown(&Serves::One(worker)), request.serves_shown());
        let needed = EnvironmentSpec::from_text("arm", [0; 3], "dt = 0.02").unwrap();
        let refusal = Answer::refused(Refusal::Environment, 7, Some(needed), 1);
        assert_eq!(refusal.needs(), format!("{needed} = \"dt = 0.02\""));
        // A spec known only by its hash has no text to show.
        let hashed = EnvironmentSpec::from_parts(b"arm", 0x5eed, [0; 3]).unwrap();
        assert_eq!(
            Answer::refused(Refusal::Environment, 7, Some(hashed), 1).needs(),
            hashed.to_string()
        );
        assert_eq!(
            WorkerMessage::request(0, 1, Serves::Any).serves_shown(),
            Serves::Any.to_string()
        );
        // A longer text: its start, cut at a character boundary (the 2-byte 'é' straddles the
        // capacity), and its length.
        let long = format!("{}é{}", "a".repeat(MAX_SETTINGS_TEXT - 1), "b".repeat(100));
        let spec = EnvironmentSpec::from_text("arm", [0; 3], &long).unwrap();
        let shown = WorkerMessage::request(0, 1, Serves::One(spec)).serves_shown();
        assert_eq!(
            shown,
            format!(
                "{spec} = \"{}\"... ({} bytes)",
                "a".repeat(MAX_SETTINGS_TEXT - 1),
                long.len()
            )
        );
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
        let error = WireTask::new(0, &task, spec()).unwrap_err();
        assert_eq!(
            error.to_string(),
            "a task's context has 9 values, the wire carries at most 8 (MAX_CONTEXT)"
        );
        assert_eq!(check_task_sizes(MAX_CONTEXT, MAX_THETA), Ok(()));
        assert_eq!(check_task_sizes(MAX_CONTEXT + 1, 0), Err(error));
        let error = check_task_sizes(1, MAX_THETA + 1).unwrap_err();
        assert_eq!(
            error.to_string(),
            "a task's theta has 65 values, the wire carries at most 64 (MAX_THETA)"
        );
        let mut wire = WireOutcome::new(0, &Outcome::new(3, 1.0, 1.0)).unwrap();
        wire.reward = f64::NAN;
        assert!(!wire.to_outcome().1.is_ok());
        assert!(!WireOutcome::new(0, &Outcome::failed(4)).unwrap().to_outcome().1.is_ok());
        let most = Outcome::new(5, 0.0, 0.0).with_diagnostics((0..MAX_DIAGNOSTICS).map(|d| d as f64).collect());
        assert_eq!(WireOutcome::new(0, &most).unwrap().to_outcome().1, most);
        let too_many = Outcome::new(5, 0.0, 0.0).with_diagnostics(vec![0.0; MAX_DIAGNOSTICS + 1]);
        assert_eq!(
            WireOutcome::new(0, &too_many).unwrap_err().to_string(),
            "an outcome's diagnostics has 17 values, the wire carries at most 16 (MAX_DIAGNOSTICS)"
        );
    }

    #[test]
    fn declared_sizes_cross_in_requests_and_refusals() {
        let sizes = Sizes { context: 2, theta: 21 };
        assert_eq!(WorkerMessage::request(0, 1, Serves::Any).sizes(), None);
        assert_eq!(
            WorkerMessage::request(0, 1, Serves::Any).declaring(sizes).sizes(),
            Some(sizes)
        );
        let refusal = Answer::refused_sizes(7, sizes);
        assert_eq!(
            (refusal.response(), refusal.refusal(), refusal.needed_sizes()),
            (Some(Response::Refused), Some(Refusal::Sizes), sizes)
        );
        assert_eq!(sizes.to_string(), "contexts of 2 and parameters of 21 values");
    }

    #[test]
    fn the_payloads_have_the_sizes_docs_choices_gives() {
        use std::mem::size_of;
        assert_eq!(size_of::<WireEnvironment>(), 64);
        assert_eq!(size_of::<WireTask>(), 672);
        assert_eq!(size_of::<WireOutcome>(), 168);
        assert_eq!(size_of::<WorkerMessage>(), 11_128);
        assert_eq!(size_of::<Answer>(), 360);
    }
}
