//! Which recorded rollouts a C-REPS update uses.

use std::collections::VecDeque;

use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// The sample memory an update runs on. Every update uses everything in memory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum MemoryConfig {
    /// The most recent `capacity` rollouts (BOLeRo's deques of `n_samples_per_update`).
    SlidingWindow {
        /// Maximum number of rollouts kept, >= 1.
        capacity: usize,
    },
    /// For every training task separately, the `per_task` rollouts with the highest reward
    /// (P Sec. 5.2 / Appendix A: "the best N/K rollouts" per task); a tie keeps the older one.
    BestPerTask {
        /// Rollouts kept per task, >= 1.
        per_task: usize,
    },
}

impl Default for MemoryConfig {
    /// The last 100 rollouts: BOLeRo's `n_samples_per_update`. A window forgets rollouts of the
    /// early, worse policies; with [`CRepsConfig::update_every`](super::CRepsConfig) = 25 each
    /// rollout takes part in four updates.
    fn default() -> Self {
        Self::SlidingWindow { capacity: 100 }
    }
}

impl MemoryConfig {
    /// The paper's Sec. 5.2 memory of `samples` rollouts over `tasks` training tasks: the best
    /// `samples / tasks` per task, rounded down, at least 1.
    pub fn best_per_task(samples: usize, tasks: usize) -> Self {
        Self::BestPerTask {
            per_task: (samples / tasks.max(1)).max(1),
        }
    }
}

/// One stored rollout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Sample {
    /// The context itself, for updates that also move a context distribution (SPRL).
    pub context: Vec<f64>,
    pub features: DVector<f64>,
    pub theta: DVector<f64>,
    pub reward: f64,
}

/// What one [`Memory::push`] changed: where the sample went (`None`: it was not kept) and the
/// sample it pushed out (the window's oldest, or the bucket's worst).
pub(crate) struct Pushed {
    position: Option<usize>,
    evicted: Option<Sample>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) enum Memory {
    Window {
        capacity: usize,
        samples: VecDeque<Sample>,
    },
    /// One bucket per task, each sorted by descending reward, older first among equals.
    PerTask {
        per_task: usize,
        buckets: Vec<Vec<Sample>>,
    },
}

impl Memory {
    pub fn new(config: &MemoryConfig, n_tasks: usize) -> Self {
        match *config {
            MemoryConfig::SlidingWindow { capacity } => Memory::Window {
                capacity,
                samples: VecDeque::with_capacity(capacity),
            },
            MemoryConfig::BestPerTask { per_task } => Memory::PerTask {
                per_task,
                buckets: vec![Vec::with_capacity(per_task + 1); n_tasks],
            },
        }
    }

    /// Stores `sample` for `task` (which must be < n_tasks); returns what [`undo`](Self::undo)
    /// needs to take it back.
    pub fn push(&mut self, task: usize, sample: Sample) -> Pushed {
        match self {
            Memory::Window { capacity, samples } => {
                let evicted = if samples.len() == *capacity {
                    samples.pop_front()
                } else {
                    None
                };
                samples.push_back(sample);
                Pushed {
                    position: Some(samples.len() - 1),
                    evicted,
                }
            }
            Memory::PerTask { per_task, buckets } => {
                let bucket = &mut buckets[task];
                let position = bucket.partition_point(|kept| kept.reward >= sample.reward);
                if position == *per_task {
                    // Worse than every kept one of a full bucket: nothing changes.
                    return Pushed {
                        position: None,
                        evicted: None,
                    };
                }
                bucket.insert(position, sample);
                let evicted = if bucket.len() > *per_task { bucket.pop() } else { None };
                Pushed {
                    position: Some(position),
                    evicted,
                }
            }
        }
    }

    /// Take back the last [`push`](Self::push) for `task`, which returned `pushed`.
    pub fn undo(&mut self, task: usize, pushed: Pushed) {
        match self {
            Memory::Window { samples, .. } => {
                if pushed.position.is_some() {
                    samples.pop_back();
                }
                if let Some(evicted) = pushed.evicted {
                    samples.push_front(evicted);
                }
            }
            Memory::PerTask { buckets, .. } => {
                let bucket = &mut buckets[task];
                if let Some(position) = pushed.position {
                    bucket.remove(position);
                }
                bucket.extend(pushed.evicted);
            }
        }
    }

