#!/usr/bin/env python3
"""Line pose on real data: omnitrack against PoseLib on the Oxford VGG multiview line sequences.

    python3 tools/bench_vgg.py DATA_DIR                 # shipped solver settings, E2 and E3
    python3 tools/bench_vgg.py DATA_DIR --draws 20      # 20 outlier draws per view at 30 %

DATA_DIR is the `oxford_data` directory of GitHub `petrhruby97/efficient_absolute` (model_house,
corridor, merton1-3, library, wadham: the VGG group's hand-matched 2D lines, their reconstructed
3D lines and every view's 3x4 camera matrix). It is not in this repository; get it with
`git clone --depth 1 https://github.com/petrhruby97/efficient_absolute` and pass
`efficient_absolute/oxford_data`.

What it does:
 1. Reuses tools/bench_pnl.py's venv (numpy, PoseLib from PyPI) and Rust runner
    (tools/src/bin/pnl_bench.rs), built in release.
 2. Per view: decomposes P = K [R | t] (RQ). model_house and corridor are reconstructions in a
    left-handed frame (det R = -1): the world is mirrored in z for the whole sequence, which
    leaves every image unchanged. Their K has skew, which PoseLib's pinhole cannot take: every
    2D end point is mapped through K^-1 and back through a skew-free K' (f = (fx + fy) / 2, the
    same principal point), an exact homography of the image, so both methods see the same lines.
 3. A correspondence is a 3D line of the sequence and its matched 2D line in the view
    (`nview-lines`). At 30 % outliers, round(0.3 n) of a view's 2D lines are replaced by random
    segments inside the image's extent (`--draws` draws per view, seeded).
 4. Runs PoseLib's estimate_absolute_pose_pnpl (lines only, max_epipolar_error 4 px as in
    bench_pnl.py) and ours on identical correspondences: `--method lms` with the settings of
    firmware_config/tracker.toml (what `omnitrack pose --method lms` runs), once per line error
    in `--errors` (default e2,e3).
 5. Prints per sequence and outlier level: views, lines per view, median rotation error (deg),
    median camera-centre error (in the reconstruction's units, and as % of the median distance
    from the camera to its lines) and failures (no pose, rotation error > 5 deg or centre error
    > 10 % of that distance) for each method.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS))
import bench_pnl  # noqa: E402  (the venv, the runner and PoseLib's call are shared)

SEQUENCES = {
    # name: (2D prefix, P files directory, P prefix, views)
    "model_house": ("2D/house.", "3D", "house.", [f"{i:03d}" for i in range(10)]),
    "corridor": ("2D/bt.", "3D", "bt.", [f"{i:03d}" for i in range(11)]),
    "merton1": ("2D/", "2D", "", ["001", "002", "003"]),
    "merton2": ("2D/", "2D", "", ["001", "002", "003"]),
    "merton3": ("2D/", "2D", "", ["001", "002", "003"]),
    "library": ("2D/", "2D", "", ["001", "002", "003"]),
    "wadham": ("2D/", "2D", "", ["001", "002", "003", "004", "005"]),
}
ROT_FAIL_DEG, CENTRE_FAIL_FRAC = 5.0, 0.10


def read_rows(path: Path):
    rows = []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts:
            rows.append(parts)
    return rows


def rq(m):
    """M = K R with K upper triangular, positive diagonal."""
    import numpy as np

    flip = np.flipud(np.eye(3))
    q, r = np.linalg.qr((flip @ m).T)
    k = flip @ r.T @ flip
    rot = flip @ q.T
    d = np.diag(np.sign(np.diag(k)))
    return k @ d, d @ rot


def load_sequence(root: Path, name: str):
    """Views as dicts: K' (skew-free), R_cw, t_cw, lines (u1 v1 u2 v2 X1 Y1 Z1 X2 Y2 Z2), extent."""
    import numpy as np

    lines_prefix, p_dir, p_prefix, views = SEQUENCES[name]
    d = root / name
    l3d_name = {"model_house": "3D/house.l3d", "corridor": "3D/bt.l3d"}.get(name, "3D/l3d")
    l3d = np.array([[float(x) for x in r[:6]] for r in read_rows(d / l3d_name)])
    nview = read_rows(d / (lines_prefix + "nview-lines"))
    ps = []
    for v in views:
        p = np.array([[float(x) for x in r[:4]] for r in read_rows(d / p_dir / f"{p_prefix}{v}.P")])
        # Scale sign: the 3D lines lie in front of the camera.
        ends = np.vstack([l3d[:, :3], l3d[:, 3:]])
        depth = (np.hstack([ends, np.ones((len(ends), 1))]) @ p.T)[:, 2]
        if np.median(depth) < 0:
            p = -p
        ps.append(p)
    k0, r0 = rq(ps[0][:, :3])
    mirror = np.linalg.det(r0) < 0
    s = np.diag([1.0, 1.0, -1.0]) if mirror else np.eye(3)
    if mirror:
        l3d = np.hstack([l3d[:, :3] @ s, l3d[:, 3:] @ s])
    out = []
    for vi, (v, p) in enumerate(zip(views, ps)):
        m = p[:, :3] @ s
        k, r = rq(m)
        if np.linalg.det(r) < 0:
            raise SystemExit(f"{name} view {v}: handedness differs from the first view")
        # P = lam K [R | t] with K[2, 2] = 1.
        lam = k[2, 2]
        k = k / lam
        t = np.linalg.solve(k, p[:, 3]) / lam
        f = (k[0, 0] + k[1, 1]) / 2.0
        kp = np.array([[f, 0.0, k[0, 2]], [0.0, f, k[1, 2]], [0.0, 0.0, 1.0]])
        to_kp = kp @ np.linalg.inv(k)
        rows2d = [[float(x) for x in r[:4]] for r in read_rows(d / (lines_prefix + f"{v}.lines"))]
        lines = []
        for j, match in enumerate(nview):
            if vi >= len(match) or match[vi] in ("*", "-1"):
                continue
            i = int(match[vi])
            u1, v1, u2, v2 = rows2d[i]
            a = to_kp @ np.array([u1, v1, 1.0])
            b = to_kp @ np.array([u2, v2, 1.0])
            lines.append([a[0] / a[2], a[1] / a[2], b[0] / b[2], b[1] / b[2], *l3d[j]])
        lines = np.array(lines)
        all2d = np.array(rows2d)
        extent = (float(all2d[:, [0, 2]].max()), float(all2d[:, [1, 3]].max()))
        out.append({"view": v, "K": [f, f, float(k[0, 2]), float(k[1, 2])], "R_cw": r, "t_cw": t,
                    "lines": lines, "extent": extent})
    return out, mirror


