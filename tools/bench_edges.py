#!/usr/bin/env python3
"""OpenCV line detectors on the same rig frames as omnitrack's edge benchmark.

    python3 tools/bench_edges.py DIR [--repeats N] [--threads N]

DIR holds PNG frames written by `cargo bench --bench edges` (DIR/frameNNN_sK.png; one frame =
the sensor images with the same NNN: six for the shipped rig). The script creates (or reuses)
the venv tools/.venv-bench-edges, installs numpy and opencv-contrib-python-headless into it, re-runs
itself inside it, and times, for each frame, the whole frame through
  - cv2.createLineSegmentDetector (LSD, default parameters), and
  - cv2.ximgproc.createFastLineDetector (FLD, default parameters),
both on the grey image (cv2.cvtColor RGB->GRAY included in the time; PNG decoding excluded).
OpenCV runs with cv2.setNumThreads(N) (--threads, default 2). Wall time is time.perf_counter_ns;
CPU time is time.process_time_ns, every thread of this process (OpenCV's workers included; the
script itself runs nothing else meanwhile). It prints one JSON line per detector:
  {"detector": "lsd", "frames": n, "p50_ms": .., "p99_ms": .., "max_ms": .., "cpu_p50_ms": ..,
   "cpu_p99_ms": .., "lines_per_frame": .., "threads": N}
"""
import glob
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(HERE, ".venv-bench-edges")
PY = os.path.join(VENV, "bin", "python")


def ensure_venv():
    if os.path.abspath(sys.prefix) == os.path.abspath(VENV):
        return
    if not os.path.exists(PY):
        print(f"bench_edges: creating {VENV}", file=sys.stderr)
        subprocess.check_call([sys.executable, "-m", "venv", VENV])
    try:
        subprocess.check_call([PY, "-c", "import cv2, numpy; cv2.ximgproc"], stderr=subprocess.DEVNULL)
    except subprocess.CalledProcessError:
        print("bench_edges: installing numpy, opencv-contrib-python-headless", file=sys.stderr)
        subprocess.check_call([PY, "-m", "pip", "install", "-q", "numpy", "opencv-contrib-python-headless"])
    os.execv(PY, [PY] + sys.argv)


def pct(sorted_ms, q):
    return sorted_ms[int(round((len(sorted_ms) - 1) * q))]


def main():
    ensure_venv()
    import cv2  # noqa: E402

    args = sys.argv[1:]
    repeats = 3
    threads = 2
    if "--repeats" in args:
        i = args.index("--repeats")
        repeats = int(args[i + 1])
        del args[i : i + 2]
    if "--threads" in args:
        i = args.index("--threads")
        threads = int(args[i + 1])
        del args[i : i + 2]
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    paths = sorted(glob.glob(os.path.join(args[0], "frame*_s*.png")))
    frames = {}
    for p in paths:
        key = os.path.basename(p).split("_s")[0]
        img = cv2.imread(p, cv2.IMREAD_COLOR)
        if img is None:
            print(f"bench_edges: {p}: cannot read", file=sys.stderr)
            sys.exit(1)
        frames.setdefault(key, []).append(img)
    if not frames:
        print(f"bench_edges: {args[0]}: no frame*_s*.png", file=sys.stderr)
        sys.exit(1)
    cv2.setNumThreads(threads)
    lsd = cv2.createLineSegmentDetector()
    fld = cv2.ximgproc.createFastLineDetector()
    for name, det in (("lsd", lambda g: lsd.detect(g)[0]), ("fld", lambda g: fld.detect(g))):
        times, cpu, counts = [], [], []
        for _ in range(repeats):
            for key in sorted(frames):
                t0 = time.perf_counter_ns()
                c0 = time.process_time_ns()
                n = 0
                for img in frames[key]:
                    g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                    lines = det(g)
                    n += 0 if lines is None else len(lines)
                cpu.append((time.process_time_ns() - c0) * 1e-6)
                times.append((time.perf_counter_ns() - t0) * 1e-6)
                counts.append(n)
        times.sort()
        cpu.sort()
        print(json.dumps({
            "detector": name,
            "frames": len(times),
            "p50_ms": round(pct(times, 0.5), 3),
            "p99_ms": round(pct(times, 0.99), 3),
            "max_ms": round(times[-1], 3),
            "cpu_p50_ms": round(pct(cpu, 0.5), 3),
            "cpu_p99_ms": round(pct(cpu, 0.99), 3),
            "threads": threads,
            "lines_per_frame": round(sum(counts) / len(counts), 1),
        }))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
