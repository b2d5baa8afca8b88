//! The Python packages from `cargo test`: a virtual environment in the build directory with the
//! worker package (`processes/worker/python`) installed from its sources (pip fetches iceoryx2
//! from PyPI once), its unittest suite run against this build's `acps`, and its policy reader
//! checked against the learner's own numbers; and the `acps` package (`python/`) built from this
//! checkout by maturin, with its own suite.

use crate::problems::{self, LONG_BOWL, bowl_toml, bowl_worker};
use crate::{run_name, succeeded, temp_dir};
use acps_experiments::records::SavedPolicy;
use acps_wire::ipc;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The package's directory.
fn package() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../worker/python")
}

/// The build directory (`target/`), from the binary under test (`target/<profile>/acps`).
fn target_dir() -> PathBuf {
    let acps = Path::new(env!("CARGO_BIN_EXE_acps"));
    acps.parent()
        .and_then(Path::parent)
        .expect("the acps binary lies in target/<profile>/")
        .to_path_buf()
}

/// What the venv needs beside the worker package to build the acps package without build
/// isolation (so that rebuilds reuse one interpreter path and the workspace's artifacts).
const BUILD_REQUIREMENTS: [&str; 2] = ["maturin>=1.16,<2", "numpy"];

/// A hash of the worker package's sources (names and contents) and the build requirements:
/// the environment is reinstalled when it changes.
fn sources_hash() -> u64 {
    let package = package();
    let mut files = vec![package.join("pyproject.toml")];
    let mut modules: Vec<PathBuf> = std::fs::read_dir(package.join("acps_worker"))
        .expect("the package's module directory")
        .map(|entry| entry.expect("a directory entry").path())
        .filter(|path| path.is_file())
        .collect();
    modules.sort();
    files.extend(modules);
    let requirements = acps_shared::fnv1a(acps_shared::FNV_OFFSET, BUILD_REQUIREMENTS.concat().as_bytes());
    files.iter().fold(requirements, |hash, file| {
        let name = file.file_name().expect("a file name").to_string_lossy();
        let hash = acps_shared::fnv1a(hash, name.as_bytes());
        acps_shared::fnv1a(hash, &std::fs::read(file).expect("a readable source"))
    })
}

fn show(output: &Output) -> String {
    format!(
        "status {}\nstdout:\n{}\nstderr:\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// `command`'s output, or a panic saying what `what` was and showing the output.
fn run(what: &str, command: &mut Command) -> Output {
    let output = command
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start {command:?}: {e}"));
    assert!(output.status.success(), "{what} failed: {}", show(&output));
    output
}

/// The Python of `target/python-venv`, with the current package installed. Created once per
/// build directory; test threads and processes take a file lock while they check or build it.
fn python() -> &'static Path {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let target = target_dir();
        let venv = target.join("python-venv");
        let lock_path = target.join("python-venv.lock");
        let lock = std::fs::File::create(&lock_path).expect("the venv's lock file");
        lock.lock().expect("locking the venv");
        let stamp = venv.join("acps-sources");
        let wanted = format!("{:016x}", sources_hash());
        let python = venv.join("bin/python");
        if std::fs::read_to_string(&stamp).ok().as_deref() != Some(wanted.as_str()) || !python.exists() {
            let _ = std::fs::remove_dir_all(&venv);
            run(
                "creating a Python virtual environment (python3 with the venv module is needed)",
                Command::new("python3").arg("-m").arg("venv").arg(&venv),
            );
            let output = Command::new(&python)
                .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check"])
                // With the examples' MuJoCo, which the test of the MuJoCo example needs, and
                // what builds the acps package (`acps_python`).
                .arg(format!("{}[examples]", package().display()))
                .args(BUILD_REQUIREMENTS)
                .output()
                .expect("pip runs");
            assert!(
                output.status.success(),
                "pip could not install the Python worker package with its examples' dependencies \
                 and maturin (iceoryx2, mujoco, maturin; is PyPI reachable from this machine?): {}",
                show(&output)
            );
            std::fs::write(&stamp, &wanted).expect("writing the venv's stamp");
        }
        lock.unlock().expect("unlocking the venv");
        python
    })
}

/// The venv's Python with the `acps` package of this checkout installed: built by maturin
/// into this build directory (the workspace's own artifacts, so only the extension module
/// compiles), once per test process, since its Rust sources are the whole workspace.
fn acps_python() -> &'static Path {
    static INSTALLED: OnceLock<&'static Path> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        let python = python();
        let lock = std::fs::File::create(target_dir().join("python-venv.lock")).expect("the venv's lock file");
        lock.lock().expect("locking the venv");
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        run(
            "building and installing the acps package (pip install ./python)",
            Command::new(python)
                .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check"])
                .args(["--no-build-isolation", "--no-deps", "--force-reinstall"])
                .arg(root.join("python"))
                .env("CARGO_TARGET_DIR", target_dir())
                // pip runs the venv's `maturin` by name.
                .env("PATH", on_path(python.parent().expect("the venv's bin/"))),
        );
        lock.unlock().expect("unlocking the venv");
        python
    })
}

