#!/usr/bin/env bash
# Regenerates the tables and plots of EXPERIMENTS.md (the seed's experiments, one command each).
# Usage: scripts/experiments.sh  (from the repository root; builds hter in release first)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin hter -q
H="${CARGO_TARGET_DIR:-target}/release/hter"

D=docs/experiments
mkdir -p "$D"
echo "## step to 4 °C";            $H compare --scenario step --plot "$D/step.png"
echo "## piecewise, full load";     $H compare --scenario piecewise --plot "$D/piecewise.png"
echo "## half load";                $H compare --scenario half-load --plot "$D/half-load.png"
echo "## H-TER II";                 $H compare --scenario piecewise --plant hter2 --plot "$D/hter2.png"
echo "## step load disturbance";    $H compare --scenario disturbance --plot "$D/disturbance.png"
echo "## GPC, λ";
for l in 0.01 0.1 1 3 10 30; do
  printf 'λ = %s: ' "$l"; $H sim --scenario piecewise --controller gpc --lambda "$l" --json
done
M2="arx:-1.74927,0.751376;-0.0270791,-0.029865"
echo "## unmodelled dynamics: fixed 2nd-order model, delay 1 vs 5 samples, on the 5-node plant"
for k in 1 5; do printf 'k = %s: ' "$k"; $H sim --scenario piecewise --controller gpc --model "$M2;$k" --json; done
echo "## GPC T-filter: C = 1 vs C = 1 - 0.8 q^-1 (fixed model, k = 1)"
for c in "" ";-0.8"; do printf 'C%s: ' "$c"; $H sim --scenario piecewise --controller gpc --model "$M2;1$c" --json; done
echo "## self-tuning GPC with its estimate (the seed's Figs 5.21, 6.9)"
$H sim --scenario piecewise --controller gpc --plot "$D/gpc-estimate.png" > /dev/null
