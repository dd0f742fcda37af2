#!/usr/bin/env bash
# Reproduces docs/report: renders synthetic sequences from the bundled motion profiles with
# nuisances, runs the paper's grid with `regtrack eval --reinit` (a tracker that fails is restarted
# from the ground truth 5 frames later; failures are counted), and draws the report.
#   bash docs/evidence.sh [OUT]      (default OUT = target/evidence; about 15 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/evidence}
bin=${REGTRACK_BIN:-target/release/regtrack}
[ -n "${REGTRACK_BIN:-}" ] || cargo build --release --quiet
data=$out/data
mkdir -p "$data"
tex=assets/textures
render() { # name motion texture background [nuisance flags...]
    local name=$1 motion=$2 texture=$3 background=$4
    shift 4
    [ -f "$data/$name.txt" ] || "$bin" synth --texture "$tex/$texture" --background "$tex/$background" \
        --motion "assets/motion/$motion.txt" --out "$data" --name "$name" --noise 2 --seed 7 "$@"
}
render book_plain   tmt_dl_bookIII_s5 skimage_coffee.png skimage_grass.png
render bricks_light ucsb_bricks_ld    skimage_brick.png  skimage_grass.png --gain-drift 0.3 --local-light 0.4
render bricks_m1    ucsb_bricks_m1    skimage_brick.png  skimage_coffee.png --motion-blur 3
render bricks_m3    ucsb_bricks_m3    skimage_brick.png  skimage_coffee.png --jpeg-quality 70
render bricks_rt    ucsb_bricks_rt    skimage_brick.png  skimage_grass.png --bias-drift 20
render bricks_uc    ucsb_bricks_uc    skimage_brick.png  skimage_grass.png --occlusion 0.15 --jpeg-quality 80
render bricks_zm    ucsb_bricks_zm    skimage_brick.png  skimage_coffee.png --local-light 0.3

ams=ssd,zncc,ncc,scv,rscv,lscv,mi,ccre
# 1. Every AM x SM on homography (NN ranks MI and CCRE, which have no embedding, by their own
#    similarity).
"$bin" eval --dataset "$data" --sm falk,ialk,fclk,iclk,esm --am "$ams" --ssm homography \
    --jobs 2 --reinit --out "$out/grid_am_sm"
"$bin" eval --dataset "$data" --sm nn1k,nn10k,nnic --am "$ams" --ssm homography \
    --jobs 2 --reinit --out "$out/grid_nn"
# 2. Every SSM with ESM + ZNCC, each against its own SSM's low-DOF ground truth (the paper's
#    protocol; homography is in grid 1, translation in grid 3).
"$bin" eval --dataset "$data" --sm esm --am zncc --gt-ssm own \
    --ssm isometry,similitude,affine,sl3,corner --jobs 2 --reinit --out "$out/grid_ssm"
# 3. The translation grid with NN and PF, against 2-DOF ground truth as the paper does.
"$bin" eval --dataset "$data" --sm iclk,esm,nn1k,pf --am ssd,zncc --ssm translation \
    --gt-ssm translation --jobs 2 --reinit --out "$out/grid_translation"
# 4. The learning-based trackers, against the same 2-DOF ground truth as grid 3.
"$bin" eval --dataset "$data" --tracker kcf,dsst,rct,tld,cmt --gt-ssm translation \
    --jobs 2 --reinit --out "$out/grid_learning"
"$bin" report "$out/grid_am_sm" "$out/grid_nn" "$out/grid_ssm" "$out/grid_translation" \
    "$out/grid_learning" --out docs/report
