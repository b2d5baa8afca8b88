//! The command line's arguments: what `acps --help` shows; `crate::commands` carries a command
//! out.

use acps_experiments::progress::PROGRESS_EVERY;
use acps_experiments::run_dir::{DEFAULT_CHECKPOINT_EVERY, MAX_FAILED_SHARE};
use acps_experiments::settings::{self, ExperimentFile, MAX_EPISODES, MAX_RUNS, parse_option};
use acps_fleet::processes::MAX_NICE;
use acps_fleet::server::WORKER_STARTUP;
use acps_wire::ipc::{MAX_IN_FLIGHT_PER_WORKER, MAX_WORKERS};
use acps_worker::DEFAULT_QUEUE_DEPTH;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// The `acps` command line, parsed.
#[derive(Parser)]
#[command(
    long_about = None,
    name = "acps",
    version,
    about = "Active contextual policy search (Fabisch & Metzen, JMLR 2014): C-REPS learns one policy over task contexts while D-UCB chooses which context to practise next."
)]
pub struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
    /// More log lines on stderr: -v info, -vv debug (e.g. rejected C-REPS updates), -vvv
    /// trace. The ACPS_LOG variable takes tracing filter directives instead (e.g.
    /// ACPS_LOG=acps_learner=debug); IOX2_LOG_LEVEL sets iceoryx2's own log (default error).
    #[arg(long, short, action = clap::ArgAction::Count, global = true)]
    pub(crate) verbose: u8,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// The main job: the PA-10 arm learns to throw at 25 targets through a worker fleet.
    ///
    /// The grid problem (paper Section 5.2.3) with rapier3d physics, D-UCB with monotonic
    /// progress choosing the targets; shows the test error falling and writes DIR (default
    /// runs/learn). The same as `acps run grid --sim rapier --method monotonic-progress --runs 4
    /// --episodes 10000 --in-flight 8 --out runs/learn`. Ctrl-C prints the command that
    /// continues it (`acps learn --resume`).
    Learn(LearnArgs),
    /// Run one of the paper's experiments or an experiment file in this process.
    ///
    /// Several methods x seeds in parallel; writes DIR/summary.json, the plots and
    /// DIR/config.toml. Name the experiment (`acps experiment grid --runs 5`) or give an
    /// experiment file (`acps experiment --config experiments/grid-fig8.toml`).
    #[command(override_usage = "acps experiment <NAME> [OPTIONS]\n       acps experiment --config FILE [OPTIONS]")]
    Experiment(ExperimentArgs),
    /// Run an experiment or problem file through a fleet of worker processes.
    ///
    /// This process is the learner and serves tasks over iceoryx2 shared memory to worker
    /// processes it starts. Writes the same DIR/summary.json as `acps experiment` with the same
    /// --in-flight and --seed. An experiment file with a `[problem]` table of your own runs here
    /// only, on your workers (--worker-command CMD, or --workers 0 and start them yourself).
    #[command(override_usage = "acps run <NAME> [OPTIONS]\n       acps run --config FILE [OPTIONS]")]
    Run(RunArgs),
    /// Serve a running fleet's learner (`acps run ... --run NAME`) as one more worker.
    Worker(WorkerArgs),
    /// Serve this host's workers from a learner on another host (docs/HOSTS.md).
    ///
    /// Over Zenoh, from `acps run ... --listen ENDPOINT` there: to the workers this is their
    /// learner, to the learner one peer that asks for their tasks in batches. Starts --workers W
    /// workers (default: the cores) for every experiment of the run, and exits when the
    /// learner's run is over. Needs a build with the `hosts` feature.
    Relay(RelayArgs),
    /// Measure rollouts per second in-process and through worker fleets.
    ///
    /// For fleets of 1 ..= cores workers, a trivial environment (the transport's cost) and the
    /// analytic and rapier PA-10, in interleaved rounds; prints a table and writes
    /// DIR/bench.json, bench.svg and bench.png.
    Bench(BenchArgs),
    /// Replay a learned policy from a run directory, exploration off.
    ///
    /// Its mean, at --target points or at the problem's test contexts, in the simulator the run
    /// used (named in the report), printing the landing point, error and reward of every throw
    /// (the return of every context for the contextual function).
    Evaluate(EvaluateArgs),
    /// Compare the methods of run directories with a baseline, paired over seeds.
    ///
    /// The final score, the area under the learning curve (as a mean score) and the episodes to
    /// each --levels value, with mean +- SEM, the paired difference and two-sided p-values
    /// (Wilcoxon signed-rank, paired t). Prints a markdown table, or JSON.
    Compare(CompareArgs),
    /// Print the wire protocol's layout as JSON, for workers in other languages.
    ///
    /// Every payload's fields (type, offset, size, alignment), the iceoryx2 type names,
    /// capacities, codes and service settings. Workers in other languages are tested against
    /// it; docs/PROTOCOL.md explains it.
    Protocol,
}

