#!/bin/bash
# Here (no GPU): copy the data a sweep needs into .gpu/ (ignored by git; the device tool carries
# it with `carry: [".gpu"]`). ETH/UCY's leave-one-out folders repeat the same train/val files,
# so only the 16 distinct files travel (~2.7 MB); unpack_data.sh rebuilds the five folds there.
set -e
data=${TRAJPREF_DATA:?set TRAJPREF_DATA to the data folder}
repo=$(cd "$(dirname "$0")/../.." && pwd)
grep -qx "/.gpu/" "$repo/.git/info/exclude" 2>/dev/null || echo "/.gpu/" >> "$repo/.git/info/exclude"
mkdir -p "$repo/.gpu/pool" "$repo/.gpu/sdd" "$repo/.gpu/robo"
for f in "$data"/eth_ucy/*/train/*.txt "$data"/eth_ucy/*/val/*.txt; do cp -n "$f" "$repo/.gpu/pool/"; done
cp "$data"/sdd/*.npz "$repo/.gpu/sdd/"
cp "$data"/robo/val.npz "$repo/.gpu/robo/"  # Robo trains on the simulator; its test split stays here
du -sh "$repo/.gpu"
