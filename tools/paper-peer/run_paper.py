#!/usr/bin/env python3
"""Runs the paper's own stabilizer (github.com/prgumd/AMC, rotation_stabilize.py)
on one clip and writes its output as raw .y4m, for `amc compare --peer paper`.

    run_paper.py --source SRC --input CLIP --output OUT.y4m --mode stabilize \
        [--valid OUT.valid] [--fps F] [--lens lens.json | --fov DEG] [--frames N] \
        [--rotations ORIENTATIONS.csv]
    run_paper.py --source SRC --check

The authors' script reads a recording (a folder of BGR frames as .npy, their
timestamps and the intrinsics, written by their vme_research Record class)
and, with --rotstab_video --export_cropped, writes the crop of every
stabilized frame as a JPEG. This loader:

* decodes CLIP (a video, through ffmpeg, or an image folder in natural order)
  and writes it in that layout with their own Record class, to a temporary
  folder it deletes afterwards;
* calls their stabilize() in-process with the options of the issue's three
  modes (what `rotation_stabilize.py --downsample 2 --stride 1 --margins 0.125
  --rotstab_video --export_cropped` does, plus `--N_frames 1` for none,
  `--N_frames 6 --rotstab2` for stabilize, and `--saccade` too for saccade);
* catches the exported frames at cv2.imwrite, before the lossy JPEG encoding,
  undoes the 2x pixel duplication of --export_cropped (every second pixel)
  and writes them to OUT.y4m (4:4:4, BT.601 limited range);
* with --valid, writes the output's validity, one byte per output pixel per
  frame (1 valid, 0 not), frames in order (see valid_mask());
* with --rotations, hands its renderer those orientations instead of its
  tracker's (its view filter, warp and average are unchanged): a CSV with a
  header naming columns rx, ry, rz, one row per frame, the rotation vector of
  R_{0,j} (camera j's vectors into camera 0's frame; x right, y down, z
  forward), as amc's telemetry and gt.csv write them. amc compare uses it to
  tell what the paper's tracker does to its numbers from what its renderer
  does (the paper's code fed our estimates, and the truth).

Headless stubs: their script opens windows and polls keys (cv2.imshow,
waitKey, namedWindow, createTrackbar: no-ops; waitKey returns -1, no key),
imports pyqtgraph for the --est_ttc point cloud (an empty module), and
encodes the exported JPEGs with ffmpeg at the end (skipped: nothing was
written). Nothing is written into SRC (no bytecode, numba's cache elsewhere).
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import types

sys.dont_write_bytecode = True  # keep the user's clone untouched

# The settings (the paper's defaults for its videos).
DOWNSAMPLE = 2.0
MARGINS = 0.125
STRIDE = 1
N_FRAMES = {"none": 1, "stabilize": 6, "saccade": 6}
CAM = "cam_front"


def natural_key(name):
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", name)]


IMAGE_EXT = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm")


def probe(path):
    """Width, height and frame rate of a video's first video stream."""
    out = subprocess.run(
        ["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries",
         "stream=width,height,avg_frame_rate,r_frame_rate", "-of", "json", path],
        check=True, capture_output=True, text=True).stdout
    s = json.loads(out)["streams"][0]

    def rate(text):
        num, _, den = text.partition("/")
        return float(num) / float(den or 1) if float(den or 1) else 0.0

    fps = rate(s.get("avg_frame_rate", "0/0")) or rate(s.get("r_frame_rate", "0/0"))
    return int(s["width"]), int(s["height"]), fps


def frames_of(path, limit):
    """Yields BGR uint8 frames of a video or an image folder."""
    import cv2
    import numpy as np

    if os.path.isdir(path):
        names = sorted((n for n in os.listdir(path) if n.lower().endswith(IMAGE_EXT)),
                       key=natural_key)
        for n in names[:limit]:
            img = cv2.imread(os.path.join(path, n), cv2.IMREAD_COLOR)
            if img is None:
                raise SystemExit(f"run_paper.py: cannot read image {n} in {path}")
            yield img
        return
    w, h, _ = probe(path)
    cmd = ["ffmpeg", "-nostdin", "-v", "error", "-i", path, "-map", "0:v:0",
           "-fps_mode", "passthrough", "-f", "rawvideo", "-pix_fmt", "bgr24", "-"]
    if limit is not None:
        cmd[-1:-1] = ["-frames:v", str(limit)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE)
    size = w * h * 3
    try:
        while True:
            buf = proc.stdout.read(size)
            if len(buf) < size:
                break
            yield np.frombuffer(buf, np.uint8).reshape(h, w, 3)
    finally:
        proc.stdout.close()
        if proc.wait() != 0:
            raise SystemExit(f"run_paper.py: ffmpeg could not decode {path}")