#[derive(clap::Args)]
pub(crate) struct CompareArgs {
    /// A run directory written by `acps experiment` or `acps run` (summary.json and runs.csv).
    pub(crate) dir: PathBuf,
    /// A further run directory of the same experiment and seeds whose methods join the
    /// comparison (repeatable); run with retire = true, its methods are named METHOD+retire, and
    /// run with the other learner, METHOD+LEARNER (e.g. METHOD+c-cmaes).
    #[arg(long, value_name = "DIR")]
    pub(crate) with: Vec<PathBuf>,
    /// The method every other is paired with [default: the best by final mean score of
    /// round-robin, random, random-continuous and corners, among those present].
    #[arg(long)]
    pub(crate) baseline: Option<String>,
    /// Score levels L1,L2,... for the episodes to reach each (the first evaluation at or better
    /// than the level); above 0 for the throws' distances in cm.
    #[arg(long, value_name = "L1,L2,...", allow_hyphen_values = true)]
    pub(crate) levels: Option<String>,
    /// Print JSON instead of a markdown table.
    #[arg(long, conflicts_with = "wide")]
    pub(crate) json: bool,
    /// One row per method and a column per metric (difference and p-values under each value),
    /// instead of a row per method and metric.
    #[arg(long)]
    pub(crate) wide: bool,
}

#[derive(clap::Args)]
pub(crate) struct EvaluateArgs {
    /// A run directory written by `acps experiment` or `acps run` (or one of its
    /// policies/METHOD-runR.json files).
    pub(crate) dir: PathBuf,
    /// The method whose policy to replay: one with a file of the run in DIR/policies (default:
    /// the first by name).
    #[arg(long)]
    pub(crate) method: Option<String>,
    /// The run whose policy to replay (0..=999, one of the experiment's runs; default 0).
    #[arg(long, allow_hyphen_values = true, value_parser = integer::<usize>(0, MAX_RUNS as u64 - 1))]
    pub(crate) run: Option<usize>,
    /// A target X,Y to throw at (repeatable; default: the problem's test contexts).
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = crate::evaluate::parse_target)]
    pub(crate) target: Vec<Vec<f64>>,
    /// Draw the side view of the first throw into FILE (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub(crate) render: Option<PathBuf>,
}