def check_truth(views):
    """Reprojection of the 3D end points against the matched 2D segments' lines (px): the
    decomposition is right when this is small."""
    import numpy as np

    errs = []
    for v in views:
        f, _, cx, cy = v["K"]
        k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
        for l in v["lines"]:
            h = np.cross([l[0], l[1], 1.0], [l[2], l[3], 1.0])
            h /= np.linalg.norm(h[:2])
            for x in (l[4:7], l[7:10]):
                p = k @ (v["R_cw"] @ x + v["t_cw"])
                errs.append(abs(h @ (p / p[2])))
    return float(np.median(errs))


VARIANTS = {
    # name: (line error, runner flags beyond the shipped settings, column label)
    "e2": ("e2", [], "ours lms e2"),
    "e3": ("e3", [], "ours lms e3"),
    "e2-nofloor": ("e2", ["--no-pixel-floor"], "ours lms e2, no pixel floor"),
    "e3-nofloor": ("e3", ["--no-pixel-floor"], "ours lms e3, no pixel floor"),
}
CHI2_3_MEDIAN, CHI2_3_95 = 2.365974, 7.814728


def rotation_vector(m):
    """The axis-angle vector of rotation matrix m (rad)."""
    import numpy as np

    c = max(-1.0, min(1.0, (np.trace(m) - 1.0) / 2.0))
    angle = math.acos(c)
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    if angle < 1e-12:
        return w / 2.0
    return w * angle / (2.0 * math.sin(angle))


