#!/bin/bash
# Runs the same commands (scene, dataset of the procedural bed and of --scenes folders, a workflow gen with ControlNet + IP-Adapter + LoRA, img2img
# with weighted prompts, euler_a, eval, fid where INCEPTION names weights, refusals) with two vkdiff binaries, e.g. before and after a
# refactoring: every output file and stdout must be byte-identical; stderr differs in timings only.
# Usage: tools/compare_binaries.sh OLD_VKDIFF NEW_VKDIFF (from anywhere).
set -u
OLD=$(realpath "${1:?usage: tools/compare_binaries.sh OLD_VKDIFF NEW_VKDIFF}")
NEW=$(realpath "${2:?usage: tools/compare_binaries.sh OLD_VKDIFF NEW_VKDIFF}")
F=$(realpath "$(dirname "$0")/../tests/fixtures")
W=$(mktemp -d)
run() { # name, args...
  local name=$1; shift
  for v in old new; do
    local bin=$OLD; [ $v = new ] && bin=$NEW
    mkdir -p $W/$v
    (cd $W/$v && $bin "$@" > $W/$v/$name.stdout 2> $W/$v/$name.stderr; echo $? > $W/$v/$name.rc)
  done
}
run dataset dataset --out set --count 2 --crops 2 --crop-size 256 --steps 4 --prompt "white button mushrooms on dark black soil compost mycelium" --model $F/pipeline/tiny-sdxl --controlnet $F/workflow/controlnet
run workflow gen --model $F/pipeline/tiny-sdxl --prompt "mushrooms" --seed 7 --steps 3 --width 64 --height 64 --controlnet $F/workflow/controlnet --depth $F/workflow/control.png --ip-adapter $F/workflow/ip-adapter_tiny.safetensors --image-encoder $F/workflow/image_encoder --ip-image $F/workflow/style-1.png --lora $F/workflow/lora-peft.safetensors:0.7 --out wf.png --latents-out wf.safetensors
run img2img gen --model $F/pipeline/tiny-sdxl --prompt "a (mushroom:1.3) bed" --prompt-syntax weighted --seed 3 --steps 4 --sampler dpmpp_2m --scheduler karras --init-image $F/compat/init-64.png --strength 0.6 --out i2i.png
run ancestral gen --model $F/pipeline/tiny-sdxl --prompt "mushrooms on compost" --negative-prompt "blurry" --seed 11 --steps 3 --sampler euler_a --width 64 --height 64 --out a.png
run scenes dataset --out setsc --scenes $F/scenes/folders --crops 2 --crop-size 64 --steps 2 --seed 9 --prompt "fruit on a table" --model $F/pipeline/tiny-sdxl
run scene scene --out sc --seed 5 --width 640 --height 360
# FID needs Inception weights: INCEPTION=FILE (tests/fid_cli.rs writes random ones) runs it too.
[ -n "${INCEPTION:-}" ] && run fid fid --inception "$INCEPTION" $F/fid/real $F/fid/fake --batch 3 --json --cache-dir fidcache
run eval eval --gt $F/eval/gt.json --pred $F/eval/dt_segm.json --json
run evalbox eval --gt $F/eval/gt.json --pred $F/eval/dt_both.json --iou-type bbox
run badgen gen --model $F/pipeline/tiny-sdxl --prompt x --out nope/x.png
run baddataset dataset --out set2 --model $F/pipeline/tiny-sdxl --prompt x --batch 0
run badfid fid --inception /nonexistent $F/fid/real $F/fid/fake
echo "== files"
diff -r -q -x '*.stderr' $W/old $W/new && echo "all files and stdout identical"
same=$?
echo "== stderr differences (timings excluded)"
for f in $W/old/*.stderr; do n=$W/new/$(basename $f); diff <(grep -v " s\b\|s/step\|MiB\|/s\|loaded in\|made \|device:" $f) <(grep -v " s\b\|s/step\|MiB\|/s\|loaded in\|made \|device:" $n) > /dev/null || { echo "-- $(basename $f)"; diff <(grep -v " s\b\|s/step\|MiB\|/s\|loaded in\|made \|device:" $f) <(grep -v " s\b\|s/step\|MiB\|/s\|loaded in\|made \|device:" $n) | head -10; }; done
echo "work dir: $W"
exit $same
