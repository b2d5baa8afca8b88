//! `bench.json`'s rows: what `acps bench` measured, which [`crate::plot::save_bench`] draws.

use serde::Serialize;

/// One measurement.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// trivial, analytic or rapier.
    pub env: &'static str,
    /// inprocess-1, inprocess-rayon, fleet or relay.
    pub mode: &'static str,
    /// Worker processes (fleet, relay), threads (rayon) or 1.
    pub workers: usize,
    /// Rollouts (training and evaluation) per second of wall time, the median over rounds; a
    /// fleet's from the moment all its workers asked for tasks, a relay's from its first request
    /// (the learner sees one peer, not its workers: the relay asks once its first worker did).
    pub rollouts_per_s: f64,
    /// Median over rounds of the round's rate / (workers x its single-thread rate); for a relay,
    /// of the round's rate / the same round's rate of the fleet of as many direct workers.
    pub ratio: f64,
    /// Share of the fleet's serving time (median round) spent inside the learner cores.
    pub learner_share: Option<f64>,
    /// Fleet and relay only: seconds (median round) from starting the worker processes (the
    /// relay's) until the clock starts, which the rate leaves out (in-process rows build their
    /// environments before the clock starts, too).
    pub startup_seconds: Option<f64>,
    /// Fleet and relay only: the serving process's CPU time (user and system, its workers and
    /// relay excluded) per rollout served, in microseconds (median round; the whole serve,
    /// start-up included): how many hosts of workers one learner's core can feed. `None` below
    /// the counters' tick of 10 ms, or without Linux's /proc.
    pub learner_cpu_us_per_task: Option<f64>,
    /// Rollouts performed in the median round.
    pub rollouts: u64,
    /// Wall time in seconds of the median round (a fleet's from its start, as for the rate).
    pub seconds: f64,
    /// Every round's rate, in order.
    pub round_rates: Vec<f64>,
    /// Every round's ratio, in order.
    pub round_ratios: Vec<f64>,
    /// The largest share of the machine's CPU time that other processes used during a round of
    /// this row (`None` where the system does not say, Linux's /proc only, or where every round
    /// was shorter than its counters' tick of 10 ms).
    pub others_share: Option<f64>,
}

impl Row {
    /// The lowest and highest ratio over the rounds, when there were several.
    pub fn ratio_range(&self) -> Option<(f64, f64)> {
        (self.round_ratios.len() > 1).then(|| {
            let lowest = self.round_ratios.iter().copied().fold(f64::INFINITY, f64::min);
            let highest = self.round_ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (lowest, highest)
        })
    }
}

/// The long-run row: one learner of a trivial problem through a run of many episodes, writing
/// its record file and checkpoints as `acps run` does. Its cost per rollout must not grow with
/// the run, nor its memory.
#[derive(Debug, Clone, Serialize)]
pub struct LongRun {
    /// Training episodes of the run.
    pub episodes: u64,
    /// Learning rounds between two checkpoints (`acps run`'s default).
    pub checkpoint_every: u64,
    /// Checkpoints written.
    pub checkpoints: u64,
    /// Episodes in each of the two windows measured: the first and the last tenth of the run.
    pub window: u64,
    /// The learner thread's CPU time per training episode over the first window, microseconds
    /// (its rollouts, evaluations, C-REPS updates, records and checkpoints included).
    pub start_cpu_us: f64,
    /// The same over the last window.
    pub end_cpu_us: f64,
    /// Resident memory of the process after `early_episodes`, MiB.
    pub early_rss_mib: f64,
    /// When the early resident memory was read (50,000 episodes, or the run's length if
    /// shorter).
    pub early_episodes: u64,
    /// Resident memory of the process at the end of the run, MiB.
    pub end_rss_mib: f64,
    /// The size of the last checkpoint, bytes.
    pub checkpoint_bytes: u64,
    /// The size of the record file at the end, bytes.
    pub record_bytes: u64,
    /// Wall time of the run, seconds.
    pub seconds: f64,
}

impl LongRun {
    /// CPU per episode at the end over that at the start: 1 when the cost does not grow.
    pub fn cpu_growth(&self) -> f64 {
        self.end_cpu_us / self.start_cpu_us
    }

    /// Resident memory at the end over that early in the run.
    pub fn rss_growth(&self) -> f64 {
        self.end_rss_mib / self.early_rss_mib
    }
}
