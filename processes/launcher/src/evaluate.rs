//! `acps evaluate`: replay a learned policy greedily (its mean, exploration off) at chosen
//! targets or at the problem's test contexts, in the environment the run learned in.

use acps_experiments::experiment::Experiment;
use acps_experiments::paper::{self, Sim};
use acps_experiments::records::SavedPolicy;
use acps_experiments::settings::ExperimentFile;
use acps_learner::creps::RestoredPolicy;
use acps_models::benchmark::{self, Objective};
use acps_models::contextual_function;
use acps_models::environment;
use acps_models::rapier_sim::RapierConfig;
use acps_models::robot::Robot;
use acps_models::throw::{DARTBOARD_ENVIRONMENT, GRID_ENVIRONMENT, ThrowDesign, ThrowPolicy};
use acps_shared::{ContextSpace, Environment, EnvironmentSpec, Outcome, Stream, Task, TaskKind, derive_seed};
use anyhow::{Context, bail};
use std::path::Path;

/// One greedy rollout.
#[derive(Debug, Clone)]
pub struct Throw {
    /// The context (target).
    pub context: Vec<f64>,
    /// The parameters the policy chose.
    pub theta: Vec<f64>,
    /// What the environment returned.
    pub outcome: Outcome,
    /// A dartboard target off the field centres, scored as on the grid (reward -||s - b||^2).
    pub free_target: bool,
}

/// The greedy rollouts of a replay and their aggregate.
#[derive(Debug, Clone)]
pub struct Replay {
    /// One per context, in order.
    pub throws: Vec<Throw>,
    /// The problem's aggregate of the successful rollouts' scores (as the learner's evaluation
    /// computes it); `None` when every rollout failed.
    pub score: Option<f64>,
}

/// Parse `X,Y,...` into a context.
pub fn parse_target(text: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .map(|x| {
            let value: f64 = x
                .trim()
                .parse()
                .map_err(|_| format!("'{x}' in '{text}' is not a number; write the target as X,Y"))?;
            if value.is_finite() {
                Ok(value)
            } else {
                Err(format!("target coordinates must be finite, got '{x}' in '{text}'"))
            }
        })
        .collect()
}

/// `x,y,...` as typed on the command line.
fn coordinates(s: &[f64]) -> String {
    s.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",")
}

/// Refuse a policy of a problem file's problem: only the user's simulator performs its
/// rollouts.
pub fn check_simulated(saved: &SavedPolicy, path: &Path) -> anyhow::Result<()> {
    if saved.user_problem.is_some() {
        bail!(
            "{}: problem '{}' is a problem of your own, which acps cannot simulate; replay the policy in your simulator: its mean at context s is W^T phi(s) (this JSON file's policy.weights and policy.features; in Python, acps_worker.Policy.load(path).mean(context))",
            path.display(),
            saved.problem.name
        );
    }
    Ok(())
}

/// The environment the saved run learned in, as this build's experiment builds it for the run's
/// seed, after checking that the file's problem is the problem that experiment gives that run:
/// a file relabelled as another experiment, edited, or written by a build with other settings is
/// refused, naming the field that differs.
pub fn rebuild(saved: &SavedPolicy, path: &Path) -> anyhow::Result<Box<dyn Environment>> {
    let instance = (experiment_of(saved)
        .map_err(|(field, reason)| anyhow::anyhow!("{}: {field} {reason}", path.display()))?
        .instance)(saved.seed);
    let (problem, expected) = (&saved.problem, &instance.problem);
    let differs = |field: &str, ours: String, theirs: String| {
        anyhow::anyhow!(
            "{}: {field} is {ours}, but the {} experiment's run of seed {} has {theirs} (an edited file, or one written by another build)",
            path.display(),
            saved.experiment,
            saved.seed
        )
    };
    if problem.name != expected.name {
        return Err(differs(
            "problem.name",
            format!("{:?}", problem.name),
            format!("{:?}", expected.name),
        ));
    }
    let environment = instance
        .environment
        .context("the paper experiment has no environment in this process")?;
    problem
        .check_environment(environment.as_ref())
        .with_context(|| format!("{}: rebuilding the run's environment", path.display()))?;
    if problem.space != expected.space {
        return Err(differs(
            "problem.space",
            describe(&problem.space),
            describe(&expected.space),
        ));
    }
    for (field, ours, theirs) in [
        (
            "problem.training_contexts",
            &problem.training_contexts,
            &expected.training_contexts,
        ),
        ("problem.test_contexts", &problem.test_contexts, &expected.test_contexts),
    ] {
        if ours.len() != theirs.len() {
            return Err(differs(
                field,
                format!("{} contexts", ours.len()),
                format!("{}", theirs.len()),
            ));
        }
        if let Some(i) = (0..ours.len()).find(|&i| ours[i] != theirs[i]) {
            return Err(differs(
                &format!("{field}[{i}]"),
                format!("({})", coordinates(&ours[i])),
                format!("({})", coordinates(&theirs[i])),
            ));
        }
    }
    if problem.theta0 != expected.theta0 {
        return Err(differs(
            "problem.theta0",
            format!("{:?}", problem.theta0),
            format!("{:?}", expected.theta0),
        ));
    }
    if (problem.score, &problem.metric) != (expected.score, &expected.metric) {
        return Err(differs(
            "problem.score and metric",
            format!("{:?}, {:?}", problem.score, problem.metric),
            format!("{:?}, {:?}", expected.score, expected.metric),
        ));
    }
    Ok(environment)
}

