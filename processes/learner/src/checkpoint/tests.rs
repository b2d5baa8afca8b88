//! The file format: round trips, and every kind of bad file refused with its own error.

use super::*;
use crate::creps::{CRepsConfig, FeatureMap, MemoryConfig};
use crate::selection::RoundRobin;
use crate::{LearnerConfig, SearchConfig, run_in_process};
use acps_shared::{ContextSpace, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Task};

/// A stateless environment: reward -(theta - s)^2 summed.
struct Quadratic;

/// The spec of an environment named `name` without settings.
fn spec(name: &str) -> EnvironmentSpec {
    EnvironmentSpec::new(name, [0; 3], &()).unwrap()
}

impl Environment for Quadratic {
    fn spec(&self) -> EnvironmentSpec {
        spec("quadratic")
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        2
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let cost: f64 = task.theta.iter().map(|t| (t - task.context[0]).powi(2)).sum();
        Outcome::new(task.id, -cost, cost)
    }
}

fn learner(seed: u64, episodes: u64) -> Learner {
    learner_in(seed, episodes, Quadratic.spec())
}

/// A learner of a problem defined for `environment`.
fn learner_in(seed: u64, episodes: u64, environment: EnvironmentSpec) -> Learner {
    let problem = Problem {
        name: "quadratic".into(),
        training_contexts: vec![vec![0.0], vec![0.5], vec![1.0]],
        test_contexts: vec![vec![0.25], vec![0.75]],
        space: ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap(),
        theta0: vec![0.0, 0.0],
        score: ScoreAggregate::Mean,
        metric: "cost".into(),
        environment,
    };
    let selector = Box::new(RoundRobin::all(problem.training_contexts.clone()).unwrap());
    let config = LearnerConfig {
        seed,
        episodes,
        in_flight: 2,
        eval_every: 10,
        search: Some(SearchConfig::CReps(CRepsConfig {
            update_every: 10,
            memory: MemoryConfig::SlidingWindow { capacity: 20 },
            features: FeatureMap::Affine,
            ..CRepsConfig::default()
        })),
    };
    Learner::new(config, problem, selector).unwrap()
}

const STAMP: Stamp = Stamp {
    identity: 0x1234_5678_9abc_def0,
    job: 3,
};

/// A checkpoint half way through a run.
fn half_way() -> Checkpoint {
    let mut learner = learner(7, 60);
    let mut environment = Quadratic;
    for _ in 0..40 {
        let task = learner.ask().unwrap();
        learner.tell(environment.rollout(&task)).unwrap();
    }
    Checkpoint::take(&learner, &environment)
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("acps-checkpoint-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn encoding_round_trips_and_the_header_is_as_documented() {
    let checkpoint = half_way();
    let bytes = encode(STAMP, &checkpoint);
    assert_eq!(&bytes[..8], b"ACPSCKPT");
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), FORMAT_VERSION);
    assert_eq!(u64::from_le_bytes(bytes[16..24].try_into().unwrap()), STAMP.identity);
    assert_eq!(u64::from_le_bytes(bytes[24..32].try_into().unwrap()), STAMP.job);
    assert_eq!(
        u64::from_le_bytes(bytes[32..40].try_into().unwrap()) as usize,
        bytes.len() - HEADER_LEN
    );
    let decoded = decode(&bytes, STAMP).unwrap();
    assert_eq!(encode(STAMP, &decoded), bytes);
}

#[test]
fn a_restored_learner_finishes_like_the_original() {
    let mut original = learner(7, 60);
    let mut environment = Quadratic;
    for _ in 0..33 {
        let task = original.ask().unwrap();
        original.tell(environment.rollout(&task)).unwrap();
    }
    let saved = decode(&encode(STAMP, &Checkpoint::take(&original, &environment)), STAMP).unwrap();
    let mut restored = learner(7, 60);
    saved.apply(&mut restored, &mut Quadratic).unwrap();
    run_in_process(&mut original, &mut environment).unwrap();
    run_in_process(&mut restored, &mut Quadratic).unwrap();
    assert!(restored.stats().updates > 0);
    let final_bytes = |l: &Learner| encode(STAMP, &Checkpoint::take(l, &Quadratic));
    assert_eq!(final_bytes(&restored), final_bytes(&original));
}