#[derive(clap::Args)]
pub(crate) struct LearnArgs {
    /// Worker processes (0..=128; 0: start them yourself with `acps worker`) [default: the number
    /// of cores, at most 128].
    #[arg(long, allow_hyphen_values = true, value_parser = integer::<usize>(0, MAX_WORKERS as u64))]
    pub(crate) workers: Option<usize>,
    /// Independent learning runs (seeds 0 .. runs - 1, 1..=1000), for the SEM band of the curve.
    #[arg(long, default_value_t = 4, allow_hyphen_values = true, value_parser = parse_option::<usize>("runs"))]
    pub(crate) runs: usize,
    /// Training episodes (throws) per run (1..=10000000).
    #[arg(long, default_value_t = 10_000, allow_hyphen_values = true, value_parser = parse_option::<u64>("episodes"))]
    pub(crate) episodes: u64,
    /// How throws are simulated.
    #[arg(long, value_enum, default_value = "rapier")]
    pub(crate) sim: settings::SimName,
    /// Output directory.
    #[arg(long, default_value = "runs/learn")]
    pub(crate) out: PathBuf,
    /// The run's name, for workers started by hand to join (default: grid-PID).
    #[arg(long)]
    pub(crate) run: Option<String>,
    /// Continue the run in DIR (default: --out) from its checkpoints after Ctrl-C, a crash or a
    /// kill, with the other options it was started with (an interrupted run prints the
    /// command). The result is bit for bit that of an uninterrupted run.
    #[arg(long, value_name = "DIR")]
    #[allow(clippy::option_option)]
    pub(crate) resume: Option<Option<PathBuf>>,
    /// Replace a finished run in --out (its summary, tables, pictures and policies) instead
    /// of refusing to start there.
    #[arg(long, conflicts_with = "resume")]
    pub(crate) force: bool,
    /// No progress line.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

impl LearnArgs {
    /// The `acps run` this stands for.
    pub(crate) fn run_args(self) -> RunArgs {
        let settings = ExperimentFile {
            experiment: Some(settings::ExperimentName::Grid),
            sim: Some(self.sim),
            runs: Some(self.runs),
            episodes: Some(self.episodes),
            in_flight: Some(8),
            methods: Some(vec![acps_learner::Method::MonotonicProgress]),
            ..ExperimentFile::default()
        };
        RunArgs {
            experiment: ExperimentArgs {
                config: None,
                settings,
                save_config: None,
                resume: self.resume.map(|dir| dir.unwrap_or_else(|| self.out.clone())),
                out: Some(self.out),
                checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
                force: self.force,
                quiet: self.quiet,
                progress_every: PROGRESS_EVERY.as_secs_f64(),
                max_failed_share: MAX_FAILED_SHARE,
            },
            started: StartedWorkers {
                workers: self.workers,
                worker_queue_depth: DEFAULT_QUEUE_DEPTH,
                deprecated: DeprecatedWorkerInFlight { worker_in_flight: None },
                worker_nice: WorkerNiceArg { worker_nice: None },
                worker_command: None,
                worker_startup_timeout: WORKER_STARTUP.as_secs_f64(),
            },
            run: self.run,
            listen: Vec::new(),
            net: NetArgs::default(),
        }
    }
}

#[derive(clap::Args)]
pub(crate) struct BenchArgs {
    /// Output directory.
    #[arg(long, default_value = "runs/bench")]
    pub(crate) out: PathBuf,
    /// Largest fleet (1..=128; fleets beyond the number of cores are not measured) [default: the
    /// number of cores, at most 128].
    #[arg(long, allow_hyphen_values = true, value_parser = integer::<usize>(1, MAX_WORKERS as u64))]
    pub(crate) max_workers: Option<usize>,
    /// Each worker's queue: tasks it keeps asked for or queued (1..=128; at most 8 of rollouts
    /// slower than a batch's 800 us, which travel alone).
    #[arg(long, default_value_t = 128, allow_hyphen_values = true, value_parser = queue_depth())]
    pub(crate) worker_queue_depth: usize,
    #[command(flatten)]
    pub(crate) deprecated: DeprecatedWorkerInFlight,
    /// Multiplies the work per measurement, in (0, 100] (1: a few seconds per row and round; the
    /// default bench takes 62 s on 2 idle cores, up to 2.5 minutes on a busy machine, and warns
    /// when other programs took CPU time from it).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = number("a number in (0, 100]", |x| x > 0.0 && x <= 100.0))]
    pub(crate) scale: f64,
    /// Times every mode is measured, interleaved (1..=100): rows report the median round, and
    /// the table the range of the ratio over rounds.
    #[arg(long, default_value_t = 3, allow_hyphen_values = true, value_parser = integer::<usize>(1, 100))]
    pub(crate) rounds: usize,
    /// Environments to measure, comma separated.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "trivial,analytic,rapier,long-run"
    )]
    pub(crate) env: Vec<crate::bench::BenchEnv>,
    #[command(flatten)]
    pub(crate) worker_nice: WorkerNiceArg,
    /// Also measure every fleet through `acps relay` on loopback (a host of workers on the
    /// network): rows 'relay', whose ratio is to the same round's fleet of as many workers
    /// connected directly.
    #[arg(long)]
    pub(crate) relay: bool,
}