def intrinsics(args, width, height):
    """K, distortion and the model name stabilize() takes ("planar" or "fisheye")."""
    import numpy as np

    if args.lens:
        with open(args.lens) as f:
            lens = json.load(f)
        sx, sy = width / lens["width"], height / lens["height"]
        K = np.array([[lens["fx"] * sx, lens.get("skew", 0.0) * sx, lens["cx"] * sx],
                      [0.0, lens["fy"] * sy, lens["cy"] * sy],
                      [0.0, 0.0, 1.0]])
        dist = list(lens.get("dist") or [])
        model = lens.get("model", "pinhole")
        if model == "fisheye":
            return K, np.array((dist + [0.0] * 4)[:4]), "fisheye"
        if model not in ("pinhole", "opencv"):  # amc's names: opencv = k1 k2 p1 p2 k3
            raise SystemExit(f"run_paper.py: lens model {model!r} is not one the paper's code takes")
        return K, np.array((dist + [0.0] * 5)[:5]), "planar"
    f = (width / 2) / np.tan(np.radians(args.fov) / 2)
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return K, np.zeros(5), "planar"


def write_recording(args, seq):
    """Writes CLIP in the authors' layout (their Record class); returns (W, H, frames)."""
    import numpy as np
    from vme_research.hardware.record import Record

    opts = {
        "name": "Camera", "version": "0.0.1",
        "fields": [{"name": "frame", "type": str(np.ndarray), "split": True}],
        "append_fields": [{"name": n, "type": str(np.ndarray), "split": False}
                          for n in ("K", "dist", "res")],
    }
    fps = args.fps
    if fps is None:
        fps = probe(args.input)[2] if not os.path.isdir(args.input) else 30.0
    if not fps > 0:
        raise SystemExit("run_paper.py: the clip's frame rate is unknown (pass --fps)")
    rec = Record(os.path.join(seq, CAM), fields_options=opts)
    n, size = 0, None
    for frame in frames_of(args.input, args.frames):
        if size is None:
            size = (frame.shape[1], frame.shape[0])
        t = n / fps
        rec.pub(t, (np.ascontiguousarray(frame),), t_received=t)
        n += 1
    if n < 2:
        raise SystemExit(f"run_paper.py: {args.input}: fewer than 2 frames")
    K, dist, model = intrinsics(args, *size)
    rec.close(append_values=[K, dist, np.array(size)])
    return size, n, fps, model


class Y4mWriter:
    """Raw YUV4MPEG2, 4:4:4, BT.601 limited range (what amc reads back exactly)."""

    def __init__(self, path, fps):
        self.f = open(path, "wb")
        self.fps = fps
        self.header = False

    def write(self, bgr):
        import numpy as np

        h, w = bgr.shape[:2]
        if not self.header:
            num = int(round(self.fps * 1000))
            self.f.write(f"YUV4MPEG2 W{w} H{h} F{num}:1000 Ip A1:1 C444\n".encode())
            self.header = True
        b, g, r = (bgr[:, :, i].astype(np.float32) for i in range(3))
        y = 16 + (65.481 * r + 128.553 * g + 24.966 * b) / 255
        u = 128 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255
        v = 128 + (112.0 * r - 93.786 * g - 18.214 * b) / 255
        self.f.write(b"FRAME\n")
        for p in (y, u, v):
            self.f.write(np.clip(np.rint(p), 0, 255).astype(np.uint8).tobytes())

    def close(self):
        self.f.close()


