#!/usr/bin/env bash
# Sets up the paper's own implementation (github.com/prgumd/AMC, BSD-3-Clause)
# as a peer for `amc compare --peer paper`.
#
#   tools/paper-peer/setup.sh SRC [DIR]
#
# SRC: your clone of https://github.com/prgumd/AMC (its code is never copied
#      into this repository; DIR only links to it).
# DIR: where the environment goes (default: $AMC_PAPER_PEER, else
#      ~/.cache/amc/paper-peer). It receives:
#        venv/          a Python virtual environment with the packages the
#                       paper's rotation_stabilize.py imports, pinned below;
#        source         a symbolic link to SRC;
#        versions.txt   `key=value` lines: the source's commit and the
#                       versions of python, jax, jaxlib, numpy, opencv, scipy
#                       (amc compare copies them into its report).
#
# vme_research is not installed (it has no __init__.py files, so pip's
# find_packages finds nothing): the loader (run_paper.py) puts it on sys.path.
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 || "$1" == -h || "$1" == --help ]]; then
    sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
src=$(cd "$1" && pwd)
dir=${2:-${AMC_PAPER_PEER:-$HOME/.cache/amc/paper-peer}}
python=${PYTHON:-python3}

if [[ ! -f "$src/rotation_stabilize.py" || ! -d "$src/vme_research/vme_research" ]]; then
    echo "setup.sh: $src is not a clone of github.com/prgumd/AMC (no rotation_stabilize.py or vme_research/vme_research)" >&2
    exit 1
fi
commit=$(git -C "$src" rev-parse HEAD 2>/dev/null || echo unknown)
if [[ -n "$(git -C "$src" status --porcelain 2>/dev/null)" ]]; then
    commit="$commit-modified"
fi

mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
"$python" -m venv "$dir/venv"
pip=("$dir/venv/bin/python" -m pip --disable-pip-version-check -q)
"${pip[@]}" install --upgrade pip
# The versions the peer was first run with. jax on CPU; numpy 1.x (vme_research
# asks for it); headless OpenCV (the loader stubs the window calls).
# rotation_stabilize.py and vme_research also import scikit-learn, matplotlib,
# tqdm, pandas, numba and pupil_apriltags at module level (used only by modes
# the comparison does not run, but the imports must succeed). pyqtgraph is
# imported only by the point-cloud viewer of --est_ttc; the loader stubs it.
"${pip[@]}" install \
    "jax[cpu]==0.7.1" "jaxlib==0.7.1" "numpy==1.26.4" \
    "opencv-python-headless==4.11.0.86" "scipy==1.15.3" \
    "scikit-learn==1.6.1" "matplotlib==3.10.3" "tqdm==4.67.1" \
    "pandas==2.2.3" "numba==0.61.2" "pupil-apriltags==1.0.4.post11"

ln -sfn "$src" "$dir/source"
"$dir/venv/bin/python" - "$commit" "$src" > "$dir/versions.txt.tmp" <<'PY'
import platform, sys
from importlib.metadata import version
commit, src = sys.argv[1], sys.argv[2]
print(f"paper_commit={commit}")
print(f"paper_source={src}")
print(f"python={platform.python_version()}")
for key, dist in [("jax", "jax"), ("jaxlib", "jaxlib"), ("numpy", "numpy"),
                  ("opencv", "opencv-python-headless"), ("scipy", "scipy")]:
    print(f"{key}={version(dist)}")
PY
mv "$dir/versions.txt.tmp" "$dir/versions.txt"
# Checks that the paper's script imports in this environment.
"$dir/venv/bin/python" "$(dirname "$0")/run_paper.py" --source "$src" --check
echo "paper peer ready in $dir:"
cat "$dir/versions.txt"