/// `--worker-nice` of `acps run` and `acps bench`.
#[derive(clap::Args)]
pub(crate) struct WorkerNiceArg {
    /// Niceness of the started workers (0..=19; default: 10 when the workers and the learner
    /// outnumber the cores, else 0). The learner gates every worker, so it should get a core as
    /// soon as it wakes; 0 keeps the workers at full priority next to other programs.
    #[arg(long, allow_hyphen_values = true, value_parser = integer::<u8>(0, MAX_NICE.into()))]
    pub(crate) worker_nice: Option<u8>,
}

#[derive(clap::Args)]
pub(crate) struct RunArgs {
    #[command(flatten)]
    pub(crate) experiment: ExperimentArgs,
    #[command(flatten)]
    pub(crate) started: StartedWorkers,
    /// The run's name (letters, digits and '-'): its shared-memory prefix, how workers
    /// started by hand join it, and how relays of other hosts name it (default: EXPERIMENT-PID).
    #[arg(long)]
    pub(crate) run: Option<String>,
    /// Also serve relays of other hosts (`acps relay --connect ENDPOINT --relay-key FILE`
    /// there) at ENDPOINT: tcp/ADDRESS:PORT, e.g. tcp/10.0.0.1:7447. Relays must present the
    /// run directory's relay.key (made if missing; see --relay-key). Listening on an address
    /// other hosts reach is your choice: on networks that are not private, listen on loopback
    /// and let relays come through SSH tunnels (docs/HOSTS.md). Repeat for several addresses.
    #[arg(long, value_name = "ENDPOINT")]
    pub(crate) listen: Vec<String>,
    #[command(flatten)]
    pub(crate) net: NetArgs,
}

/// How a learner or relay joins the network of hosts.
#[derive(clap::Args, Default)]
pub(crate) struct NetArgs {
    /// The relays' credentials: a file of one line `acps-relay:PASSWORD`, its user's alone. A
    /// learner (--listen) takes it, or makes it where there is none [default: relay.key in the
    /// run directory, unless --zenoh-config sets the users]; a relay (--connect) presents it: a
    /// copy of its learner's.
    #[arg(long, value_name = "FILE", conflicts_with = "no_relay_key")]
    pub(crate) relay_key: Option<PathBuf>,
    /// Admit relays without credentials (a learner on loopback only: any process of this host
    /// could join as a relay), or connect without (a relay of such a learner).
    #[arg(long)]
    pub(crate) no_relay_key: bool,
    /// A Zenoh configuration file (JSON5), for user/password authentication;
    /// acps sets the mode, endpoints, scouting (off) and lease on top of it (docs/HOSTS.md).
    #[arg(long, value_name = "FILE")]
    pub(crate) zenoh_config: Option<PathBuf>,
    /// Seconds without a word after which a frozen or cut-off host is given up on (0.1..=3600;
    /// a host that crashes is noticed at once) [default: 3].
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true, value_parser = number("a number of seconds in 0.1..=3600", crate::hosts::lease_ok))]
    pub(crate) lease: Option<f64>,
}

