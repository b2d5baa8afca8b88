//! The shell commands of README.md and the docs, run as written, so that what a reader copies
//! keeps working: every command of every `sh` block runs, in its block's order, in one shell per
//! block, unless [`SKIPPED`] names it with the reason. A command the docs drop must leave that
//! list too, so the list is what the docs hold.

use crate::temp_dir;
use std::path::Path;
use std::process::Command;

/// The documents whose `sh` blocks are run.
const DOCUMENTS: [&str; 8] = [
    "README.md",
    "docs/EXPERIMENTS.md",
    "docs/FLEET.md",
    "docs/HOSTS.md",
    "docs/LIBRARY.md",
    "docs/RESULTS.md",
    "processes/worker/python/README.md",
    "python/README.md",
];

/// Commands not run here (as written, comments left out), each with the reason.
const SKIPPED: &[(&str, &str)] = &[
    (
        "cargo run --release -p acps -- learn",
        "the main job: 40-140 s of a fleet",
    ),
    ("cargo test --workspace --release", "the command that runs this test"),
    (
        "cargo build --release -p acps-worker --example bowl",
        "built by the test command (the next line runs it)",
    ),
    (
        "cargo build --release -p acps --features hosts",
        "cargo inside the tests would relink what other tests run",
    ),
    (
        "acps run --config experiments/bowl.toml --workers 0 --run mine",
        "waits for workers started by hand",
    ),
    (
        "python3 -m venv .venv && .venv/bin/pip install \"processes/worker/python[examples]\"",
        "PyPI and 200 MB; the Python tests make target/python-venv so",
    ),
    (
        "cargo run --release -p acps -- run --config processes/worker/python/examples/mujoco_reach.toml --worker-command \".venv/bin/python processes/worker/python/examples/mujoco_reach.py\" --out runs/reach",
        "needs the .venv above; the Python tests run the MuJoCo example",
    ),
    (
        ".venv/bin/pip install ./python",
        "needs the .venv above; the Python tests install the package so",
    ),
    (
        ".venv/bin/python python/examples/reach_ask_tell.py",
        "needs the .venv above; the acps package's tests run it",
    ),
    (
        ".venv/bin/acps run --config processes/worker/python/examples/reach_batch.toml --worker-command \".venv/bin/python processes/worker/python/examples/reach_batch.py --batch\"",
        "needs the .venv above; the Python tests run the batch example",
    ),
    (
        "cargo run --release -p acps -- run grid --workers 2 --out runs/grid-fleet",
        "minutes: 20 runs x 6 methods x 10,000 throws",
    ),
    (
        "cargo run --release -p acps -- run grid --workers 2",
        "minutes: 20 runs x 6 methods x 10,000 throws",
    ),
    (
        "cargo run --release -p acps -- run dartboard --workers 0 --run mine &",
        "waits for workers started by hand",
    ),
    (
        "cargo run --release -p acps -- run grid --workers 0 --run mine &",
        "waits for workers started by hand",
    ),
    (
        "cargo run --release -p acps -- worker --run mine",
        "serves the learner of the line above",
    ),
    (
        "cargo run --release -p acps -- bench",
        "minutes: every mode in 3 rounds",
    ),
    (
        "cargo run --release -p acps --features hosts -- bench --relay",
        "minutes: every mode in 3 rounds",
    ),
    (
        "cargo run --release -p acps -- bench --env analytic --rounds 5",
        "minutes: 5 rounds",
    ),
    (
        "acps run grid --sim rapier --run throw1 --workers 2 --listen tcp/10.0.0.1:7447 --out runs/throw1",
        "another host's address",
    ),
    (
        "scp learner:runs/throw1/relay.key . && acps relay --connect tcp/10.0.0.1:7447 --relay-key relay.key --workers 64",
        "another host",
    ),
    (
        "acps run grid --sim rapier --runs 4 --episodes 10000 --run throw1 --workers 2 --listen tcp/10.0.0.1:7447 --out runs/throw1",
        "another host's address",
    ),
    (
        "acps relay --connect tcp/10.0.0.1:7447 --relay-key relay.key --workers 64",
        "another host",
    ),
    ("scp 10.0.0.1:runs/throw1/relay.key .", "another host"),
    ("ssh -N -f -L 7447:127.0.0.1:7447 user@learner-host", "another host"),
    (
        "acps run grid --sim rapier --workers 0 --listen tcp/127.0.0.1:7447",
        "waits for relays; tests/launcher/hosts.rs runs learners and relays",
    ),
    (
        "acps relay --connect tcp/127.0.0.1:7447 --relay-key relay.key --workers 16",
        "serves the learner of the line above",
    ),
    (
        "acps experiment --config experiments/grid-fig8.toml",
        "minutes: 20 runs x 6 methods x 10,000 throws",
    ),
    (
        "acps experiment --config experiments/grid-fig8.toml --runs 2 --out runs/try",
        "a minute: 2 runs x 6 methods x 10,000 throws",
    ),
    (
        "acps run --config runs/try/config.toml --workers 2 --out runs/again",
        "runs the run of the line above again",
    ),
    (
        "acps experiment --config experiments/grid-fig8.toml --out runs/fig8-analytic",
        "minutes: a paper figure",
    ),
    (
        "acps experiment --config experiments/grid-fig8-rapier.toml --runs 10 --out runs/fig8-rapier-10",
        "an hour: a paper figure",
    ),
    (
        "acps experiment --config experiments/dartboard-fig10.toml --sim rapier --runs 1 --out runs/fig10-rapier",
        "an hour: a paper figure",
    ),
    (
        "acps run --config experiments/dartboard-fig10.toml --sim rapier --runs 1 --workers 2 --out runs/fig10-rapier-fleet",
        "an hour: a paper figure",
    ),
    (
        "acps experiment --config experiments/dims-fig6-ns1.toml",
        "minutes: a paper figure",
    ),
    (
        "acps experiment --config experiments/function-fig4.toml",
        "minutes: a paper figure",
    ),
    (
        "acps experiment --config experiments/toy-fig2a.toml",
        "minutes: a paper figure",
    ),
    (
        "acps experiment --config experiments/toy-fig3.toml",
        "minutes: a paper figure",
    ),
    (
        "export PATH=$PWD/target/python-venv/bin:$PATH",
        "the venv the Python tests make; its runs below are skipped",
    ),
    (
        "W=\"python processes/worker/python/examples/mujoco_reach.py\"",
        "the runs that use it are skipped",
    ),
    (
        "acps run --config reach.toml --memory window --worker-command \"$W\" --out runs/reach-window",
        "minutes: 10 runs of a MuJoCo arm",
    ),
    (
        "acps run --config reach.toml --memory best-per-task --worker-command \"$W\" --out runs/reach-best",
        "minutes: 10 runs of a MuJoCo arm",
    ),
    (
        "acps run --config reach.toml --learner c-cmaes --worker-command \"$W\" --out runs/reach-c-cmaes",
        "minutes: 10 runs of a MuJoCo arm",
    ),
    (
        "python processes/worker/python/examples/reach_floor.py",
        "needs MuJoCo (the venv)",
    ),
    (
        "acps experiment --config experiments/beyond-grid.toml --out runs/beyond-grid",
        "65 s",
    ),
    (
        "acps experiment --config experiments/beyond-grid-retire.toml --out runs/beyond-grid-retire",
        "26 s, and compared with the skipped line above",
    ),
    (
        "acps compare runs/beyond-grid --with runs/beyond-grid-retire --levels 10,5,3 --wide",
        "compares the skipped runs above",
    ),
    (
        "acps experiment --config experiments/beyond-dims.toml --out runs/beyond-dims",
        "36 s",
    ),
    (
        "acps experiment --config experiments/beyond-dims-retire.toml --out runs/beyond-dims-retire",
        "compared with the skipped line above",
    ),
    (
        "acps compare runs/beyond-dims/ns-1 --with runs/beyond-dims-retire/ns-1 --wide",
        "compares the skipped runs above",
    ),
    (
        "acps experiment --config experiments/beyond-dartboard.toml --out runs/beyond-dartboard",
        "383 s",
    ),
    (
        "acps experiment --config experiments/beyond-dartboard-retire.toml --out runs/beyond-dartboard-retire",
        "136 s",
    ),
    (
        "acps compare runs/beyond-dartboard --with runs/beyond-dartboard-retire --levels 10,5,2 --wide",
        "compares the skipped runs above",
    ),
    (
        "acps experiment --config experiments/beyond-grid-self-paced.toml --out runs/beyond-grid-self-paced",
        "23 s",
    ),
    (
        "acps experiment --config experiments/beyond-dims-self-paced.toml --out runs/beyond-dims-self-paced",
        "16 s",
    ),
    (
        "acps compare runs/beyond-grid-self-paced --levels 10,5,3 --wide",
        "compares the skipped run above",
    ),
    (
        "acps experiment --config experiments/beyond-grid.toml --sim rapier --runs 10 --out runs/beyond-grid-rapier-10-all",
        "an hour",
    ),
    (
        "acps compare runs/beyond-grid-rapier-10-all --levels 10,5,3 --wide",
        "compares the skipped run above",
    ),
    (
        "pip install processes/worker/python",
        "installs into the reader's Python; the Python tests install it into theirs",
    ),
    (
        "ACPS_BIN=target/release/acps python -m unittest discover -s tests -t .",
        "the worker package's suite, which the Python tests run",
    ),
    (
        "pip install ./python",
        "installs into the reader's Python; the Python tests install it into theirs",
    ),
];

