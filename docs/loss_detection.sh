#!/usr/bin/env bash
# Reproduces the loss-detection tables of docs/robustness.md ("Knowing when it is lost"): the
# evidence set (rendered by docs/evidence.sh's first part), the lit sequences (the test
# write_the_lit_sequences) and three fast-motion renders, each run by ESM, FCLK, FALK, ICLK x SSD,
# ZNCC on homography with --reinit and with on_loss=continue; "before" is the same with the checks
# off. The lost_when_off / lost_when_on columns of each summary.csv are the figures.
#   bash docs/loss_detection.sh [OUT]      (default OUT = target/loss; a few minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/loss}
bin=${REGTRACK_BIN:-target/release/regtrack}
[ -n "${REGTRACK_BIN:-}" ] || cargo build --release --quiet
ev=target/evidence/data
[ -f "$ev/bricks_zm.txt" ] || { echo "render the evidence set first: bash docs/evidence.sh" >&2; exit 1; }
lit=$out/data/lit
[ -f "$lit/stars.txt" ] || REGTRACK_LIT_OUT=$(realpath -m "$lit") cargo test --quiet --test it \
    write_the_lit_sequences
fast=$out/data/fast
tex=assets/textures
for spec in m1x2:ucsb_bricks_m1:2 m3x2:ucsb_bricks_m3:2 ucx1:ucsb_bricks_uc:1; do
    IFS=: read -r name motion step <<<"$spec"
    [ -f "$fast/$name.txt" ] || "$bin" synth --texture "$tex/skimage_coffee.png" \
        --background "$tex/skimage_brick.png" --motion "assets/motion/$motion.txt" \
        --step "$step" --noise 3 --jpeg-quality 90 --out "$fast" --name "$name"
done
for set in ev:$ev lit:$lit fast:$fast; do
    IFS=: read -r name data <<<"$set"
    for mode in reinit continue; do
        flags=(--reinit); [ "$mode" = continue ] && flags=(--on_loss continue)
        for checks in after before; do
            off=(); [ "$checks" = before ] && off=(--min_confidence -1 --confidence_drop 0)
            "$bin" eval --dataset "$data" --sm esm,fclk,falk,iclk --am ssd,zncc --ssm homography \
                --jobs 2 "${flags[@]}" "${off[@]}" --out "$out/${name}_${mode}_$checks" | grep '^ALL'
        done
    done
done
