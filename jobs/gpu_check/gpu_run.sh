#!/bin/sh
# The prepared GPU call (docs/gpu.md): from the device's bare image, install the carried bundle offline, make sray
# importable from this checkout, run the plan's gpu-check stages that are not yet in the report while the time
# budget lasts, and write what the next call needs to resume under $OUT (5 files).
#
#   OUT      where the results go (the device's $OUT)                               required
#   BUNDLE   the wheel folder `make gpu-bundle` wrote                               default outputs/gpu-bundle
#   RESUME   a folder holding an earlier call's gpu_check.json (and gpu-run.tar)    default .gpu-resume
#   BUDGET_S seconds this call may spend on stages (a stage is started only when    default 540
#            its estimate below fits in what is left; the next call resumes)
#   STAGES   the stages, in order                                                   default the plan below
#   DRY_RUN  1: every stage on the CPU at toy sizes (how the suite tests this)      default 0
#   PYTHON   the interpreter                                                        default python3
#   WORK     scratch folder (site packages, the report, the stages' files)          default /tmp/sray-gpu-run
set -eu
repo=$(cd "$(dirname "$0")/../.." && pwd)
out=${OUT:?set OUT to the folder the results go to}
bundle=${BUNDLE:-$repo/outputs/gpu-bundle}
resume=${RESUME:-$repo/.gpu-resume}
budget=${BUDGET_S:-540}
stages=${STAGES:-"environment ray fleet minutes"}
python=${PYTHON:-python3}
work=${WORK:-/tmp/sray-gpu-run}
start=$(date +%s)
mkdir -p "$out" "$work/check"
log="$out/gpu-run.log"
touch "$work/started"

estimate() {  # seconds a stage takes on one H100/H200 (what the budget is checked against)
    case $1 in environment) echo 20 ;; tests) echo 120 ;; ray) echo 150 ;; fleet) echo 150 ;; minutes) echo 480 ;;
               *) echo 120 ;; esac
}

say() { echo "[gpu-run $(( $(date +%s) - start )) s] $*" | tee -a "$log"; }

if [ ! -f "$bundle/install.sh" ]; then
    say "no bundle at $bundle: run make gpu-bundle on the CPU machine and carry outputs/gpu-bundle"; exit 2
fi
PYTHON=$python sh "$bundle/install.sh" "$work/site" >>"$log" 2>&1 || { say "bundle install failed (see $log)"; exit 2; }
mkdir -p "$work/path/sray"
for part in model data_tools platform jobs; do ln -sfn "$repo/$part" "$work/path/sray/$part"; done
export PYTHONPATH="$work/site:$work/path" RAY_USAGE_STATS_ENABLED=0 PYTHONUNBUFFERED=1
if [ -f "$resume/gpu_check.json" ] || [ -f "$resume/gpu-run.tar" ]; then
    if [ -f "$resume/gpu-run.tar" ]; then tar -xf "$resume/gpu-run.tar" -C "$work/check"; fi
    if [ -f "$resume/gpu_check.json" ]; then cp "$resume/gpu_check.json" "$work/check/"; fi
    say "resuming: $(cd "$work/check" && "$python" -c 'import json; print(", ".join(json.load(open("gpu_check.json"))["stages"]) or "nothing")') already done"
fi
say "bundle installed; stages: $stages; budget $budget s"

dry=""; [ "${DRY_RUN:-0}" = 1 ] && dry="--dry-run"
status=0
for stage in $stages; do
    done_already=$(cd "$work/check" && "$python" -c "import json, sys; print(sys.argv[1] in json.load(open('gpu_check.json'))['stages'])" "$stage" 2>/dev/null || echo False)
    if [ "$done_already" = True ]; then say "$stage: already in the report"; continue; fi
    left=$(( budget - ($(date +%s) - start) ))
    need=$(estimate "$stage"); [ -n "$dry" ] && need=0
    if [ "$left" -lt "$need" ]; then
        say "$stage needs about $need s and $left s are left: stopping here; call again with RESUME holding this call's files"
        break
    fi
    say "$stage ..."
    timeout "$(( left > 1 ? left : 1 ))" "$python" -m sray.jobs.cli gpu-check $dry --stages "$stage" \
        --out "$work/check" >>"$log" 2>&1 || status=1
    say "$stage: $(cd "$work/check" && "$python" -c "import json, sys; r = json.load(open('gpu_check.json'))['stages'].get(sys.argv[1]); print(r['status'] + ': ' + r['summary'] if r else 'stopped by the time limit')" "$stage")"
done

# What comes back: the report, the log, one tar of the stages' small files (the resume state; no shards,
# checkpoints or videos) and one of the docs files the GPU stages rewrote (docs.tar: untar it in the checkout).
cp "$work/check/gpu_check.json" "$out/" 2>/dev/null || true
cp "$work/check/gpu_check.md" "$out/" 2>/dev/null || true
(cd "$work/check" && find . -type f \( -name '*.json' -o -name '*.md' -o -name '*.log' -o -name '*.csv' -o -name '*.png' \) \
    -not -path '*/shards/*' -not -path '*/scenes/*' -not -path '*/checkpoints/*' -not -path '*/renders/*' -not -path '*/mlruns/*' -size -2M \
    | tar -cf "$out/gpu-run.tar" -T -)
(cd "$repo" && find docs -type f -newer "$work/started" | tar -cf "$out/docs.tar" -T -)
say "done: $(ls "$out" | tr '\n' ' ')"
exit $status
