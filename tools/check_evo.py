#!/usr/bin/env python3
"""Checks `omnitrack-desk eval` against evo on the same TUM files.

Creates a virtual environment in tools/.venv-evo (once), installs evo there, writes a ground-truth
trajectory and a noisy, jittered, partly dropped estimate of it, runs evo_ape / evo_rpe and our
`omnitrack-desk eval --json` with the same options, and prints every statistic side by side.
Exits 1 if any differs by more than 1e-6 (relative), 2 if a tool could not be run.

Usage: python3 tools/check_evo.py [--desk-bin PATH] [--keep DIR]
Without --desk-bin the binary is run through `cargo run -p omnitrack-tools` (CARGO_TARGET_DIR is
honoured).
"""

import argparse
import json
import math
import os
import random
import re
import subprocess
import sys
import tempfile
import venv
import zipfile
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
REPO = TOOLS.parent
VENV = TOOLS / ".venv-evo"
# The version whose definitions crates/desk/src/eval.rs follows; override with EVO_SPEC=evo to try newer.
EVO_SPEC = os.environ.get("EVO_SPEC", "evo==1.38.1")
TOLERANCE = 1e-6
STATS = ["rmse", "mean", "median", "std", "min", "max"]


def venv_bin(name):
    return VENV / "bin" / name


