#!/bin/bash
# On the GPU machine: rebuild <root>/eth_ucy/<fold>/{train,val} from .gpu/pool (each fold holds
# out its own scenes' files, as the Social-GAN leave-one-out folders do) and <root>/sdd.
set -e
root=${1:-/tmp/data}
repo=$(cd "$(dirname "$0")/../.." && pwd)
declare -A held=([eth]="biwi_eth" [hotel]="biwi_hotel" [univ]="students001 students003"
                 [zara1]="crowds_zara01" [zara2]="crowds_zara02")
for fold in eth hotel univ zara1 zara2; do
  for split in train val; do
    d=$root/eth_ucy/$fold/$split; mkdir -p "$d"
    for f in "$repo"/.gpu/pool/*_$split.txt; do
      b=$(basename "$f"); skip=0
      for h in ${held[$fold]}; do [[ $b == ${h}_* ]] && skip=1; done
      [[ $skip == 0 ]] && cp "$f" "$d/"
    done
  done
  mkdir -p "$root/eth_ucy/$fold/test"  # test splits are read here, on the CPU, never there
done
mkdir -p "$root/sdd" && cp "$repo"/.gpu/sdd/* "$root/sdd/"
if [ -d "$repo/.gpu/robo" ]; then mkdir -p "$root/robo" && cp "$repo"/.gpu/robo/* "$root/robo/"; fi