/// The paper experiment that wrote `saved`, with the settings its environment's spec records
/// (the simulator; the function's n_s and n_theta), or the field that names none. The spec's
/// sizes are checked against the file's own before anything is built from them, so that a file
/// cannot make this process build an environment larger than the file.
fn experiment_of(saved: &SavedPolicy) -> Result<Experiment, (&'static str, String)> {
    let problem = &saved.problem;
    let spec = &problem.environment;
    let [first, n_theta, problem_seed] = spec.parameters();
    let options = ExperimentFile {
        runs: Some(1),
        ..Default::default()
    };
    let environment_name = |expected: &str| {
        if spec.name() == expected {
            Ok(())
        } else {
            Err((
                "problem.environment.name",
                format!(
                    "{:?} is not the {} experiment's environment {expected:?} (was the file's experiment or problem edited?)",
                    spec.name(),
                    saved.experiment
                ),
            ))
        }
    };
    match saved.experiment.as_str() {
        name @ ("grid" | "dartboard") => {
            environment_name(if name == "grid" { GRID_ENVIRONMENT } else { DARTBOARD_ENVIRONMENT })?;
            let sim = Sim::from_parameter(first).ok_or((
                "problem.environment.parameters",
                format!("[{first}, ..] must start with 0 (analytic) or 1 (rapier), the simulator"),
            ))?;
            Ok(if name == "grid" {
                paper::grid(sim, &options)
            } else {
                paper::dartboard(sim, &options)
            })
        }
        name @ ("function" | "dims") => {
            environment_name(contextual_function::ENVIRONMENT)?;
            let (n_s, dim, n) = (first, problem.context_dim(), problem.theta0.len());
            if (n_s, n_theta, problem_seed) != (dim as u64, n as u64, saved.seed) || n <= dim {
                return Err((
                    "problem.environment.parameters",
                    format!(
                        "[n_s, n_theta, problem seed] = [{n_s}, {n_theta}, {problem_seed}] must be the problem's context dimension {dim}, its n_theta {n} (theta0's entries, more than n_s) and the run's seed {}",
                        saved.seed
                    ),
                ));
            }
            let options = ExperimentFile {
                n_theta: Some(n),
                ..options
            };
            match name {
                "function" if dim == 2 => Ok(paper::function(&options)),
                "function" => Err((
                    "problem.space",
                    format!("must have 2 dimensions in the function experiment, got {dim}"),
                )),
                _ => Ok(paper::dims(dim, &options)),
            }
        }
        name @ ("sphere" | "rosenbrock") => {
            let objective = if name == "sphere" { Objective::Sphere } else { Objective::Rosenbrock };
            environment_name(objective.environment())?;
            let (n_s, dim, n) = (first, problem.context_dim(), problem.theta0.len());
            if (n_s, n_theta, problem_seed) != (dim as u64, n as u64, saved.seed) {
                return Err((
                    "problem.environment.parameters",
                    format!(
                        "[n_s, n_theta, problem seed] = [{n_s}, {n_theta}, {problem_seed}] must be the problem's context dimension {dim}, its n_theta {n} and the run's seed {}",
                        saved.seed
                    ),
                ));
            }
            Ok(paper::benchmark(objective, &options))
        }
        "toy" => Err((
            "experiment",
            "\"toy\" learns no policy (its Section 4 model has no parameters); policy files come from function, dims, grid, dartboard, sphere and rosenbrock".into(),
        )),
        other => Err((
            "experiment",
            format!(
                "must be one of function, dims, grid, dartboard, sphere, rosenbrock (the experiments acps simulates; a problem of your own has a user_problem field), got {other:?}"
            ),
        )),
    }
}

