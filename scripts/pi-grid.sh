#!/usr/bin/env bash
# The best PI on a grid of gains: runs `hter compare --controllers pi --kp K --ti T --json` for
# every K in $KP and T in $TI on the case its arguments describe (any `hter sim` flags), and
# prints the PI with the lowest IAE among the runs that keep the load at or above 2 °C, as a
# markdown table row: | case | Kp | Ti | IAE | min °C | bound | IAE / bound |.
#
# Usage: scripts/pi-grid.sh [--header] [hter sim flags...]   (from the repository root)
#   scripts/pi-grid.sh --header --scenario piecewise
#   scripts/pi-grid.sh --scenario half-load
#   scripts/pi-grid.sh --scenario piecewise --plant hter2
# Grid (override with the environment): KP="0.2 0.3 … 1.0" duty/°C, TI="150 200 … 900" s;
# CASE names the case in the row (default: the flags).
# Set HTER to use an already built binary (otherwise it builds hter in release first).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/lib.sh
hter_bin
KP="${KP:-0.2 0.3 0.4 0.5 0.6 0.7 0.8 0.9 1.0}"
TI="${TI:-150 200 250 300 350 400 450 500 550 600 650 700 750 800 850 900}"
if [[ "${1:-}" == "--header" ]]; then
  shift
  echo "| case | Kp (duty/°C) | Ti (s) | IAE (°C·s) | min (°C) | bound (°C·s) | IAE / bound |"
  echo "| --- | --- | --- | --- | --- | --- | --- |"
fi
best=""
for kp in $KP; do
  for ti in $TI; do
    j=$("$HTER" compare --controllers pi --kp "$kp" --ti "$ti" --json "$@")
    iae=$(field iae "$j"); tmin=$(field min_temp_c "$j"); bound=$(field bound_iae "$j")
    best=$(printf '%s\n%s %s %s %s %s\n' "$best" "$iae" "$kp" "$ti" "$tmin" "$bound" |
      awk 'NF == 5 && $4 >= 2.0' | sort -g | head -1)
  done
done
[[ -n "$best" ]] || { echo "error: no PI on the grid keeps the load at or above 2 °C" >&2; exit 1; }
read -r iae kp ti tmin bound <<<"$best"
awk -v c="${CASE:-${*:-default case}}" -v kp="$kp" -v ti="$ti" -v iae="$iae" -v tmin="$tmin" -v b="$bound" \
  'BEGIN { printf "| %s | %s | %s | %.0f | %.2f | %.0f | %.2f |\n", c, kp, ti, iae, tmin, b, iae / b }'
