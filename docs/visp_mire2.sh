#!/usr/bin/env bash
# Scores the learning-based trackers on ViSP's hand-held `mire-2` sequence against its
# translation ground truth, as docs/learning.md reports. (Not the registration trackers: the
# ground truth was proposed by FCLK-SSD and checked by eye, so they would be scored against
# themselves.)
# Needs the Debian package visp-images-data (apt-get install visp-images-data); the ground
# truth is assets/visp/mire2.txt (made in the inspector, see assets/README.md).
#
#   bash docs/visp_mire2.sh [OUT]     # OUT defaults to target/visp_mire2
set -euo pipefail
cd "$(dirname "$0")/.."
frames=/usr/share/visp-images-data/ViSP-images/mire-2
[ -d "$frames" ] || { echo "$frames: install the Debian package visp-images-data" >&2; exit 1; }
out=$(realpath -m "${1:-target/visp_mire2}")
root=$out/data
mkdir -p "$root/mire2"
for i in $(seq 40 501); do
    f=$(printf "image.%04d.pgm" "$i")
    ln -sf "$frames/$f" "$root/mire2/$f"
done
cp assets/visp/mire2.txt "$root/mire2.txt"
bin=${REGTRACK_BIN:-target/release/regtrack}
"$bin" eval --dataset "$root" --tracker dft,fragtrack,mil,struck,kcf,dsst,rct,tld,cmt \
    --gt-ssm translation --out "$out/learning"