def stub_headless(cv2):
    """Window and key calls of the script: no-ops (headless OpenCV has none)."""
    for name in ("imshow", "namedWindow", "createTrackbar", "destroyAllWindows",
                 "destroyWindow", "moveWindow", "resizeWindow", "setTrackbarPos"):
        setattr(cv2, name, lambda *a, **k: None)
    cv2.waitKey = lambda *a, **k: -1
    # pyqtgraph: imported by vme_research's point-cloud viewer, used only by --est_ttc.
    pg = types.ModuleType("pyqtgraph")
    pg.opengl = types.ModuleType("pyqtgraph.opengl")
    pg.Qt = types.ModuleType("pyqtgraph.Qt")
    pg.Qt.QtCore = types.SimpleNamespace()
    sys.modules.update({"pyqtgraph": pg, "pyqtgraph.opengl": pg.opengl,
                        "pyqtgraph.Qt": pg.Qt})


def import_paper(source):
    os.environ.setdefault("MPLBACKEND", "Agg")
    os.environ.setdefault("NUMBA_CACHE_DIR",
                          os.path.join(tempfile.gettempdir(), "amc-paper-numba"))
    # vme_research has no __init__.py files (namespace packages): put it on the path.
    sys.path[:0] = [source, os.path.join(source, "vme_research")]
    import cv2
    stub_headless(cv2)
    import rotation_stabilize
    return cv2, rotation_stabilize


def valid_mask(cv2, np, valid, crop):
    """The output's validity, from the paper's own mask.

    The paper's renderer (warp_back_frames) warps each averaged frame with
    cv2.warpPerspective, border constant 0: a pixel a frame does not cover is
    averaged in as black. It also warps an all-ones image with nearest
    neighbour and ANDs those over the averaged frames: that is its `valid`
    (used by its own metrics and saccade test), the crop of which we take.
    The bilinear warp already mixes black into the pixels next to that
    mask's edge, so those (one pixel, 3x3 erosion) count as invalid too.
    In mode none nothing is warped: the whole crop is valid.
    """
    x0, y0, x1, y1 = crop
    if valid is None:
        return np.ones((y1 - y0, x1 - x0), np.uint8)
    m = valid[y0:y1, x0:x1].astype(np.uint8)
    return cv2.erode(m, np.ones((3, 3), np.uint8))


def read_rotations(path):
    """The rows' R_{0,j} (3x3) from a CSV with columns rx, ry, rz."""
    import cv2
    import numpy as np

    with open(path) as f:
        header = [c.strip() for c in f.readline().split(",")]
        try:
            cols = [header.index(c) for c in ("rx", "ry", "rz")]
        except ValueError:
            raise SystemExit(f"run_paper.py: {path}: no rx, ry, rz columns in the header {header}")
        out = []
        for n, line in enumerate(f, start=2):
            if not line.strip():
                continue
            cells = line.split(",")
            try:
                w = np.array([float(cells[c]) for c in cols])
            except (IndexError, ValueError):
                raise SystemExit(f"run_paper.py: {path} line {n}: not three numbers in rx, ry, rz")
            if not np.all(np.isfinite(w)):
                raise SystemExit(f"run_paper.py: {path} line {n}: a rotation is not finite")
            out.append(cv2.Rodrigues(w)[0])
    return out


