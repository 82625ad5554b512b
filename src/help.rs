//! What `--help` prints after the flags: examples, the environment variables that apply, and
//! the exit codes, so a user learns the command from its help alone.

/// The exit codes, as `src/exit_code.rs` assigns them.
const EXIT_CODES: &str = "Exit codes: 0 done; 2 usage or bad input (flags, files, settings: do not retry); 3 the \
device (none, lost, hung, --require-gpu); 4 stopped, the same command resumes (disk full, a signal); 1 anything \
else.";

/// The variables every command that opens a Vulkan device reads.
const DEVICE_ENV: &str = "  VKDIFF_DEVICE          the device, as --device takes it
  VKDIFF_REQUIRE_GPU=1   refuse a CPU device (lavapipe), as --require-gpu
  VKDIFF_MEMORY_BUDGET   device memory vkdiff may use, e.g. 8G (plans the VAE, refuses past it)
  VKDIFF_SUBMIT_TIMEOUT  seconds a submission may run before the device counts as hung [60; CPU 600, lavapipe +1200 a kernel it compiles]
  VKDIFF_SUBMIT_GFLOP    matrix work per submission, lower for GPUs with a short watchdog
  VKDIFF_VALIDATE=1      run under the Khronos validation layer (for bug reports)";

/// Where model flags look for Hugging Face ids.
const HUB_ENV: &str = "  HF_HUB_CACHE, HF_HOME  where Hugging Face ids are found (else ~/.cache/huggingface/hub)";

pub fn gen() -> String {
    format!(
        "Examples:
  vkdiff gen -m stabilityai/stable-diffusion-xl-base-1.0 -p \"a red bicycle\" -o bike.png
  vkdiff gen -m sd_xl_base_1.0.safetensors --vae madebyollin/sdxl-vae-fp16-fix -p \"...\" -s 42 -o out.png
  vkdiff gen -m SDXL --controlnet diffusers/controlnet-depth-sdxl-1.0 --depth scene/depth.exr \\
      --ip-adapter h94/IP-Adapter/sdxl_models/ip-adapter_sdxl.safetensors \\
      --image-encoder h94/IP-Adapter/sdxl_models/image_encoder --ip-image style.jpg \\
      --lora mine.safetensors:0.8 -p \"white button mushrooms on dark compost\" -o out.png

Environment:
{DEVICE_ENV}
{HUB_ENV}

{EXIT_CODES}"
    )
}

pub fn dataset() -> String {
    format!(
        "Examples:
  vkdiff dataset --render-only --out beds --count 8 --crops 3 --crop-size 512   (no model, no GPU)
  vkdiff dataset preview beds && xdg-open beds/preview.html
  vkdiff dataset --out set --count 2000 --crops 3 --steps 30 -m stabilityai/stable-diffusion-xl-base-1.0 \\
      --controlnet diffusers/controlnet-depth-sdxl-1.0 --control-scale 0.5 --prompt \"white button mushrooms\"
  vkdiff dataset --out set ... --shard 3/8          (one process of eight; the same command resumes)
  vkdiff dataset export set --format yolo --out set-yolo

Environment (also: SLURM_ARRAY_TASK_ID/MIN/COUNT and, with --shards, JOB_COMPLETION_INDEX pick the shard):
{DEVICE_ENV}
{HUB_ENV}

{EXIT_CODES}"
    )
}

pub fn eval() -> String {
    format!(
        "Examples:
  vkdiff eval --gt annotations.json --pred detections.json
  vkdiff eval --gt annotations.json --pred boxes.json --iou-type bbox --json > scores.json
  vkdiff eval --gt annotations.json --pred poses.json --iou-type keypoints

{EXIT_CODES}"
    )
}

pub fn fid() -> String {
    format!(
        "Examples (the Inception weights: torch-fidelity's weights-inception-2015-12-05-6726825d.pth):
  vkdiff fid real/ set/images --inception weights-inception-2015-12-05-6726825d.pth
  vkdiff fid real/ set/images --inception pt_inception.pth --cache --kid-subset-size 100 --json

Environment:
{DEVICE_ENV}

{EXIT_CODES}"
    )
}

pub fn bench() -> String {
    format!(
        "Examples (real architectures with random weights: nothing to download):
  vkdiff bench report --out my-gpu.json                     (the whole suite: the paper's image first)
  vkdiff bench report --quick --out lavapipe.json           (the small suite, minutes on a CPU device)
  vkdiff bench compare h200.json my-gpu.json --markdown --html compare.html
  vkdiff bench unet --size 1024 --reference-device cuda     (beside diffusers on the same GPU)
  vkdiff bench dataset --size 1024 --steps 30               (the paper's image, end to end)
  vkdiff bench kernels --filter linear --no-cpu-reference
  vkdiff bench vae --size 1024 --precision f16

Environment:
{DEVICE_ENV}
  VKDIFF_REFERENCE_PYTHON  the Python that runs the references (torch, diffusers) [python3]
  VKDIFF_COOPERATIVE=0   leave the matrix units out (the tiled kernels alone)

{EXIT_CODES}"
    )
}

pub fn top() -> String {
    format!(
        "Start with: vkdiff dataset --render-only --out beds --count 4 --crops 2 --crop-size 512, then
vkdiff dataset preview beds. Each command's --help has examples.

{EXIT_CODES}"
    )
}
