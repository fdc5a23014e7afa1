#!/usr/bin/env bash
# A study of `auto`'s rules on the scene family: each member run with the default
# configuration (plateau stop on), run to its whole budget (stop off), where it has
# indirect light and no normal map, run to its budget at the variance step's other rate
# (0.01 where `auto` gave 0.03, 0.03 where it gave 0.01), and where it recovers a normal map,
# with the moment filter's other setting (5 levels where `auto` left it off, off where it
# filtered), one run at a time. Rules are chosen on the train split; the test split only
# judges them. Prints one CSV line per run: member, variant, iterations, start and final
# observed-texel RMSE (the handed-back state), the last state's, the last and first
# evaluations' image relMSE, and for a normal map the start and final mean angle error.
#
#   ci/family_study.sh OUT SPLIT COUNT [FIRST]
#
# The runs are timed by each member's budget: leave the machine otherwise idle.
set -euo pipefail
out=$1 split=$2 count=$3 first=${4:-0}
bin=${PSRESTIR:-target/release/psrestir}
"$bin" make-scenes "$out/scenes" --family "$split" --count $((first + count)) >/dev/null
run() { # member dir, variant name, extra flags...
  local dir=$1 name=$2; shift 2
  local o="$out/runs/$(basename "$dir")/$name"
  "$bin" optimize "$dir/task.toml" --out "$o" "$@" >"$o.log" 2>&1 || { echo "$(basename "$dir"),$name,failed"; return; }
  python3 - "$o" "$(basename "$dir")" "$name" <<'PY'
import csv, sys
o, member, name = sys.argv[1:]
rows = list(csv.DictReader(open(f"{o}/metrics.csv")))
tex = list(csv.DictReader(open(f"{o}/texture_errors.csv")))[0]
evals = [r for r in rows if r["image_relmse"]]
angles = [tex.get("initial_angle_deg_observed") or "", tex.get("final_angle_deg_observed") or ""]
print(f'{member},{name},{rows[-1]["iteration"]},{float(tex["initial_rmse_observed"]):.5f},'
      f'{float(tex["final_rmse_observed"]):.5f},{float(rows[-1]["texture_rmse_observed"] or "nan"):.5f},'
      f'{float(evals[-1]["image_relmse"]):.5e},{float(evals[0]["image_relmse"]):.5e},'
      f'{angles[0]},{angles[1]}')
PY
}
echo "member,variant,iterations,start_rmse,final_rmse,last_rmse,last_image_relmse,start_image_relmse,start_angle,final_angle"
for member in $(ls "$out/scenes/$split" | sort -t- -k1,1n | tail -n +$((first + 1))); do
  dir="$out/scenes/$split/$member"
  mkdir -p "$out/runs/$(basename "$dir")"
  task="$dir/task.toml"
  depth=$(sed -n 's/^max_depth = //p' "$task")
  slot=$(sed -n 's/^slot = "\(.*\)"/\1/p' "$task" | head -1)
  run "$dir" default
  run "$dir" full --set optimizer.stop_on_plateau=false
  if [ "$depth" -gt 1 ] && [ "$slot" != normal ]; then
    # The other of 0.01 and 0.03 than the rate `auto` gave the default run.
    other=0.01
    grep -q "learning rates [^;]* 0\.01;" "$out/runs/$member/default.log" && other=0.03
    run "$dir" "full_lr$other" --set optimizer.stop_on_plateau=false --set "textures.0.learning_rate=$other"
  fi
  if [ "$slot" = normal ]; then
    if grep -q "with filtered moments" "$out/runs/$member/default.log"; then
      run "$dir" unfiltered --moment-filter 0
    else
      run "$dir" filtered --moment-filter 5
    fi
  fi
done