def ensure_evo():
    """The venv's evo, installed on first use; its pip output goes to stderr."""
    if not venv_bin("evo_ape").exists():
        print(f"creating {VENV} and installing {EVO_SPEC} (once)...", file=sys.stderr)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
        subprocess.run(
            [str(venv_bin("python")), "-m", "pip", "install", "--quiet", EVO_SPEC],
            check=True,
            stdout=sys.stderr,
        )
    version = subprocess.run(
        [str(venv_bin("python")), "-c", "import evo; print(evo.__version__)"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    return version


def quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_from_rotvec(v):
    angle = math.sqrt(sum(c * c for c in v))
    if angle < 1e-15:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(angle / 2) / angle
    return (math.cos(angle / 2), v[0] * s, v[1] * s, v[2] * s)


def tum_line(t, p, q):
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return f"{t:.9f} {p[0]:.9f} {p[1]:.9f} {p[2]:.9f} {x / n:.12f} {y / n:.12f} {z / n:.12f} {w / n:.12f}\n"


def write_trajectories(folder):
    """A 20 s walk at 30 Hz and an estimate of it: 3 cm / 1° noise, a small rigid offset (so that
    alignment matters), timestamps jittered by up to 4 ms, one pose in ten dropped, and a
    ground truth that runs 1 s longer than the estimate."""
    rng = random.Random(9)
    gt_lines, est_lines = [], []
    offset = (0.05, -0.03, 0.02)
    for k in range(630):
        t = 1700000000.0 + k / 30.0
        s = k / 30.0
        p = (4.0 * math.cos(0.2 * s), 3.0 * math.sin(0.3 * s), 1.6 + 0.05 * math.sin(2.0 * s))
        q = quat_mul(quat_from_rotvec((0.0, 0.0, 0.2 * s)), quat_from_rotvec((0.05 * math.sin(s), 0.03, 0.0)))
        gt_lines.append(tum_line(t, p, q))
        if k >= 600 or k % 10 == 7:
            continue
        pe = tuple(p[i] + offset[i] + rng.gauss(0.0, 0.03) for i in range(3))
        qe = quat_mul(q, quat_from_rotvec(tuple(rng.gauss(0.0, math.radians(1.0)) for _ in range(3))))
        est_lines.append(tum_line(t + rng.uniform(-0.004, 0.004), pe, qe))
    gt, est = folder / "gt.tum", folder / "est.tum"
    gt.write_text("# timestamp tx ty tz qx qy qz qw\n" + "".join(gt_lines))
    est.write_text("# timestamp tx ty tz qx qy qz qw\n" + "".join(est_lines))
    return gt, est


def evo_stats(folder, tool, relation, gt, est, case, tag):
    """Statistics evo saves for one metric (stats.json inside its --save_results zip)."""
    out = folder / f"{tag}.zip"
    cmd = [str(venv_bin(tool)), "tum", str(gt), str(est), "-r", relation, "--no_warnings"]
    cmd += ["--t_max_diff", str(case["max_diff"]), "--save_results", str(out)]
    if case["align"]:
        cmd.append("--align")
    if tool == "evo_rpe":
        cmd += ["--delta", str(case["delta"]), "--delta_unit", "f"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    with zipfile.ZipFile(out) as z:
        stats = json.loads(z.read("stats.json"))
        stats["count"] = npy_length(z.read("error_array.npy"))
    return stats


def npy_length(data):
    """Length of a 1-D .npy array, read from its header (no numpy needed here)."""
    if not data.startswith(b"\x93NUMPY"):
        raise RuntimeError("evo's error_array.npy is not a .npy file")
    header_len = int.from_bytes(data[8:10], "little") if data[6] == 1 else int.from_bytes(data[8:12], "little")
    header = data[10 : 10 + header_len].decode("latin1") if data[6] == 1 else data[12 : 12 + header_len].decode("latin1")
    match = re.search(r"'shape':\s*\((\d+),?\)", header)
    if not match:
        raise RuntimeError(f"unexpected .npy header {header!r}")
    return int(match.group(1))


def ours(desk_bin, gt, est, case):
    args = ["eval", str(gt), str(est), "--json", "--rpe-delta", str(case["delta"])]
    args += ["--max-diff", str(case["max_diff"])]
    if case["align"]:
        args.append("--align")
    if desk_bin:
        cmd = [desk_bin] + args
    else:
        cmd = ["cargo", "run", "-q", "-p", "omnitrack-tools", "--bin", "omnitrack-desk", "--"] + args
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"omnitrack-desk eval failed: {done.stderr.strip()}")
    return json.loads(done.stdout)


def rel_diff(a, b):
    scale = max(abs(a), abs(b))
    return 0.0 if scale < 1e-12 else abs(a - b) / scale


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--desk-bin", help="a built omnitrack-desk binary")
    parser.add_argument("--keep", help="write the trajectories and evo's results here")
    args = parser.parse_args()
    try:
        version = ensure_evo()
    except (subprocess.CalledProcessError, OSError) as e:
        print(f"check_evo: cannot set up evo in {VENV}: {e}", file=sys.stderr)
        return 2
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="check_evo_"))
    folder.mkdir(parents=True, exist_ok=True)
    gt, est = write_trajectories(folder)
    cases = [
        {"name": "default", "align": False, "delta": 1, "max_diff": 0.01},
        {"name": "--align --rpe-delta 3", "align": True, "delta": 3, "max_diff": 0.01},
        {"name": "--max-diff 0.003", "align": False, "delta": 1, "max_diff": 0.003},
    ]
    print(f"evo {version} vs omnitrack-desk eval on {gt} and {est}")
    print(f"{'case / metric':<44} {'stat':<7} {'evo':>16} {'omnitrack':>16} {'rel. diff':>10}")
    worst = 0.0
    try:
        for case in cases:
            mine = ours(args.desk_bin, gt, est, case)
            metrics = [
                ("ATE translation (m)", "evo_ape", "trans_part", mine["ate"]["translation_m"]),
                ("ATE rotation (deg)", "evo_ape", "angle_deg", mine["ate"]["rotation_deg"]),
                ("RPE translation (m)", "evo_rpe", "trans_part", mine["rpe"]["translation_m"]),
                ("RPE rotation (deg)", "evo_rpe", "angle_deg", mine["rpe"]["rotation_deg"]),
            ]
            for i, (label, tool, relation, our_stats) in enumerate(metrics):
                tag = f"{case['name']}-{i}".replace(" ", "_").replace("-", "")
                theirs = evo_stats(folder, tool, relation, gt, est, case, tag)
                for stat in STATS + ["count"]:
                    d = rel_diff(theirs[stat], our_stats[stat])
                    worst = max(worst, d)
                    flag = "" if d <= TOLERANCE else "  <-- differs"
                    name = f"{case['name']}: {label}" if stat == "rmse" else ""
                    if stat == "count":
                        print(f"{name:<44} {stat:<7} {theirs[stat]:>16} {our_stats[stat]:>16} {d:>10.1e}{flag}")
                    else:
                        print(f"{name:<44} {stat:<7} {theirs[stat]:>16.10f} {our_stats[stat]:>16.10f} {d:>10.1e}{flag}")
    except (subprocess.CalledProcessError, RuntimeError, OSError, KeyError, json.JSONDecodeError) as e:
        detail = getattr(e, "stderr", "") or ""
        print(f"check_evo: {e} {detail.strip()}", file=sys.stderr)
        return 2
    ok = worst <= TOLERANCE
    print(f"largest relative difference {worst:.2e}: {'agree' if ok else 'DISAGREE'} (tolerance {TOLERANCE:g})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