/// Refuse targets the saved problem cannot take: a wrong dimension or a point outside the
/// context space.
pub fn check_targets(saved: &SavedPolicy, targets: &[Vec<f64>]) -> anyhow::Result<()> {
    let problem = &saved.problem;
    for target in targets {
        if target.len() != problem.context_dim() {
            bail!(
                "--target {}: the {} problem's targets have {} coordinates",
                coordinates(target),
                problem.name,
                problem.context_dim()
            );
        }
        if !problem.space.contains(target) {
            bail!(
                "--target {}: outside the {} problem's context space, which takes {}",
                coordinates(target),
                problem.name,
                describe(&problem.space)
            );
        }
    }
    Ok(())
}

/// The space in words: the accepted range of a target.
fn describe(space: &ContextSpace) -> String {
    match space {
        ContextSpace::Box { low, high } => low
            .iter()
            .zip(high)
            .enumerate()
            .map(|(d, (l, h))| format!("coordinate {d} in [{l}, {h}]"))
            .collect::<Vec<_>>()
            .join(", "),
        ContextSpace::Ball { radius, .. } => format!("distance from the origin <= {radius}"),
    }
}

/// Throw `policy` greedily at `contexts` in `environment`, the one [`rebuild`] made for
/// `saved`. Task ids and seeds are the context's index and its
/// derived seed; the built-in environments of saved policies do not draw random numbers, so the
/// outcome depends on the context and the policy only. On the dartboard, whose reward exists at
/// field centres only, other targets get the grid's reward.
pub fn replay(
    saved: &SavedPolicy,
    policy: &RestoredPolicy,
    environment: &mut dyn Environment,
    contexts: &[Vec<f64>],
) -> anyhow::Result<Replay> {
    let mut free = environment::free_targets(&saved.problem.environment).context("rebuilding the run's environment")?;
    let throws: Vec<Throw> = contexts
        .iter()
        .enumerate()
        .map(|(index, context)| {
            let task = Task {
                id: index as u64,
                kind: TaskKind::Evaluate,
                seed: derive_seed(saved.seed, Stream::Environment, index as u64),
                context: context.clone(),
                theta: policy.greedy(context),
            };
            let field_centre = saved.problem.training_contexts.contains(context);
            let (outcome, free_target) = match free.as_mut() {
                Some(free) if !field_centre => (free.rollout(&task), true),
                _ => (environment.rollout(&task), false),
            };
            Throw {
                context: task.context,
                theta: task.theta,
                outcome,
                free_target,
            }
        })
        .collect();
    let scores: Vec<f64> = throws
        .iter()
        .filter(|t| t.outcome.is_ok())
        .map(|t| t.outcome.score)
        .collect();
    Ok(Replay {
        score: saved.problem.score.apply(&scores),
        throws,
    })
}

/// True for the PA-10 problems, whose outcomes carry the landing point and score the distance in cm.
pub fn is_throwing(saved: &SavedPolicy) -> bool {
    saved.user_problem.is_none() && matches!(saved.problem.name.as_str(), "grid" | "dartboard")
}

/// What performs the rollouts of the environment `spec` names, with the settings that change
/// them: the throwing simulator, or the contextual function's sizes and seed.
fn simulator(spec: &EnvironmentSpec) -> String {
    let [first, second, third] = spec.parameters();
    match (spec.name(), Sim::from_parameter(first)) {
        (GRID_ENVIRONMENT | DARTBOARD_ENVIRONMENT, Some(Sim::Analytic)) => {
            "analytic (the PA-10's commanded joint state at release, closed-form flight)".into()
        }
        (GRID_ENVIRONMENT | DARTBOARD_ENVIRONMENT, Some(Sim::Rapier)) => {
            // The environment's spec matched this build's, whose arm has the default settings.
            let c = RapierConfig::default();
            format!(
                "rapier (the PA-10 as a rapier3d multibody tracking the throw with joint motors: step {} s, {} solver iterations, motor stiffness {:e} 1/s^2, damping {:e} 1/s; closed-form flight after release)",
                c.dt, c.solver_iterations, c.motor_stiffness, c.motor_damping
            )
        }
        (contextual_function::ENVIRONMENT, _) => {
            format!("the contextual function of n_s = {first}, n_theta = {second}, problem seed {third}")
        }
        (name @ (benchmark::SPHERE_ENVIRONMENT | benchmark::ROSENBROCK_ENVIRONMENT), _) => {
            format!("the {name} of n_s = {first}, n_theta = {second}, problem seed {third}")
        }
        (name, _) => name.to_string(),
    }
}

