#!/bin/bash
# Automatic fog (`mr fog --depth auto`) on camera-size photos: the photo's own size
# (--working-size 0) against the working size (the default), as whole processes, alternating
# (the order flipped each pair), medians of wall time and peak memory (/usr/bin/time).
#
#   bench/compare_auto_fog.sh MR LOOK PAIRS PHOTO...
#     MR     the mr binary (e.g. build/cli/mr)
#     LOOK   a scene file, e.g. gallery/looks/haze.json
#     PAIRS  runs of each (e.g. 3)
#
# The photos of the README's table are originals of gallery/tune photos, from Debian 12
# packages (gallery/manifest.csv names them): `apt-get download lomiri-wallpapers-16.04
# plasma-workspace-wallpapers && dpkg -x <deb> root`, then e.g.
#   root/usr/share/wallpapers/Kite/contents/images/2560x1600.jpg            (4.1 MP)
#   root/usr/share/backgrounds/sunset_by_Aitzol_Berasategi.jpg              (12.2 MP)
#   root/usr/share/backgrounds/Kleiber_by_Lukas_Baubkus.jpg                 (20.4 MP, 20.04 set)
set -euo pipefail
mr=$1 look=$2 pairs=$3
shift 3
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
run() {  # run PHOTO SIZE -> "wall_s peak_mib"
  /usr/bin/time -f "%e %M" -o "$out/t" "$mr" fog "$1" --depth auto --scene "$look" \
    --out-dir "$out/o" --overwrite -q --working-size "$2" >/dev/null
  awk '{printf "%.2f %.0f\n", $1, $2 / 1024}' "$out/t"
}
median() { sort -n | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
printf "| photo | size | own size: wall s | peak MiB | working size: wall s | peak MiB |\n"
printf "|---|---|---|---|---|---|\n"
for photo in "$@"; do
  : >"$out/full"
  : >"$out/work"
  for ((i = 0; i < pairs; i++)); do
    if ((i % 2 == 0)); then
      run "$photo" 0 >>"$out/full"
      run "$photo" 1280 >>"$out/work"
    else
      run "$photo" 1280 >>"$out/work"
      run "$photo" 0 >>"$out/full"
    fi
  done
  size=$(oiiotool --info "$photo" | sed -E 's/.*: *([0-9]+) x +([0-9]+).*/\1x\2/')
  printf "| %s | %s | %s | %s | %s | %s |\n" "$(basename "$photo")" "$size" \
    "$(cut -d' ' -f1 "$out/full" | median)" "$(cut -d' ' -f2 "$out/full" | median)" \
    "$(cut -d' ' -f1 "$out/work" | median)" "$(cut -d' ' -f2 "$out/work" | median)"
done
