#!/bin/bash
# A sharded evaluation on a single-node Slurm, end to end: for those who have (or can install)
# slurm-wlm; not part of .ci/run. Run as root on a Debian/Ubuntu machine without systemd:
#
#   bash docs/slurm/single-node-trial.sh [REGTRACK_BINARY]
#
# It installs slurm-wlm and munge if missing, starts munged, slurmctld and slurmd by hand with
# ../shared/slurm/slurm.conf (this host's name put in), renders two small sequences, submits
# docs/slurm/eval-array.sbatch as 4 shards, cancels shard 2 part way and submits it again
# (it resumes), checks that merge refuses the set while a shard is missing, merges and
# reports the whole, and compares the merged summary with an unsharded run's. The daemons are
# stopped at the end.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
REGTRACK=$(realpath "${1:-$ROOT/target/release/regtrack}")
CONF=${SLURM_CONF_TEMPLATE:-$ROOT/../shared/slurm/slurm.conf}
WORK=$(mktemp -d /tmp/regtrack-slurm.XXXXXX)
chmod 755 "$WORK"

if ! command -v sbatch >/dev/null; then
    apt-get update && apt-get install -y slurm-wlm munge
fi
if ! sinfo >/dev/null 2>&1; then
    sed "s/\bvm\b/$(hostname -s)/g" "$CONF" > /etc/slurm/slurm.conf
    mkdir -p /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge
    chown slurm: /var/spool/slurmctld /var/log/slurm
    chown munge: /run/munge
    pgrep -x munged >/dev/null || runuser -u munge -- /usr/sbin/munged
    /usr/sbin/slurmctld
    /usr/sbin/slurmd
    STARTED=1
    for _ in $(seq 30); do sinfo -h -o %T 2>/dev/null | grep -q idle && break; sleep 1; done
fi
sinfo

cd "$WORK"
mkdir -p data logs
for m in ucsb_bricks_uc ucsb_bricks_zm; do
    "$REGTRACK" synth --texture "$ROOT/assets/textures/skimage_coffee.png" \
        --motion "$ROOT/assets/motion/$m.txt" --out data --name "$m" >/dev/null
done
# Runs of a few seconds each (nearest neighbour over 50,000 indexed warps), two a shard, so
# that a task can be cancelled between its runs.
export DATASET=$WORK/data RESULTS=$WORK/results REGTRACK SM=nn AM=ssd,zncc,ncc,sad
export EXTRA="--param samples=50000"
EVAL=(eval --dataset data --sm "$SM" --am "$AM" --ssm homography --param samples=50000)
# 4 shards of the sbatch script (its SHARDS set to 4, its trackers kept).
sed -e 's/^SHARDS=8/SHARDS=4/' -e 's/^#SBATCH --array=0-7/#SBATCH --array=0-3/' \
    "$HERE/eval-array.sbatch" > eval4.sbatch
job=$(sbatch --parsable eval4.sbatch)
echo "submitted job $job (4 shards)"
# Cancel shard 2 once it has finished its first run (its second is under way).
for _ in $(seq 600); do
    compgen -G "results/shard2/tracking_data/*/*_run.json" >/dev/null && break; sleep 0.1
done
scancel "${job}_2" || true
echo "cancelled shard 2 with $(compgen -G 'results/shard2/tracking_data/*/*_run.json' | wc -l) of its 2 runs finished"
while squeue -h -j "$job" 2>/dev/null | grep -q .; do sleep 1; done
echo "--- merge with shard 2 cancelled (must be refused):"
if "$REGTRACK" merge --out results/all results/shard* 2>&1; then
    echo "ERROR: an incomplete set was merged" >&2
    exit 1
fi
echo "--- shard 2 submitted again (resumes):"
job2=$(sbatch --parsable --array=2 eval4.sbatch)
while squeue -h -j "$job2" 2>/dev/null | grep -q .; do sleep 1; done
cat logs/eval-"${job2}"_2.out
echo "--- merge and report:"
"$REGTRACK" merge --out results/all results/shard*
"$REGTRACK" report results/shard* --out results/all/report
echo "--- the same evaluation unsharded:"
"$REGTRACK" "${EVAL[@]}" --jobs 2 --out results/whole >/dev/null 2>&1
cut -d, -f1-10 results/all/summary.csv | sort > merged.csv
cut -d, -f1-10 results/whole/summary.csv | sort > whole.csv
if diff merged.csv whole.csv; then
    echo "merged summary = unsharded summary (timings aside)"
else
    echo "ERROR: the merged summary differs from the unsharded one" >&2
    exit 1
fi
echo "logs and results in $WORK"
if [ "${STARTED:-0}" = 1 ]; then
    kill "$(cat /run/slurmd.pid)" "$(cat /run/slurmctld.pid)" 2>/dev/null || true
fi
