#!/usr/bin/env python3
"""Line quality on real photographs (YorkUrbanDB, or the Oxford VGG `model_house`): omnitrack's
edge extractor beside OpenCV's LSD, FastLineDetector and EDLines, scored against the
hand-marked segments by one rule, into benches/results/DATE-MACHINE/lines-DATASET.md.

    python3 tools/bench_lines_real.py DB [--work DIR] [--passes N] [--omnitrack-dir DIR]
                                         [--omnitrack-args "ARGS"] [--min-gt-px L] [--min-det-px L]
                                         [--offset PX] [--no-results 1]

DB is either of two layouts, told apart by what it holds.

Oxford: the VGG multi-view `model_house` folder (DB/images/house.NNN.pgm, 768x576 grey, and
DB/2D/house.NNN.lines: one segment a line, "x0 y0 x1 y1 ...", in pixels with (0,0) at the centre
of the top-left pixel, so --offset defaults to 0 there; DB/3D/house.000.P gives the camera,
whose K the script takes by an RQ decomposition). The public repository
petrhruby97/efficient_absolute carries it as oxford_data/model_house/; keep it outside this
repository. Issue 51's rule on it: a line counts as found when one detection covers half of it
(the table's "GT half-covered by one"), and its recall should be at least LSD's.

YorkUrbanDB:
the original York Urban Line Segment Database of Denis, Elder and
Estrada, ECCV 2008): DB/cameraParameters.mat and, for each of the 102 images, DB/NAME/NAME.jpg
(640x480) with DB/NAME/NAMELinesAndVP.mat (`lines`: 2k x 2 end points x, y, in MATLAB's 1-based
pixel coordinates). The public repository johndpope/BMVC-Dubska carries that folder whole
(YorkUrbanDB/); keep it outside this repository (e.g. /work/data/yorkurban/YorkUrbanDB).

The script creates (or reuses) the venv tools/.venv-bench-lines-real, installs numpy, scipy and
opencv-contrib-python-headless into it, re-runs itself inside it, and then
  1. decodes every JPEG once with OpenCV and writes it as PNG to WORK/images (default WORK:
     target/bench-lines-real), so that every detector sees the same pixels;
  2. runs `cargo bench --bench edges_real -- --images WORK/images --out WORK/omnitrack
     --intrinsics fx,fy,cx,cy --passes N` (release build; the published camera:
     f = focal / pixelSize = 674.9 px, principal point pp - 1 = (306.55, 250.45)), which writes
     omnitrack's edges per image and times `EdgeDetector::detect_sensor` (colour image, edges +
     hue, one thread, decoding not timed); `--omnitrack-args "..."` appends options of that
     bench (e.g. "--min-support 0.85"); `--omnitrack-dir DIR` skips this and reads DIR;
  3. times OpenCV on the same PNGs, default parameters, cvtColor BGR->GRAY included in the time,
     decoding not, cv2.setNumThreads(2) as in tools/bench_edges.py (the three run single-threaded
     inside; omnitrack gets one thread):
       LSD         cv2.createLineSegmentDetector()
       FLD         cv2.ximgproc.createFastLineDetector()
       EDLines     cv2.ximgproc.createEdgeDrawing(): detectEdges(grey), then detectLines()
     N passes over all images after one warm-up pass, like omnitrack;
  4. scores all four by the rule below and prints the table. omnitrack gets two rows from one
     detection: its edges as the tracker takes them, each over the whole span its plane was
     fitted to (merging bridges gaps between collinear pieces: a line broken by an occluder, or
     the tops of a row of windows), and the pieces of them that the image shows (the CSV's
     `pieces` column).

The matching rule (the same for every detector). Coordinates are OpenCV's: (0,0) is the centre
of the top-left pixel, so the MATLAB ground truth is shifted by --offset (default -1 px; of
0, -0.5, -1 and -1.5, -1 gives omnitrack, FastLineDetector and EDLines their best strict recall).
  - Ground truth: the segments of NAMELinesAndVP.mat at least --min-gt-px (30) long. York's
    annotation marks only lines along the three Manhattan directions, and not all of them: a
    correct detection of any other straight edge (furniture, texture, foliage) counts against
    precision, for every detector alike. Precision is therefore low in absolute terms and only
    its comparison between detectors means something.
  - Detections: segments at least --min-det-px (20) long; shorter ones are dropped, for every
    detector (omnitrack itself drops edges shorter than 2 deg, ~23 px here).
  - A detection d matches a ground-truth segment g when the angle between their directions is at
    most 3 deg, both end points of d lie within 2 px of g's line (perpendicular distance), and
    d's projection onto g's line overlaps g.
  - Recall: the length of every ground-truth segment covered by the union of its matched
    detections' projections, summed over all images, over the summed ground-truth length.
    Also given: the fraction of ground-truth segments half of which one detection covers
    (the issue's earlier measure on Oxford: end points within 2 px, direction within 3 deg,
    half the line covered).
  - Precision: the length of every detection covered by the union of its matched ground-truth
    segments' projections onto it, summed, over the summed detected length.
The same figures at a strict (1 px, 1.5 deg) and a loose (3 px, 5 deg) tolerance follow.
Time: p50 and p99 over all (image, pass) detections, and p50 over FastLineDetector's p50.
"""
import glob
import json
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
VENV = os.path.join(HERE, ".venv-bench-lines-real")
PY = os.path.join(VENV, "bin", "python")