    /// Every stored sample: oldest first for the window, task by task (best first) otherwise.
    pub fn samples(&self) -> Box<dyn Iterator<Item = &Sample> + '_> {
        match self {
            Memory::Window { samples, .. } => Box::new(samples.iter()),
            Memory::PerTask { buckets, .. } => Box::new(buckets.iter().flatten()),
        }
    }

    /// The first stored sample, to forge in tests.
    #[cfg(test)]
    pub fn first_mut(&mut self) -> Option<&mut Sample> {
        match self {
            Memory::Window { samples, .. } => samples.front_mut(),
            Memory::PerTask { buckets, .. } => buckets.iter_mut().flatten().next(),
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Memory::Window { samples, .. } => samples.len(),
            Memory::PerTask { buckets, .. } => buckets.iter().map(Vec::len).sum(),
        }
    }

    /// Whether `self` (a saved memory) can replace `fresh`, a memory built from the same
    /// configuration: the same kind and size, and samples of `context_dim` coordinates, `n_phi`
    /// features and `n_theta` parameters. Says why not.
    pub fn check_fits(
        &self,
        fresh: &Memory,
        context_dim: usize,
        n_phi: usize,
        n_theta: usize,
    ) -> Result<(), MemoryFitError> {
        match (self, fresh) {
            (Memory::Window { capacity, samples }, Memory::Window { capacity: expected, .. }) => {
                if capacity != expected || samples.len() > *capacity {
                    return Err(MemoryFitError::Window {
                        capacity: *capacity,
                        held: samples.len(),
                        expected: *expected,
                    });
                }
            }
            (
                Memory::PerTask { per_task, buckets },
                Memory::PerTask {
                    per_task: expected,
                    buckets: expected_buckets,
                },
            ) => {
                if per_task != expected
                    || buckets.len() != expected_buckets.len()
                    || buckets.iter().any(|b| b.len() > *per_task)
                {
                    return Err(MemoryFitError::PerTask {
                        per_task: *per_task,
                        tasks: buckets.len(),
                        expected: *expected,
                        expected_tasks: expected_buckets.len(),
                    });
                }
            }
            _ => return Err(MemoryFitError::Kind),
        }
        if self
            .samples()
            .any(|s| s.context.len() != context_dim || s.features.len() != n_phi || s.theta.len() != n_theta)
        {
            return Err(MemoryFitError::SampleShape {
                context_dim,
                n_phi,
                n_theta,
            });
        }
        Ok(())
    }
}