/// Runs before each block: `cargo run --release -p P [--example E] -- ARGS` runs what the test
/// command built (cargo itself would rebuild and relink binaries that other tests run), and
/// any other cargo command fails the block.
const CARGO: &str = r#"cargo() {
    if [ "$1 $2 $3" != "run --release -p" ]; then
        echo "not run by the docs test: cargo $* (list it in SKIPPED with the reason)" >&2
        return 97
    fi
    bin="target/release/$4"
    shift 4
    if [ "$1" = "--features" ]; then shift 2; fi
    if [ "$1" = "--example" ]; then bin="target/release/examples/$2"; shift 2; fi
    if [ "$1" = "--" ]; then shift; fi
    "$bin" "$@"
}
"#;

/// The commands of `text`'s `sh` blocks, one list per block: `\`-continued lines joined, and
/// comments left out (a `#` after whitespace outside quotes).
fn blocks(text: &str) -> Vec<Vec<String>> {
    let mut blocks = Vec::new();
    let mut current: Option<Vec<String>> = None;
    let mut pending = String::new();
    for line in text.lines() {
        let fence = line.trim_start();
        match &mut current {
            None if fence == "```sh" => current = Some(Vec::new()),
            None => {}
            Some(_) if fence.starts_with("```") => blocks.push(current.take().expect("in a block")),
            Some(commands) => {
                let code = without_comment(line);
                if let Some(start) = code.strip_suffix('\\') {
                    pending.push_str(start.trim());
                    pending.push(' ');
                } else {
                    pending.push_str(code.trim());
                    let command = std::mem::take(&mut pending).trim().to_string();
                    if !command.is_empty() {
                        commands.push(command);
                    }
                }
            }
        }
    }
    blocks
}