TOLERANCES = [("main", 2.0, 3.0), ("strict", 1.0, 1.5), ("loose", 3.0, 5.0)]


def ensure_venv():
    if os.path.abspath(sys.prefix) == os.path.abspath(VENV):
        return
    if not os.path.exists(PY):
        print(f"bench_lines_real: creating {VENV}", file=sys.stderr)
        subprocess.check_call([sys.executable, "-m", "venv", VENV])
    try:
        subprocess.check_call(
            [PY, "-c", "import cv2, numpy, scipy.io; cv2.ximgproc.createEdgeDrawing"], stderr=subprocess.DEVNULL
        )
    except subprocess.CalledProcessError:
        print("bench_lines_real: installing numpy, scipy, opencv-contrib-python-headless", file=sys.stderr)
        subprocess.check_call([PY, "-m", "pip", "install", "-q", "numpy", "scipy", "opencv-contrib-python-headless"])
    os.execv(PY, [PY] + sys.argv)


def pct(sorted_ms, q):
    return sorted_ms[int(round((len(sorted_ms) - 1) * q))]


def parse_args(argv):
    opts = {"work": os.path.join(ROOT, "target", "bench-lines-real"), "passes": 5, "omnitrack-dir": None,
            "omnitrack-args": "",
            "min-gt-px": 30.0, "min-det-px": 20.0, "offset": None, "no-results": 0.0}
    rest = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a.startswith("--") and a[2:] in opts:
            if i + 1 >= len(argv):
                sys.exit(f"bench_lines_real: {a} needs a value")
            key = a[2:]
            v = argv[i + 1]
            opts[key] = v if key in ("work", "omnitrack-dir", "omnitrack-args") else (int(v) if key == "passes" else float(v))
            i += 2
        elif a in ("-h", "--help"):
            print(__doc__)
            sys.exit(0)
        else:
            rest.append(a)
            i += 1
    if len(rest) != 1:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    return rest[0], opts


def load_db(db, offset):
    """[(name, image path, gt array k x 4 in OpenCV pixels)], camera (fx, fy, cx, cy), the data
    set's name, the offset applied."""
    if glob.glob(os.path.join(db, "images", "*.pgm")) and glob.glob(os.path.join(db, "2D", "*.lines")):
        offset = 0.0 if offset is None else offset
        items, cam = load_oxford(db, offset)
        return items, cam, "Oxford VGG " + os.path.basename(os.path.normpath(db)), offset
    offset = -1.0 if offset is None else offset
    items, cam = load_york(db, offset)
    return items, cam, "YorkUrbanDB", offset


def load_oxford(db, offset):
    import numpy as np
    import scipy.linalg

    items = []
    for img in sorted(glob.glob(os.path.join(db, "images", "*.pgm"))):
        name = os.path.basename(img)[: -len(".pgm")]
        path = os.path.join(db, "2D", name + ".lines")
        if not os.path.exists(path):
            continue
        rows = []
        with open(path) as fh:
            for line in fh:
                parts = line.split()
                if len(parts) >= 4:
                    rows.append([float(v) for v in parts[:4]])
        items.append((name, img, np.asarray(rows, dtype=np.float64).reshape(-1, 4) + offset))
    if not items:
        sys.exit(f"bench_lines_real: {db}: no images/NAME.pgm with 2D/NAME.lines")
    p_files = sorted(glob.glob(os.path.join(db, "3D", "*.P")))
    if not p_files:
        sys.exit(f"bench_lines_real: {db}/3D: no camera matrix (NAME.P)")
    with open(p_files[0]) as fh:
        p = np.array([float(v) for v in re.split(r"\s+", fh.read().strip())], dtype=np.float64).reshape(3, 4)
    k, _ = scipy.linalg.rq(p[:, :3])
    # RQ leaves the signs to choose: a positive diagonal, and K[2,2] = 1.
    k = k @ np.diag(np.sign(np.diag(k)))
    k = k / k[2, 2]
    return items, (abs(float(k[0, 0])), abs(float(k[1, 1])), float(k[0, 2]) + offset, float(k[1, 2]) + offset)