#[test]
fn files_are_written_atomically_and_read_back() {
    let dir = temp_dir("files");
    let path = dir.join("job.ckpt");
    assert!(read(&path, STAMP).unwrap().is_none(), "no file, no checkpoint");
    let checkpoint = half_way();
    write(&path, STAMP, &checkpoint).unwrap();
    // Overwriting replaces the file; no temporary file stays behind.
    write(&path, STAMP, &checkpoint).unwrap();
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names, ["job.ckpt"]);
    let read_back = read(&path, STAMP).unwrap().unwrap();
    assert_eq!(encode(STAMP, &read_back), encode(STAMP, &checkpoint));
    let _ = std::fs::remove_dir_all(dir);
}

/// The error `bytes` give when read from a file, and its message.
fn refused(dir: &Path, bytes: &[u8], stamp: Stamp) -> (CheckpointDecodeError, String) {
    let path = dir.join("bad.ckpt");
    std::fs::write(&path, bytes).unwrap();
    let error = read(&path, stamp).unwrap_err();
    let message = error.to_string();
    assert!(
        message.starts_with(&format!("checkpoint {}: ", path.display())),
        "the message names the file: {message}"
    );
    match error {
        CheckpointReadError::Decode { source, .. } => (source, message),
        CheckpointReadError::Io { .. } => panic!("a file that exists is read: {message}"),
    }
}

