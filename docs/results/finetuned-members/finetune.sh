#!/bin/bash
# Session 31: each member of models/hard-ensemble7.pt, 12 more minutes of its own recipe on the
# delayed-restart dynamics (hard.toml's default since session 30), step size 1e-4, one thread each,
# two at a time.
cd "$(dirname "$0")/../../.." && source .venv/bin/activate
BASE="--scenario hard --teacher-sight view --teacher-approach-speed 2 --teacher-approach-signs own --teacher-brake-for-blockers --teacher-wait-outside-zones --teacher-break-wait-cycles --gamma 0.998 --delay-max 30 --brake-weight 5 --reuse 1 --steps-per-round 2000 --buffer-samples 100000 --average-half-life 1000 --learning-rate 0.0001 --minutes 12 --threads 1"
extra() {
  case $1 in
    0|3) echo "" ;;
    2) echo "--blocker-weight 5" ;;
    1|5) echo "--blocker-weight 5 --priority-exponent 1" ;;
    4|6) echo "--standing-input --blocker-weight 5 --priority-exponent 1" ;;
  esac
}
run() {
  i=$1
  crossway pretrain $BASE $(extra $i) --init-from runs/members/m$i.pt --seed $((310+i)) --out runs/s31/ft-m$i > runs/s31/ft-m$i.log 2>&1
}
for pair in "0 1" "2 3" "4 5" "6"; do
  for i in $pair; do run $i & done
  wait
done
echo done > runs/s31/finetune.done