def load_york(db, offset):
    import numpy as np
    import scipy.io as sio

    cam_path = os.path.join(db, "cameraParameters.mat")
    if not os.path.exists(cam_path):
        sys.exit(f"bench_lines_real: {cam_path}: missing (is {db} the YorkUrbanDB folder?)")
    cam = sio.loadmat(cam_path)
    f = float(cam["focal"][0, 0] / cam["pixelSize"][0, 0])
    pp = cam["pp"][0] + offset
    items = []
    for d in sorted(glob.glob(os.path.join(db, "P*"))):
        name = os.path.basename(d)
        jpg = os.path.join(d, name + ".jpg")
        mat = os.path.join(d, name + "LinesAndVP.mat")
        if not (os.path.exists(jpg) and os.path.exists(mat)):
            continue
        pts = np.asarray(sio.loadmat(mat)["lines"], dtype=np.float64) + offset
        gt = np.concatenate([pts[0::2], pts[1::2]], axis=1)
        items.append((name, jpg, gt))
    if not items:
        sys.exit(f"bench_lines_real: {db}: no NAME/NAME.jpg with NAME/NAMELinesAndVP.mat")
    return items, (f, f, float(pp[0]), float(pp[1]))


def run_omnitrack(images_dir, out_dir, cam, passes, extra):
    cmd = ["cargo", "bench", "--bench", "edges_real", "--", "--images", images_dir, "--out", out_dir,
           "--intrinsics", ",".join(f"{v:.4f}" for v in cam), "--passes", str(passes)] + extra.split()
    print("bench_lines_real: " + " ".join(cmd), file=sys.stderr)
    res = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    if res.returncode != 0:
        sys.exit(f"bench_lines_real: cargo bench failed ({res.returncode})")
    return res.stdout.strip()


def read_omnitrack(out_dir, names):
    """(edges, pieces, sorted times): per image the edges' end points (k x 4), and the pieces the
    image shows (the `pieces` column split at its gaps; the edge itself where it is empty; nothing
    where it is `none`)."""
    import csv

    import numpy as np

    edges, pieces = {}, {}
    for n in names:
        path = os.path.join(out_dir, n + ".csv")
        if not os.path.exists(path):
            sys.exit(f"bench_lines_real: {path}: missing")
        e_rows, p_rows = [], []
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader)
            col = header.index("pieces") if "pieces" in header else None
            for row in reader:
                end_points = [float(x) for x in row[:4]]
                e_rows.append(end_points)
                groups = row[col].split(";") if col is not None and row[col] else []
                if groups == ["none"]:
                    continue  # the image shows no piece of this edge as a line
                if groups:
                    p_rows.extend([float(x) for x in g.split()] for g in groups)
                else:
                    p_rows.append(end_points)
        edges[n] = np.array(e_rows, dtype=float).reshape(-1, 4)
        pieces[n] = np.array(p_rows, dtype=float).reshape(-1, 4)
    times = []
    with open(os.path.join(out_dir, "timing.csv")) as fh:
        next(fh)
        for line in fh:
            times.append(float(line.rsplit(",", 1)[1]))
    return edges, pieces, sorted(times)


def run_opencv(pngs, passes):
    """{detector: ({name: k x 4}, sorted ms)}."""
    import cv2
    import numpy as np

    cv2.setNumThreads(2)
    lsd = cv2.createLineSegmentDetector()
    fld = cv2.ximgproc.createFastLineDetector()
    ed = cv2.ximgproc.createEdgeDrawing()

    def edlines(g):
        ed.detectEdges(g)
        return ed.detectLines()

    dets = [("OpenCV LSD", lambda g: lsd.detect(g)[0]), ("OpenCV FastLineDetector", fld.detect),
            ("OpenCV EDLines", edlines)]
    imgs = [(n, cv2.imread(p, cv2.IMREAD_COLOR)) for n, p in pngs]
    out = {}
    for label, det in dets:
        segs, times = {}, []
        for p in range(passes + 1):
            for n, img in imgs:
                t0 = time.perf_counter_ns()
                g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                lines = det(g)
                dt = (time.perf_counter_ns() - t0) * 1e-6
                if p > 0:
                    times.append(dt)
                else:
                    segs[n] = np.zeros((0, 4)) if lines is None else np.asarray(lines, np.float64).reshape(-1, 4)
        out[label] = (segs, sorted(times))
    return out