/// The worker processes a learner or relay starts.
#[derive(clap::Args)]
pub(crate) struct StartedWorkers {
    /// Worker processes to start (0..=128, the most a fleet serves; 0: start them yourself)
    /// [default: the number of cores, at most 128].
    #[arg(long, allow_hyphen_values = true, value_parser = integer::<usize>(0, MAX_WORKERS as u64))]
    pub(crate) workers: Option<usize>,
    /// Each started worker's queue: tasks it keeps asked for or queued (1..=128; at most 8 of
    /// rollouts slower than a batch's 800 us, which travel alone). Not the learner's window
    /// (--in-flight), which sets the results.
    #[arg(long, default_value_t = DEFAULT_QUEUE_DEPTH, allow_hyphen_values = true, value_parser = queue_depth())]
    pub(crate) worker_queue_depth: usize,
    #[command(flatten)]
    pub(crate) deprecated: DeprecatedWorkerInFlight,
    #[command(flatten)]
    pub(crate) worker_nice: WorkerNiceArg,
    /// Start the --workers W workers with this shell command instead of `acps worker`: your
    /// own simulator's worker, in any language (a problem file's problem needs it, or
    /// --workers 0). Each runs as `sh -c "exec CMD"` with ACPS_RUN (the run's name),
    /// ACPS_RUN_SECRET (its secret) and ACPS_WORKER_INDEX (0..W-1) set; --worker-queue-depth
    /// does not apply.
    #[arg(long, value_name = "CMD")]
    pub(crate) worker_command: Option<String>,
    /// Seconds the started workers may take to connect (1..=86400): a run whose workers are all
    /// still starting after it (stuck at an import, say) stops and says so.
    #[arg(long, value_name = "SECONDS", default_value_t = WORKER_STARTUP.as_secs_f64(), allow_hyphen_values = true, value_parser = number("a number of seconds in 1..=86400", |x| (1.0..=86400.0).contains(&x)))]
    pub(crate) worker_startup_timeout: f64,
}

#[derive(clap::Args)]
pub(crate) struct RelayArgs {
    /// Where the learner listens (its --listen): tcp/HOST:PORT.
    #[arg(long, value_name = "ENDPOINT", required = true)]
    pub(crate) connect: Vec<String>,
    /// The run to join [default: the one the learner serves].
    #[arg(long)]
    pub(crate) run: Option<String>,
    #[command(flatten)]
    pub(crate) started: StartedWorkers,
    /// This host's own run name, which its workers started by hand join (`acps worker --run
    /// NAME`) [default: relay-PID].
    #[arg(long, value_name = "NAME")]
    pub(crate) local_run: Option<String>,
    /// Seconds to wait for the learner when starting (0..=86400).
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true, value_parser = number("a number of seconds in 0..=86400", |x| (0.0..=86400.0).contains(&x)))]
    pub(crate) startup_timeout: f64,
    /// Seconds to wait for a learner that vanished mid-run to come back (resumed with --resume)
    /// before the relay exits (0..=86400).
    #[arg(long, default_value_t = 60.0, allow_hyphen_values = true, value_parser = number("a number of seconds in 0..=86400", |x| (0.0..=86400.0).contains(&x)))]
    pub(crate) wait_for_learner: f64,
    /// Most tasks kept asked for or queued beyond what the workers hold (1..=4096): the relay
    /// keeps what its workers take in two round trips to the learner and one batch (16..=128)
    /// more, up to this.
    #[arg(long, default_value_t = 1024, allow_hyphen_values = true, value_parser = integer::<usize>(1, 4096))]
    pub(crate) queue: usize,
    #[command(flatten)]
    pub(crate) net: NetArgs,
    /// Print nothing unless something goes wrong.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

#[derive(clap::Args)]
pub(crate) struct WorkerArgs {
    /// The run to join (the learner's --run) [default: the ACPS_RUN environment variable, which
    /// a learner sets for the workers it starts].
    #[arg(long)]
    pub(crate) run: Option<String>,
    /// The worker's queue: tasks it keeps asked for or queued (1..=128): more hides the wake-up
    /// latency between processes; cheap rollouts travel in batches of up to half of them, and at
    /// most 8 of rollouts slower than a batch's 800 us, which travel alone, are in flight.
    #[arg(long, default_value_t = DEFAULT_QUEUE_DEPTH, allow_hyphen_values = true, value_parser = queue_depth())]
    pub(crate) queue_depth: usize,
    /// Deprecated name of --queue-depth (a worker's queue is not the learner's window).
    #[arg(long = "in-flight", hide = true, conflicts_with = "queue_depth", allow_hyphen_values = true, value_parser = queue_depth())]
    pub(crate) in_flight: Option<usize>,
    /// The worker's name in iceoryx2's node list: 1 to 128 ASCII letters, digits, '-', '_' and
    /// '.', not 'learner' (default: worker-PID).
    #[arg(long)]
    pub(crate) name: Option<String>,
    /// Seconds to wait for the run's learner to appear (0..=86400, a day).
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true, value_parser = number("a number of seconds in 0..=86400", |x| (0.0..=86400.0).contains(&x)))]
    pub(crate) startup_timeout: f64,
    /// Microseconds to poll for an answer before blocking (0..=1000000; 0 when processes
    /// outnumber cores).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true, value_parser = integer::<u64>(0, 1_000_000))]
    pub(crate) spin_us: u64,
    /// Lower this worker's priority to niceness N (0..=19), so that a learner sharing its
    /// cores gets the CPU first; a worker already at N or above keeps its niceness.
    #[arg(long, value_name = "N", default_value_t = 0, allow_hyphen_values = true, value_parser = integer::<u8>(0, MAX_NICE.into()))]
    pub(crate) nice: u8,
    /// Print nothing unless something goes wrong.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