#[test]
fn truncated_files_are_refused_as_truncated() {
    let dir = temp_dir("truncated");
    let bytes = encode(STAMP, &half_way());
    for len in [
        0,
        5,
        8,
        30,
        HEADER_LEN - 1,
        HEADER_LEN,
        HEADER_LEN + 1,
        bytes.len() / 2,
        bytes.len() - 1,
    ] {
        let (kind, message) = refused(&dir, &bytes[..len], STAMP);
        assert!(
            matches!(kind, CheckpointDecodeError::Truncated { len: l, .. } if l == len as u64),
            "{len} bytes: {message}"
        );
        assert!(message.contains("truncated"), "{message}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    let (kind, message) = refused(&dir, &longer, STAMP);
    assert!(matches!(kind, CheckpointDecodeError::Corrupt(_)), "{message}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn every_flipped_byte_is_detected() {
    let bytes = encode(STAMP, &half_way());
    for at in 0..bytes.len() {
        for flip in [0x01, 0x80] {
            let mut bad = bytes.clone();
            bad[at] ^= flip;
            let kind = decode(&bad, STAMP).unwrap_err();
            let expected = match at {
                0..8 => matches!(kind, CheckpointDecodeError::NotACheckpoint),
                8..12 => matches!(kind, CheckpointDecodeError::Version { .. }),
                // The length: too long a file reads as corrupt, too short as truncated, and
                // beyond any checkpoint as too large.
                32..40 => matches!(
                    kind,
                    CheckpointDecodeError::Truncated { .. }
                        | CheckpointDecodeError::Corrupt(_)
                        | CheckpointDecodeError::TooLarge { .. }
                ),
                _ => matches!(kind, CheckpointDecodeError::Corrupt(_)),
            };
            assert!(expected, "byte {at} ^ {flip:#x}: {kind}");
        }
    }
}

#[test]
fn foreign_wrong_job_wrong_magic_and_wrong_version_are_named() {
    let dir = temp_dir("foreign");
    let bytes = encode(STAMP, &half_way());
    let other_run = Stamp {
        identity: 0xfeed,
        ..STAMP
    };
    let (kind, message) = refused(&dir, &bytes, other_run);
    assert!(
        matches!(kind, CheckpointDecodeError::Foreign { found, expected } if found == STAMP.identity && expected == 0xfeed)
    );
    assert!(
        message.contains("another experiment")
            && message.contains("123456789abcdef0")
            && message.contains("000000000000feed"),
        "{message}"
    );
    let (kind, message) = refused(&dir, &bytes, Stamp { job: 4, ..STAMP });
    assert!(
        matches!(kind, CheckpointDecodeError::WrongJob { found: 3, expected: 4 }),
        "{message}"
    );

    let (kind, message) = refused(&dir, b"{\"not\": \"a checkpoint\"}", STAMP);
    assert!(matches!(kind, CheckpointDecodeError::NotACheckpoint), "{message}");
    assert!(message.contains("not an acps checkpoint"), "{message}");

    // A future version, with a consistent checksum: refused by version before anything else.
    let mut future = bytes.clone();
    future[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let checksum = fnv1a(fnv1a(FNV_OFFSET, &future[..40]), &future[HEADER_LEN..]);
    future[40..48].copy_from_slice(&checksum.to_le_bytes());
    let (kind, message) = refused(&dir, &future, STAMP);
    assert!(
        matches!(kind, CheckpointDecodeError::Version { found, supported: FORMAT_VERSION } if found == FORMAT_VERSION + 1)
    );
    assert!(
        message.contains(&format!("format version {}", FORMAT_VERSION + 1))
            && message.contains(&format!("version {FORMAT_VERSION}")),
        "{message}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_checkpoint_of_another_learner_is_refused_by_restore() {
    let checkpoint = half_way();
    // Another seed.
    let error = checkpoint
        .clone()
        .apply(&mut learner(8, 60), &mut Quadratic)
        .unwrap_err();
    assert_eq!(
        error.to_string(),
        "the checkpoint is of a learner with seed 7, this one has seed 8"
    );
    // Another length.
    let error = checkpoint
        .clone()
        .apply(&mut learner(7, 61), &mut Quadratic)
        .unwrap_err();
    assert_eq!(
        error.to_string(),
        "the checkpoint is of a learner with episodes 60, this one has episodes 61"
    );
    // Another environment.
    let error = checkpoint
        .clone()
        .apply(&mut learner_in(7, 60, spec("cubic")), &mut Quadratic)
        .unwrap_err();
    assert_eq!(
        error.to_string(),
        format!(
            "the checkpoint is of a learner with environment {}, this one has environment {}",
            spec("quadratic"),
            spec("cubic")
        )
    );
    // An environment state for an environment that keeps none.
    let mut with_state = checkpoint;
    with_state.environment = vec![1, 2, 3];
    let error = with_state.apply(&mut learner(7, 60), &mut Quadratic).unwrap_err();
    assert!(error.to_string().starts_with("environment state: "), "{error}");
}

#[test]
fn a_remembered_rollout_no_run_of_the_problem_could_have_is_refused() {
    // A context of 1e300 reached a self-paced update as an infinite log-density ratio.
    let mut forged = half_way();
    *forged.learner.first_context_mut().unwrap() = vec![1e300];
    let error = forged.apply(&mut learner(7, 60), &mut Quadratic).unwrap_err();
    assert_eq!(
        error.to_string(),
        "the checkpoint's learner state is inconsistent: a remembered rollout's context [1e300] lies outside the problem's contexts ([0.0]..=[1.0])"
    );
    // At the edge of the space it is a context a run may have had.
    let mut edge = half_way();
    *edge.learner.first_context_mut().unwrap() = vec![1.0];
    edge.apply(&mut learner(7, 60), &mut Quadratic).unwrap();
}

/// Run `learner` to the end, taking its records after every `take_every` outcomes (0: never),
/// and return every task it handed out and every record, in order.
fn run_taking(mut learner: Learner, take_every: usize) -> (Vec<Task>, crate::Records, Learner) {
    let (mut tasks, mut records, mut told) = (Vec::new(), crate::Records::default(), 0);
    while let Some(task) = learner.ask() {
        tasks.push(task.clone());
        learner.tell(Quadratic.rollout(&task)).unwrap();
        told += 1;
        if take_every > 0 && told % take_every == 0 {
            records.extend(learner.take_records());
        }
    }
    records.extend(learner.take_records());
    (tasks, records, learner)
}

#[test]
fn taking_records_changes_nothing_the_learner_does() {
    let (tasks, records, untaken) = run_taking(learner(5, 200), 0);
    assert_eq!(records.episodes.len(), 200);
    assert_eq!(records.evaluations.len(), 21, "before training and every 10 episodes");
    assert!(!records.updates.is_empty());
    for take_every in [1, 7, 50] {
        let (tasks_taking, records_taking, taking) = run_taking(learner(5, 200), take_every);
        assert_eq!(tasks_taking, tasks, "taking every {take_every}");
        assert_eq!(records_taking, records, "taking every {take_every}");
        assert_eq!(taking.latest_score(), untaken.latest_score());
        assert_eq!(taking.rounds(), untaken.rounds());
        assert_eq!(taking.stats(), untaken.stats());
    }
}

#[test]
fn a_learner_whose_records_are_taken_has_snapshots_of_constant_size() {
    let size_after = |episodes: u64| {
        let mut learner = learner(5, episodes);
        while let Some(task) = learner.ask() {
            learner.tell(Quadratic.rollout(&task)).unwrap();
            learner.take_records();
        }
        encode(STAMP, &Checkpoint::take(&learner, &Quadratic)).len()
    };
    let untaken = |episodes: u64| {
        let mut learner = learner(5, episodes);
        run_in_process(&mut learner, &mut Quadratic).unwrap();
        encode(STAMP, &Checkpoint::take(&learner, &Quadratic)).len()
    };
    // Only the counters' variable-length integers grow (a few bytes).
    let (short, long) = (size_after(100), size_after(2000));
    assert!(
        long <= short + 32,
        "{short} bytes after 100 episodes, {long} after 2000"
    );
    assert!(
        untaken(2000) > 10 * untaken(100),
        "the history grows the snapshot when kept"
    );
}

#[test]
fn a_restored_learner_continues_its_record_counts() {
    let mut original = learner(7, 60);
    for _ in 0..33 {
        let task = original.ask().unwrap();
        original.tell(Quadratic.rollout(&task)).unwrap();
    }
    let first = original.take_records();
    let saved = decode(&encode(STAMP, &Checkpoint::take(&original, &Quadratic)), STAMP).unwrap();
    let mut restored = learner(7, 60);
    saved.apply(&mut restored, &mut Quadratic).unwrap();
    assert_eq!(restored.records_taken(), crate::RecordCounts::of(&first));
    let (_, rest, _) = run_taking(restored, 1);
    let (_, all, _) = run_taking(learner(7, 60), 0);
    let mut joined = first;
    joined.extend(rest);
    assert_eq!(joined, all);
}

mod journal_files {
    use super::*;
    use crate::checkpoint::journal::{self, JOURNAL_HEADER_LEN, JournalError, JournalMark, JournalWriter};

    /// Every record of a 60-episode run, in two parts taken half way.
    fn records() -> (crate::Records, crate::Records) {
        let mut learner = learner(7, 60);
        for _ in 0..40 {
            let task = learner.ask().unwrap();
            learner.tell(Quadratic.rollout(&task)).unwrap();
        }
        let first = learner.take_records();
        run_in_process(&mut learner, &mut Quadratic).unwrap();
        (first, learner.take_records())
    }

    /// A record file holding `first`, the mark after it, and the file's path.
    fn written(dir: &Path, first: &crate::Records) -> (PathBuf, JournalMark) {
        let path = dir.join("job.records");
        let mut writer = JournalWriter::create(&path, STAMP).unwrap();
        writer.append(first).unwrap();
        (path.clone(), writer.flush().unwrap())
    }

    fn decode_error(error: JournalError, path: &Path) -> CheckpointDecodeError {
        let message = error.to_string();
        assert!(
            message.starts_with(&format!("record file {}: ", path.display())),
            "the message names the file: {message}"
        );
        match error {
            JournalError::Decode { source, .. } => source,
            JournalError::Io { .. } => panic!("a file that exists is read: {message}"),
        }
    }

    #[test]
    fn records_read_back_as_written_and_the_header_is_as_documented() {
        let dir = temp_dir("journal-round-trip");
        let (first, second) = records();
        let (path, mark) = written(&dir, &first);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"ACPSRECS");
        assert_eq!(u64::from_le_bytes(bytes[16..24].try_into().unwrap()), STAMP.identity);
        assert_eq!(u64::from_le_bytes(bytes[24..32].try_into().unwrap()), STAMP.job);
        assert_eq!(mark.len, bytes.len() as u64);
        assert_eq!(mark.records, crate::RecordCounts::of(&first));
        assert_eq!(journal::read(&path, STAMP, &mark).unwrap(), first);
        resume_and_finish(&path, &mark, first, second);
        let _ = std::fs::remove_dir_all(dir);
    }

    /// Resume the record file at `path` from `mark` (after `first`), append `second`, and check
    /// that both parts read back in order.
    fn resume_and_finish(path: &Path, mark: &JournalMark, first: crate::Records, second: crate::Records) {
        let mut writer = JournalWriter::resume(path, STAMP, mark).unwrap();
        assert_eq!(std::fs::metadata(path).unwrap().len(), mark.len, "cut back to the mark");
        writer.append(&second).unwrap();
        let end = writer.flush().unwrap();
        let mut all = first;
        all.extend(second);
        assert_eq!(journal::read(path, STAMP, &end).unwrap(), all);
    }

    #[test]
    fn resuming_cuts_what_was_written_after_the_mark() {
        let dir = temp_dir("journal-cut");
        let (first, second) = records();
        let (path, mark) = written(&dir, &first);
        // Records written after the checkpoint, then a kill: half a frame at the end.
        let mut writer = JournalWriter::resume(&path, STAMP, &mark).unwrap();
        writer.append(&second).unwrap();
        writer.flush().unwrap();
        let len = std::fs::metadata(&path).unwrap().len();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&path)
            .unwrap()
            .set_len(len - 3)
            .unwrap();
        resume_and_finish(&path, &mark, first, second);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn truncated_corrupted_and_foreign_record_files_are_refused() {
        let dir = temp_dir("journal-refused");
        let (first, _) = records();
        let (path, mark) = written(&dir, &first);
        let good = std::fs::read(&path).unwrap();
        for len in [
            0,
            5,
            JOURNAL_HEADER_LEN - 1,
            JOURNAL_HEADER_LEN,
            good.len() / 2,
            good.len() - 1,
        ] {
            std::fs::write(&path, &good[..len]).unwrap();
            let kind = decode_error(JournalWriter::resume(&path, STAMP, &mark).err().unwrap(), &path);
            // Cut inside the header, it falls short of the header; after it, of the mark.
            let want = if len < JOURNAL_HEADER_LEN {
                JOURNAL_HEADER_LEN as u64
            } else {
                mark.len
            };
            assert!(
                matches!(kind, CheckpointDecodeError::Truncated { len: l, expected } if l == len as u64 && expected == want),
                "{len} bytes: {kind}"
            );
            assert!(kind.to_string().contains("truncated"), "{kind}");
            // Refused, the file is left as it was.
            assert_eq!(std::fs::read(&path).unwrap(), &good[..len]);
        }
        for at in [0, 9, 20, 28, JOURNAL_HEADER_LEN, JOURNAL_HEADER_LEN + 3, good.len() - 1] {
            let mut bad = good.clone();
            bad[at] ^= 0x10;
            std::fs::write(&path, &bad).unwrap();
            let kind = decode_error(journal::read(&path, STAMP, &mark).unwrap_err(), &path);
            let expected = match at {
                0..8 => matches!(kind, CheckpointDecodeError::NotARecordFile),
                8..12 => matches!(kind, CheckpointDecodeError::Version { .. }),
                16..24 => matches!(kind, CheckpointDecodeError::Foreign { .. }),
                24..32 => matches!(kind, CheckpointDecodeError::WrongJob { .. }),
                _ => matches!(kind, CheckpointDecodeError::Corrupt(_)),
            };
            assert!(expected, "byte {at}: {kind}");
        }
        std::fs::write(&path, &good).unwrap();
        let other = Stamp { job: 9, ..STAMP };
        let kind = decode_error(journal::read(&path, other, &mark).unwrap_err(), &path);
        assert!(
            matches!(kind, CheckpointDecodeError::WrongJob { found: 3, expected: 9 }),
            "{kind}"
        );
        // A FIFO in its place would block both readers; it is refused, by name.
        std::fs::remove_file(&path).unwrap();
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&path)
                .status()
                .unwrap()
                .success()
        );
        for error in [
            journal::read(&path, STAMP, &mark).unwrap_err(),
            JournalWriter::resume(&path, STAMP, &mark).err().unwrap(),
        ] {
            assert_eq!(decode_error(error, &path), CheckpointDecodeError::NotAFile("a FIFO"));
        }
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn fifos_devices_directories_and_forged_lengths_are_refused_without_blocking_or_allocating() {
    let dir = temp_dir("not-files");
    let kind = |path: &Path| match read(path, STAMP) {
        Err(CheckpointReadError::Decode {
            source: CheckpointDecodeError::NotAFile(kind),
            ..
        }) => kind,
        other => panic!("{}: {other:?}", path.display()),
    };
    // A FIFO would block the reader until a writer came; a link to /dev/zero never end.
    let fifo = dir.join("fifo.ckpt");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    assert_eq!(kind(&fifo), "a FIFO");
    let zero = dir.join("zero.ckpt");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    assert_eq!(kind(&zero), "a device");
    assert_eq!(kind(&dir), "a directory");
    // A link to a checkpoint is read as the checkpoint.
    let real = dir.join("real.ckpt");
    write(&real, STAMP, &half_way()).unwrap();
    let link = dir.join("link.ckpt");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    assert!(read(&link, STAMP).unwrap().is_some());
    // A header that announces more payload than any checkpoint has.
    let mut bytes = encode(STAMP, &half_way());
    bytes[32..40].copy_from_slice(&(1u64 << 62).to_le_bytes());
    let (error, message) = refused(&dir, &bytes, STAMP);
    assert_eq!(error, CheckpointDecodeError::TooLarge { len: 1 << 62 });
    assert!(
        message.contains("more than the 1073741824 a checkpoint may have"),
        "{message}"
    );
    // A length inside the payload that claims 2^62 bytes is an error, not an allocation.
    let claim = [253, 0, 0, 0, 0, 0, 0, 0, 0x40];
    assert!(bincode::serde::decode_from_slice::<Vec<u8>, _>(&claim, decode_config()).is_err());
    assert!(bincode::serde::decode_from_slice::<String, _>(&claim, decode_config()).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}
