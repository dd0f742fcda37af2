#!/usr/bin/env bash
# Compares the tracking output of two regtrack binaries, bit for bit: every `regtrack eval`
# corner, error, success-rate and run file (the time columns aside) for each gradient search
# method x {SSD, ZNCC, MI} x {homography, affine}, at the defaults and at the paper's settings
# (one level, no line search, no polish), on the demo and on two rendered sequences (fast motion
# with blur, a brick texture under changing light); then the other paths of a frame (the SSM
# hierarchy, NN and PF and the cascades, the losses and their policies, the re-initialisations).
#
#   bash tests/same_bits.sh OLD_BIN NEW_BIN [WORK_DIR]
#
# A refactoring that should not change behaviour passes it (exit 0, "identical"); anything else
# lists the files that differ and exits 1. About 10 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
old=$(realpath "$1")
new=$(realpath "$2")
work=${3:-target/same_bits}
mkdir -p "$work"
work=$(realpath "$work")
data=$work/data
mkdir -p "$data"
tex=assets/textures
render() { # name motion texture background [flags...]
    local name=$1 motion=$2 texture=$3 background=$4
    shift 4
    [ -f "$data/$name.txt" ] || "$new" synth --texture "$tex/$texture" \
        --background "$tex/$background" --motion "assets/motion/$motion.txt" --out "$data" \
        --name "$name" --noise 2 --seed 7 "$@" >/dev/null
}
[ -f "$data/demo_book.txt" ] || "$new" demo --cache "$data" >/dev/null
# Fast motion with blur (losses, re-detection, regions regrown), and light that changes.
render fast_m1 ucsb_bricks_m1 skimage_brick.png skimage_coffee.png --motion-blur 3 --step 2 \
    --frames 240
render bricks_light ucsb_bricks_ld skimage_brick.png skimage_grass.png --gain-drift 0.3 \
    --local-light 0.4 --frames 240

# eval NAME ARGS...: the same eval with both binaries, into $work/{old,new}/NAME.
both() {
    local name=$1
    shift
    for side in old new; do
        local bin=$old
        [ $side = new ] && bin=$new
        rm -rf "$work/$side/$name"
        "$bin" eval --dataset "$data" --jobs 2 --no-resume --out "$work/$side/$name" "$@" \
            >/dev/null
    done
}
gradient=falk,ialk,fclk,iclk,esm
both defaults --sm $gradient --am ssd,zncc,mi --ssm homography,affine
both paper --sm $gradient --am ssd,zncc,mi --ssm homography,affine --pyramid_levels 1 \
    --line_search off --polish off
both hierarchy --sm iclk,esm --am ssd,zncc --ssm homography --ssm_hierarchy on
both sampling --sm nn1k,nnic,pf,cascade:nn1k+esm,parallel:esm+fclk,lm:iclk --am ssd,zncc \
    --ssm homography,translation
both continue --sm fclk,esm --am ssd,scv --ssm homography --on_loss continue --reinit
both stop --sm iclk --am zncc,ssd --ssm similitude,homography --on_loss stop --reinit
both ilm --sm fclk,iclk --am ssd --ssm homography --ilm pgb --seqs bricks_light
both border --sm esm,iclk --am ncc,lscv --ssm homography --grid border --res 40

python3 - "$work" <<'EOF'
import json, pathlib, sys
work = pathlib.Path(sys.argv[1])
TIME = {"search_us", "update_us"}

def strip_json(v):
    if isinstance(v, dict):
        return {k: strip_json(x) for k, x in v.items() if k not in TIME}
    if isinstance(v, list):
        return [strip_json(x) for x in v]
    return v

def content(path, other=None):
    if path.name.endswith("_run.json"):
        run = strip_json(json.loads(path.read_text()))
        # A tracker parameter only one binary has (one added since) is left out: a run at
        # its default must track as before.
        if other is not None and other.exists():
            mine = run.get("spec", {}).get("params")
            peer = json.loads(other.read_text()).get("spec", {}).get("params")
            if isinstance(mine, dict) and isinstance(peer, dict):
                for k in [k for k in mine if k not in peer]:
                    del mine[k]
        return run
    lines = path.read_text().splitlines()
    if path.name.endswith("_errors.txt"):
        # The last two columns are times.
        return [l.split("\t")[:-2] for l in lines]
    return lines

old, new = work / "old", work / "new"
files = sorted(p.relative_to(old) for p in old.rglob("tracking_data/*/*") if p.is_file())
if not files:
    sys.exit("no output to compare")
differ = []
for rel in files:
    b = new / rel
    if not b.exists() or content(old / rel, b) != content(b, old / rel):
        differ.append(str(rel))
extra = sorted(str(p.relative_to(new)) for p in new.rglob("tracking_data/*/*")
               if p.is_file() and not (old / p.relative_to(new)).exists())
for d in differ:
    print("differs:", d)
for e in extra:
    print("only in the new output:", e)
if differ or extra:
    sys.exit(1)
print(f"identical: {len(files)} files ({len([f for f in files if f.name.endswith('_run.json')])} runs)")
EOF
