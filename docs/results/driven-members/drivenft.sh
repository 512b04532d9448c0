#!/bin/bash
# Session 32: each member of ens7ft (session 31), 12 more minutes of its own recipe with the episodes the
# student would drive driven by ens7ft itself (--driver-checkpoint): DAgger on the ensemble's states.
cd "$(git rev-parse --show-toplevel)" && source .venv/bin/activate
BASE="--scenario hard --teacher-sight view --teacher-approach-speed 2 --teacher-approach-signs own --teacher-brake-for-blockers --teacher-wait-outside-zones --teacher-break-wait-cycles --gamma 0.998 --delay-max 30 --brake-weight 5 --reuse 1 --steps-per-round 2000 --buffer-samples 100000 --average-half-life 1000 --learning-rate 0.0001 --minutes 12 --threads 1 --driver-checkpoint runs/s31/ens7ft.pt"
extra() {
  case $1 in
    0|3) echo "" ;;
    2) echo "--blocker-weight 5" ;;
    1|5) echo "--blocker-weight 5 --priority-exponent 1" ;;
    4|6) echo "--standing-input --blocker-weight 5 --priority-exponent 1" ;;
  esac
}
start() {  # the file of ens7ft's member i
  case $1 in 0|1|2|3|4) echo runs/s31/ft-m$1/pretrained.pt ;; 5|6) echo runs/s31/ft-m$1/pretrained-last.pt ;; esac
}
run() {
  i=$1
  crossway pretrain $BASE $(extra $i) --init-from $(start $i) --seed $((320+i)) --out runs/s32/dv-m$i > runs/s32/dv-m$i.log 2>&1
}
for pair in "0 1" "2 3" "4 5" "6"; do
  for i in $pair; do run $i & done
  wait
done
echo done > runs/s32/drivenft.done
