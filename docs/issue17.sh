#!/usr/bin/env bash
# Reproduces the tables of docs/robustness.md, "Issue 17": the eight gradient trackers (ESM, FCLK,
# FALK, ICLK x SSD, ZNCC; homography) with the paper's settings and with the defaults, on
#   ev    the evidence set with --reinit (rendered by docs/evidence.sh's first part)
#   evn   the same without re-initialisation
#   fast  six fast-motion renders (the coffee over the brick, UCSB profiles at 1-3x speed)
#   stars the star field and lit  the other lit sequences (the test write_the_lit_sequences)
#   st2   four dim star fields (docs/render_stars.py)
#   box, box2  a camera around a box whose faces turn to a lamp (docs/render_box.py, two seeds)
# and, when VISP=path/to/visp_track is given (built from ../shared/peers/visp, whose run.py it
# uses), ViSP's template trackers on the same frames.
#   bash docs/issue17.sh [OUT]     (default OUT = target/issue17; about 15 minutes on 2 cores,
#                                   numpy and Pillow for the renders)
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath -m "${1:-target/issue17}")
bin=${REGTRACK_BIN:-target/release/regtrack}
[ -n "${REGTRACK_BIN:-}" ] || cargo build --release --quiet
ev=target/evidence/data
[ -f "$ev/bricks_zm.txt" ] || { echo "render the evidence set first: bash docs/evidence.sh" >&2; exit 1; }
data=$out/data
[ -f "$data/lit/stars.txt" ] || REGTRACK_LIT_OUT="$data/lit" cargo test --quiet --test it \
    write_the_lit_sequences
motion=../shared/data/motion
for spec in m1x2:m1:2 m3x2:m3:2 ucx1:uc:1 m1x3:m1:3 m2x1:m2:1 pdx2:pd:2; do
    IFS=: read -r name profile step <<<"$spec"
    [ -f "$data/fast/$name.txt" ] || "$bin" synth --texture assets/textures/skimage_coffee.png \
        --background assets/textures/skimage_brick.png --motion "$motion/ucsb_bricks_$profile.txt" \
        --step "$step" --noise 3 --jpeg-quality 90 --out "$data/fast" --name "$name"
done
[ -f "$data/stars2/s_d.txt" ] || python3 docs/render_stars.py "$data/stars2"
[ -f "$data/box/box_right.txt" ] || python3 docs/render_box.py "$data/box"
[ -f "$data/box2/box2_right.txt" ] || python3 docs/render_box.py "$data/box2" --seed 2 \
    --name box2 --textures skimage_camera.png,skimage_chelsea.png
sets="ev:$ev:reinit: evn:$ev::: fast:$data/fast::: stars:$data/lit::stars lit:$data/lit::sparse,brick50,brick100 st2:$data/stars2::: box:$data/box::: box2:$data/box2:::"
paper=(--sigma 3 --levels 1 --line_search off --polish off --on_loss stop --predict off)
for s in $sets; do
    IFS=: read -r name dir mode seqs _ <<<"$s"
    flags=(); [ "$mode" = reinit ] && flags=(--reinit)
    [ -n "$seqs" ] && flags+=(--seqs "$seqs")
    for settings in paper defaults; do
        extra=(); [ "$settings" = paper ] && extra=("${paper[@]}")
        "$bin" eval --dataset "$dir" --sm esm,fclk,falk,iclk --am ssd,zncc --ssm homography \
            --jobs 2 "${flags[@]}" "${extra[@]}" --out "$out/$settings/$name" >/dev/null
    done
    if [ -n "${VISP:-}" ] && [ "$mode" != reinit ]; then
        sel=(); [ -n "$seqs" ] && sel=(--seqs "$seqs")
        python3 "$(dirname "$VISP")/run.py" --bin "$VISP" --root "$dir" "${sel[@]}" \
            --trackers ssd_esm,ssd_fc,ssd_fa,ssd_ic,zncc_fa,zncc_ic --out "$out/visp/$name" >/dev/null
    fi
done
python3 - "$out" $sets <<'PY'
import csv, os, sys
out, sets = sys.argv[1], [s.split(':')[0] for s in sys.argv[2:]]
peer = {'esm-ssd': 'ssd_esm', 'fclk-ssd': 'ssd_fc', 'falk-ssd': 'ssd_fa', 'iclk-ssd': 'ssd_ic',
        'falk-zncc': 'zncc_fa', 'iclk-zncc': 'zncc_ic'}
def ours(settings, s):
    rows = list(csv.DictReader(open(f'{out}/{settings}/{s}/summary.csv')))
    one = len({r['sequence'] for r in rows}) == 1
    return {r['sm'] + '-' + r['am']: float(r['sr5']) for r in rows if r['sequence'] == 'ALL' or one}
def visp(s):
    # the peer's run.py: frame-weighted ALL rows when a set has several sequences
    p = f'{out}/visp/{s}/summary.csv'
    if not os.path.exists(p): return {}
    rows = list(csv.DictReader(open(p)))
    return {r['tracker']: float(r['sr5']) for r in ([r for r in rows if r['sequence'] == 'ALL'] or rows)}
print('| tracker | ' + ' | '.join(sets) + ' |')
print('|---|' + '---|' * len(sets))
for t in ['esm-ssd', 'esm-zncc', 'fclk-ssd', 'fclk-zncc', 'falk-ssd', 'falk-zncc', 'iclk-ssd', 'iclk-zncc']:
    cells = []
    for s in sets:
        c = f"{ours('paper', s)[t]:.2f} -> {ours('defaults', s)[t]:.2f}"
        v = visp(s).get(peer.get(t))
        cells.append(c + (f' ({v:.2f})' if v is not None else ''))
    print(f'| {t.upper()} | ' + ' | '.join(cells) + ' |')
PY
