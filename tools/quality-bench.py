#!/usr/bin/env python3
"""The tracking benchmark that cannot be tuned into (docs/accuracy.md#benchmark).

Renders synthetic clips (`amc synth`) across classes of shake speed, readout,
lens, size, blur, noise and JPEG quality, on two disjoint sets of seeds:
tuning seeds (settings are chosen on these) and validation seeds (the docs
quote these only). Each clip is tracked at the defaults with the readout
given, and, for rolling-shutter clips, with `--readout-ms auto`; each
rolling-shutter class has a global-shutter twin (same seeds and shake) for
the RS/GS ratio. Reports per class and seed set: the median and worst of the
per-frame error (median over the clip), the final orientation error, the
RS/GS ratio of the per-frame medians, and the auto readout's estimate.

    python3 tools/quality-bench.py                 # all classes, both seed sets
    python3 tools/quality-bench.py --quick         # one seed per set, small clips only
    python3 tools/quality-bench.py --out DIR --json results.json

Needs a built `amc` (cargo build --release), ffmpeg, and ../shared/data's
panorama. Standard library only.
"""

import argparse
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TUNING_SEEDS = [1, 2]
VALIDATION_SEEDS = [101, 102]

# name: (width, height, lens and rate flags, shake deg/s, readout ms, seconds, degrade)
# degrade: None, or (gaussian blur sigma px, noise strength 0..100, JPEG q 2..31).
# 60 fps and a 12-20 Hz shake (a flapping-wing drone) unless stated; a 33 ms
# readout is a 30 fps sensor's (a phone: no 60 fps sensor reads out longer
# than its frame period; the 20 ms class at 60 fps is the gyro issue's
# held-out kind), shaken at 2-8 Hz as a hand does (12-20 Hz is above 30 fps'
# Nyquist rate: no estimate between frames can follow it).
CLASSES = {
    "320-90-50": (320, 180, ["--fov", "90"], 50, 0, 3, None),
    "320-90-100": (320, 180, ["--fov", "90"], 100, 0, 3, None),
    "320-90-100-rs15": (320, 180, ["--fov", "90"], 100, 15, 3, None),
    "320-90-400": (320, 180, ["--fov", "90"], 400, 0, 3, None),
    "640-60-100": (640, 360, ["--fov", "60"], 100, 0, 3, None),
    "640-90-100": (640, 360, ["--fov", "90"], 100, 0, 3, None),
    "640-90-100-rs16": (640, 360, ["--fov", "90"], 100, 16, 3, None),
    "640-120-100": (640, 360, ["--fov", "120"], 100, 0, 3, None),
    "640-90-300": (640, 360, ["--fov", "90"], 300, 0, 3, None),
    "640-90-300-rs20": (640, 360, ["--fov", "90"], 300, 20, 3, None),
    "640-90-300-rs33-30fps-hand": (640, 360, ["--fov", "90", "--fps", "30", "--shake-band", "2,8"], 300, 33, 3, None),
    "640-fisheye120-150": (640, 360, ["--fov", "120", "--fisheye", "0.05,0.01,0,0"], 150, 0, 3, None),
    "640-90-250-degraded": (640, 360, ["--fov", "90"], 250, 0, 3, (1.0, 6, 8)),
    "640-90-250-rs12-degraded": (640, 360, ["--fov", "90"], 250, 12, 3, (1.0, 6, 8)),
    "1280-70-100": (1280, 720, ["--fov", "70"], 100, 0, 2, None),
    "1280-70-100-rs33-30fps-hand": (1280, 720, ["--fov", "70", "--fps", "30", "--shake-band", "2,8"], 100, 33, 2, None),
}
QUICK = [k for k, v in CLASSES.items() if v[0] <= 640 and "degraded" not in k][:6]


def rot(v):
    x, y, z = v
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-15:
        return [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    kx, ky, kz = x / th, y / th, z / th
    c, s = math.cos(th), math.sin(th)
    C = 1 - c
    return [
        [c + kx * kx * C, kx * ky * C - kz * s, kx * kz * C + ky * s],
        [ky * kx * C + kz * s, c + ky * ky * C, ky * kz * C - kx * s],
        [kz * kx * C - ky * s, kz * ky * C + kx * s, c + kz * kz * C],
    ]


def mt(a):
    return [[a[j][i] for j in range(3)] for i in range(3)]


def mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def angle_deg(r):
    c = max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2))
    return math.degrees(math.acos(c))


def orientations(path):
    with open(path) as f:
        return [rot([float(r["rx"]), float(r["ry"]), float(r["rz"])]) for r in csv.DictReader(f)]


def errors(gt_csv, telemetry_csv):
    """Per-frame errors (deg) of the frame-to-frame rotations, and the final orientation error."""
    g, e = orientations(gt_csv), orientations(telemetry_csv)
    n = min(len(g), len(e))
    frame = [
        angle_deg(mm(mt(mm(mt(g[j - 1]), g[j])), mm(mt(e[j - 1]), e[j]))) for j in range(1, n)
    ]
    return frame, angle_deg(mm(mt(g[n - 1]), e[n - 1]))


