//! Record files and checkpoints through the library's run directory: a run resumed from its
//! checkpoints writes the same bytes whatever was appended to its record files after them, and
//! record files cut short of, or changed before, their checkpoint's mark are refused by name; a
//! batched run (one call for every job's ready tasks) writes the same bytes, also resumed.

use acps_experiments::run_dir::{RunDir, RunDirError};
use acps_experiments::settings::ExperimentFile;
use acps_learner::Method;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

const OUTPUTS: [&str; 5] = [
    "summary.json",
    "curves.csv",
    "runs.csv",
    "selections.csv",
    "updates.csv",
];

fn settings() -> ExperimentFile {
    ExperimentFile {
        runs: Some(2),
        episodes: Some(300),
        methods: Some(vec![Method::Random, Method::MonotonicProgress]),
        ..Default::default()
    }
}

fn out(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("acps-records-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Run the function experiment into `dir` with a checkpoint every round, resuming if asked.
fn run(dir: &Path, resume: bool) -> Result<(), RunDirError> {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../experiments/function-fig4.toml");
    let run = RunDir::plan(Some(&file), &settings(), Some(dir.to_path_buf()))?.checkpointing(1, resume)?;
    run.prepare()?;
    run.in_process(true, &AtomicBool::new(false), &|_, _| Ok(()))?;
    Ok(())
}

fn outputs(dir: &Path) -> Vec<Vec<u8>> {
    OUTPUTS
        .iter()
        .map(|name| std::fs::read(dir.join(name)).unwrap())
        .collect()
}

/// Every record file of the run in `dir`.
fn record_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "records"))
        .collect();
    files.sort();
    files
}