def errors(trial, r):
    """(rotation error deg, centre error, failed, d2 rotation, d2 centre): the errors of one
    result against the truth, and each as a squared Mahalanobis distance under the result's own
    covariance (None without one). The covariance is T_world_camera's: camera centre in the world,
    then the small rotation δθ of R_wc = exp(δθ) R_wc_true, world frame."""
    import numpy as np

    if not r["ok"]:
        return math.inf, math.inf, True, None, None
    re = bench_pnl.rot_err_deg(r["R"], trial["R_cw"])
    c = -r["R"].T @ r["t"]
    dc = c - trial["centre"]
    ce = float(np.linalg.norm(dc))
    failed = re > ROT_FAIL_DEG or ce > CENTRE_FAIL_FRAC * trial["scale"]
    d2r = d2c = None
    cov = r.get("cov")
    if cov is not None and np.all(np.isfinite(cov)):
        dth = rotation_vector(r["R"].T @ trial["R_cw"])
        try:
            d2c = float(dc @ np.linalg.solve(cov[:3, :3], dc))
            d2r = float(dth @ np.linalg.solve(cov[3:, 3:], dth))
        except np.linalg.LinAlgError:
            pass
    return re, ce, failed, d2r, d2c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", type=Path, help="the oxford_data directory")
    ap.add_argument("--draws", type=int, default=10, help="outlier draws per view at 30 %% (default 10)")
    ap.add_argument("--variants", default="e2,e3,e2-nofloor",
                    help=f"our variants to run, of {','.join(VARIANTS)} (default e2,e3,e2-nofloor)")
    ap.add_argument("--seed", type=int, default=20261127)
    ap.add_argument("--runner", type=Path, default=None, help="use this pnl_bench binary, skip the build")
    ap.add_argument("--baseline-runner", type=Path, default=None,
                    help="also run this pnl_bench binary (an earlier build) with the shipped settings, as a column")
    ap.add_argument("--baseline-label", default="ours lms e2, before", help="that column's name")
    ap.add_argument("--no-results", action="store_true", help="do not write the results file")
    args = ap.parse_args()
    if not bench_pnl.in_bench_venv():
        bench_pnl.ensure_venv_and_reexec()
    import numpy as np

    if not args.data.is_dir():
        sys.exit(f"{args.data}: not a directory (pass efficient_absolute/oxford_data)")
    if args.runner is None:
        bench_pnl.build_runner()
    runner = args.runner or bench_pnl.RUNNER
    shipped = bench_pnl.shipped_solver_args()
    rng = np.random.default_rng(args.seed)
    trials, groups, notes = [], [], []
    for name in SEQUENCES:
        views, mirror = load_sequence(args.data, name)
        note = (f"{name}: {len(views)} views, {np.mean([len(v['lines']) for v in views]):.0f} lines per view, "
                f"{'mirrored (left-handed), ' if mirror else ''}median end-point line distance at the truth "
                f"{check_truth(views):.2f} px")
        notes.append(note)
        print(f"[vgg] {note}", flush=True)
        for outliers in (0.0, 0.3):
            start = len(trials)
            for v in views:
                for _ in range(1 if outliers == 0 else args.draws):
                    lines = v["lines"].copy()
                    n_out = int(round(outliers * len(lines)))
                    for i in rng.choice(len(lines), size=n_out, replace=False) if n_out else []:
                        w, h = v["extent"]
                        while True:
                            a, b = rng.uniform([0, 0], [w, h]), rng.uniform([0, 0], [w, h])
                            if np.linalg.norm(a - b) >= bench_pnl.MIN_LEN_PX:
                                break
                        lines[i, :4] = [a[0], a[1], b[0], b[1]]
                    centre = -v["R_cw"].T @ v["t_cw"]
                    mids = (lines[:, 4:7] + lines[:, 7:10]) / 2.0
                    trials.append({
                        "id": len(trials), "seed": int(rng.integers(0, 2**63 - 1)), "K": v["K"],
                        "uv1": lines[:, 0:2], "uv2": lines[:, 2:4], "X1": lines[:, 4:7], "X2": lines[:, 7:10],
                        "R_cw": v["R_cw"], "t_cw": v["t_cw"], "centre": centre, "view": (name, v["view"]),
                        "outliers": outliers,
                        "scale": float(np.median(np.linalg.norm(mids - centre, axis=1))),
                        "cam": {"model": "PINHOLE", "width": int(math.ceil(v["extent"][0])),
                                "height": int(math.ceil(v["extent"][1])), "params": v["K"]},
                    })
            groups.append((name, outliers, start, len(trials)))
    variants = [v for v in args.variants.split(",") if v]
    for v in variants:
        if v not in VARIANTS:
            sys.exit(f"--variants: unknown {v!r} (known: {', '.join(VARIANTS)})")
    methods = [("PoseLib", None)] + [(VARIANTS[v][2], v) for v in variants]
    if args.baseline_runner:
        methods.append((args.baseline_label, "baseline"))
    results, seconds = {}, {}
    for label, variant in methods:
        t0 = time.time()
        if variant is None:
            results[label] = bench_pnl.run_poselib(trials, 600.0)
        elif variant == "baseline":
            results[label] = bench_pnl.run_ours(trials, "lms", args.baseline_runner, 600.0, extra=shipped)
        else:
            # The shipped settings, with the line error of this column instead of the shipped one.
            error, flags, _ = VARIANTS[variant]
            i = shipped.index("--error")
            extra = shipped[:i] + shipped[i + 2 :] + ["--error", error, *flags]
            results[label] = bench_pnl.run_ours(trials, "lms", runner, 600.0, extra=extra)
        seconds[label] = time.time() - t0
        print(f"[vgg] {label}: {seconds[label]:.1f} s", flush=True)
    errs = {label: [errors(t, r) for t, r in zip(trials, results[label])] for label, _ in methods}

    out = []
    out.append(f"Shipped Med_R_and_T settings: `{' '.join(shipped)}` (the error as in each column). "
               "\"no pixel floor\": the solver not given the camera's pixel (its inlier gate on the lines' own σ̂)."
               + (f" \"{args.baseline_label}\": the build at `{args.baseline_runner}`, shipped settings."
                  if args.baseline_runner else ""))
    out.append("")
    out.extend(f"- {n}" for n in notes)
    out.append("")
    out.append("Median rotation error (°) / camera-centre error (reconstruction units, and % of the median "
               f"distance to the lines) / failures (no pose, rotation error > {ROT_FAIL_DEG:g}° or centre error "
               f"> {CENTRE_FAIL_FRAC * 100:g} % of that distance):")
    out.append("")
    out.append("| sequence | outliers | trials |" + "".join(f" {m} |" for m, _ in methods))
    out.append("|" + " --- |" * (3 + len(methods)))
    for name, outliers, lo, hi in groups:
        scale = float(np.median([t["scale"] for t in trials[lo:hi]]))
        cells = []
        for label, _ in methods:
            e = errs[label][lo:hi]
            r = float(np.median([x[0] for x in e]))
            c = float(np.median([x[1] for x in e]))
            fails = sum(x[2] for x in e)
            cells.append(f" {r:.3f} / {c:.4f} ({100 * c / scale:.2f} %) / {fails} |")
        out.append(f"| {name} | {outliers * 100:.0f} % | {hi - lo} |" + "".join(cells))

    # The paired test: each view is a pair (ours, PoseLib) on identical lines. At 30 % outliers
    # a view's error is the median over its draws (the draws of one view share its lines, so the
    # view, not the draw, is the independent unit); the per-draw pairs are given beside it.
    view_keys = list(dict.fromkeys(t["view"] for t in trials))

    def per_view(label, outliers, k):
        vals = []
        for key in view_keys:
            xs = [e[k] for t, e in zip(trials, errs[label]) if t["view"] == key and t["outliers"] == outliers]
            vals.append(float(np.median(xs)))
        return vals

    def per_draw(label, outliers, k):
        return [e[k] for t, e in zip(trials, errs[label]) if t["outliers"] == outliers]

    out.append("")
    out.append(f"Paired test against PoseLib, pooled over all {len(view_keys)} views: median of the per-view "
               "ratios ours / PoseLib, and one-sided Wilcoxon signed-rank p-values (exact) on log(ours / PoseLib) "
               "for \"ours worse\" and \"ours better\". At 30 % outliers a view's error is the median over its "
               f"{args.draws} draws; the per-draw pairs ({args.draws} × {len(view_keys)}) follow in brackets. "
               "Fails: trials where only that method failed.")
    out.append("")
    out.append("| ours | outliers | rotation: ratio / p worse / p better | centre: ratio / p worse / p better "
               "| [per draw: rotation ratio / p worse; centre ratio / p worse] | fails ours only / PoseLib only |")
    out.append("| --- | --- | --- | --- | --- | --- |")
    verdicts = []
    for label, variant in methods[1:]:
        for outliers in (0.0, 0.3):
            cells = []
            worst = 0.0
            for k in (0, 1):
                n, med, pw, pb = bench_pnl.paired(per_view(label, outliers, k), per_view("PoseLib", outliers, k))
                cells.append(f"{med:.2f} / {pw:.3f} / {pb:.3f}")
                worst = min(worst or 1.0, pw)
            dr = bench_pnl.paired(per_draw(label, outliers, 0), per_draw("PoseLib", outliers, 0))
            dc = bench_pnl.paired(per_draw(label, outliers, 1), per_draw("PoseLib", outliers, 1))
            ours_f = [e[2] for t, e in zip(trials, errs[label]) if t["outliers"] == outliers]
            pl_f = [e[2] for t, e in zip(trials, errs["PoseLib"]) if t["outliers"] == outliers]
            only_ours = sum(a and not b for a, b in zip(ours_f, pl_f))
            only_pl = sum(b and not a for a, b in zip(ours_f, pl_f))
            out.append(f"| {label} | {outliers * 100:.0f} % | {cells[0]} | {cells[1]} | [{dr[1]:.2f} / {dr[2]:.3f}; "
                       f"{dc[1]:.2f} / {dc[2]:.3f}] | {only_ours} / {only_pl} |")
            verdicts.append((label, outliers, worst, only_ours))
    if args.baseline_runner:
        out.append("")
        out.append(f"Each of ours against \"{args.baseline_label}\", paired the same way (ratio / p worse / p better):")
        out.append("")
        out.append("| ours | outliers | rotation | centre |")
        out.append("| --- | --- | --- | --- |")
        for label, variant in methods[1:]:
            if variant == "baseline":
                continue
            for outliers in (0.0, 0.3):
                cells = []
                for k in (0, 1):
                    _, med, pw, pb = bench_pnl.paired(per_view(label, outliers, k),
                                                      per_view(args.baseline_label, outliers, k))
                    cells.append(f"{med:.2f} / {pw:.3f} / {pb:.3f}")
                out.append(f"| {label} | {outliers * 100:.0f} % | {cells[0]} | {cells[1]} |")
    out.append("")
    for label, _ in methods[1:]:
        rows = [v for v in verdicts if v[0] == label]
        met = all(p >= 0.05 and f == 0 for _, _, p, f in rows)
        out.append(f"- {label}: not worse than PoseLib at p < 0.05 (rotation and centre, 0 % and 30 %) and no "
                   f"view failing only for us: {'met' if met else 'not met'} "
                   f"(smallest p worse {min(p for _, _, p, _ in rows):.3f}, ours-only failures "
                   f"{sum(f for *_, f in rows)}).")

    # The lines kept and the covariance's honesty.
    out.append("")
    out.append("Lines kept (median share of a view's lines in the final fit) and the §5 covariance against the "
               "observed errors: d² is an error's squared Mahalanobis distance under the solution's own "
               "covariance, rotation and centre each χ²₃ when the covariance is honest (median "
               f"{CHI2_3_MEDIAN:.2f}, 95 % below {CHI2_3_95:.2f}). \"Spread\" = √(median d² / {CHI2_3_MEDIAN:.2f}): "
               "the observed spread over the predicted one (1: honest; above 1: the covariance is too small).")
    out.append("")
    out.append("| ours | outliers | kept | rotation: spread / within 95 % | centre: spread / within 95 % |")
    out.append("| --- | --- | --- | --- | --- |")
    for label, _ in methods[1:]:
        for outliers in (0.0, 0.3):
            sel = [(t, r, e) for t, r, e in zip(trials, results[label], errs[label]) if t["outliers"] == outliers]
            kept = [r["inliers"] / r["lines"] for _, r, _ in sel if r["ok"] and r.get("lines")]
            cells = []
            for k in (3, 4):
                d2 = np.array([e[k] for *_, e in sel if e[k] is not None])
                if len(d2) == 0:
                    cells.append("- / -")
                    continue
                cells.append(f"{math.sqrt(np.median(d2) / CHI2_3_MEDIAN):.2f} / {100 * np.mean(d2 <= CHI2_3_95):.0f} %")
            share = f"{100 * np.median(kept):.0f} %" if kept else "-"
            out.append(f"| {label} | {outliers * 100:.0f} % | {share} | {cells[0]} | {cells[1]} |")
    out.append("")
    base = [m for m, _ in methods[1:]]
    out.append("Time of the whole run per method (solver calls with I/O, same run, this machine): "
               + ", ".join(f"{m} {seconds[m]:.1f} s" for m in ["PoseLib", *base]) + ".")
    text = "\n".join(out)
    print()
    print(text)
    if not args.no_results:
        cmd = "python3 tools/bench_vgg.py DATA_DIR" + ("" if args.draws == 10 else f" --draws {args.draws}") + (
            "" if args.variants == "e2,e3,e2-nofloor" else f" --variants {args.variants}") + (
            " --baseline-runner BEFORE" if args.baseline_runner else "")
        path = bench_pnl.write_results("vgg", "Line pose on the Oxford VGG lines: omnitrack against PoseLib, paired",
                                       cmd, text)
        print(f"\n[vgg] wrote {path.relative_to(bench_pnl.REPO)}")


if __name__ == "__main__":
    main()