def median(v):
    s = sorted(v)
    if not s:
        return float("nan")
    k = len(s) // 2
    return s[k] if len(s) % 2 else 0.5 * (s[k - 1] + s[k])


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr}")
    return r


def make_clip(amc, pano, work, name, seed, readout_ms):
    w, h, lens, dps, _, seconds, degrade = CLASSES[name]
    clip = os.path.join(work, f"{name}-{seed}-rs{readout_ms}")
    if os.path.isdir(clip):
        return clip
    run([amc, "synth", pano, "-o", clip, "--width", str(w), "--height", str(h), *lens,
         "--shake-dps", str(dps), "--rolling-shutter-ms", str(readout_ms),
         "--seconds", str(seconds), "--seed", str(seed)])
    if degrade:
        sigma, noise, q = degrade
        out = clip + "-jpg"
        os.makedirs(out)
        for f in ("gt.csv", "lens.json", "meta.json"):
            shutil.copy(os.path.join(clip, f), out)
        run(["ffmpeg", "-loglevel", "error", "-y", "-i", os.path.join(clip, "frame-%06d.png"),
             "-vf", f"gblur=sigma={sigma},noise=alls={noise}:allf=t", "-q:v", str(q),
             os.path.join(out, "frame-%06d.jpg")])
        shutil.rmtree(clip)
        os.rename(out, clip)
    return clip


def track(amc, clip, readout):
    """Tracks `clip` at the defaults (rendering kept cheap: it does not change the tracking)."""
    tel = os.path.join(clip, f"telemetry-{readout}.csv")
    metrics = os.path.join(clip, f"metrics-{readout}.json")
    run([amc, "stabilize", clip, "-o", os.path.join(clip, "out.y4m"), "-q", "--gyro", "off",
         "--n-avg", "1", "--zoom", "none", "--readout-ms", str(readout),
         "--telemetry", tel, "--metrics", metrics])
    os.remove(os.path.join(clip, "out.y4m"))
    frame, final = errors(os.path.join(clip, "gt.csv"), tel)
    with open(metrics) as f:
        used = json.load(f)["readout_ms"]
    return {"median": median(frame), "worst": max(frame), "final": final, "readout_ms": used}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one seed per set, six small classes")
    ap.add_argument("--classes", help="comma-separated class names (default: all)")
    ap.add_argument("--out", help="keep the clips here (default: a temporary folder)")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--amc", default=os.path.join(ROOT, "target", "release", "amc"))
    ap.add_argument("--pano", default=os.path.join(ROOT, "..", "shared", "data", "pano",
                                                  "pannellum_examplepano.jpg"))
    a = ap.parse_args()
    if not os.path.exists(a.amc):
        sys.exit(f"{a.amc} not found: cargo build --release -p amc-cli")
    names = a.classes.split(",") if a.classes else (QUICK if a.quick else list(CLASSES))
    for n in names:
        if n not in CLASSES:
            sys.exit(f"unknown class {n} (known: {', '.join(CLASSES)})")
    sets = {"tuning": TUNING_SEEDS[:1] if a.quick else TUNING_SEEDS,
            "validation": VALIDATION_SEEDS[:1] if a.quick else VALIDATION_SEEDS}
    work = a.out or tempfile.mkdtemp(prefix="amc-quality-bench-")
    os.makedirs(work, exist_ok=True)
    results = []
    for name in names:
        readout = CLASSES[name][4]
        for set_name, seeds in sets.items():
            rows = []
            for seed in seeds:
                clip = make_clip(a.amc, a.pano, work, name, seed, readout)
                row = {"seed": seed, **track(a.amc, clip, readout)}
                if readout > 0:
                    twin = make_clip(a.amc, a.pano, work, name, seed, 0)
                    row["gs_median"] = track(a.amc, twin, 0)["median"]
                    row["ratio"] = row["median"] / row["gs_median"]
                    row["auto_readout_ms"] = track(a.amc, clip, "auto")["readout_ms"]
                rows.append(row)
                print(f"{name} {set_name} seed {seed}: {row}", file=sys.stderr)
            results.append({"class": name, "set": set_name, "seeds": rows})
    print("| class | seeds | per-frame median (median / worst seed) | worst frame | final | RS/GS (worst) | auto readout (true) |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        s = r["seeds"]
        meds = [x["median"] for x in s]
        line = (f"| {r['class']} | {r['set']} | {median(meds):.4f} / {max(meds):.4f} deg | "
                f"{max(x['worst'] for x in s):.3f} deg | {max(x['final'] for x in s):.3f} deg | ")
        if "ratio" in s[0]:
            line += f"{max(x['ratio'] for x in s):.2f} | "
            line += ", ".join(f"{x['auto_readout_ms']:.1f}" for x in s)
            line += f" ({CLASSES[r['class']][4]} ms) |"
        else:
            line += " | |"
        print(line)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    if not a.out:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