/// `PATH` with `dir` first.
fn on_path(dir: &Path) -> std::ffi::OsString {
    let rest = std::env::var_os("PATH").unwrap_or_default();
    std::env::join_paths(std::iter::once(dir.to_path_buf()).chain(std::env::split_paths(&rest)))
        .expect("a PATH without separators in its parts")
}

#[test]
fn python_package_unittests_pass() {
    // From the tests' own directory, so that `import acps` is the installed package and not
    // the sources beside it (which lack the built extension).
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python/tests");
    let output = Command::new(acps_python())
        .args(["-m", "unittest", "discover", "-v", "-s", ".", "-t", "."])
        .current_dir(tests)
        .output()
        .expect("the venv's python runs");
    assert!(
        output.status.success(),
        "the acps package's tests failed: {}",
        show(&output)
    );
}

#[test]
fn python_worker_unittests_pass() {
    let output = Command::new(python())
        .args(["-m", "unittest", "discover", "-v", "-s", "tests", "-t", "."])
        .current_dir(package())
        .env("ACPS_BIN", env!("CARGO_BIN_EXE_acps"))
        .output()
        .expect("the venv's python runs");
    assert!(
        output.status.success(),
        "the Python worker's tests failed: {}",
        show(&output)
    );
}

/// Python's means of the policy file at `path` at `contexts`, as f64 bits.
fn python_means(path: &Path, contexts: &[Vec<f64>]) -> Vec<Vec<u64>> {
    let script = "import json, struct, sys, acps_worker\n\
        policy = acps_worker.Policy.load(sys.argv[1])\n\
        bits = lambda x: struct.unpack('<Q', struct.pack('<d', x))[0]\n\
        contexts = json.loads(sys.stdin.read())\n\
        print(json.dumps([[bits(t) for t in policy.mean(c)] for c in contexts]))\n";
    let mut child = Command::new(python())
        .args(["-c", script])
        .arg(path)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the venv's python runs");
    let input = serde_json::to_string(contexts).unwrap();
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(output.status.success(), "Policy.mean failed: {}", show(&output));
    serde_json::from_slice(&output.stdout).expect("Python printed the means' bits as JSON")
}

#[test]
fn policy_means_are_rusts_bit_for_bit() {
    let root = temp_dir("python-policies");
    // Quadratic features of 2 and 3 dimensions (6 and 10 features: nalgebra's dot product sums
    // blocks of 8 differently) and polar-quadratic ones.
    let experiments: [&[&str]; 3] = [&["function"], &["dims", "--n-s", "3"], &["grid"]];
    for (index, experiment) in experiments.iter().enumerate() {
        let out = root.join(index.to_string());
        let mut args: Vec<&str> = vec!["experiment"];
        args.extend_from_slice(experiment);
        args.extend_from_slice(&["--runs", "1", "--episodes", "60", "--method", "random", "-q", "--out"]);
        let output = Command::new(env!("CARGO_BIN_EXE_acps"))
            .args(&args)
            .arg(&out)
            .output()
            .expect("acps runs");
        assert!(output.status.success(), "acps {args:?}: {}", show(&output));
        let path = SavedPolicy::path(&out, "random", 0);
        let (saved, restored) = SavedPolicy::load(&path).unwrap();
        let problem = &saved.problem;
        let mut contexts: Vec<Vec<f64>> = problem.test_contexts.clone();
        contexts.extend(problem.training_contexts.iter().cloned());
        // Off the grids too: negative, tiny and large values.
        let dim = problem.context_dim();
        contexts.push((0..dim).map(|i| -0.37 * (i as f64 + 1.0)).collect());
        contexts.push((0..dim).map(|i| 1e-9 * (i as f64 + 3.0)).collect());
        contexts.push((0..dim).map(|i| -1234.5 + i as f64).collect());
        let rust: Vec<Vec<u64>> = contexts
            .iter()
            .map(|s| restored.greedy(s).iter().map(|t| t.to_bits()).collect())
            .collect();
        let python = python_means(&path, &contexts);
        for ((context, rust), python) in contexts.iter().zip(&rust).zip(&python) {
            assert_eq!(
                python,
                rust,
                "{}: the means at {context:?} differ (Python vs Rust, as f64 bits)",
                path.display()
            );
        }
        assert_eq!(python.len(), contexts.len());
    }
}

/// The command line of the Python bowl worker (processes/worker/python/examples/bowl.py).
fn python_bowl() -> String {
    format!(
        "'{}' '{}'",
        python().display(),
        package().join("examples/bowl.py").display()
    )
}