/// `line` up to a comment, trimmed at its end.
fn without_comment(line: &str) -> &str {
    let mut quote = None;
    let mut previous = ' ';
    for (at, c) in line.char_indices() {
        match (quote, c) {
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), _) if c == q => quote = None,
            (None, '#') if previous.is_whitespace() => return line[..at].trim_end(),
            _ => {}
        }
        previous = c;
    }
    line.trim_end()
}

#[test]
fn a_block_s_commands_are_its_lines_without_comments() {
    let text = "x\n```sh\na --b 1   # one\nc \"d # e\" \\\n    --f # two\n\n```\n```toml\nno = 1\n```\n";
    assert_eq!(
        blocks(text),
        vec![vec!["a --b 1".to_string(), "c \"d # e\" --f".to_string()]]
    );
}

#[test]
fn the_commands_of_the_docs_run_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let root = root.canonicalize().expect("the workspace's root");
    let profile = Path::new(env!("CARGO_BIN_EXE_acps"))
        .parent()
        .expect("the binary's directory");
    // The reader's checkout: its files, and `target/release` (the build under test). Runs write
    // into it, not into the checkout.
    let dir = temp_dir("docs");
    std::fs::create_dir_all(dir.join("target")).unwrap();
    std::os::unix::fs::symlink(profile, dir.join("target/release")).unwrap();
    for entry in ["experiments", "processes", "python", "docs"] {
        std::os::unix::fs::symlink(root.join(entry), dir.join(entry)).unwrap();
    }
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let path_line = blocks(&readme)
        .into_iter()
        .flatten()
        .find(|command| command.starts_with("export PATH="))
        .expect("README puts acps on PATH with an `export PATH=` line of a sh block");
    let mut seen = Vec::new();
    let mut ran = 0;
    for document in DOCUMENTS {
        let text = std::fs::read_to_string(root.join(document)).unwrap_or_else(|e| panic!("{document}: {e}"));
        for block in blocks(&text) {
            let mut script = format!("set -e\n{path_line}\n{CARGO}");
            for command in block {
                seen.push(command.clone());
                if command == path_line || SKIPPED.iter().any(|(skipped, _)| *skipped == command) {
                    continue;
                }
                script.push_str(&format!("echo '$ {}' >&2\n{command}\n", command.replace('\'', "'\\''")));
                ran += 1;
            }
            let started = std::time::Instant::now();
            let output = Command::new("timeout")
                .args(["--signal=KILL", "300", "sh", "-c", &script])
                .current_dir(&*dir)
                .output()
                .expect("sh runs");
            assert!(
                output.status.success(),
                "a command of {document} failed ({}):\n{}",
                output.status,
                String::from_utf8_lossy(&output.stderr)
            );
            eprintln!("{document}: a block in {:.1} s", started.elapsed().as_secs_f64());
        }
    }
    let stale: Vec<_> = SKIPPED
        .iter()
        .filter(|(skipped, _)| !seen.iter().any(|c| c == skipped))
        .collect();
    assert!(stale.is_empty(), "SKIPPED names commands no document holds: {stale:?}");
    assert!(ran >= 5, "only {ran} commands ran");
}
