#!/usr/bin/env python3
"""PnL benchmark: omnitrack's line pose solver (Kumar & Hanson 1989) against PoseLib, one command.

    python3 tools/bench_pnl.py            # full protocol, 500 trials per cell (~ a few minutes)
    python3 tools/bench_pnl.py --quick    # 50 trials per cell
    python3 tools/bench_pnl.py --trials 100 --method r_and_t --seed 7

What it does, in order:
 1. Creates (or reuses) the venv tools/.venv-bench, installs numpy and PoseLib (PyPI package
    `poselib`, the official pybind11 bindings) into it, and re-runs itself inside it.
 2. Generates the PnL protocol data (seeded): pinhole f = 800 px, 640x480, principal point at
    the centre; per trial a random camera pose and n 3D segments whose end points are at depth
    4-8 m and project inside the image (2D length >= MIN_LEN_PX); Gaussian noise of sigma = 1 or
    5 px on each 2D end point coordinate; n = 6, 10, 20, 30; 0 / 30 / 50 % outliers (round(f*n)
    of the 2D segments replaced by random segments inside the image).
 3. Runs PoseLib's estimate_absolute_pose_pnpl with lines only (no points), ransac option
    max_epipolar_error = 4 px (the line threshold of the pnpl estimator; PoseLib's other options
    left at their defaults), timing each call with time.perf_counter_ns around the call only.
 4. Builds and runs our Rust runner (tools/src/bin/pnl_bench.rs, omnitrack::solver::med_r_and_t
    or r_and_t) on the identical data, passed as JSON lines; the runner times each solver call
    with std::time::Instant around the call only.
 5. Prints, per cell, both methods side by side, and the paired test: every trial is a pair
    (ours, PoseLib) on identical data; per cell and pooled per outlier level, the median ratio
    of the errors and a one-sided Wilcoxon signed-rank p-value (exact) that ours is worse. With
    --baseline-runner, the same of ours against an earlier build of ours, run on the same data.
    Writes it all to benches/results/DATE-MACHINE/pnl.md (date, commit, machine at its head).

Error definitions (both methods compared in T_camera_world = (R, t), x_cam = R X_world + t; the
world origin is the centroid of the scene's end points, so |t_true| is the camera-to-scene
distance):
  rotation error     = angle of R_est R_true^T (degrees)
  translation error  = |t_est - t_true| / |t_true| (percent)
  failure            = no result, or rotation error > 5 deg, or translation error > 10 %
  medians            = over all trials of the cell; a trial with no result counts as +inf
  time               = median microseconds per call
  ratios             = PoseLib / ours (time ratio > 1: ours faster; error ratio > 1: ours more
                       accurate)
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
REPO = TOOLS.parent
VENV = TOOLS / ".venv-bench"
PACKAGES = ["numpy", "poselib"]

FOCAL, WIDTH, HEIGHT = 800.0, 640, 480
CX, CY = WIDTH / 2.0, HEIGHT / 2.0
DEPTH = (4.0, 8.0)
MIN_LEN_PX = 20.0  # shorter 2D segments (before noise) are redrawn: their direction is noise
NOISES = [1.0, 5.0]
NS = [6, 10, 20, 30]
OUTLIERS = [0.0, 0.3, 0.5]
POSELIB_RANSAC = {"max_epipolar_error": 4.0}
ROT_FAIL_DEG, TRANS_FAIL_PCT = 5.0, 10.0
RUNNER = REPO / "target" / "release" / "pnl_bench"


# --------------------------------------------------------------------------------------------
# 1. The venv
# --------------------------------------------------------------------------------------------


def venv_python() -> Path:
    return VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def in_bench_venv() -> bool:
    return Path(sys.prefix).resolve() == VENV.resolve()


def ensure_venv_and_reexec() -> None:
    """Create tools/.venv-bench if needed, install the packages, and re-run this script in it."""
    py = venv_python()
    if not py.exists():
        print(f"[bench] creating venv {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=False).create(VENV)
    check = subprocess.run([str(py), "-c", "import numpy, poselib"], capture_output=True)
    if check.returncode != 0:
        print(f"[bench] pip install {' '.join(PACKAGES)} into {VENV}", flush=True)
        r = subprocess.run([str(py), "-m", "pip", "install", "--quiet", "--upgrade", "pip"])
        r = subprocess.run([str(py), "-m", "pip", "install", "--quiet", "--only-binary=poselib", *PACKAGES])
        if r.returncode != 0:
            v = f"{sys.version_info.major}.{sys.version_info.minor}"
            sys.exit(
                f"[bench] error: could not install {PACKAGES} from PyPI. PoseLib ships binary wheels "
                f"(package `poselib`) only for some Python versions/platforms; if there is none for "
                f"Python {v} on {platform.machine()} {platform.system()}, run this script with a "
                f"Python that has one (e.g. `python3.11 tools/bench_pnl.py`) after deleting {VENV}."
            )
    # The script that was run (bench_pnl.py itself, or a benchmark that imports it).
    os.execv(str(py), [str(py), str(Path(sys.argv[0]).resolve()), *sys.argv[1:]])


# --------------------------------------------------------------------------------------------
# 2. Data
# --------------------------------------------------------------------------------------------


def random_rotation(rng):
    import numpy as np

    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_segment_px(rng):
    """Two pixel end points uniform in the image, at least MIN_LEN_PX apart."""
    import numpy as np

    while True:
        a = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT])
        b = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT])
        if np.linalg.norm(a - b) >= MIN_LEN_PX:
            return a, b


def make_trial(rng, n: int, noise: float, outlier_frac: float):
    """One trial: returns (uv1, uv2, X1, X2, R_cw, t_cw, is_outlier)."""
    import numpy as np

    uv1 = np.empty((n, 2))
    uv2 = np.empty((n, 2))
    Xc1 = np.empty((n, 3))
    Xc2 = np.empty((n, 3))
    for i in range(n):
        a, b = random_segment_px(rng)
        da, db = rng.uniform(*DEPTH, size=2)
        uv1[i], uv2[i] = a, b
        Xc1[i] = np.array([(a[0] - CX) / FOCAL, (a[1] - CY) / FOCAL, 1.0]) * da
        Xc2[i] = np.array([(b[0] - CX) / FOCAL, (b[1] - CY) / FOCAL, 1.0]) * db
    # Random pose: world origin at the scene centroid, random orientation of the world axes.
    c0 = np.vstack([Xc1, Xc2]).mean(axis=0)
    R_wc = random_rotation(rng)
    X1 = (Xc1 - c0) @ R_wc.T
    X2 = (Xc2 - c0) @ R_wc.T
    R_cw, t_cw = R_wc.T, c0  # x_cam = R_cw X_world + t_cw
    uv1 = uv1 + rng.normal(0.0, noise, uv1.shape)
    uv2 = uv2 + rng.normal(0.0, noise, uv2.shape)
    n_out = int(round(outlier_frac * n))
    out_idx = rng.choice(n, size=n_out, replace=False) if n_out else np.array([], dtype=int)
    is_out = np.zeros(n, dtype=bool)
    for i in out_idx:
        uv1[i], uv2[i] = random_segment_px(rng)
        is_out[i] = True
    return uv1, uv2, X1, X2, R_cw, t_cw, is_out


# --------------------------------------------------------------------------------------------
# 3. / 4. Methods
# --------------------------------------------------------------------------------------------


def rot_err_deg(R_est, R_true) -> float:
    import numpy as np

    c = (np.trace(R_est @ R_true.T) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def trans_err_pct(t_est, t_true) -> float:
    import numpy as np

    return 100.0 * float(np.linalg.norm(t_est - t_true) / np.linalg.norm(t_true))


def run_poselib(trials, max_seconds: float):
    import numpy as np
    import poselib

    default_cam = {"model": "PINHOLE", "width": WIDTH, "height": HEIGHT, "params": [FOCAL, FOCAL, CX, CY]}
    p2 = np.zeros((0, 2))
    p3 = np.zeros((0, 3))
    out = []
    start = time.time()
    for k, tr in enumerate(trials):
        if time.time() - start > max_seconds:
            sys.exit(
                f"[bench] error: PoseLib is too slow: only {k} of {len(trials)} trials in {max_seconds:.0f} s. "
                f"Use --trials N or raise --max-seconds."
            )
        uv1, uv2, X1, X2 = tr["uv1"], tr["uv2"], tr["X1"], tr["X2"]
        ransac = dict(POSELIB_RANSAC, seed=int(tr["seed"] % (2**31)))
        t0 = time.perf_counter_ns()
        try:
            cam = tr.get("cam", default_cam)
            pose, info = poselib.estimate_absolute_pose_pnpl(p2, p3, uv1, uv2, X1, X2, cam, ransac, {})
            ok = True
        except Exception as e:  # noqa: BLE001 - any failure of the library is a failure
            ok, pose, info = False, None, str(e)
        us = (time.perf_counter_ns() - t0) / 1e3
        if ok and not (np.all(np.isfinite(pose.R)) and np.all(np.isfinite(pose.t))):
            ok = False
        if ok and info.get("num_inliers", 0) == 0:
            ok = False  # PoseLib returns an identity pose when RANSAC found nothing
        out.append({"ok": ok, "us": us, "R": pose.R if ok else None, "t": pose.t if ok else None})
        if (k + 1) % 1000 == 0:
            print(f"[bench]   poselib {k + 1}/{len(trials)}", flush=True)
    return out


def shipped_solver_args() -> list[str]:
    """The runner flags that make it run what `omnitrack pose` runs: firmware_config/tracker.toml's
    [solver] error, lms_outlier_fraction, lms_success_probability and lms_outlier_threshold."""
    import tomllib

    cfg = tomllib.loads((REPO / "firmware_config" / "tracker.toml").read_text())["solver"]
    return [
        "--error",
        cfg["error"],
        "--epsilon",
        str(cfg["lms_outlier_fraction"]),
        "--success",
        str(cfg["lms_success_probability"]),
        "--threshold",
        str(cfg["lms_outlier_threshold"]),
    ]


def build_runner() -> None:
    print("[bench] cargo build --release -p omnitrack-tools --bin pnl_bench", flush=True)
    r = subprocess.run(["cargo", "build", "--release", "-p", "omnitrack-tools", "--bin", "pnl_bench"], cwd=REPO)
    if r.returncode != 0:
        sys.exit(
            "[bench] error: the Rust runner did not build. If the errors are `no med_r_and_t in solver`, "
            "the solver (omnitrack::solver::med_r_and_t / r_and_t) is not written yet."
        )


def run_ours(trials, method: str, runner: Path, max_seconds: float, extra=()):
    import numpy as np

    with tempfile.TemporaryDirectory(prefix="bench_pnl_") as d:
        inp, outp = Path(d) / "trials.jsonl", Path(d) / "results.jsonl"
        with inp.open("w") as f:
            for tr in trials:
                lines = np.hstack([tr["uv1"], tr["uv2"], tr["X1"], tr["X2"]])
                k = tr.get("K", [FOCAL, FOCAL, CX, CY])
                rec = {"id": tr["id"], "seed": tr["seed"], "K": k, "lines": lines.tolist()}
                f.write(json.dumps(rec) + "\n")
        try:
            r = subprocess.run(
                [str(runner), "--input", str(inp), "--output", str(outp), "--method", method, *extra],
                timeout=max_seconds,
            )
        except subprocess.TimeoutExpired:
            sys.exit(
                f"[bench] error: ours ({method}) is too slow: {len(trials)} trials did not finish in "
                f"{max_seconds:.0f} s (> {1e3 * max_seconds / len(trials):.1f} ms per call). Use --trials N "
                f"or raise --max-seconds."
            )
        if r.returncode != 0:
            sys.exit(f"[bench] error: {runner.name} exited with {r.returncode}")
        by_id = {}
        with outp.open() as f:
            for line in f:
                rec = json.loads(line)
                by_id[rec["id"]] = rec
    out = []
    for tr in trials:
        rec = by_id.get(tr["id"])
        if rec is None or not rec["ok"]:
            out.append({"ok": False, "us": rec["us"] if rec else float("nan"), "R": None, "t": None})
            continue
        # The runner reports T_world_camera; compare in T_camera_world like PoseLib.
        R_wc = np.array(rec["t_world_camera"]["R"]).reshape(3, 3)
        c = np.array(rec["t_world_camera"]["t"])
        R_cw = R_wc.T
        t_cw = -R_cw @ c
        ok = bool(np.all(np.isfinite(R_cw)) and np.all(np.isfinite(t_cw)))
        cov = np.array(rec["covariance"]).reshape(6, 6) if "covariance" in rec else None
        out.append({"ok": ok, "us": rec["us"], "R": R_cw, "t": t_cw, "cov": cov,
                    "inliers": rec.get("inliers"), "lines": rec.get("lines")})
    return out


# --------------------------------------------------------------------------------------------
# 5. Statistics and the table
# --------------------------------------------------------------------------------------------


def trial_errors(trials, results):
    """Per trial: (rotation error deg, translation error %), inf for no result."""
    out = []
    for tr, res in zip(trials, results):
        if not res["ok"]:
            out.append((math.inf, math.inf))
        else:
            out.append((rot_err_deg(res["R"], tr["R_cw"]), trans_err_pct(res["t"], tr["t_cw"])))
    return out


def cell_stats(trials, results):
    import numpy as np

    rot, tra, fail, us = [], [], 0, []
    for tr, res in zip(trials, results):
        us.append(res["us"])
        if not res["ok"]:
            rot.append(math.inf)
            tra.append(math.inf)
            fail += 1
            continue
        re = rot_err_deg(res["R"], tr["R_cw"])
        te = trans_err_pct(res["t"], tr["t_cw"])
        rot.append(re)
        tra.append(te)
        if not (re <= ROT_FAIL_DEG and te <= TRANS_FAIL_PCT):
            fail += 1
    return {
        "rot": float(np.median(rot)),
        "tra": float(np.median(tra)),
        "fail": 100.0 * fail / len(trials),
        "us": float(np.nanmedian(us)),
    }


EXACT_SIGNED_RANK_MAX = 600


def signed_rank_p(d) -> float:
    """Exact one-sided Wilcoxon signed-rank p-value for "the d are centred above 0": P(W+ >= w)
    under H0 (each |d| equally likely to carry either sign), where W+ is the sum of the ranks of
    the positive d among |d|. Zeros (and NaN, e.g. both methods failed) are dropped, as Wilcoxon
    does; tied |d| share their mean rank, and the null distribution is computed for those very
    (half-integer) ranks, so the p-value is exact with ties too. +-inf ranks above every finite d.
    Beyond EXACT_SIGNED_RANK_MAX pairs, the normal approximation (tie-corrected)."""
    import numpy as np

    d = np.asarray([x for x in d if x == x and x != 0.0], dtype=float)
    n = len(d)
    if n == 0:
        return 1.0
    a = np.abs(d)
    order = np.argsort(a, kind="stable")
    ranks2 = np.empty(n, dtype=np.int64)  # twice the mid-ranks, integers
    i = 0
    while i < n:
        j = i
        while j + 1 < n and a[order[j + 1]] == a[order[i]]:
            j += 1
        for k in range(i, j + 1):
            ranks2[order[k]] = i + j + 2  # 2 * mean of the 1-based ranks i+1..j+1
        i = j + 1
    w = int(ranks2[d > 0].sum())
    if n > EXACT_SIGNED_RANK_MAX:
        # The exact distribution costs n³ here: past this size the normal approximation with the
        # tie correction is exact to three decimals (continuity-corrected, in doubled ranks).
        mean = ranks2.sum() / 2.0
        sd = math.sqrt(float((ranks2.astype(float) ** 2).sum()) / 4.0)
        return float(0.5 * math.erfc((w - 1.0 - mean) / sd / math.sqrt(2.0))) if sd > 0 else 1.0
    dist = np.zeros(int(ranks2.sum()) + 1)
    dist[0] = 1.0
    for r in ranks2:
        shifted = np.zeros_like(dist)
        shifted[r:] = dist[:-r] if r > 0 else dist
        dist = 0.5 * (dist + shifted)
    return float(min(1.0, dist[w:].sum()))


def paired(ours, theirs):
    """A paired comparison of errors on identical data: (pairs, median of ours / theirs,
    p that ours is worse, p that ours is better), both one-sided Wilcoxon signed-rank on
    log(ours / theirs). A failure counts as an infinite error, so it ranks above any finite
    difference; two failures are a tie and drop out."""
    import numpy as np

    o, t = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.log(o) - np.log(t)
        r = o / t
    r = r[~np.isnan(r)]
    med = float(np.median(r)) if len(r) else math.nan
    return len(o), med, signed_rank_p(d), signed_rank_p(-d)


def results_dir() -> Path:
    """benches/results/DATE-ARCH-Nc, as omnitrack::desk::results names it."""
    date = datetime.datetime.now().strftime("%Y-%m-%d")
    return REPO / "benches" / "results" / f"{date}-{platform.machine()}-{os.cpu_count()}c"


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores"


def commit() -> str:
    def git(*a):
        r = subprocess.run(["git", *a], cwd=REPO, capture_output=True, text=True)
        return r.stdout.strip() if r.returncode == 0 else ""

    h = git("rev-parse", "--short", "HEAD")
    if not h:
        return "unknown"
    return h + ("-dirty" if git("status", "--porcelain", "--untracked-files=no") else "")


def write_results(name: str, title: str, command: str, body: str) -> Path:
    """Writes benches/results/DATE-MACHINE/NAME.md headed as omnitrack::desk::results does."""
    d = results_dir()
    d.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.timezone.utc)
    path = d / f"{name}.md"
    path.write_text(
        f"# {title}\n\n- date: {now.strftime('%Y-%m-%d %H:%M')} UTC\n- commit: {commit()}\n"
        f"- machine: {machine()}\n- command: `{command}`\n\n{body}\n"
    )
    return path


def ratio(a: float, b: float) -> str:
    if not (math.isfinite(a) and math.isfinite(b)) or b == 0:
        return "-"
    return f"{a / b:.2f}"


def fmt(x: float, nd: int) -> str:
    return f"{x:.{nd}f}" if math.isfinite(x) else "inf"


HEADER = (
    "| σ px | n | out % | rot° PL | rot° ours | rot ratio | t% PL | t% ours | t ratio "
    "| fail% PL | fail% ours | µs PL | µs ours | time ratio |"
)


def table_rows(rows):
    lines = [HEADER, "|" + "---|" * 14]
    for (noise, n, of), pl, us_ in rows:
        lines.append(
            f"| {noise:g} | {n} | {of * 100:.0f} | {fmt(pl['rot'], 3)} | {fmt(us_['rot'], 3)} "
            f"| {ratio(pl['rot'], us_['rot'])} | {fmt(pl['tra'], 2)} | {fmt(us_['tra'], 2)} "
            f"| {ratio(pl['tra'], us_['tra'])} | {pl['fail']:.1f} | {us_['fail']:.1f} "
            f"| {pl['us']:.0f} | {us_['us']:.0f} | {ratio(pl['us'], us_['us'])} |"
        )
    return lines


def paired_table(trials, cells, ours, pl, before=None):
    """Every trial is a pair (ours, PoseLib) on identical data: per cell and pooled per outlier
    level, the median of the ratios ours / PoseLib and the one-sided Wilcoxon signed-rank p that
    ours is worse; with a baseline build, the same of ours against it (p that ours got worse)."""
    e_ours, e_pl = trial_errors(trials, ours), trial_errors(trials, pl)
    e_before = trial_errors(trials, before) if before is not None else None
    head = "| σ px | n | out % | rot ours/PL: ratio / p worse | t ours/PL: ratio / p worse |"
    if e_before is not None:
        head += (" rot ours/before: ratio / p worse | t ours/before: ratio / p worse | fail% before "
                 "| before/PL, rot: ratio / p worse; t: ratio / p worse |")
    lines = [
        "Paired: each trial is a pair on identical data. Ratio = median over the trials of ours / the other "
        "(below 1: ours more accurate); p worse = one-sided Wilcoxon signed-rank p-value on "
        "log(ours / other) that ours is worse (exact up to 600 pairs, the tie-corrected normal approximation "
        "beyond). Pooled rows take every trial of that outlier level.",
        "",
        head,
        "|" + "---|" * (head.count("|") - 1),
    ]

    def cells_of(idx):
        out = []
        for k in (0, 1):
            _, med, pw, _ = paired([e_ours[i][k] for i in idx], [e_pl[i][k] for i in idx])
            out.append(f"{med:.2f} / {pw:.3f}")
        if e_before is not None:
            for k in (0, 1):
                _, med, pw, _ = paired([e_ours[i][k] for i in idx], [e_before[i][k] for i in idx])
                out.append(f"{med:.2f} / {pw:.3f}")
            sub = [trials[i] for i in idx]
            out.append(f"{cell_stats(sub, [before[i] for i in idx])['fail']:.1f}")
            vs = []
            for k in (0, 1):
                _, med, pw, _ = paired([e_before[i][k] for i in idx], [e_pl[i][k] for i in idx])
                vs.append(f"{med:.2f} / {pw:.3f}")
            out.append("; ".join(vs))
        return " | ".join(out)

    for (noise, n, of), a, b in cells:
        lines.append(f"| {noise:g} | {n} | {of * 100:.0f} | {cells_of(range(a, b))} |")
    for of in OUTLIERS:
        idx = [i for (key, a, b) in cells if key[2] == of for i in range(a, b)]
        lines.append(f"| all | all | {of * 100:.0f} | {cells_of(idx)} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=500, help="trials per cell (default 500)")
    ap.add_argument("--quick", action="store_true", help="50 trials per cell")
    ap.add_argument("--seed", type=int, default=20260101, help="data seed")
    ap.add_argument("--method", choices=["lms", "r_and_t"], default="lms", help="our solver")
    ap.add_argument("--runner", type=Path, default=None, help="use this pnl_bench binary, skip the build")
    ap.add_argument("--baseline-runner", type=Path, default=None,
                    help="also run this pnl_bench binary (an earlier build) with the same settings, and test ours "
                         "against it cell by cell")
    ap.add_argument(
        "--max-seconds", type=float, default=420.0, help="give up on a method that takes longer than this (default 420)"
    )
    ap.add_argument("--no-md", action="store_true", help="do not write the results file")
    ap.add_argument(
        "--runner-settings",
        action="store_true",
        help="run ours with the runner's own Med_R_and_T settings instead of firmware_config/tracker.toml's",
    )
    args = ap.parse_args()
    if not in_bench_venv():
        ensure_venv_and_reexec()
    import numpy as np
    import poselib

    trials_per_cell = 50 if args.quick else args.trials
    if args.runner is None:
        build_runner()
    runner = args.runner or RUNNER

    rng = np.random.default_rng(args.seed)
    cells, trials = [], []
    for noise in NOISES:
        for n in NS:
            for of in OUTLIERS:
                start = len(trials)
                for _ in range(trials_per_cell):
                    uv1, uv2, X1, X2, R_cw, t_cw, is_out = make_trial(rng, n, noise, of)
                    trials.append(
                        {"id": len(trials), "seed": int(rng.integers(0, 2**63 - 1)), "uv1": uv1, "uv2": uv2,
                         "X1": X1, "X2": X2, "R_cw": R_cw, "t_cw": t_cw, "is_out": is_out}
                    )
                cells.append(((noise, n, of), start, len(trials)))
    print(f"[bench] {len(trials)} trials ({trials_per_cell} per cell, {len(cells)} cells), seed {args.seed}",
          flush=True)

    t0 = time.time()
    print(f"[bench] ours ({args.method}) ...", flush=True)
    extra = [] if args.runner_settings else shipped_solver_args()
    print(f"[bench] our settings: {' '.join(extra) if extra else 'the runner defaults'}", flush=True)
    ours = run_ours(trials, args.method, runner, args.max_seconds, extra=extra)
    t_ours = time.time() - t0
    before = None
    if args.baseline_runner:
        print(f"[bench] ours before ({args.baseline_runner}) ...", flush=True)
        before = run_ours(trials, args.method, args.baseline_runner, args.max_seconds, extra=extra)
    t0 = time.time()
    print(f"[bench] PoseLib {poselib.__version__ if hasattr(poselib, '__version__') else ''} ...", flush=True)
    pl = run_poselib(trials, args.max_seconds)
    t_pl = time.time() - t0
    print(f"[bench] wall time: ours {t_ours:.1f} s (incl. JSON I/O), PoseLib {t_pl:.1f} s", flush=True)
    full = 2 * 4 * 3 * 500
    for name, t in (("ours", t_ours), ("PoseLib", t_pl)):
        if t / len(trials) * full > 300:
            print(f"[bench] note: {name} would take ~{t / len(trials) * full / 60:.1f} min on the full protocol")

    rows = []
    for key, a, b in cells:
        rows.append((key, cell_stats(trials[a:b], pl[a:b]), cell_stats(trials[a:b], ours[a:b])))
    table = table_rows(rows)
    print()
    print("\n".join(table))
    paired_lines = paired_table(trials, cells, ours, pl, before)
    print()
    print("\n".join(paired_lines))

    try:
        from importlib.metadata import version

        pl_version = version("poselib")
    except Exception:  # noqa: BLE001
        pl_version = "?"
    nproc = os.cpu_count()
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    method_name = {
        "lms": "Med_R_and_T (least k-th squares over 3-line subsets solved in closed form, sized for ε = 0.5 "
        "outliers at 99.999 % success, the best poses concentrated (FAST-LTS), lines re-judged by an F-test "
        "against each fit's own σ̂ (never below the camera's pixel), the most likely fit kept and its lines "
        "fitted last under Cauchy's loss; tracker.toml's settings unless --runner-settings)",
        "r_and_t": "R_and_T (no guess, line error E2)",
    }
    md = [
        "# PnL benchmark: omnitrack vs PoseLib",
        "",
        f"Generated by `python3 tools/bench_pnl.py{' --quick' if args.quick else ''}"
        f"{'' if args.quick or args.trials == 500 else f' --trials {args.trials}'}"
        f"{'' if args.method == 'lms' else ' --method ' + args.method}` on "
        f"{datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}; machine: {cpu}, nproc = {nproc}, "
        f"{platform.system()} {platform.machine()}, Python {platform.python_version()}, "
        f"PoseLib {pl_version}, numpy {np.__version__}.",
        "",
        f"Data: pinhole f = {FOCAL:g} px, {WIDTH}×{HEIGHT}, principal point at the centre; random camera pose; "
        f"3D segments with end points at depth {DEPTH[0]:g}–{DEPTH[1]:g} m projecting inside the image "
        f"(2D length ≥ {MIN_LEN_PX:g} px); Gaussian noise σ on each 2D end point coordinate; outliers = 2D "
        f"segment replaced by a random segment in the image; {trials_per_cell} trials per cell, seed {args.seed}.",
        "",
        f"PL = PoseLib `estimate_absolute_pose_pnpl` (lines only, ransac_opt {POSELIB_RANSAC}, other "
        f"options default). Ours = `omnitrack::solver::{'med_r_and_t' if args.method == 'lms' else 'r_and_t'}` "
        f"— {method_name[args.method]}, other `SolverOptions` defaults, via `tools/src/bin/pnl_bench.rs`.",
        "",
        "rot° = median rotation error (deg); t% = median |t_est − t_true| / |t_true| in T_camera_world, i.e. "
        "relative to the camera-to-scene-centroid distance (%); medians over all trials, no result = ∞. "
        f"fail% = no result, or rotation error > {ROT_FAIL_DEG:g}°, or translation error > {TRANS_FAIL_PCT:g} %. "
        "µs = median time per call (the call only). Ratios are PoseLib / ours: time ratio > 1 means ours is "
        "faster, error ratio > 1 means ours is more accurate.",
        "",
        *table,
        "",
        *paired_lines,
        "",
    ]
    if not args.no_md:
        cmd = (f"python3 tools/bench_pnl.py{' --quick' if args.quick else ''}"
               f"{'' if args.quick or args.trials == 500 else f' --trials {args.trials}'}"
               f"{'' if args.method == 'lms' else ' --method ' + args.method}"
               f"{' --baseline-runner BEFORE' if before is not None else ''}")
        path = write_results("pnl", "PnL benchmark: omnitrack vs PoseLib", cmd, "\n".join(md[2:]))
        print(f"\n[bench] wrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
