#!/usr/bin/env python3
"""Writes the results file of a timed CI run (issue 48: CI within 20 minutes, a fresh clone's
`cargo test` within 10, each measured on a clean clone and cited from the README).

In: the log of `time .ci/run` on a clean clone (its `== [Ns] step` lines and bash's `real`
line) and, optionally, the log of `/usr/bin/time -v cargo test` on another clean clone. Out:
`benches/results/<date>-<machine>/ci.md` with the date, the commit, the machine, each step's
start and length, and the fresh `cargo test`'s wall and CPU time.

    time .ci/run > ci.log 2>&1          # in a clean clone, nothing else running
    /usr/bin/time -v cargo test > test.log 2>&1   # in another clean clone
    tools/ci/times.py --ci ci.log --fresh-test test.log --commit "$(git rev-parse --short HEAD)"
"""
import argparse
import datetime
import os
import re
import subprocess
import sys


def seconds(text):
    """'13m19.621s' (bash's time) or 'h:mm:ss' / 'm:ss.ss' (GNU time) as seconds."""
    m = re.fullmatch(r"(?:(\d+)m)?([\d.]+)s", text)
    if m:
        return int(m.group(1) or 0) * 60 + float(m.group(2))
    parts = [float(p) for p in text.split(":")]
    total = 0.0
    for p in parts:
        total = total * 60 + p
    return total


def machine():
    cores = os.cpu_count() or 0
    model = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.uname().machine}-{cores}c", f"{model}, {cores} cores"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ci", required=True, help="log of `time .ci/run`")
    ap.add_argument("--fresh-test", help="log of `/usr/bin/time -v cargo test`")
    ap.add_argument("--commit", required=True, help="the commit both clones were made of")
    ap.add_argument("--note", default="", help="what else ran on the machine")
    a = ap.parse_args()

    steps, real = [], None
    for line in open(a.ci, errors="replace"):
        m = re.match(r"== \[(\d+)s\] (.*)", line)
        if m:
            steps.append((int(m.group(1)), m.group(2).strip()))
        m = re.match(r"real\s+(\S+)", line)
        if m:
            real = seconds(m.group(1))
    if not steps or real is None:
        sys.exit(f"{a.ci}: no '== [Ns] step' lines or no 'real' line: not a log of `time .ci/run`")

    short, long = machine()
    today = datetime.datetime.now(datetime.timezone.utc)
    out_dir = os.path.join("benches", "results", f"{today:%Y-%m-%d}-{short}")
    os.makedirs(out_dir, exist_ok=True)
    lines = [
        "# CI and a fresh clone's `cargo test`",
        "",
        f"- date: {today:%Y-%m-%d %H:%M} UTC",
        f"- commit: {a.commit}",
        f"- machine: {long}",
        "- command: `time .ci/run` on a clean clone; `/usr/bin/time -v cargo test` on another",
        f"- written by: `tools/ci/times.py`{'; ' + a.note if a.note else ''}",
        "",
        f"`.ci/run`: **{real:.0f} s ({int(real // 60)} min {real % 60:.0f} s)**, target 20 min.",
        "",
        "| step | starts at (s) | takes (s) |",
        "| --- | --- | --- |",
    ]
    ends = [s for s, _ in steps[1:]] + [real]
    for (start, name), end in zip(steps, ends):
        if name == "done":
            continue
        lines.append(f"| {name} | {start} | {end - start:.0f} |")
    if a.fresh_test:
        wall = user = system = None
        code = None
        for line in open(a.fresh_test, errors="replace"):
            line = line.strip()
            if line.startswith("Elapsed (wall clock) time"):
                wall = seconds(line.rsplit(" ", 1)[1])
            elif line.startswith("User time (seconds):"):
                user = float(line.rsplit(" ", 1)[1])
            elif line.startswith("System time (seconds):"):
                system = float(line.rsplit(" ", 1)[1])
            elif line.startswith("Exit status:"):
                code = int(line.rsplit(" ", 1)[1])
        if wall is None or user is None or system is None:
            sys.exit(f"{a.fresh_test}: not the output of `/usr/bin/time -v`")
        lines += [
            "",
            f"A fresh clone's `cargo test` (`CARGO_INCREMENTAL=0`): **{wall:.0f} s "
            f"({int(wall // 60)} min {wall % 60:.0f} s)** wall, {user + system:.0f} s of CPU, "
            f"exit status {code}; target 10 min.",
        ]
    path = os.path.join(out_dir, "ci.md")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(path)


if __name__ == "__main__":
    main()
