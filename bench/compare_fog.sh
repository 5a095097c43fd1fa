#!/usr/bin/env bash
# Whole-process comparison (issue 12): `mr fog --backend cpu` against a numpy float32 script
# (bench/numpy_fog.py) and the OIIO decode+encode floor (`oiiotool in.jpg -o out.jpg`), on
# photo-like JPEGs with float depth EXRs, side by side in one sitting. Medians of RUNS runs of
# wall time and of peak RSS (/usr/bin/time -f '%e %M'). Public tools only.
#
#   bench/compare_fog.sh [build/cli/mr] [sizes in MP, default "2 12 24"] [runs, default 5]
#   SCRATCH=/tmp/compare_fog BATCH=100 bench/compare_fog.sh build/cli/mr "2 12 24 50"
#
# Same fog for all: visibility 150 m, airlight 0.8 (linear), quality-95 4:4:4 JPEG out.
# BATCH=N (default 0: off) also times a batch of N 2 MP photos: `mr fog` on the folder against
# oiiotool per photo (sequential, and two at a time with xargs -P2).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
mr=$(realpath "${1:-$here/../build/cli/mr}")
sizes=${2:-"2 12 24"}
runs=${3:-5}
scratch=${SCRATCH:-/tmp/compare_fog}
python=/usr/bin/python3  # Debian's, with python3-numpy and python3-openimageio
mkdir -p "$scratch"

declare -A dims=([2]="1632 1224" [12]="4000 3000" [24]="5656 4242" [50]="8165 6124")

# median of the numbers on stdin
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }

# time_it LOG CMD...: appends "wall_s peak_kib" of one run to LOG
time_it() {
  local log=$1; shift
  /usr/bin/time -f '%e %M' -o "$scratch/time.txt" "$@" > /dev/null 2> "$scratch/stderr.txt" || {
    echo "FAILED: $*" >&2; cat "$scratch/stderr.txt" >&2; exit 1; }
  tail -1 "$scratch/time.txt" >> "$log"
}

printf '%-5s | %-15s | %-15s | %-15s | %-8s | %-9s\n' "MP" "mr fog s (MiB)" "numpy s (MiB)" \
  "oiiotool s (MiB)" "numpy/mr" "mr/floor"
printf '%s\n' "------|-----------------|-----------------|------------------|----------|----------"
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
  ms=$(cut -d' ' -f1 "$scratch/mr_$mp.log" | median); mm=$(cut -d' ' -f2 "$scratch/mr_$mp.log" | median)
  ns=$(cut -d' ' -f1 "$scratch/np_$mp.log" | median); nm=$(cut -d' ' -f2 "$scratch/np_$mp.log" | median)
  os=$(cut -d' ' -f1 "$scratch/oiio_$mp.log" | median); om=$(cut -d' ' -f2 "$scratch/oiio_$mp.log" | median)
  printf '%-5s | %5.2f (%6.0f)  | %5.2f (%6.0f)  | %5.2f (%6.0f)   | %6.2fx  | %6.2fx\n' "$mp" \
    "$ms" "$(echo "$mm / 1024" | bc -l)" "$ns" "$(echo "$nm / 1024" | bc -l)" "$os" \
    "$(echo "$om / 1024" | bc -l)" "$(echo "$ns / $ms" | bc -l)" "$(echo "$ms / $os" | bc -l)"
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
    ln -s "$stem.jpg" "$dir/f$i.jpg"
    ln -s "${stem}_depth.exr" "$dir/f${i}_depth.exr"
  done
  start=$(date +%s.%N)
  "$mr" fog "$dir" --out-dir "$scratch/batch_out" --visibility 150m --airlight 0.8 --backend cpu -q
  t_mr=$(echo "$(date +%s.%N) - $start" | bc -l)
  start=$(date +%s.%N)
  for ((i = 0; i < batch; ++i)); do oiiotool "$dir/f$i.jpg" -o "$scratch/batch_oiio/f$i.jpg"; done
  t_seq=$(echo "$(date +%s.%N) - $start" | bc -l)
  rm -rf "$scratch/batch_oiio"; mkdir -p "$scratch/batch_oiio"
  start=$(date +%s.%N)
  seq 0 $((batch - 1)) | xargs -P2 -I{} oiiotool "$dir/f{}.jpg" -o "$scratch/batch_oiio/f{}.jpg"
  t_par=$(echo "$(date +%s.%N) - $start" | bc -l)
  printf '\nbatch of %d 2 MP photos (%dx%d): mr fog %.1f s (%.1f photos/s); oiiotool per photo: %.1f s sequential (%.1f/s), %.1f s two at a time (%.1f/s)\n' \
    "$batch" "$w" "$h" "$t_mr" "$(echo "$batch / $t_mr" | bc -l)" "$t_seq" \
    "$(echo "$batch / $t_seq" | bc -l)" "$t_par" "$(echo "$batch / $t_par" | bc -l)"
fi
