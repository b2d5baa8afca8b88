#!/usr/bin/env bash
# Runs every experiment file here with one acps binary into OUT/, shortened so the whole set takes
# minutes (--runs 3, at most 3000 episodes; rapier 300), so that two builds can be compared:
#   experiments/same-results.sh BINARY OUT        # e.g. once with the old build, once with the new
#   diff -r OLD_OUT NEW_OUT && echo identical    # summary.json and every CSV, byte for byte
# The problem file (bowl.toml) runs through the fleet with the Rust bowl worker, which must be
# built beside BINARY (cargo build --release -p acps-worker --example bowl).
set -euo pipefail
acps=$(realpath "$1")
out=$2
worker="$(dirname "$acps")/examples/bowl"
here="$(cd "$(dirname "$0")" && pwd)"
mkdir -p "$out"
for file in "$here"/*.toml; do
    name=$(basename "$file" .toml)
    args=(--config "$file" --runs 3 --out "$out/$name" -q)
    case "$name" in
    *rapier*) args+=(--episodes 300) ;;
    bowl) ;;
    *) args+=(--episodes 3000) ;;
    esac
    echo "$name"
    if [ "$name" = bowl ]; then
        "$acps" run "${args[@]}" --worker-command "$worker"
    else
        "$acps" experiment "${args[@]}"
    fi
    # Pictures are for reading, not comparing; checkpoints carry the build that wrote them; a
    # fleet's record files group each batch of records by kind as the outcomes happened to
    # arrive (read back, the records are the same); run.json holds the wall-clock figures.
    find "$out/$name" \( -name '*.png' -o -name '*.svg' -o -name '*.ckpt' -o -name '*.records' -o -name run.json \) -delete
done
