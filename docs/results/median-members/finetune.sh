#!/bin/bash
# Session 33: each member of session 31's ens7ft (runs/s31/ft-m*: the averaged weights of m0-m4, the last
# weights of m5 and m6, as ens7ft joins them), 8 more minutes of its own recipe with the acceleration
# mean fitted by its absolute error (--acceleration-loss absolute: the median of the teacher's labels),
# at the default step size, one thread each, two at a time.
cd "$(dirname "$0")/../../.." && source .venv/bin/activate
BASE="--scenario hard --teacher-sight view --teacher-approach-speed 2 --teacher-approach-signs own --teacher-brake-for-blockers --teacher-wait-outside-zones --teacher-break-wait-cycles --gamma 0.998 --delay-max 30 --brake-weight 5 --reuse 1 --steps-per-round 2000 --buffer-samples 100000 --average-half-life 1000 --acceleration-loss absolute --minutes 8 --threads 1"
extra() {
  case $1 in
    0|3) echo "" ;;
    2) echo "--blocker-weight 5" ;;
    1|5) echo "--blocker-weight 5 --priority-exponent 1" ;;
    4|6) echo "--standing-input --blocker-weight 5 --priority-exponent 1" ;;
  esac
}
start() {
  case $1 in
    5|6) echo "runs/s31/ft-m$1/pretrained-last.pt" ;;
    *) echo "runs/s31/ft-m$1/pretrained.pt" ;;
  esac
}
run() {
  i=$1
  crossway pretrain $BASE $(extra $i) --init-from $(start $i) --seed $((330+i)) --out runs/s33/md-m$i > runs/s33/md-m$i.log 2>&1
}
for pair in "0 1" "2 3" "4 5" "6"; do
  for i in $pair; do run $i & done
  wait
done
echo done > runs/s33/median.done