def run(args):
    cv2, rs = import_paper(args.source)
    import numpy as np

    if args.check:
        print("rotation_stabilize imports:", rs.__file__)
        return
    rotations = read_rotations(args.rotations) if args.rotations else None
    work = tempfile.mkdtemp(prefix=".amc-paper-", dir=args.work)
    try:
        t0 = time.perf_counter()
        (w, h), n, fps, model = write_recording(args, work)
        if rotations is not None and len(rotations) != n:
            raise SystemExit(f"run_paper.py: {args.rotations}: {len(rotations)} rotations for {n} frames")
        t1 = time.perf_counter()
        ds_w, ds_h = int(w / DOWNSAMPLE), int(h / DOWNSAMPLE)
        crop = (int(ds_w * MARGINS), int(ds_h * MARGINS),
                ds_w - int(ds_w * MARGINS), ds_h - int(ds_h * MARGINS))
        out = Y4mWriter(args.output, fps)
        valid_out = open(args.valid, "wb") if args.valid else None
        stabilized_dir = os.path.join(work, CAM + "_stabilized")
        state = {"valid": None, "frames": 0, "updates": 0}

        # The mask the renderer returns with each stabilized frame.
        update = rs.RotStabOmega.update

        def update_keeping_valid(self, *a, **k):
            if rotations is not None:
                # Its R_cprime_c0_t0 takes output rays to source rays (its warp
                # samples the source at K R_cprime_c0_t0 R_view^T K^-1 x): the
                # transpose of our R_{0,j}. Given, its tracker is not asked.
                k["R_cprime_c0_t0"] = rotations[state["updates"]].T.astype(np.float64)
            state["updates"] += 1
            r = update(self, *a, **k)
            state["valid"] = r[2]
            return r

        rs.RotStabOmega.update = update_keeping_valid

        imwrite = cv2.imwrite

        def capture(path, img, *a):
            if os.path.dirname(path) != stabilized_dir:
                return imwrite(path, img, *a)
            # --export_cropped: the crop upsampled 2x by pixel duplication.
            frame = img[::2, ::2]
            expect = (crop[3] - crop[1], crop[2] - crop[0])
            if frame.shape[:2] != expect:
                raise SystemExit(f"run_paper.py: exported frame {frame.shape[:2]}, expected {expect}")
            out.write(frame)
            if valid_out:
                valid_out.write(valid_mask(cv2, np, state["valid"], crop).tobytes())
            state["frames"] += 1
            return True

        cv2.imwrite = capture
        # stabilize() reads the script's global command line at its end (to
        # encode the exported JPEGs): the flags this call stands for.
        rs.args = argparse.Namespace(
            rotstab_video=True, export_cropped=True, undistort_video=False,
            rotstab2=args.mode != "none", saccade=args.mode == "saccade",
            downsample=DOWNSAMPLE, stride=STRIDE, margins=MARGINS,
            N_frames=N_FRAMES[args.mode])
        # That encoding: nothing was written to encode.
        rs.subprocess = types.SimpleNamespace(run=lambda *a, **k: None)
        cv2.setNumThreads(1)  # as rotation_stabilize.py's __main__ does

        cam = rs.Load(os.path.join(work, CAM)).get_appended()
        rs.stabilize(
            work, CAM, model, np.array(cam["K"]), np.array(cam["dist"]),
            False, DOWNSAMPLE,  # rotate, downsample
            False, False,  # affine, rotstab
            args.mode != "none", False,  # rotstab2, rotstab_gyro
            args.mode == "saccade",
            True, True, False, False,  # rotstab_video, export_cropped, export_stab_only, undistort_video
            False,  # frame_filt
            False, False, False, False,  # est_ttc, est_nf, est_foe, april
            False, False,  # metrics, benchmark
            margins=MARGINS, tracker_stride=STRIDE, N_frames=N_FRAMES[args.mode])
        t2 = time.perf_counter()
        out.close()
        if valid_out:
            valid_out.close()
        if state["frames"] != n:
            raise SystemExit(f"run_paper.py: {state['frames']} frames out of {n}")
        # Read by amc compare: the paper's own loop, without decoding and the layout.
        print(f"paper-timing frames={n} layout_s={t1 - t0:.3f} stabilize_s={t2 - t1:.3f}",
              file=sys.stderr)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--source", required=True, help="clone of github.com/prgumd/AMC")
    p.add_argument("--check", action="store_true", help="only import the paper's script")
    p.add_argument("--input", help="video file or image folder")
    p.add_argument("--output", help="output .y4m")
    p.add_argument("--valid", help="output validity (one byte per pixel per frame)")
    p.add_argument("--mode", choices=sorted(N_FRAMES), default="stabilize")
    p.add_argument("--fps", type=float, help="frame rate (default: the video's; 30 for folders)")
    p.add_argument("--lens", help="amc lens.json (pinhole, opencv or fisheye)")
    p.add_argument("--fov", type=float, default=40.0,
                   help="horizontal field of view of a centred pinhole, degrees (without --lens)")
    p.add_argument("--frames", type=int, help="only the first N frames")
    p.add_argument("--rotations",
                   help="CSV (columns rx, ry, rz: R_{0,j} per frame) its renderer takes instead of its tracker's estimates")
    p.add_argument("--work", help="folder for the temporary recording (default: the system's)")
    args = p.parse_args()
    if not args.check and not (args.input and args.output):
        p.error("--input and --output are required (or --check)")
    run(args)


if __name__ == "__main__":
    main()
