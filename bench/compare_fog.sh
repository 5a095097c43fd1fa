#!/usr/bin/env bash
# Whole-process comparison (issue 12): `mr fog --backend cpu` against a numpy float32 script
# (bench/numpy_fog.py) and the OIIO decode+encode floor (`oiiotool in.jpg -o out.jpg`), on
# photo-like JPEGs with float depth EXRs, side by side in one sitting. Medians of RUNS runs of
# wall time, CPU time (user + system) and peak RSS (/usr/bin/time -f '%e %M %U %S'). Public
# tools only. CPU time is printed too because wall time on a shared machine includes waiting.
#
#   bench/compare_fog.sh [build/cli/mr] [sizes in MP, default "2 12 24"] [runs, default 5]
#   SCRATCH=/tmp/compare_fog BATCH=100 bench/compare_fog.sh build/cli/mr "2 12 24 50"
#
# Same fog for all: visibility 150 m, airlight 0.8 (linear), quality-95 4:4:4 JPEG out.
# BATCH=N (default 0: off) also times a batch of N 2 MP photos: `mr fog` on the folder against
# one oiiotool process over the numbered frames (the floor without start-up per photo) and
# oiiotool per photo two at a time (xargs -P2).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
mr=$(realpath "${1:-$here/../build/cli/mr}")
sizes=${2-"2 12 24"}  # "" with BATCH=N: the batch alone
runs=${3:-5}
scratch=${SCRATCH:-/tmp/compare_fog}
python=/usr/bin/python3  # Debian's, with python3-numpy and python3-openimageio
mkdir -p "$scratch"

declare -A dims=([2]="1632 1224" [12]="4000 3000" [24]="5656 4242" [50]="8165 6124")

# median of the numbers on stdin
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }

# time_it LOG CMD...: appends "wall_s peak_kib user_s sys_s" of one run to LOG
time_it() {
  local log=$1; shift
  /usr/bin/time -f '%e %M %U %S' -o "$scratch/time.txt" "$@" > /dev/null 2> "$scratch/stderr.txt" || {
    echo "FAILED: $*" >&2; cat "$scratch/stderr.txt" >&2; exit 1; }
  tail -1 "$scratch/time.txt" >> "$log"
}

# stats LOG: "wall cpu mib" medians
stats() {
  local wall cpu mib
  wall=$(awk '{print $1}' "$1" | median)
  cpu=$(awk '{print $3 + $4}' "$1" | median)
  mib=$(awk '{print $2 / 1024}' "$1" | median)
  echo "$wall $cpu $mib"
}

echo "medians of $runs runs; wall s / CPU s / peak MiB"
printf '%-4s | %-21s | %-21s | %-21s | %-12s | %-12s\n' "MP" "mr fog --backend cpu" "numpy float32" \
  "oiiotool in -o out" "numpy/mr" "mr/oiiotool"
printf '%s\n' "-----|-----------------------|-----------------------|-----------------------|--------------|-------------"
for mp in $sizes; do
  read -r w h <<< "${dims[$mp]}"
  stem="$scratch/p$mp"
  [[ -f "${stem}_depth.exr" ]] || "$python" "$here/make_fog_inputs.py" "$here/../sample_photos/leuven.jpg" "$stem" "$w" "$h"
  rm -f "$scratch"/{mr,np,oiio}_$mp.log
  for ((i = 0; i < runs; ++i)); do  # interleaved, so all three share the machine's mood
    time_it "$scratch/mr_$mp.log" "$mr" fog "$stem.jpg" --depth "${stem}_depth.exr" --out-dir \
      "$scratch/out" --visibility 150m --airlight 0.8 --backend cpu --overwrite -q
    time_it "$scratch/np_$mp.log" "$python" "$here/numpy_fog.py" "$stem.jpg" "${stem}_depth.exr" \
      "$scratch/out/np_$mp.jpg" 150 0.8
    time_it "$scratch/oiio_$mp.log" oiiotool "$stem.jpg" -o "$scratch/out/oiio_$mp.jpg"
  done
  read -r mw mc mm <<< "$(stats "$scratch/mr_$mp.log")"
  read -r nw nc nm <<< "$(stats "$scratch/np_$mp.log")"
  read -r ow oc om <<< "$(stats "$scratch/oiio_$mp.log")"
  printf '%-4s | %5.2f / %5.2f / %5.0f | %5.2f / %5.2f / %5.0f | %5.2f / %5.2f / %5.0f | %4.2fx wall  | %4.2fx wall\n' \
    "$mp" "$mw" "$mc" "$mm" "$nw" "$nc" "$nm" "$ow" "$oc" "$om" "$(echo "$nw / $mw" | bc -l)" \
    "$(echo "$mw / $ow" | bc -l)"
done

batch=${BATCH:-0}
if ((batch > 0)); then
  read -r w h <<< "${dims[2]}"
  stem="$scratch/p2"
  [[ -f "${stem}_depth.exr" ]] || "$python" "$here/make_fog_inputs.py" "$here/../sample_photos/leuven.jpg" "$stem" "$w" "$h"
  dir="$scratch/batch_in"
  rm -rf "$dir" "$scratch/batch_out" "$scratch/batch_oiio"
  mkdir -p "$dir" "$scratch/batch_out" "$scratch/batch_oiio"
  for ((i = 0; i < batch; ++i)); do  # links: the page cache holds one photo, as for any tool
    f=$(printf 'f%04d' "$i")
    ln -s "$stem.jpg" "$dir/$f.jpg"
    ln -s "${stem}_depth.exr" "$dir/${f}_depth.exr"
  done
  /usr/bin/time -f '%e %U %S' -o "$scratch/batch_mr.txt" "$mr" fog "$dir" --out-dir \
    "$scratch/batch_out" --visibility 150m --airlight 0.8 --backend cpu -q
  # The floor without start-up per photo: one oiiotool process over the numbered frames.
  /usr/bin/time -f '%e %U %S' -o "$scratch/batch_frames.txt" oiiotool --frames "0-$((batch - 1))" \
    "$dir/f#.jpg" -o "$scratch/batch_oiio/f#.jpg"
  rm -rf "$scratch/batch_oiio"; mkdir -p "$scratch/batch_oiio"
  /usr/bin/time -f '%e %U %S' -o "$scratch/batch_par.txt" bash -c \
    "ls $dir | grep -v _depth | xargs -P2 -I{} oiiotool $dir/{} -o $scratch/batch_oiio/{}"
  row() { awk -v n="$batch" -v what="$1" '{printf "%-34s %7.1f s wall %6.1f s CPU  %6.2f photos/s\n", what, $1, $2 + $3, n / $1}' "$2"; }
  echo
  echo "batch of $batch 2 MP photos (${w}x${h}, JPEG + float depth EXR), one process each line:"
  row "mr fog <folder> (one process)" "$scratch/batch_mr.txt"
  row "oiiotool --frames (one process)" "$scratch/batch_frames.txt"
  row "oiiotool per photo, xargs -P2" "$scratch/batch_par.txt"
fi