#[derive(clap::Args)]
pub(crate) struct ExperimentArgs {
    /// Read the experiment from an experiment file (one per paper figure in experiments/); options
    /// given as well override the file's values.
    #[arg(long, short, value_name = "FILE")]
    pub(crate) config: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) settings: ExperimentFile,
    /// Write the resolved experiment file (every setting, defaults filled in) to FILE and exit
    /// without running; `--config FILE` runs it. Every run also writes DIR/config.toml.
    #[arg(long, value_name = "FILE")]
    pub(crate) save_config: Option<PathBuf>,
    /// Output directory [default: runs/NAME, or runs/STEM for --config STEM.toml].
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Write each (method, run) job's checkpoint to DIR/checkpoints after every N learning
    /// rounds (C-REPS updates; evaluations for the toy model, which has no policy) and when the
    /// job ends; 0: no checkpoints (0..=10000000: more than a run has rounds means at its end
    /// only). A run started without --resume removes old checkpoints there.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CHECKPOINT_EVERY, allow_hyphen_values = true, value_parser = integer::<u64>(0, MAX_EPISODES))]
    pub(crate) checkpoint_every: u64,
    /// Continue the run whose output directory is DIR from its checkpoints, after a crash, a
    /// kill or Ctrl-C (which prints the whole command); give the arguments the run was started
    /// with. The result is bit for bit that of an uninterrupted run.
    #[arg(long, value_name = "DIR")]
    pub(crate) resume: Option<PathBuf>,
    /// Replace a finished run in the output directory (its summary, tables, pictures and
    /// policies) instead of refusing to start there.
    #[arg(long, conflicts_with = "resume")]
    pub(crate) force: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    /// When stderr is not a terminal (a log, a pipe): write the progress as a plain line every
    /// this many seconds (0.1..=3600) instead of the live bar.
    #[arg(long, value_name = "SECONDS", default_value_t = PROGRESS_EVERY.as_secs_f64(), allow_hyphen_values = true, value_parser = number("a number of seconds in 0.1..=3600", |x| (0.1..=3600.0).contains(&x)))]
    pub(crate) progress_every: f64,
    /// End with an error (exit 2, the run directory written) when more than this share of a
    /// method's rollouts, training and evaluation, failed (0..=1; 1 accepts any but a run whose
    /// every rollout failed).
    #[arg(long, value_name = "SHARE", default_value_t = MAX_FAILED_SHARE, allow_hyphen_values = true, value_parser = number("a share in 0..=1", |x| (0.0..=1.0).contains(&x)))]
    pub(crate) max_failed_share: f64,
}

/// The value parser of an integer option in `low..=high`: every refusal, also of a negative or
/// non-numeric value, names the range.
fn integer<T: TryFrom<u64>>(low: u64, high: u64) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static {
    move |text: &str| {
        text.parse::<u64>()
            .ok()
            .filter(|n| (low..=high).contains(n))
            .and_then(|n| T::try_from(n).ok())
            .ok_or_else(|| format!("must be an integer in {low}..={high}"))
    }
}

