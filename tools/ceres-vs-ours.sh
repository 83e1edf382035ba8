#!/usr/bin/env bash
# Ceres 2.1 and our solver on the same BAL problems, in one sitting, alternating, several rounds, and a
# table of medians and ratios (docs/optimisation.md, "Speed against Ceres"). Not part of CI.
#
#   tools/ceres-vs-ours.sh [ROUNDS] [sparse|dense]
#
# ROUNDS (default 5): each round runs, for every problem, Ceres once then ours once (`slam-app
# optim-bench --only NAME --reps 1`), so both see the same machine load. Both use one thread, LM,
# Schur elimination of the points, Ceres' default tolerances; Ceres' linear solver is SPARSE_SCHUR as in
# fixtures/optim/ANCHORS.md, or DENSE_SCHUR with `dense`. Times are of the solve only (parsing and
# building the problem excluded) on both sides: wall time, and process CPU time, which is steadier on a
# shared machine. Final costs must agree within 0.1 % (the anchors' tolerance).
#
# Needs: apt-get install -y libceres-dev (Ceres 2.1.0 on Debian 12) and g++; builds
# tools/ceres-bench/build/ceres_bal and target/release/slam-app when missing.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds="${1:-5}"
linear="${2:-sparse}"
data="${DATA:-fixtures/optim}"
ceres=tools/ceres-bench/build/ceres_bal
ours="${OURS:-target/release/slam-app}"   # OURS=path/to/slam-app compares another build
[ -x "$ceres" ] || bash tools/ceres-bench/build.sh
[ -x "$ours" ] || cargo build --release -p slam-app
case "$rounds" in ''|*[!0-9]*) echo "ROUNDS must be a number" >&2; exit 2;; esac
case "$linear" in sparse|dense) ;; *) echo "linear solver must be sparse or dense" >&2; exit 2;; esac

# name | file | huber (0/1)
problems=(
  "problem-49 L2|problem-49-7776-pre.txt|0"
  "problem-49 Huber|problem-49-7776-pre.txt|1"
  "problem-16 L2|problem-16-22106-pre.txt|0"
  "problem-16 Huber|problem-16-22106-pre.txt|1"
)
log="$(mktemp)"
trap 'rm -f "$log" "$log.ceres-stderr"' EXIT
echo "ceres-vs-ours: $rounds rounds, Ceres $linear Schur, $(date -u '+%Y-%m-%d %H:%M UTC'), load $(cut -d' ' -f1-3 /proc/loadavg)"
for ((r = 1; r <= rounds; r++)); do
  for p in "${problems[@]}"; do
    IFS='|' read -r name file huber <<<"$p"
    line="$("$ceres" "$data/$file" "$huber" 1 "$linear" 2>>"$log.ceres-stderr" | grep '^RESULT')"
    secs="$(sed -E 's/.* seconds=([^ ]+).*/\1/' <<<"$line")"
    cpu="$(sed -E 's/.* cpu=([^ ]+).*/\1/' <<<"$line")"
    final="$(sed -E 's/.* final=([^ ]+).*/\1/' <<<"$line")"
    echo "ceres|$name|$secs|$cpu|$final" >>"$log"
    row="$("$ours" optim-bench --data "$data" --only "$name" --reps 1 | grep -E "^$name +[0-9]")"
    # columns: name(2 words) initial final best vs iters time ... ; CPU seconds is the last column
    read -r _ _ _ ofinal _ _ _ osecs _ <<<"$row"
    ocpu="$(awk '{print $NF}' <<<"$row")"
    echo "ours|$name|$osecs|$ocpu|$ofinal" >>"$log"
  done
  echo "round $r of $rounds done" >&2
done
printf '%-18s %9s %9s %6s %9s %9s %6s %14s %14s %9s\n' problem "Ceres s" "ours s" ratio "Ceres cpu" "ours cpu" ratio "Ceres cost" "our cost" "agree"
for p in "${problems[@]}"; do
  IFS='|' read -r name _ _ <<<"$p"
  awk -F'|' -v name="$name" '
    function median(a, n,   i, j, t) {
      for (i = 2; i <= n; i++) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]; a[j + 1] = t }
      return (n % 2) ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
    }
    $2 == name && $1 == "ceres" { cs[++nc] = $3; cc[nc] = $4; cf = $5 }
    $2 == name && $1 == "ours"  { os[++no] = $3; oc[no] = $4; of = $5 }
    END {
      mcs = median(cs, nc); mos = median(os, no); mcc = median(cc, nc); moc = median(oc, no)
      rel = (of - cf) / cf; ok = (rel <= 1e-3 && rel >= -1e-3) ? "yes" : "NO"
      printf "%-18s %9.3f %9.3f %6.2f %9.3f %9.3f %6.2f %14.6e %14.6e %5s %+.4f%%\n",
        name, mcs, mos, mos / mcs, mcc, moc, (mcc > 0 ? moc / mcc : 0), cf, of, ok, 100 * rel
    }' "$log"
done
echo "ratio = our median / Ceres' median (below 1: ours is faster); medians over $rounds alternating rounds."
