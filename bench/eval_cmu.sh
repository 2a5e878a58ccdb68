#!/usr/bin/env bash
# The accuracy runs behind the manual's tables (docs/reconstruction.md; EVALUATION.md):
# leave-one-take-out over ../shared/data/cmu, with 10% dropout, with new users, on the
# held-out split, and the paper's K and N sweeps. Single-threaded (samba eval limits
# BLAS to one thread); pinned to one core where taskset exists.
#
#   bench/eval_cmu.sh OUT_DIR        (defaults: data ../shared/data/cmu or $SAMBA_DATA/cmu)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-eval-results}"
data="${SAMBA_DATA:-$here/../../shared/data}/cmu"
[ -d "$data" ] || { echo "no CMU data at $data (set SAMBA_DATA)" >&2; exit 1; }
mkdir -p "$out"
pin=(); command -v taskset >/dev/null && pin=(taskset -c 0)
samba_eval() { "${pin[@]}" python -m samba.cli eval "$@"; }

# Held-out split: every sixth take from the second (never used to tune `best`).
mapfile -t all < <(ls "$data"/*.bvh | sort)
held=(); train=()
for i in "${!all[@]}"; do
  if (( i % 6 == 1 )); then held+=("${all[$i]}"); else train+=("${all[$i]}"); fi
done

samba_eval --train "$data" --test "$data" --json "$out/loto.json" --plots "$out/loto" | tee "$out/loto.txt"
samba_eval --train "$data" --test "$data" --dropout 0.1 --json "$out/dropout.json" | tee "$out/dropout.txt"
samba_eval --train "$data" --test "$data" --new-user --json "$out/new_user.json" | tee "$out/new_user.txt"
samba_eval --train "${train[@]}" --test "${held[@]}" --json "$out/heldout.json" --plots "$out/heldout" | tee "$out/heldout.txt"
samba_eval --train "${train[@]}" --test "${held[@]}" --methods samba \
  --sweep-k 1,2,5,10,20,30,50 --sweep-n 1,2,5,10,20 --json "$out/sweeps.json" --plots "$out/sweeps" \
  | tee "$out/sweeps.txt"
