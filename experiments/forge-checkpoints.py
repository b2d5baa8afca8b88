#!/usr/bin/env python3
"""Forge checkpoints as a hostile tester would, and resume from each forgery: a hang or a crash
is a finding; a refusal (exit 2) or a finished run (exit 0) is not.

For each method, a grid run is stopped half way with Ctrl-C; then every 8-byte float 1.0 of its
checkpoint's payload (a sample of them) and a sample of other windows that read as floats of
magnitude 1e-3..1e3 are replaced by each of the given values, the checksum is recomputed (the
format is in processes/learner/src/checkpoint/mod.rs), and the run is resumed under a timeout.

    python3 experiments/forge-checkpoints.py target/release/acps /tmp/forge \\
        --methods alp-gmm,self-paced --learner c-reps

Prints each finding (place, value, exit code, seconds, the end of stderr) and a count of exit
codes per method. Exit status 1 when there was a finding.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import shutil
import signal
import struct
import subprocess
import sys
import time

HEADER = 48
FNV_OFFSET = 0xCBF29CE484222325
FNV_PRIME = 0x100000001B3


def fnv1a(state: int, data: bytes) -> int:
    """FNV-1a 64 of ``data`` continuing from ``state`` (Rust: ``acps_shared::fnv1a``)."""
    for byte in data:
        state = ((state ^ byte) * FNV_PRIME) & 0xFFFFFFFFFFFFFFFF
    return state


def forged(raw: bytes, place: int, value: float) -> bytes:
    """``raw`` with the 8 payload bytes at ``place`` replaced by ``value``, checksum recomputed."""
    payload = bytearray(raw[HEADER:])
    payload[place : place + 8] = struct.pack("<d", value)
    header = bytearray(raw[:HEADER])
    header[40:48] = struct.pack(
        "<Q", fnv1a(fnv1a(FNV_OFFSET, bytes(header[:40])), bytes(payload))
    )
    return bytes(header) + bytes(payload)


def places(payload: bytes, sample: int) -> list[int]:
    """A sample of the places of 1.0, and of other windows that read as modest floats."""
    ones, others = [], []
    for i in range(len(payload) - 7):
        (x,) = struct.unpack("<d", payload[i : i + 8])
        if x == 1.0:
            ones.append(i)
        elif not math.isnan(x) and 1e-3 < abs(x) < 1e3:
            others.append(i)
    return (
        ones[:: max(1, len(ones) // sample)] + others[:: max(1, len(others) // sample)]
    )


def stopped_run(acps: str, run: list[str], out: str) -> str:
    """Start ``run`` into ``out``, Ctrl-C it once a checkpoint exists; its checkpoint file."""
    shutil.rmtree(out, ignore_errors=True)
    process = subprocess.Popen(
        [acps, *run, "--out", out], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    while not glob.glob(f"{out}/checkpoints/*.ckpt"):
        if time.monotonic() > deadline or process.poll() is not None:
            process.kill()
            said = process.communicate()[1].decode(errors="replace").strip()
            raise SystemExit(f"{out}: no checkpoint appeared: {said}")
        time.sleep(0.01)
    time.sleep(0.3)
    process.send_signal(signal.SIGINT)
    process.wait()
    return min(glob.glob(f"{out}/checkpoints/*.ckpt"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("acps", help="the acps binary")
    parser.add_argument("work", help="a directory for the runs (emptied)")
    parser.add_argument(
        "--methods", default="alp-gmm,self-paced,monotonic-progress,sagg-riac"
    )
    parser.add_argument("--learner", default="c-reps")
    parser.add_argument("--values", default="nan,1e300", help="comma-separated floats")
    parser.add_argument(
        "--sample", type=int, default=30, help="places of each kind per method"
    )
    parser.add_argument(
        "--timeout", type=float, default=30.0, help="seconds per resume"
    )
    args = parser.parse_args()
    values = [float(v) for v in args.values.split(",")]
    findings = 0
    for method in args.methods.split(","):
        run = [
            "experiment", "grid", "--runs", "1", "--episodes", "6000", "--checkpoint-every", "2",
            "--learner", args.learner, "--method", method, "-q",
        ]  # fmt: skip
        base = os.path.join(args.work, method)
        checkpoint = stopped_run(args.acps, run, base)
        with open(checkpoint, "rb") as file:
            raw = file.read()
        chosen = places(raw[HEADER:], args.sample)
        print(
            f"{method}: {len(raw) - HEADER} payload bytes, {len(chosen)} places",
            flush=True,
        )
        codes: dict[str, int] = {}
        for place in chosen:
            for value in values:
                trial = base + "-forged"
                shutil.rmtree(trial, ignore_errors=True)
                shutil.copytree(base, trial)
                with open(
                    os.path.join(trial, "checkpoints", os.path.basename(checkpoint)),
                    "wb",
                ) as f:
                    f.write(forged(raw, place, value))
                started = time.monotonic()
                try:
                    done = subprocess.run(
                        [args.acps, *run, "--out", trial, "--resume", trial],
                        capture_output=True,
                        timeout=args.timeout,
                        check=False,
                    )
                    code, said = (
                        str(done.returncode),
                        done.stderr.decode(errors="replace"),
                    )
                except subprocess.TimeoutExpired:
                    code, said = "timeout", ""
                seconds = time.monotonic() - started
                codes[code] = codes.get(code, 0) + 1
                if code not in ("0", "2"):
                    findings += 1
                    tail = said[-300:].replace("\n", " | ")
                    print(
                        f"  FINDING place {place} value {value}: {code} after {seconds:.1f} s: {tail}"
                    )
        shutil.rmtree(base + "-forged", ignore_errors=True)
        print(f"{method}: exit codes {codes}", flush=True)
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