/// The replay as a table, one line per context, then the statistics of the per-context scores.
pub fn report(saved: &SavedPolicy, replay: &Replay, test_set: bool) -> String {
    let throwing = is_throwing(saved);
    let score_name = if throwing { "error (cm)" } else { "score" };
    let format = |v: &[f64]| v.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>().join(", ");
    let mut lines = vec![
        format!(
            "{} {} run {} (seed {}, {} training episodes), greedy policy:",
            saved.experiment, saved.method, saved.run, saved.seed, saved.training_episodes
        ),
        format!(
            "simulator: {}; environment {}",
            simulator(&saved.problem.environment),
            saved.problem.environment
        ),
    ];
    for throw in &replay.throws {
        let o = &throw.outcome;
        let line = match (o.is_ok(), throwing) {
            (false, _) => format!("  target ({}): the rollout failed", format(&throw.context)),
            (true, true) => format!(
                "  target ({}): landed ({}), error {:.3} cm, reward {:.6}{}",
                format(&throw.context),
                format(&o.diagnostics),
                o.score,
                o.reward,
                if throw.free_target {
                    " (not a field centre: -||target - landing||^2)"
                } else {
                    ""
                }
            ),
            (true, false) => format!(
                "  context ({}): return {:.6}, score {:.6}",
                format(&throw.context),
                o.reward,
                o.score
            ),
        };
        lines.push(line);
    }
    let mut scores: Vec<f64> = replay
        .throws
        .iter()
        .filter(|t| t.outcome.is_ok())
        .map(|t| t.outcome.score)
        .collect();
    scores.sort_by(f64::total_cmp);
    let failed = replay.throws.len() - scores.len();
    if let (Some(first), Some(last)) = (scores.first(), scores.last()) {
        let mean = scores.iter().sum::<f64>() / scores.len() as f64;
        let middle = scores.len() / 2;
        let median = if scores.len() % 2 == 1 {
            scores[middle]
        } else {
            (scores[middle - 1] + scores[middle]) / 2.0
        };
        lines.push(format!(
            "{score_name}: mean {mean:.4}, median {median:.4}, min {first:.4}, max {last:.4} over {} contexts, {failed} failed",
            scores.len()
        ));
    } else {
        lines.push(format!("every one of the {failed} rollouts failed"));
    }
    if test_set {
        let show = |s: Option<f64>| s.map_or("n/a".to_string(), |s| s.to_string());
        lines.push(format!(
            "test-set score ({}): {} (the learner's last evaluation: {})",
            saved.problem.metric,
            show(replay.score),
            show(saved.final_score)
        ));
    }
    lines.join("\n") + "\n"
}

/// Refuse a `--render` file before anything is thrown: the problem must have throws and the
/// file must be .svg or .png.
pub fn check_render(saved: &SavedPolicy, path: &Path) -> anyhow::Result<()> {
    if !is_throwing(saved) {
        bail!(
            "--render draws a throw; the {} experiment has no throws",
            saved.experiment
        );
    }
    if !matches!(path.extension().and_then(|e| e.to_str()), Some("svg" | "png")) {
        bail!("--render {}: the file name must end in .svg or .png", path.display());
    }
    Ok(())
}

/// Draw the side view of the throw at `throw`'s target into `path` (.svg or .png).
pub fn render(saved: &SavedPolicy, throw: &Throw, path: &Path) -> anyhow::Result<()> {
    check_render(saved, path)?;
    let policy = ThrowPolicy::new(ThrowDesign::pa10(), 0.01)?;
    let trajectory = policy
        .trajectory(&throw.theta)
        .map_err(|e| anyhow::anyhow!("rolling out the throw: {e}"))?;
    let title = format!(
        "{} run {}: throw at ({:.3}, {:.3}), arm every 0.1 s, ball after release",
        saved.method, saved.run, throw.context[0], throw.context[1]
    );
    acps_reports::plot::save_throw(&Robot::pa10(), &trajectory, &title, path)
        .map_err(|e| anyhow::anyhow!("rendering {}: {e}", path.display()))
}