/// The bowl problem, shortened by `args`, on 2 workers of `command`: its summary.json's bytes.
fn bowl_summary(command: &str, test: &str, dir: &Path, args: &[&str]) -> Vec<u8> {
    let out = dir.join(test);
    let mut all = vec!["-q"];
    all.extend_from_slice(args);
    succeeded(&problems::run(&bowl_toml(), command, "2", test, &out, &all));
    std::fs::read(out.join("summary.json")).unwrap()
}

#[test]
fn python_bowl_workers_give_rust_bowl_workers_bits() {
    let dir = temp_dir("python-bowl");
    let rust = bowl_summary(&format!("'{}'", bowl_worker().display()), "bowl-rust", &dir, &[]);
    let python = bowl_summary(&python_bowl(), "bowl-python", &dir, &[]);
    assert!(
        python == rust,
        "summary.json of 2 Python workers differs from 2 Rust workers':\n{}\n{}",
        String::from_utf8_lossy(&python),
        String::from_utf8_lossy(&rust)
    );
    // Batch workers (numpy, one call per batch), with a window wide enough for batches.
    let wide = ["--in-flight", "32"];
    let rust = bowl_summary(&format!("'{}'", bowl_worker().display()), "bowl-rust-wide", &dir, &wide);
    let batch = bowl_summary(&format!("{} --batch", python_bowl()), "bowl-batch", &dir, &wide);
    assert!(
        batch == rust,
        "summary.json of 2 Python batch workers differs from 2 Rust workers':\n{}\n{}",
        String::from_utf8_lossy(&batch),
        String::from_utf8_lossy(&rust)
    );
    let rust_batch = bowl_summary(
        &format!("'{}' --batch", bowl_worker().display()),
        "bowl-rust-batch",
        &dir,
        &wide,
    );
    assert!(
        rust_batch == rust,
        "summary.json of 2 Rust batch workers differs from 2 Rust workers':\n{}\n{}",
        String::from_utf8_lossy(&rust_batch),
        String::from_utf8_lossy(&rust)
    );
}

#[test]
fn a_sigkilled_python_worker_changes_nothing() {
    let dir = temp_dir("python-bowl-kill");
    let shape = LONG_BOWL;
    let reference = bowl_summary(&format!("'{}'", bowl_worker().display()), "kill-ref", &dir, &shape);
    // Each worker writes its PID (exec keeps it) before it becomes the Python bowl worker.
    let pids = dir.join("pids");
    std::fs::create_dir_all(&pids).unwrap();
    let command = format!(
        "sh -c 'echo $$ > {}/$ACPS_WORKER_INDEX; exec {}'",
        pids.display(),
        python_bowl().replace('\'', "")
    );
    let out = dir.join("killed");
    let name = run_name("py-kill");
    let mut learner = Command::new("timeout")
        .args(["--signal=KILL", "180", env!("CARGO_BIN_EXE_acps"), "run", "--config"])
        .arg(bowl_toml())
        .args([
            "--worker-command",
            &command,
            "--workers",
            "2",
            "--run",
            name.as_str(),
            "-q",
        ])
        .args(shape)
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Learning has begun (a checkpoint after every update) and worker 0 is known: kill it.
    let victim = pids.join("0");
    problems::wait_for_learning(&mut learner, &out, || victim.exists());
    let pid = std::fs::read_to_string(&victim).unwrap().trim().to_string();
    let killed = Command::new("kill").args(["-9", &pid]).status().unwrap();
    assert!(killed.success(), "worker 0 (PID {pid}) was gone before it was killed");
    assert!(!out.join("summary.json").exists(), "killed before the end");
    let output = learner.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "the run with a killed worker failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    crate::assert_clean(&name);
    let summary = std::fs::read(out.join("summary.json")).unwrap();
    assert!(summary == reference, "a killed Python worker changed the result");
    assert!(ipc::live_nodes(&name).is_ok_and(|alive| alive == 0));
}

#[test]
fn the_mujoco_arm_learns_to_reach_through_python_workers() {
    let dir = temp_dir("mujoco-reach");
    let example = package().join("examples");
    let command = format!(
        "'{}' '{}'",
        python().display(),
        example.join("mujoco_reach.py").display()
    );
    let out = dir.join("run");
    // Briefly: one run of 200 episodes (README's command runs 2 x 1500).
    let shape = ["-q", "--runs", "1", "--episodes", "200"];
    succeeded(&problems::run(
        &example.join("mujoco_reach.toml"),
        &command,
        "2",
        "mujoco-reach",
        &out,
        &shape,
    ));
    let curves = std::fs::read_to_string(out.join("curves.csv")).unwrap();
    let scores: Vec<f64> = curves
        .lines()
        .skip(1)
        .map(|line| line.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    let (first, last) = (scores[0], *scores.last().unwrap());
    // The arm starts 55 cm from the targets on average; 200 episodes bring it within 20 cm.
    assert!(first > 40.0 && last < 0.5 * first, "distance {first} cm -> {last} cm");
    assert!(out.join("curves.png").exists() && out.join("policies").is_dir());
}
