#!/usr/bin/env bash
# The control baselines trained on part of the dev split and measured on episodes nothing in
# their training saw (docs/measured/baseline-gates.md). Two stages, each a separate GPU lease if need be:
#
#   STAGE=train bash starter-kit/baselines/held_out.sh   # camera + privileged runs -> $RUN/{cam,priv}
#   STAGE=eval  bash starter-kit/baselines/held_out.sh   # both gates on the held-out episodes -> $RUN/results
#   STAGE=all   bash starter-kit/baselines/held_out.sh   # one, then the other
#
# Long: start it detached (`setsid nohup ... &`) and follow $RUN/held_out.log.
#
# What is held out:
# - training (both baselines): dev instructions TRAIN_INSTRUCTIONS (1-100) with collection seed 1
#   and DAgger rounds drawn from the same instructions; the final checkpoint is used (none is
#   chosen by evaluation, so no selection set is needed);
# - evaluation: dev instructions 101-163 with batch seed EVAL_SEED (2: neither training nor the
#   60-episode dev gate, seed 0, used it), and the first 100 test-split instructions with the
#   organiser's ground truth; the gate is judged on both together (each kind >= 100 tasks).
#
# Settings (environment): RUN [/tmp/kr-held-out], TRAIN_INSTRUCTIONS [1-100], EVAL_SEED [2],
# EVAL_DEV [101-163] / EVAL_TEST [1-100] (the held-out ranges), EVAL [cam priv] (which gates),
# CAM_ARGS / PRIV_ARGS (extra train.py arguments; the privileged run is done before the camera
# run's rounds start, so CAM_ARGS="--teacher $RUN/priv/ckpt.pt --beta B" lets it drive a share of
# them), JOBS [16], DEVICE [cuda], CAM_CKPT /
# PRIV_CKPT / DIFF_CKPT (evaluate these checkpoints instead of $RUN's), TRAIN [cam priv] (which
# baselines to train: cam, priv, diff), PRIV_JOBS [4] (the privileged gate's jobs: its gate runs
# beside the camera's, which takes JOBS). The diffusion baseline (TRAIN=diff, EVAL=diff) trains
# through its own pipeline (diffusion_policy/device_pipeline.sh, STOP_AFTER=train) on episodes
# of TRAIN_INSTRUCTIONS; DIFF_EPISODES [1000] and DIFF_MINUTES [10] set its data and time. On a machine of several GPUs,
# give each run its own with CUDA_VISIBLE_DEVICES and RUN, or give one gate several: GPUS [1] = 2
# runs the dev and test parts side by side, one GPU and one served policy each (JOBS jobs each),
# GPUS = 4 each part's halves (for a slow policy's gate, the diffusion baseline's: "Run 6" in
# docs/measured/baseline-gates.md); one EVAL at a time then.
# Needs python3 with the baselines installed (pip install -e ./starter-kit -e "./starter-kit/baselines[control]"
# and ./python; on a GPU machine of the developers' `device` tool, device_setup.sh links them).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
cd "$REPO"
RUN="${RUN:-/tmp/kr-held-out}"
TRAIN_INSTRUCTIONS="${TRAIN_INSTRUCTIONS:-1-100}"
EVAL_SEED="${EVAL_SEED:-2}"
EVAL_DEV="${EVAL_DEV:-101-163}"
EVAL_TEST="${EVAL_TEST:-1-100}"
JOBS="${JOBS:-16}"
DEVICE="${DEVICE:-cuda}"
STAGE="${STAGE:?set STAGE=train, eval or all}"
mkdir -p "$RUN"
exec > >(tee -a "$RUN/held_out.log") 2>&1
say() { echo "[held_out $(date +%H:%M:%S)] $*"; }

train() {
  local cam="" want=" ${TRAIN:-cam priv} "
  if [[ $want == *" cam "* ]]; then
    say "camera baseline: dev $TRAIN_INSTRUCTIONS"
    # shellcheck disable=SC2086
    (cd "$HERE/camera" && python3 train.py --out "$RUN/cam" --instructions "$TRAIN_INSTRUCTIONS" --device "$DEVICE" \
       --workers "$JOBS" --envs "$JOBS" ${CAM_ARGS:-}) >"$RUN/cam.log" 2>&1 &
    cam=$!
    # The privileged run starts once the camera run's behaviour cloning holds the GPU and leaves
    # the CPUs to it (its own expert stream renders no image).
    while kill -0 $cam 2>/dev/null && ! grep -q "^\[.*\] bc: " "$RUN/cam.log" 2>/dev/null; do sleep 5; done
  fi
  if [[ $want == *" priv "* ]]; then
    say "privileged baseline: dev $TRAIN_INSTRUCTIONS"
    # shellcheck disable=SC2086
    python3 "$HERE/privileged/train.py" --out "$RUN/priv" --instructions "$TRAIN_INSTRUCTIONS" --device "$DEVICE" \
      --workers "$JOBS" --envs "$JOBS" ${PRIV_ARGS:-} >"$RUN/priv.log" 2>&1 || say "privileged run failed (see priv.log)"
  fi
  if [[ $want == *" diff "* ]]; then
    say "diffusion baseline: dev $TRAIN_INSTRUCTIONS"
    KR_BIN="${KITCHEN_R_BIN:-$REPO/target/release/kitchen-r}" WORK="$RUN/diff" STOP_AFTER=train TRAIN_INSTRUCTIONS="$TRAIN_INSTRUCTIONS" \
      EPISODES="${DIFF_EPISODES:-1000}" TRAIN_MIN="${DIFF_MINUTES:-10}" DEVICE="$DEVICE" \
      bash "$HERE/diffusion_policy/device_pipeline.sh" >"$RUN/diff.log" 2>&1 || say "diffusion run failed (see diff.log)"
  fi
  if [ -n "$cam" ]; then wait $cam || { say "camera run failed (see cam.log)"; exit 1; }; fi
  say "trained: $(ls -la "$RUN"/cam/ckpt.pt "$RUN"/priv/ckpt.pt "$RUN"/diff/results/ckpt.pt 2>&1 | tr '\n' ' ')"
}