#[test]
fn records_appended_after_the_checkpoint_are_cut_on_resume() {
    let dir = out("appended");
    run(&dir, false).unwrap();
    let reference = outputs(&dir);
    let files = record_files(&dir);
    assert_eq!(files.len(), 2 * 2, "one per method and run");
    // As if the process had written records after its last checkpoint and then been killed:
    // whole frames and a cut one.
    for file in &files {
        let mut bytes = std::fs::read(file).unwrap();
        let tail = bytes[bytes.len() - 50..].to_vec();
        bytes.extend_from_slice(&tail);
        bytes.extend_from_slice(&tail[..7]);
        std::fs::write(file, bytes).unwrap();
    }
    run(&dir, true).unwrap();
    assert!(outputs(&dir) == reference, "the resumed run writes the same bytes");
    // Resumed after every job had finished, this process performed nothing.
    let report = json(&dir.join("run.json"));
    assert_eq!(
        (report["resumed"].as_bool(), report["rollouts"].as_u64()),
        (Some(true), Some(0))
    );
    let _ = std::fs::remove_dir_all(dir);
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn run_json_says_what_the_run_did() {
    let dir = out("report");
    run(&dir, false).unwrap();
    let (report, summary) = (json(&dir.join("run.json")), json(&dir.join("summary.json")));
    let methods = summary["methods"].as_object().unwrap();
    let evaluations: u64 = methods
        .values()
        .map(|m| m["evaluation_rollouts"].as_u64().unwrap())
        .sum();
    // Monotonic progress first rolls out the initial policy once on every training context.
    let baselines = 2 * summary["training_contexts"].as_array().unwrap().len() as u64;
    assert_eq!(report["mode"], "in-process");
    assert_eq!(report["resumed"], false);
    assert_eq!(report["episodes"], 2 * 2 * 300);
    assert_eq!(
        report["rollouts"].as_u64().unwrap(),
        1200 + evaluations + baselines,
        "{report}"
    );
    let (rate, seconds) = (
        report["rollouts_per_s"].as_f64().unwrap(),
        report["seconds"].as_f64().unwrap(),
    );
    assert!((rate * seconds - report["rollouts"].as_f64().unwrap()).abs() < 1e-6 * rate * seconds);
    let workers = report["workers"].as_f64().unwrap();
    assert!(workers >= 1.0);
    assert!((report["rollouts_per_s_per_worker"].as_f64().unwrap() * workers - rate).abs() < 1e-9 * rate);
    assert_eq!(
        (report["failed_training"].as_u64(), report["failed_evaluation"].as_u64()),
        (Some(0), Some(0))
    );
    assert!(report["reissued"].is_null(), "{report}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn record_files_cut_short_of_or_changed_before_their_mark_are_refused_by_name() {
    let dir = out("refused");
    run(&dir, false).unwrap();
    let victim = record_files(&dir)[1].clone();
    let good = std::fs::read(&victim).unwrap();
    let cases: [(&str, Vec<u8>); 3] = [
        ("truncated", good[..good.len() - 10].to_vec()),
        ("corrupted", {
            let mut bad = good.clone();
            let middle = bad.len() / 2;
            bad[middle] ^= 0x04;
            bad
        }),
        ("another experiment", {
            let mut bad = good.clone();
            bad[16] ^= 0x01;
            bad
        }),
    ];
    for (what, bytes) in cases {
        std::fs::write(&victim, &bytes).unwrap();
        let error = run(&dir, true).unwrap_err();
        let message = format!(
            "{error}: {}",
            error.run_error().map_or(String::new(), |e| e.to_string())
        );
        assert!(
            message.contains(&victim.display().to_string()) && message.contains(what),
            "{what}: {message}"
        );
    }
    // Put back, it resumes.
    std::fs::write(&victim, &good).unwrap();
    run(&dir, true).unwrap();
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_checkpoint_whose_record_mark_is_missing_or_does_not_fit_its_learner_is_refused_by_name() {
    use acps_learner::checkpoint::{self, Stamp};
    let dir = out("mark");
    run(&dir, false).unwrap();
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../experiments/function-fig4.toml");
    let planned = RunDir::plan(Some(&file), &settings(), Some(dir.clone())).unwrap();
    // Jobs are method-major: random's two runs, then monotonic progress's.
    let stamp = Stamp {
        identity: planned.jobs[0].experiment.identity(),
        job: 2,
    };
    let path = dir.join("checkpoints").join("monotonic-progress-run-0.ckpt");
    let good = checkpoint::read(&path, stamp).unwrap().unwrap();
    let mut counted_wrong = good.clone();
    counted_wrong.records.as_mut().unwrap().records.episodes += 1;
    let mut unmarked = good.clone();
    unmarked.records = None;
    for (bad, says) in [
        (counted_wrong, "its record file mark counts 301 episodes"),
        (unmarked, "it records no record file"),
    ] {
        checkpoint::write(&path, stamp, &bad).unwrap();
        let error = run(&dir, true).unwrap_err();
        let message = format!(
            "{error}: {}",
            error.run_error().map_or(String::new(), |e| e.to_string())
        );
        assert!(
            message.contains(&path.display().to_string()) && message.contains(says),
            "{message}"
        );
    }
    checkpoint::write(&path, stamp, &good).unwrap();
    run(&dir, true).unwrap();
    let _ = std::fs::remove_dir_all(dir);
}

/// The function experiment into `dir` through [`RunDir::batched`], its environments built as
/// the in-process run builds them; `stop_after` rounds of batches, then `perform` says stop.
fn run_batched(dir: &Path, resume: bool, stop_after: Option<usize>) -> Result<Vec<usize>, RunDirError> {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../experiments/function-fig4.toml");
    let run = RunDir::plan(Some(&file), &settings(), Some(dir.to_path_buf()))?.checkpointing(1, resume)?;
    run.prepare()?;
    let mut environments: Vec<_> = run.jobs[0]
        .experiment
        .jobs()
        .unwrap()
        .into_iter()
        .map(|job| job.environment.unwrap())
        .collect();
    let mut sizes = Vec::new();
    let mut perform = |tasks: &[(usize, acps_shared::Task)]| {
        if stop_after.is_some_and(|rounds| sizes.len() == rounds) {
            return None;
        }
        sizes.push(tasks.len());
        Some(
            tasks
                .iter()
                .map(|(job, task)| environments[*job].rollout(task))
                .collect(),
        )
    };
    run.batched(true, &AtomicBool::new(false), &|_, _| Ok(()), &mut perform)?;
    Ok(sizes)
}

#[test]
fn a_batched_run_writes_the_in_process_bytes_and_resumes_to_them_after_a_stop() {
    let (reference, batched, stopped) = (out("batched-ref"), out("batched"), out("batched-stop"));
    run(&reference, false).unwrap();
    let sizes = run_batched(&batched, false, None).unwrap();
    assert_eq!(outputs(&batched), outputs(&reference));
    // Every job's ready tasks go in one call: 4 jobs, so batches of more than one task.
    assert!(sizes.iter().any(|&n| n >= 4), "{sizes:?}");
    let error = run_batched(&stopped, false, Some(40)).unwrap_err();
    assert!(
        matches!(
            error.run_error(),
            Some(acps_experiments::experiment::RunError::Interrupted)
        ),
        "{error}"
    );
    run_batched(&stopped, true, None).unwrap();
    assert_eq!(outputs(&stopped), outputs(&reference));
    for dir in [reference, batched, stopped] {
        std::fs::remove_dir_all(dir).unwrap();
    }
}
