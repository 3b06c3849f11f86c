#!/usr/bin/env bash
# Regenerates the tables and plots of EXPERIMENTS.md (the seed's experiments, one command each).
# Every table sits in EXPERIMENTS.md between `<!-- table: NAME -->` and `<!-- /table -->`; this
# rewrites each block in place with the output of its command (the markdown `hter compare`
# prints: the physical bound first, then each controller with its IAE / bound) and echoes it.
# The prose around the tables is not touched.
# Usage: scripts/experiments.sh  (from the repository root; builds hter in release first)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin hter -q
H="${CARGO_TARGET_DIR:-target}/release/hter"
DOC=EXPERIMENTS.md
D=docs/experiments
mkdir -p "$D"

# put NAME: the table on stdin replaces the block NAME of $DOC.
put() {
  local t; t=$(mktemp)
  cat >"$t"
  echo "## $1"; cat "$t"; echo
  grep -q "^<!-- table: $1 -->$" "$DOC" || { echo "error: no '<!-- table: $1 -->' block in $DOC" >&2; exit 1; }
  awk -v name="$1" -v file="$t" '
    $0 == "<!-- table: " name " -->" { print; while ((getline l < file) > 0) print l; skip = 1; next }
    skip && $0 == "<!-- /table -->" { skip = 0 }
    !skip { print }' "$DOC" >"$DOC.new"
  mv "$DOC.new" "$DOC"
  rm -f "$t"
}
# The markdown table of a compare run (its header line and the notes below it dropped).
table() { "$H" compare "$@" | awk '/^\|/ { print } /^$/ && seen { exit } /^\|/ { seen = 1 }'; }
# The rows of one controller from `hter compare --controllers C`, each labelled $1, under the
# compare header with its first column named $2 (for a sweep of one parameter).
sweep_header() { "$H" compare --controllers pi --duration 10 | awk -v h="$1" '/^\| controller/ { sub(/controller/, h); print; getline; print; exit }'; }
sweep_row() { local label=$1; shift; "$H" compare "$@" | awk -v l="$label" '/^\| (onoff|p|pi|gmvc|igmvc|gpc) \|/ { sub(/^\| [a-z]+ \|/, "| " l " |"); print }'; }
bound_row() { "$H" compare "$@" --controllers pi | awk '/^\| bound \|/ { print }'; }

HTER="$H" scripts/targets.sh                                         | put targets
table --scenario step --plot "$D/step.png"                           | put step
table --scenario piecewise --plot "$D/piecewise.png"                 | put piecewise
table --scenario half-load --plot "$D/half-load.png"                 | put half-load
table --scenario piecewise --plant hter2 --plot "$D/hter2.png"       | put hter2
table --scenario disturbance --plot "$D/disturbance.png"             | put disturbance

{
  sweep_header "λ"
  bound_row --scenario piecewise
  for l in 0.01 0.1 0.5 1 3 10 30; do
    label=$l; [[ $l == 0.5 ]] && label="**0.5 (default)**"
    sweep_row "$label" --scenario piecewise --controllers gpc --lambda "$l"
  done
} | put gpc-lambda

M2="arx:-1.74927,0.751376;-0.0270791,-0.029865"
{
  sweep_header "fixed model"
  bound_row --scenario piecewise
  for k in 1 5; do sweep_row "delay k = $k" --scenario piecewise --controllers gpc --model "$M2;$k"; done
} | put unmodelled

{
  sweep_header "fixed model, k = 1"
  bound_row --scenario piecewise
  sweep_row "C = 1" --scenario piecewise --controllers gpc --model "$M2;1"
  sweep_row "C = 1 − 0.8 q⁻¹" --scenario piecewise --controllers gpc --model "$M2;1;-0.8"
} | put t-filter

# The best PI on the --kp × --ti grid of each case (scripts/pi-grid.sh).
{
  HTER="$H" CASE="piecewise, H-TER I full" scripts/pi-grid.sh --header --scenario piecewise
  HTER="$H" CASE="half-load, H-TER I" scripts/pi-grid.sh --scenario half-load
  HTER="$H" CASE="piecewise, H-TER II" scripts/pi-grid.sh --scenario piecewise --plant hter2
} | put pi-grid

# Energy (issue 18): the modules on the SSR against the buck drive. One JSON field of a
# `hter sim --json` object on stdin.
field() { sed -E "s/.*\"$1\":(-?[0-9.eE+]+).*/\1/"; }
# Wh per day (mean_power_w × 24 h, the pre-roll excluded as in every metric) and the time outside
# 2–8 °C, min, of scenario $1 with controller $2 on drive $3: "WH OUT".
day() {
  local j; j=$("$H" sim --scenario "$1" --controller "$2" --drive "$3" --json)
  echo "$(field mean_power_w <<<"$j") $(field time_outside_2_8_s <<<"$j")"
}
{
  echo "| controller | mission SSR (Wh/day) | mission buck | buck / SSR | mission outside 2–8 °C, SSR / buck (min) | hot-zone SSR (Wh/day) | hot-zone buck | buck / SSR | hot-zone outside 2–8 °C, SSR / buck (min) |"
  echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"
  for c in onoff pi igmvc gpc; do
    row="| $c"
    for s in mission hot-zone; do
      read -r ps os < <(day "$s" "$c" ssr)
      read -r pb ob < <(day "$s" "$c" buck)
      row+=$(awk -v ps="$ps" -v pb="$pb" -v os="$os" -v ob="$ob" \
        'BEGIN { printf " | %.0f | %.0f | %.2f | %.0f / %.0f", 24 * ps, 24 * pb, pb / ps, os / 60, ob / 60 }')
    done
    echo "$row |"
  done
} | put energy-day

# Holding 4 °C for 6 h (scenarios/hold-4c-6h.json), self-tuning GPC, both carriers, four ambients.
{
  echo "| plant | ambient (°C) | SSR (W) | buck (W) | buck / SSR | steady-state error, SSR / buck (°C) | min, SSR / buck (°C) |"
  echo "| --- | --- | --- | --- | --- | --- | --- |"
  for p in hter1 hter2; do
    for a in 25 28 32 43; do
      js=$("$H" sim --scenario scenarios/hold-4c-6h.json --plant "$p" --ambient "$a" --drive ssr --json)
      jb=$("$H" sim --scenario scenarios/hold-4c-6h.json --plant "$p" --ambient "$a" --drive buck --json)
      awk -v p="$p" -v a="$a" -v ps="$(field mean_power_w <<<"$js")" -v pb="$(field mean_power_w <<<"$jb")" \
        -v es="$(field steady_state_error_c <<<"$js")" -v eb="$(field steady_state_error_c <<<"$jb")" \
        -v ms="$(field min_temp_c <<<"$js")" -v mb="$(field min_temp_c <<<"$jb")" \
        'BEGIN { printf "| %s | %s | %.1f | %.2f | %.3f | %.3f / %.3f | %.2f / %.2f |\n", p, a, ps, pb, pb / ps, es, eb, ms, mb }'
    done
  done
} | put energy-hold

# Self-tuning GPC with its estimate (the seed's Figs 5.21, 6.9): a plot only.
"$H" sim --scenario piecewise --controller gpc --plot "$D/gpc-estimate.png" >/dev/null