CAM_CKPT="${CAM_CKPT:-$RUN/cam/ckpt.pt}"
PRIV_CKPT="${PRIV_CKPT:-$RUN/priv/ckpt.pt}"
DIFF_CKPT="${DIFF_CKPT:-$RUN/diff/results/ckpt.pt}"
# Halves of a 1-based inclusive range A-B when asked for 2 or more parts (else the range).
halves() {
  local a=${1%-*} b=${1#*-}
  if [ "$2" -lt 2 ] || [ "$a" -ge "$b" ]; then echo "$1"; return; fi
  local m=$(((a + b) / 2))
  echo "$a-$m $((m + 1))-$b"
}
gate() {  # name track serve-command train-log jobs
  local name=$1 track=$2 serve=$3 log=$4 jobs=$5
  local out="$RUN/results/$name"
  # GPUS > 1: the held-out parts run side by side, one GPU (and its own served policy) each:
  # 2 GPUs take dev and test, 4 take each one's halves. Episode seeds are per instruction, so
  # the episodes are those of one run over the whole ranges.
  local gpus=${GPUS:-1} parts=() pids=() dirs=() i=0 failed=0 p s r
  for r in $(halves "$EVAL_DEV" $((gpus / 2))); do parts+=("dev:$r"); done
  for r in $(halves "$EVAL_TEST" $((gpus / 2))); do parts+=("test:$r"); done
  for p in "${parts[@]}"; do
    s=${p%%:*} r=${p#*:}
    dirs+=("$out/$s-$r")
    if [ "$gpus" -gt 1 ]; then
      CUDA_VISIBLE_DEVICES=$((i % gpus)) python3 "$HERE/gate.py" --track "$track" --out "$out/$s-$r" --split "$s" \
        --instructions "$r" --seed "$EVAL_SEED" --held-out --no-offline --jobs "$jobs" --train-log "$log" --serve "$serve" &
      pids+=($!)
    else
      python3 "$HERE/gate.py" --track "$track" --out "$out/$s-$r" --split "$s" --instructions "$r" \
        --seed "$EVAL_SEED" --held-out --no-offline --jobs "$jobs" --train-log "$log" --serve "$serve"
    fi
    i=$((i + 1))
  done
  for p in "${pids[@]}"; do wait "$p" || failed=1; done
  [ "$failed" = 0 ] || { say "a part of the $name gate failed"; return 1; }
  python3 "$HERE/gate.py" --track "$track" --out "$out" --train-log "$log" --combine "${dirs[@]}"
}
evaluate() {
  # The gates run side by side: the privileged one is light (no images) and done well before.
  local pids=()
  for which in ${EVAL:-cam priv}; do
    case $which in
      cam) gate camera standard "python3 $HERE/camera/serve.py --checkpoint $CAM_CKPT --listen 127.0.0.1:0 --device $DEVICE" \
             "$(dirname "$CAM_CKPT")/train_log.json" "$JOBS" & pids+=($!) ;;
      priv) { gate privileged privileged "python3 $HERE/privileged/serve.py --checkpoint $PRIV_CKPT --listen 127.0.0.1:0" \
             "$(dirname "$PRIV_CKPT")/train_log.json" "${PRIV_JOBS:-4}" || say "privileged gate failed"; } & pids+=($!) ;;
      diff) gate diffusion standard "python3 $HERE/diffusion_policy/serve.py --checkpoint $DIFF_CKPT --listen 127.0.0.1:0 --device $DEVICE --concurrency $JOBS" \
             "$(dirname "$DIFF_CKPT")/train_log.json" "$JOBS" & pids+=($!) ;;
      *) echo "EVAL=$which: use cam, priv and/or diff" >&2; exit 2 ;;
    esac
  done
  local failed=0
  for p in "${pids[@]}"; do wait "$p" || failed=1; done
  say "done: $RUN/results"
  return $failed
}

case $STAGE in
  train) train ;;
  eval) evaluate ;;
  all) train && evaluate ;;
  *) echo "STAGE=$STAGE: use train, eval or all" >&2; exit 2 ;;
esac