def score(dets, gts, min_gt, min_det, dist_px, ang_deg):
    """(length recall, fraction of GT segments half-covered by one detection, length precision)."""
    import numpy as np

    cos_tol = np.cos(np.radians(ang_deg))
    gt_len = gt_cov = det_len = det_cov = 0.0
    gt_n = gt_half = 0
    for name, gt in gts.items():
        gt = gt[np.hypot(gt[:, 2] - gt[:, 0], gt[:, 3] - gt[:, 1]) >= min_gt]
        d = dets[name]
        d = d[np.hypot(d[:, 2] - d[:, 0], d[:, 3] - d[:, 1]) >= min_det]
        if len(gt) == 0 and len(d) == 0:
            continue
        ga, gb = gt[:, :2], gt[:, 2:]
        da, db = d[:, :2], d[:, 2:]
        gl = np.linalg.norm(gb - ga, axis=1)
        dl = np.linalg.norm(db - da, axis=1)
        gu = (gb - ga) / gl[:, None]
        du = (db - da) / dl[:, None]
        gn = np.stack([-gu[:, 1], gu[:, 0]], axis=1)
        # Pairwise (GT i, detection j).
        cos = np.abs(gu @ du.T)
        off_a = np.abs(np.einsum("ik,ijk->ij", gn, da[None, :, :] - ga[:, None, :]))
        off_b = np.abs(np.einsum("ik,ijk->ij", gn, db[None, :, :] - ga[:, None, :]))
        # Detection end points along each GT line, and GT end points along each detection.
        ta = np.einsum("ik,ijk->ij", gu, da[None, :, :] - ga[:, None, :])
        tb = np.einsum("ik,ijk->ij", gu, db[None, :, :] - ga[:, None, :])
        lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
        ov_lo, ov_hi = np.maximum(lo, 0.0), np.minimum(hi, gl[:, None])
        match = (cos >= cos_tol) & (off_a <= dist_px) & (off_b <= dist_px) & (ov_hi > ov_lo)
        sa = np.einsum("jk,ijk->ij", du, ga[:, None, :] - da[None, :, :])
        sb = np.einsum("jk,ijk->ij", du, gb[:, None, :] - da[None, :, :])
        slo = np.maximum(np.minimum(sa, sb), 0.0)
        shi = np.minimum(np.maximum(sa, sb), dl[None, :])
        for i in range(len(gt)):
            js = np.nonzero(match[i])[0]
            gt_len += gl[i]
            gt_n += 1
            gt_cov += union_length([(ov_lo[i, j], ov_hi[i, j]) for j in js])
            if len(js) and np.max(ov_hi[i, js] - ov_lo[i, js]) >= 0.5 * gl[i]:
                gt_half += 1
        for j in range(len(d)):
            is_ = np.nonzero(match[:, j])[0]
            det_len += dl[j]
            det_cov += union_length([(slo[i, j], shi[i, j]) for i in is_])
    return gt_cov / max(gt_len, 1e-9), gt_half / max(gt_n, 1), det_cov / max(det_len, 1e-9)


def union_length(intervals):
    total, end = 0.0, -float("inf")
    for a, b in sorted(intervals):
        if b <= a:
            continue
        if a > end:
            total += b - a
            end = b
        elif b > end:
            total += b - end
            end = b
    return total


