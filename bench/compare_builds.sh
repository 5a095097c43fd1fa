#!/usr/bin/env bash
# Before/after of two builds of `mr` as whole processes (issue 14: "benchmarks no slower"):
# `mr fog` at 1920x1080 with a sun (shafts), normal quality, on a photo-like JPEG with a float
# depth EXR made from a sample photo; the two binaries interleaved so both share the machine's
# mood. Prints each run's wall s / CPU s / peak MiB and the medians, and compares the outputs.
#
#   bench/compare_builds.sh OLD_MR NEW_MR [cpu|vulkan] [runs, default 3]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
old=$(realpath "$1"); new=$(realpath "$2"); backend=${3:-cpu}; runs=${4:-3}
scratch=${SCRATCH:-/tmp/compare_builds}
mkdir -p "$scratch"
[[ -f "$scratch/p1080_depth.exr" ]] ||
  /usr/bin/python3 "$here/make_fog_inputs.py" "$here/../sample_photos/leuven.jpg" "$scratch/p1080" 1920 1080
rm -f "$scratch"/times_{old,new}.txt
for ((i = 0; i < runs; ++i)); do
  for v in old new; do
    mr=$old; [[ $v == new ]] && mr=$new
    /usr/bin/time -f '%e %M %U %S' -a -o "$scratch/times_$v.txt" "$mr" fog "$scratch/p1080.jpg" \
      --depth "$scratch/p1080_depth.exr" --backend "$backend" --quality normal --sun-elevation 25 \
      --sun-azimuth 30 --visibility 150m --out-dir "$scratch/out_$v" --overwrite > /dev/null
  done
done
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
for v in old new; do
  echo "$v ($backend, $runs runs): wall $(awk '{print $1}' "$scratch/times_$v.txt" | median) s," \
    "CPU $(awk '{print $3 + $4}' "$scratch/times_$v.txt" | median) s," \
    "peak $(awk '{print $2 / 1024}' "$scratch/times_$v.txt" | median) MiB"
done
oiiotool "$scratch/out_old/p1080_fog.jpg" "$scratch/out_new/p1080_fog.jpg" --diff 2>&1 | tail -3 || true
