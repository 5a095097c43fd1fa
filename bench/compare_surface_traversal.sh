#!/usr/bin/env bash
# How the CPU traces the occluder surface on real photos (issue 12, "Jagged depth traced in the
# image"): `mr fog --depth auto` with the gallery's sun-bank look, as a user runs it, with the
# surface forced through Embree's BVH (MR_SURFACE_TRAVERSAL=bvh, the behaviour before), forced
# into the depth-image walk (image) and chosen per photo (auto, the default), interleaved so all
# three share the machine's mood. Prints per photo the medians of wall s / CPU s / peak MiB and
# which forced run's output auto's equals (both, where the traversals agree on every pixel).
#
#   bench/compare_surface_traversal.sh MR [runs, default 3] [photos..., default below]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
mr=$(realpath "$1"); runs=${2:-3}; shift 2 || shift $#
gallery="$here/../gallery"
photos=("$@")
[[ ${#photos[@]} -gt 0 ]] || photos=("$gallery/tune/dragonfly.jpg" "$gallery/tune/bridge.jpg"
  "$gallery/heldout/picosdeeuropa.jpg" "$gallery/heldout/dune_pano.jpg"
  "$gallery/heldout/moss.jpg")
scratch=${SCRATCH:-/tmp/compare_surface_traversal}
mkdir -p "$scratch"
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
printf '%-22s %-26s %-26s %-26s %s\n' photo "auto (wall/CPU/MiB)" "image (forced)" \
  "bvh (forced, before)" "auto's output equals"
for photo in "${photos[@]}"; do
  stem=$(basename "${photo%.*}")
  rm -f "$scratch/$stem".times_*
  for ((i = 0; i < runs; ++i)); do
    for mode in auto image bvh; do
      MR_SURFACE_TRAVERSAL=$mode /usr/bin/time -f '%e %M %U %S' -a -o "$scratch/$stem.times_$mode" \
        "$mr" fog "$photo" --depth auto --scene "$gallery/looks/sun_bank.json" --backend cpu \
        --out-dir "$scratch/out_$mode" --overwrite --quiet > "$scratch/$stem.log" 2>&1
    done
  done
  cells=()
  for mode in auto image bvh; do
    t="$scratch/$stem.times_$mode"
    wall=$(awk '{print $1}' "$t" | median)
    cpu=$(awk '{print $3 + $4}' "$t" | median)
    mib=$(awk '{print int($2 / 1024)}' "$t" | median)
    cells+=("$wall / $cpu / $mib")
  done
  out="${stem}_fog.jpg"
  same=""
  cmp -s "$scratch/out_auto/$out" "$scratch/out_image/$out" && same="image"
  cmp -s "$scratch/out_auto/$out" "$scratch/out_bvh/$out" && same="${same:+$same and }bvh"
  printf '%-22s %-26s %-26s %-26s %s\n' "$stem" "${cells[0]}" "${cells[1]}" "${cells[2]}" "${same:-neither}"
done