def main():
    ensure_venv()
    import cv2

    db, opts = parse_args(sys.argv[1:])
    items, cam, dataset, offset = load_db(db, opts["offset"])
    work = os.path.abspath(opts["work"])
    img_dir = os.path.join(work, "images")
    os.makedirs(img_dir, exist_ok=True)
    pngs = []
    for name, jpg, _ in items:
        png = os.path.join(img_dir, name + ".png")
        if not os.path.exists(png):
            img = cv2.imread(jpg, cv2.IMREAD_COLOR)
            if img is None:
                sys.exit(f"bench_lines_real: {jpg}: cannot read")
            cv2.imwrite(png, img)
        pngs.append((name, png))
    size = cv2.imread(pngs[0][1], cv2.IMREAD_GRAYSCALE).shape
    gts = {name: gt for name, _, gt in items}
    names = [n for n, _ in pngs]

    if opts["omnitrack-dir"]:
        om_dir, om_line = os.path.abspath(opts["omnitrack-dir"]), "(omnitrack edges read from the given directory)"
    else:
        om_dir = os.path.join(work, "omnitrack")
        om_line = run_omnitrack(img_dir, om_dir, cam, opts["passes"], opts["omnitrack-args"])
    om_segs, om_pieces, om_times = read_omnitrack(om_dir, names)
    # Two rows for one detection: the edges as the tracker takes them (each over the whole span
    # its plane was fitted to, bridging the gaps between collinear pieces), and the pieces of
    # them that the image shows (the CSV's `pieces` column).
    results = {
        "omnitrack EdgeDetector, edges (whole span)": (om_segs, om_times),
        "omnitrack EdgeDetector, pieces shown": (om_pieces, om_times),
    }
    results.update(run_opencv(pngs, opts["passes"]))

    min_gt, min_det = opts["min-gt-px"], opts["min-det-px"]
    n_gt = sum(int((((g[:, 2] - g[:, 0]) ** 2 + (g[:, 3] - g[:, 1]) ** 2) >= min_gt**2).sum()) for g in gts.values())
    fld_p50 = pct(results["OpenCV FastLineDetector"][1], 0.5)
    out = []

    def emit(line=""):
        print(line)
        sys.stdout.flush()
        out.append(line)

    emit(f"# Lines on real photos: {dataset}, {len(items)} images {size[1]}x{size[0]}, {n_gt} hand-marked segments >= "
         f"{min_gt:g} px; detections >= {min_det:g} px; {opts['passes']} timed passes")
    emit(f"# camera fx={cam[0]:.2f} fy={cam[1]:.2f} cx={cam[2]:.2f} cy={cam[3]:.2f} (OpenCV pixels, GT offset {offset:+g})")
    for line in om_line.splitlines()[:2]:
        emit(f"# {line}")
    emit()
    emit("| detector (tolerance 2 px, 3 deg) | recall (length) | GT half-covered by one | precision (length) "
          "| detections/image | p50 ms | p99 ms | p50 / FLD p50 |")
    emit("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    summary = {}
    for label, (segs, times) in results.items():
        r, half, p = score(segs, gts, min_gt, min_det, 2.0, 3.0)
        per_img = sum(
            int((((s[:, 2] - s[:, 0]) ** 2 + (s[:, 3] - s[:, 1]) ** 2) >= min_det**2).sum()) for s in segs.values()
        ) / len(segs)
        p50 = pct(times, 0.5)
        emit(f"| {label} | {100 * r:.1f} % | {100 * half:.1f} % | {100 * p:.1f} % | {per_img:.0f} | {p50:.2f} "
             f"| {pct(times, 0.99):.2f} | {p50 / fld_p50:.2f} |")
        summary[label] = {"recall": r, "half": half, "precision": p, "p50_ms": p50}
    emit()
    emit("| detector | " + " | ".join(f"{t} ({d:g} px, {a:g} deg) recall / precision" for t, d, a in TOLERANCES[1:])
          + " |")
    emit("| --- |" + " ---: |" * (len(TOLERANCES) - 1))
    for label, (segs, _) in results.items():
        cells = []
        for _, d, a in TOLERANCES[1:]:
            r, _, p = score(segs, gts, min_gt, min_det, d, a)
            cells.append(f"{100 * r:.1f} / {100 * p:.1f} %")
        emit(f"| {label} | " + " | ".join(cells) + " |")
    emit()
    emit(json.dumps({k: {kk: round(vv, 4) for kk, vv in v.items()} for k, v in summary.items()}))
    if not opts["no-results"]:
        sys.path.insert(0, HERE)
        import bench_pnl

        slug = re.sub(r"[^a-z0-9]+", "-", dataset.lower()).strip("-")
        extra = f' --omnitrack-args "{opts["omnitrack-args"]}"' if opts["omnitrack-args"] else ""
        path = bench_pnl.write_results(
            f"lines-{slug}", f"Lines on real photos: {dataset}, omnitrack against OpenCV's detectors",
            f"python3 tools/bench_lines_real.py DB --passes {opts['passes']}{extra}", "\n".join(out))
        print(f"bench_lines_real: wrote {path.relative_to(bench_pnl.REPO)}", file=sys.stderr)


if __name__ == "__main__":
    main()
