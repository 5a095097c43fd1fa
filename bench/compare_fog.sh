#!/usr/bin/env bash
# Whole-process comparison (issue 12): `mr fog --backend cpu` against a numpy float32 script
# (bench/numpy_fog.py) and the OIIO decode+encode floor (`oiiotool in.jpg -o out.jpg`), on
# photo-like JPEGs with float depth EXRs, side by side in one sitting. Medians of RUNS runs of
# wall time, CPU time (user + system) and peak RSS (/usr/bin/time -f '%e %M %U %S'). Public
# tools only. CPU time is printed too because wall time on a shared machine includes waiting.
#
#   bench/compare_fog.sh [build/cli/mr] [sizes in MP, default "2 12 24"] [runs, default 5]
#   SCRATCH=/tmp/compare_fog BATCH=100 bench/compare_fog.sh build/cli/mr "2 12 24 50"
#   BATCH=1000 bench/compare_fog.sh build/cli/mr ""     # the 1000-frame batch alone
#
# Same fog for all: visibility 150 m, airlight 0.8 (linear), quality-95 4:4:4 JPEG out.
# BATCH=N (default 0: off) also times a batch of N 2 MP frames (files of their own) and prints
# its throughput rows: `mr fog` on the folder; the floor as one `oiiotool --frames` process (one
# core: oiiotool 2.4 has no parallel frames) and as one such process per core over its share of
# the frames (the floor's throughput on this machine); the numpy script over the folder in one
# process; with BATCH_XARGS=1 also oiiotool per photo, a process each, xargs -P<cores>.
# BATCH_RUNS=R (default 1) repeats the batch rows, interleaved, and prints medians.
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
  # N frames as files of their own (copies of one photo-like frame and its depth map), made
  # once per N; read once before timing so that every tool finds them in the page cache.
  if [[ "$(cat "$dir/.frames" 2> /dev/null)" != "$batch $(stat -c %Y "$stem.jpg")" ]]; then
    rm -rf "$dir"
    mkdir -p "$dir"
    for ((i = 0; i < batch; ++i)); do
      f=$(printf 'f%04d' "$i")
      cp "$stem.jpg" "$dir/$f.jpg"
      cp "${stem}_depth.exr" "$dir/${f}_depth.exr"
    done
    echo "$batch $(stat -c %Y "$stem.jpg")" > "$dir/.frames"
  fi
  cat "$dir"/* > /dev/null
  cores=$(nproc)
  batch_runs=${BATCH_RUNS:-1}
  # batch_time NAME CMD...: appends "wall_s peak_kib user_s sys_s" to batch_NAME.log
  batch_time() {
    local name=$1; shift
    rm -rf "$scratch/batch_out"; mkdir -p "$scratch/batch_out"
    /usr/bin/time -f '%e %M %U %S' -o "$scratch/time.txt" "$@" > /dev/null 2> "$scratch/stderr.txt" || {
      echo "FAILED: $*" >&2; tail -5 "$scratch/stderr.txt" >&2; exit 1; }
    tail -1 "$scratch/time.txt" >> "$scratch/batch_$name.log"
  }
  # The floor on all cores: one oiiotool --frames process per core, each over its share.
  split_frames() {
    local per=$(((batch + cores - 1) / cores)) first last
    for ((first = 0; first < batch; first += per)); do
      last=$((first + per - 1 < batch - 1 ? first + per - 1 : batch - 1))
      oiiotool --frames "$first-$last" "$dir/f#.jpg" -o "$scratch/batch_out/f#.jpg" &
    done
    wait
  }
  export -f split_frames
  export batch cores dir scratch
  names=(mr frames split numpy)
  [[ -n "${BATCH_XARGS:-}" ]] && names+=(xargs)
  for name in "${names[@]}"; do rm -f "$scratch/batch_$name.log"; done
  for ((r = 0; r < batch_runs; ++r)); do  # interleaved, as above
    batch_time mr "$mr" fog "$dir" --out-dir "$scratch/batch_out" --visibility 150m \
      --airlight 0.8 --backend cpu -q
    # The floor without start-up per photo: one oiiotool process over the numbered frames.
    batch_time frames oiiotool --frames "0-$((batch - 1))" "$dir/f#.jpg" -o "$scratch/batch_out/f#.jpg"
    batch_time split bash -c split_frames
    batch_time numpy "$python" "$here/numpy_fog.py" --folder "$dir" "$scratch/batch_out" 150 0.8
    [[ -n "${BATCH_XARGS:-}" ]] && batch_time xargs bash -c \
      "ls $dir | grep -v _depth | xargs -P$cores -I{} oiiotool $dir/{} -o $scratch/batch_out/{}"
  done
  row() {
    read -r bw bc bm <<< "$(stats "$scratch/batch_$2.log")"
    printf '%-44s | %7.1f | %7.1f | %5.0f | %6.2f\n' "$1" "$bw" "$bc" "$bm" "$(echo "$batch / $bw" | bc -l)"
  }
  echo
  echo "batch of $batch 2 MP photos (${w}x${h} JPEG + float zip depth EXR, files of their own)," \
    "medians of $batch_runs runs, $cores cores; load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
  printf '%-44s | %7s | %7s | %5s | %6s\n' "one line = one timed command" "wall s" "CPU s" "MiB" "fps"
  row "mr fog <folder> (one process, -j $cores)" mr
  row "oiiotool --frames (one process)" frames
  row "oiiotool --frames, $cores processes (shares)" split
  row "numpy_fog.py --folder (one process)" numpy
  [[ -n "${BATCH_XARGS:-}" ]] && row "oiiotool per photo, xargs -P$cores" xargs
  read -r mw _ <<< "$(stats "$scratch/batch_mr.log")"
  read -r sw _ <<< "$(stats "$scratch/batch_split.log")"
  printf 'mr throughput / the floor on all cores (oiiotool --frames x %d): %.2f\n' "$cores" \
    "$(echo "$sw / $mw" | bc -l)"
fi
