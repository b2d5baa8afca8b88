//! The example runs an experiment file from a Rust program and writes the same run directory as
//! `acps experiment` would: summary, tables, policies, pictures and the resolved file.

use std::path::Path;
use std::process::Command;

#[test]
fn run_file_writes_a_run_directory_from_an_experiment_file() {
    let deps = std::env::current_exe().expect("the test's path");
    let profile = deps.parent().and_then(|d| d.parent()).expect("target/PROFILE/deps");
    let example = profile.join("examples").join("run_file");
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../experiments/function-fig4.toml");
    let out = std::env::temp_dir().join(format!("acps-run-file-{}", std::process::id()));
    let output = Command::new("timeout")
        .args(["--signal=KILL", "300"])
        .arg(&example)
        .arg(&file)
        .arg(&out)
        .output()
        .expect("the example starts");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{}\n{stdout}",
        String::from_utf8_lossy(&output.stderr)
    );
    for name in [
        "summary.json",
        "config.toml",
        "curves.csv",
        "runs.csv",
        "curves.png",
        "policies/random-run1.json",
    ] {
        assert!(out.join(name).is_file(), "{name} missing in {}", out.display());
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        (summary["runs"].as_u64(), summary["training_episodes"].as_u64()),
        (Some(2), Some(500))
    );
    // Every method of the file, each with its final score printed.
    let methods = summary["methods"].as_object().unwrap();
    assert_eq!(methods.len(), 6);
    for method in methods.keys() {
        assert!(stdout.contains(&format!("  {method}: final mean score ")), "{stdout}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}