/// Why a saved sample memory cannot replace the one its configuration builds, as
/// [`CRepsRestoreError::Memory`](super::CRepsRestoreError::Memory) reports it: each message
/// completes "the saved memory is ...".
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MemoryFitError {
    /// A sliding window of another capacity, or holding more samples than its capacity.
    #[error("a sliding window of {capacity} holding {held}, expected one of {expected}")]
    Window {
        /// The saved window's capacity.
        capacity: usize,
        /// Samples it holds.
        held: usize,
        /// The configured capacity.
        expected: usize,
    },
    /// A per-task memory of another size or number of tasks, or with a task over its size.
    #[error("a per-task memory of {per_task} x {tasks} tasks, expected {expected} x {expected_tasks}")]
    PerTask {
        /// The saved memory's samples per task.
        per_task: usize,
        /// Its tasks.
        tasks: usize,
        /// The configured samples per task.
        expected: usize,
        /// The configured tasks.
        expected_tasks: usize,
    },
    /// A sliding window where a per-task memory is configured, or the reverse.
    #[error("a memory of another kind than configured")]
    Kind,
    /// A sample of other widths than the learner's.
    #[error("a sample that does not have {context_dim} context coordinates, {n_phi} features and {n_theta} parameters")]
    SampleShape {
        /// The learner's context dimension.
        context_dim: usize,
        /// Its number of features.
        n_phi: usize,
        /// Its number of parameters.
        n_theta: usize,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample whose single feature tags it with `id`.
    fn sample(id: f64, reward: f64) -> Sample {
        Sample {
            context: vec![id],
            features: DVector::from_element(1, id),
            theta: DVector::zeros(1),
            reward,
        }
    }

    fn ids(memory: &Memory) -> Vec<f64> {
        memory.samples().map(|s| s.features[0]).collect()
    }

    #[test]
    fn window_drops_the_oldest() {
        let mut memory = Memory::new(&MemoryConfig::SlidingWindow { capacity: 3 }, 2);
        for id in 0..5 {
            memory.push(id % 2, sample(id as f64, 100.0 - id as f64));
        }
        assert_eq!(memory.len(), 3);
        assert_eq!(ids(&memory), [2.0, 3.0, 4.0]);
    }

    #[test]
    fn best_per_task_keeps_each_tasks_best_and_older_ties() {
        let mut memory = Memory::new(&MemoryConfig::BestPerTask { per_task: 2 }, 3);
        // Task 0 gets rewards 1, 5, 3, 5, 0; task 1 gets -10 only (worse than anything in
        // task 0, but kept because it is task 1's best); task 2 stays empty.
        let pushes = [
            (0, 0.0, 1.0),
            (0, 1.0, 5.0),
            (1, 2.0, -10.0),
            (0, 3.0, 3.0),
            (0, 4.0, 5.0),
            (0, 5.0, 0.0),
        ];
        for (task, id, reward) in pushes {
            memory.push(task, sample(id, reward));
        }
        assert_eq!(memory.len(), 3);
        // The two 5s of task 0, the older one first; then task 1's only sample.
        assert_eq!(ids(&memory), [1.0, 4.0, 2.0]);
        // A third 5 ties with the kept ones and loses to them.
        memory.push(0, sample(6.0, 5.0));
        assert_eq!(ids(&memory), [1.0, 4.0, 2.0]);
        memory.push(0, sample(7.0, 6.0));
        assert_eq!(ids(&memory), [7.0, 1.0, 2.0]);
    }

    #[test]
    fn an_undone_push_leaves_the_memory_as_it_was() {
        let configs = [
            MemoryConfig::SlidingWindow { capacity: 3 },
            MemoryConfig::BestPerTask { per_task: 2 },
        ];
        for config in configs {
            let mut memory = Memory::new(&config, 2);
            // Each push undone on every state from empty to full: new best, worst and ties.
            for (id, reward) in [(0.0, 1.0), (1.0, 5.0), (2.0, 3.0), (3.0, 5.0), (4.0, 0.0), (5.0, 9.0)] {
                for (task, trial) in [(0, 4.0), (0, 5.0), (0, -1.0), (1, 2.0), (0, 10.0)] {
                    let before = memory.clone();
                    let pushed = memory.push(task, sample(99.0, trial));
                    memory.undo(task, pushed);
                    assert_eq!(memory, before, "{config:?}: reward {trial} for task {task}");
                }
                memory.push(0, sample(id, reward));
            }
        }
    }

    #[test]
    fn a_saved_memory_that_does_not_fit_says_why() {
        let window = |capacity| Memory::new(&MemoryConfig::SlidingWindow { capacity }, 2);
        let per_task = |per_task, tasks| Memory::new(&MemoryConfig::BestPerTask { per_task }, tasks);
        assert_eq!(window(3).check_fits(&window(3), 1, 1, 1), Ok(()));
        assert_eq!(
            window(4).check_fits(&window(3), 1, 1, 1),
            Err(MemoryFitError::Window {
                capacity: 4,
                held: 0,
                expected: 3
            })
        );
        let error = per_task(2, 3).check_fits(&per_task(2, 4), 1, 1, 1).unwrap_err();
        assert_eq!(error.to_string(), "a per-task memory of 2 x 3 tasks, expected 2 x 4");
        assert_eq!(
            window(3).check_fits(&per_task(3, 2), 1, 1, 1),
            Err(MemoryFitError::Kind)
        );
        let mut saved = window(3);
        saved.push(0, sample(0.0, 1.0));
        assert_eq!(saved.check_fits(&window(3), 1, 1, 1), Ok(()));
        assert_eq!(
            saved.check_fits(&window(3), 2, 1, 1).unwrap_err().to_string(),
            "a sample that does not have 2 context coordinates, 1 features and 1 parameters"
        );
    }
}
