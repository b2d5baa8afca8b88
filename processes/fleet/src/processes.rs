//! Worker processes a fleet starts, and their scheduling priority.

use std::process::Child;
use std::time::{Duration, Instant};

/// True when every process of a fleet of `workers` (the learner included) has a core of its own.
fn cores_to_spare(workers: usize) -> bool {
    workers < std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// How long the learner and the workers of a fleet of `workers` poll before blocking: only
/// when every process has a core of its own, since polling processes that share cores slow
/// each other down.
pub fn spin(workers: usize) -> Duration {
    if cores_to_spare(workers) {
        Duration::from_micros(50)
    } else {
        Duration::ZERO
    }
}

/// The niceness of started workers unless the user chooses: 10 when the fleet shares cores with
/// the learner, else 0. Every worker waits for the learner's answers, so the learner must get a
/// core as soon as it wakes; at equal priority the scheduler lets a worker finish its time
/// slice first (measured in docs/FLEET.md#throughput).
pub fn default_nice(workers: usize) -> u8 {
    if cores_to_spare(workers) { 0 } else { 10 }
}

/// The largest niceness (the lowest priority) of Linux.
pub const MAX_NICE: u8 = 19;

/// The scheduling priority could not be lowered.
#[derive(Debug, thiserror::Error)]
pub enum PriorityError {
    /// Beyond Linux's range.
    #[error("niceness must be in 0..={MAX_NICE}, got {0}")]
    OutOfRange(u8),
    /// The kernel refused.
    #[error("setting the niceness to {0}: {1}")]
    Set(u8, std::io::Error),
    /// The current niceness could not be read.
    #[error("reading the niceness: {0}")]
    Read(std::io::Error),
}

/// Lower this process's scheduling priority to niceness `nice` (0..=[`MAX_NICE`]) unless it
/// already runs at that niceness or above (started under `nice`, say): raising a priority
/// needs privileges. Call it before starting threads, which inherit it.
pub fn lower_priority(nice: u8) -> Result<(), PriorityError> {
    if nice > MAX_NICE {
        return Err(PriorityError::OutOfRange(nice));
    }
    if niceness()? >= i32::from(nice) {
        return Ok(());
    }
    // SAFETY: setpriority only reads its integer arguments.
    let result = unsafe { libc::setpriority(libc::PRIO_PROCESS as _, 0, nice.into()) };
    if result != 0 {
        return Err(PriorityError::Set(nice, std::io::Error::last_os_error()));
    }
    Ok(())
}

/// The calling thread's niceness.
fn niceness() -> Result<i32, PriorityError> {
    // getpriority returns -1 both for niceness -1 and for an error; errno tells them apart.
    // SAFETY: errno is this thread's; getpriority only reads its integer arguments.
    let nice = unsafe {
        *libc::__errno_location() = 0;
        libc::getpriority(libc::PRIO_PROCESS as _, 0)
    };
    let error = std::io::Error::last_os_error();
    if nice == -1 && error.raw_os_error() != Some(0) {
        return Err(PriorityError::Read(error));
    }
    Ok(nice)
}

/// How many of `children` are still running.
pub fn running(children: &mut [Child]) -> usize {
    children
        .iter_mut()
        .map(|child| matches!(child.try_wait(), Ok(None)))
        .filter(|&running| running)
        .count()
}

/// How many of `children` ended with a failure: a status other than 0, or a signal.
pub fn failed(children: &mut [Child]) -> usize {
    children
        .iter_mut()
        .map(|child| matches!(child.try_wait(), Ok(Some(status)) if !status.success()))
        .filter(|&failed| failed)
        .count()
}

/// How `children` ended, counted by kind: `2 with status 1, 1 killed by signal 9`; those not
/// ended yet are left out. A worker that stopped on an error exits with a status other than 0,
/// which tells the user whether to look for an error above.
pub fn exits(children: &mut [Child]) -> String {
    use std::os::unix::process::ExitStatusExt as _;
    let mut kinds: Vec<(String, usize)> = Vec::new();
    for child in children {
        let Ok(Some(status)) = child.try_wait() else {
            continue;
        };
        let kind = match (status.code(), status.signal()) {
            (Some(code), _) => format!("with status {code}"),
            (None, Some(signal)) => format!("killed by signal {signal}"),
            (None, None) => format!("{status}"),
        };
        match kinds.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, count)) => *count += 1,
            None => kinds.push((kind, 1)),
        }
    }
    kinds
        .iter()
        .map(|(kind, count)| format!("{count} {kind}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Wait for the workers to leave (they stop when the learner says the run is over or is gone);
/// kill any that does not within a few seconds, or that cannot be waited for.
pub fn reap(children: &mut [Child]) {
    let deadline = Instant::now() + Duration::from_secs(5);
    for child in children.iter_mut() {
        while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if !matches!(child.try_wait(), Ok(Some(_))) {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workers_yield_to_the_learner_only_when_they_share_its_cores() {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(default_nice(cores), 10, "W = cores: the learner shares a core");
        assert_eq!(spin(cores), Duration::ZERO);
        if cores > 1 {
            assert_eq!(default_nice(cores - 1), 0, "a core to spare for the learner");
            assert!(spin(cores - 1) > Duration::ZERO);
        }
    }

    #[test]
    fn priority_is_only_ever_lowered() {
        // Linux keeps a niceness per thread, and each test runs on a thread of its own.
        lower_priority(5).unwrap();
        assert_eq!(niceness().unwrap(), 5);
        lower_priority(3).expect("a nicer thread keeps its niceness instead of failing");
        assert_eq!(niceness().unwrap(), 5);
        lower_priority(7).unwrap();
        assert_eq!(niceness().unwrap(), 7);
    }

    #[test]
    fn a_niceness_beyond_linux_range_is_refused() {
        let error = lower_priority(MAX_NICE + 1).unwrap_err().to_string();
        assert_eq!(error, "niceness must be in 0..=19, got 20");
    }
}