/// The value parser of a number option: `accepted` describes the numbers `ok` accepts (NaN
/// never is).
fn number(
    accepted: &'static str,
    ok: fn(f64) -> bool,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text: &str| {
        text.parse::<f64>()
            .ok()
            .filter(|&x| ok(x))
            .ok_or_else(|| format!("must be {accepted}"))
    }
}

/// A worker's queue depth: what the task service holds per worker.
fn queue_depth() -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync + 'static {
    integer(1, MAX_IN_FLIGHT_PER_WORKER as u64)
}

/// `--worker-in-flight`, the old name of `--worker-queue-depth`, still taken with a warning.
#[derive(clap::Args)]
pub(crate) struct DeprecatedWorkerInFlight {
    /// Deprecated name of --worker-queue-depth (a worker's queue is not the learner's window).
    #[arg(long = "worker-in-flight", hide = true, conflicts_with = "worker_queue_depth", allow_hyphen_values = true, value_parser = queue_depth())]
    worker_in_flight: Option<usize>,
}

impl DeprecatedWorkerInFlight {
    /// Say, once per command, that the deprecated option was given and what replaces it.
    pub(crate) fn warn(&self) {
        deprecated("--worker-in-flight", "--worker-queue-depth", self.worker_in_flight);
    }

    /// The deprecated option's value if given, else `depth`.
    pub(crate) fn or(&self, depth: usize) -> usize {
        self.worker_in_flight.unwrap_or(depth)
    }
}

/// `value` of the deprecated option `old`, after a warning to use `new` instead.
pub(crate) fn deprecated(old: &str, new: &str, value: Option<usize>) -> Option<usize> {
    if value.is_some() {
        eprintln!(
            "warning: {old} is deprecated and will be removed: use {new} (a worker's queue, not the learner's window --in-flight)"
        );
    }
    value
}

impl Cli {
    /// How many -v were given.
    pub fn verbosity(&self) -> u8 {
        self.verbose
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The options checked by their value parsers accept their bounds and refuse beyond them.
    #[test]
    fn option_ranges_include_their_bounds() {
        let parse = |args: &[&str]| {
            Cli::command()
                .try_get_matches_from(args)
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        for args in [
            &[
                "acps",
                "worker",
                "--startup-timeout",
                "0",
                "--spin-us",
                "0",
                "--nice",
                "0",
                "--queue-depth",
                "1",
            ][..],
            &[
                "acps",
                "worker",
                "--startup-timeout",
                "86400",
                "--spin-us",
                "1000000",
                "--nice",
                "19",
                "--queue-depth",
                "128",
            ],
            &[
                "acps",
                "bench",
                "--scale",
                "1e-9",
                "--max-workers",
                "1",
                "--rounds",
                "1",
                "--worker-queue-depth",
                "1",
            ],
            &[
                "acps",
                "bench",
                "--scale",
                "100",
                "--max-workers",
                "128",
                "--rounds",
                "100",
                "--worker-queue-depth",
                "128",
            ],
            &["acps", "evaluate", "dir", "--run", "0"],
            &["acps", "evaluate", "dir", "--run", "999"],
            &["acps", "learn", "--workers", "0", "--runs", "1", "--episodes", "1"],
            &[
                "acps",
                "learn",
                "--workers",
                "128",
                "--runs",
                "1000",
                "--episodes",
                "10000000",
            ],
        ] {
            assert_eq!(parse(args), Ok(()), "{args:?}");
        }
        for (args, expected) in [
            (
                &["acps", "worker", "--spin-us", "1e3"][..],
                "must be an integer in 0..=1000000",
            ),
            (&["acps", "worker", "--nice", "256"], "must be an integer in 0..=19"),
            (&["acps", "bench", "--scale", "-0"], "must be a number in (0, 100]"),
            (
                &["acps", "bench", "--rounds", "18446744073709551616"],
                "must be an integer in 1..=100",
            ),
        ] {
            let message = parse(args).unwrap_err();
            assert!(message.contains(expected), "{args:?}: {message}");
        }
    }
}
