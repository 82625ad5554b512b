//! The flags `vkdiff gen` and `vkdiff dataset` share: the model with its guides and LoRAs, and
//! how images are sampled.

use crate::hub::{resolve_model, Wants};
use crate::scene::ControlMode;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use vkdiff_pipeline::{
    ControlNetSettings, IpAdapterSettings, IpMode, IpScale, LoraSetting, ModelSettings, PredictionType, PromptSyntax,
    SamplerKind, Sampling, ScheduleOptions, SizeConditioning, TimestepSpacing, VaeTilingSetting,
};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::{Dtype, Environment};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Precision {
    /// f16 storage, f32 arithmetic (the VAE stays f32 where it would overflow).
    F16,
    F32,
}

impl Precision {
    pub fn dtype(self) -> Dtype {
        match self {
            Precision::F16 => Dtype::F16,
            Precision::F32 => Dtype::F32,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq)]
enum Schedule {
    /// The model's scheduler_config.json as it is.
    Default,
    /// Karras et al. noise levels (euler, dpmpp_2m).
    Karras,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum SyntaxArg {
    Plain,
    Weighted,
}

impl From<SyntaxArg> for PromptSyntax {
    fn from(s: SyntaxArg) -> PromptSyntax {
        match s {
            SyntaxArg::Plain => PromptSyntax::Plain,
            SyntaxArg::Weighted => PromptSyntax::Weighted,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum IpModeArg {
    Style,
    Composition,
    #[value(name = "style+composition")]
    StyleAndComposition,
}

/// The model, its guides and LoRAs: what loads once.
#[derive(Args, Debug)]
pub struct ModelArgs {
    /// SDXL model: a diffusers folder, an original single-file checkpoint, or a Hugging Face id
    /// found offline in its cache (ORG/NAME[@REVISION][/FILE]; never downloaded).
    #[arg(short = 'm', long, required = true, value_name = "DIR|FILE|ID")]
    model: Option<PathBuf>,
    /// A VAE in place of the model's: a diffusers AutoencoderKL folder, or a single file in the
    /// diffusers or original layout (a config.json beside it is read), or a Hugging Face id, such
    /// as madebyollin/sdxl-vae-fp16-fix, whose config lets it decode in f16.
    #[arg(long, value_name = "DIR|FILE|ID")]
    vae: Option<PathBuf>,
    /// A UNet in place of the model's, as diffusers' `unet=`: SDXL-Lightning's
    /// sdxl_lightning_Nstep_unet.safetensors, DMD2's dmd2_sdxl_4step_unet_fp16.bin; one file of the
    /// model's UNet architecture (diffusers or original names; .safetensors, or a torch .bin/.pth),
    /// a diffusers UNet folder, or a Hugging Face id (ORG/NAME/FILE).
    #[arg(long, value_name = "DIR|FILE|ID")]
    unet: Option<PathBuf>,
    /// f16: f16 storage, f32 arithmetic, the matrix units where the GPU has them; f32 throughout
    /// (slower; for reference checks). A VAE whose config forces upcasting decodes in f32 either way.
    #[arg(long, value_enum, default_value_t = Precision::F16)]
    precision: Precision,
    #[command(flatten)]
    pub device: crate::DeviceArgs,
    /// The VAE decode: auto (whole where it fits the device's free memory, else in the largest
    /// diffusers tiles that fit), off (whole, or fail before denoising), on (tiles of the VAE's
    /// sample_size, as diffusers' enable_tiling) or a tile side in pixels. Tiled images differ
    /// slightly from whole ones; PNGs record the tile as `vae_tile`.
    #[arg(long, default_value = "auto", value_name = "auto|off|on|PIXELS")]
    vae_tiling: VaeTilingSetting,
    /// A ControlNet: a diffusers folder, or one .safetensors in the diffusers or original (cldm)
    /// layout, or a Hugging Face id; plain, or ControlNet-Union (xinsir's). Repeat it for several,
    /// whose residuals are summed. Each may say which scene control it sees (depth, edges,
    /// segmentation, normals; a Union model several: control=depth+edges) [default: depth], and
    /// its own scale and range [default: --control-scale, --control-start, --control-end].
    #[arg(long, value_parser = parse_controlnet, value_name = "MODEL[,control=KIND[+KIND]][,scale=S][,start=F][,end=F]")]
    controlnet: Vec<ControlNetArg>,
    /// How a depth EXR maps to brightness (near is bright either way).
    #[arg(long, value_enum, default_value_t = ControlMode::Inverse)]
    control_depth: ControlMode,
    /// Multiplies the ControlNet's residuals (diffusers' controlnet_conditioning_scale).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    control_scale: f32,
    /// Fraction of the steps before which the ControlNet is off.
    #[arg(long, default_value_t = 0.0)]
    control_start: f64,
    /// Fraction of the steps after which the ControlNet is off.
    #[arg(long, default_value_t = 1.0)]
    control_end: f64,
    /// IP-Adapter for SDXL (h94 layout, .safetensors, plain or plus), or a Hugging Face id
    /// (h94/IP-Adapter/sdxl_models/ip-adapter_sdxl.safetensors): style images steer the look.
    #[arg(long, requires = "image_encoder", value_name = "FILE|ID")]
    ip_adapter: Option<PathBuf>,
    /// The adapter's CLIP vision encoder: a folder with config.json and model.safetensors
    /// (and preprocessor_config.json, else CLIP's defaults at the encoder's image size), or a
    /// Hugging Face id (h94/IP-Adapter/sdxl_models/image_encoder).
    #[arg(long, requires = "ip_adapter", value_name = "DIR|ID")]
    image_encoder: Option<PathBuf>,
    /// Weight of the image tokens' attention [default: 1]: one number for every layer, or
    /// BLOCK=SCALE (repeat it) for chosen blocks with every other layer 0, as diffusers'
    /// set_ip_adapter_scale({...}): mid, down.I, up.I, or down.I.J / up.I.J (attention J of
    /// block I). `--ip-scale up.0.1=1` is InstantStyle's style-only adapter.
    #[arg(long, allow_negative_numbers = true)]
    ip_scale: Vec<String>,
    /// InstantStyle's blocks of SDXL: style (up.0.1), composition (down.2.1) or both, each at
    /// --ip-scale (one number); every other layer is off.
    #[arg(long, value_enum, requires = "ip_adapter")]
    ip_mode: Option<IpModeArg>,
    /// A LoRA (kohya or diffusers/PEFT .safetensors, or a Hugging Face id) as FILE or
    /// FILE:STRENGTH (default 1); repeat it for several. Merged into the weights on the device.
    #[arg(long, value_parser = parse_lora, value_name = "FILE[:STRENGTH]")]
    lora: Vec<LoraSetting>,
}

/// One `--controlnet`: the model and what it sets beside the shared flags.
#[derive(Clone, Debug)]
pub struct ControlNetArg {
    model: PathBuf,
    controls: Vec<ControlKind>,
    scale: Option<f32>,
    start: Option<f64>,
    end: Option<f64>,
}

/// `MODEL[,control=KIND[+KIND]][,scale=S][,start=F][,end=F]`; the options come last, so a path
/// with a comma in it stays whole.
pub fn parse_controlnet(text: &str) -> Result<ControlNetArg, String> {
    let mut parts: Vec<&str> = text.split(',').collect();
    let mut arg = ControlNetArg { model: PathBuf::new(), controls: Vec::new(), scale: None, start: None, end: None };
    let number = |key: &str, value: &str| value.parse::<f64>().map_err(|_| format!("{key}={value} is not a number"));
    while parts.len() > 1 {
        let last = parts[parts.len() - 1];
        let Some((key, value)) = last.split_once('=') else { break };
        match key.trim() {
            "control" => {
                arg.controls = (value.split('+'))
                    .map(|name| {
                        ControlKind::parse(name).ok_or_else(|| {
                            let kinds: Vec<&str> = ControlKind::ALL.iter().map(|k| k.name()).collect();
                            format!("control={name}: expected one of {}", kinds.join(", "))
                        })
                    })
                    .collect::<Result<_, _>>()?
            }
            "scale" => arg.scale = Some(number(key, value)? as f32),
            "start" => arg.start = Some(number(key, value)?),
            "end" => arg.end = Some(number(key, value)?),
            _ => break,
        }
        parts.pop();
    }
    let model = parts.join(",");
    if model.is_empty() {
        return Err("expected MODEL[,control=KIND[+KIND]][,scale=S][,start=F][,end=F]".into());
    }
    arg.model = model.into();
    Ok(arg)
}

/// `FILE[:STRENGTH]`; a colon whose tail is not a number belongs to the path.
pub fn parse_lora(text: &str) -> Result<LoraSetting, String> {
    let (path, strength) = match text.rsplit_once(':').map(|(p, s)| (p, s.parse::<f32>())) {
        Some((p, Ok(s))) if s.is_finite() => (p, s),
        _ => (text, 1.0),
    };
    if path.is_empty() {
        return Err("expected FILE or FILE:STRENGTH".into());
    }
    Ok(LoraSetting { path: path.into(), strength })
}

impl ModelArgs {
    /// How depth becomes a control image.
    pub fn control_depth(&self) -> vkdiff_pipeline::images::ControlDepth {
        self.control_depth.into()
    }

    /// The first flag given that names a model (a render-only set takes none).
    pub fn model_flag_given(&self) -> Option<&'static str> {
        [
            ("model", self.model.is_some()),
            ("vae", self.vae.is_some()),
            ("unet", self.unet.is_some()),
            ("controlnet", !self.controlnet.is_empty()),
            ("ip_adapter", self.ip_adapter.is_some()),
            ("lora", !self.lora.is_empty()),
        ]
        .into_iter()
        .find_map(|(flag, given)| given.then_some(flag))
    }

    /// The settings, every model named by a path or a Hugging Face id resolved to its files (in
    /// the cache `env` points to).
    pub fn settings(&self, env: &Environment) -> anyhow::Result<ModelSettings> {
        let resolve = |flag: &str, path: &PathBuf, wants| resolve_model(&format!("--{flag}"), path, wants, env);
        let controlnets = (self.controlnet.iter())
            .map(|c| {
                Ok(ControlNetSettings {
                    model: resolve("controlnet", &c.model, Wants::Either)?,
                    controls: if c.controls.is_empty() { vec![ControlKind::Depth] } else { c.controls.clone() },
                    depth_mode: self.control_depth.into(),
                    scale: c.scale.unwrap_or(self.control_scale),
                    start: c.start.unwrap_or(self.control_start),
                    end: c.end.unwrap_or(self.control_end),
                })
            })
            .collect::<anyhow::Result<_>>()?;
        let mode = self.ip_mode.map(|m| match m {
            IpModeArg::Style => IpMode::Style,
            IpModeArg::Composition => IpMode::Composition,
            IpModeArg::StyleAndComposition => IpMode::StyleAndComposition,
        });
        let scale = IpScale::parse(&self.ip_scale, mode)?;
        let ip_adapter = match (&self.ip_adapter, &self.image_encoder) {
            (Some(adapter), Some(encoder)) => Some(IpAdapterSettings {
                adapter: resolve("ip-adapter", adapter, Wants::File)?,
                encoder: resolve("image-encoder", encoder, Wants::Folder)?,
                scale,
            }),
            _ => None,
        };
        // Required by the parser wherever these flags are read (not for `dataset merge`).
        let model = self.model.as_ref().map(|m| resolve("model", m, Wants::Either)).transpose()?.unwrap_or_default();
        let loras = (self.lora.iter())
            .map(|l| Ok(LoraSetting { path: resolve("lora", &l.path, Wants::File)?, strength: l.strength }))
            .collect::<anyhow::Result<_>>()?;
        Ok(ModelSettings {
            model,
            vae: self.vae.as_ref().map(|v| resolve("vae", v, Wants::Either)).transpose()?,
            unet: self.unet.as_ref().map(|u| resolve("unet", u, Wants::Either)).transpose()?,
            precision: self.precision.dtype(),
            controlnets,
            ip_adapter,
            loras,
            vae_tiling: self.vae_tiling,
        })
    }
}

/// How every image is sampled.
#[derive(Args, Debug)]
pub struct SamplingArgs {
    /// Without it, the negative conditioning is zeros (diffusers' SDXL default).
    #[arg(long)]
    pub negative_prompt: Option<String>,
    /// Denoising steps (with img2img, of the full schedule, as diffusers counts them) [default: 30,
    /// or the count of --timesteps].
    #[arg(long, conflicts_with = "timesteps")]
    steps: Option<usize>,
    /// Classifier-free guidance scale; 1 or less runs without the negative pass.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    cfg: f32,
    /// euler, euler_a, dpmpp_2m, ddim, lcm (LCM-LoRA, DMD2) or tcd (TCD, Hyper-SD), as diffusers'
    /// EulerDiscrete, EulerAncestralDiscrete, DPMSolverMultistep, DDIM, LCM and TCD schedulers.
    #[arg(long, default_value = "euler")]
    sampler: SamplerKind,
    /// Noise levels: the model's scheduler_config.json as it is, or Karras et al.'s (euler, dpmpp_2m).
    #[arg(long, value_enum, default_value_t = Schedule::Default)]
    scheduler: Schedule,
    /// leading, linspace or trailing, in place of the model's scheduler_config.json (SDXL base:
    /// leading). Lightning, Hyper-SD and Turbo want trailing. lcm and tcd have none.
    #[arg(long, value_name = "SPACING")]
    timestep_spacing: Option<TimestepSpacing>,
    /// The schedule itself, as diffusers' `timesteps=`: descending training timesteps, such as
    /// DMD2's 999,749,499,249 (euler, dpmpp_2m, lcm, tcd); the step count is theirs.
    #[arg(long, value_delimiter = ',', value_name = "T,T,...")]
    timesteps: Vec<u32>,
    /// epsilon, v_prediction or sample, in place of the model's scheduler_config.json
    /// (SDXL-Lightning's one-step x0 UNet: sample).
    #[arg(long, value_name = "TYPE")]
    prediction_type: Option<PredictionType>,
    /// tcd's gamma, the stochastic share of each step, in [0, 1] [default: 0.3].
    #[arg(long)]
    eta: Option<f64>,
    /// Noise generator: torch-cpu reproduces torch.randn on a CPU generator bit for bit.
    #[arg(long, default_value = vkdiff_pipeline::RNG, value_parser = [vkdiff_pipeline::RNG])]
    rng: String,
    /// plain: the prompt as it is, cut at CLIP's 75 tokens (diffusers). weighted: A1111's
    /// `(word:1.3)`, `(word)` ×1.1, `[word]` ÷1.1, `\(` emphasis and prompts of any length in
    /// chunks of 75, as diffusers' long-prompt-weighting SDXL pipeline (README: where ComfyUI differs).
    #[arg(long, value_enum, default_value_t = SyntaxArg::Plain)]
    prompt_syntax: SyntaxArg,
    /// SDXL size conditioning: the size of the image the model imagines it was cut from, WxH
    /// (diffusers' original_size) [default: the image size].
    #[arg(long, value_parser = parse_size)]
    original_size: Option<(usize, usize)>,
    /// SDXL crop conditioning: where that cut starts, TOP,LEFT in pixels as diffusers' tuple
    /// (0,0 asks for a centred, uncut subject).
    #[arg(long, value_parser = parse_top_left, default_value = "0,0")]
    crops_coords_top_left: (usize, usize),
    /// SDXL size conditioning: the size the model aims at, WxH (diffusers' target_size)
    /// [default: the image size].
    #[arg(long, value_parser = parse_size)]
    target_size: Option<(usize, usize)>,
}

/// `WxH`, both positive.
fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let bad = || format!("`{text}` is not WIDTHxHEIGHT (such as 1024x1024)");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    match (w.trim().parse::<usize>(), h.trim().parse::<usize>()) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(bad()),
    }
}

/// `TOP,LEFT`.
fn parse_top_left(text: &str) -> Result<(usize, usize), String> {
    let bad = || format!("`{text}` is not TOP,LEFT in pixels (such as 0,0)");
    let (top, left) = text.split_once(',').ok_or_else(bad)?;
    Ok((top.trim().parse().map_err(|_| bad())?, left.trim().parse().map_err(|_| bad())?))
}

/// The paper's step count.
const DEFAULT_STEPS: usize = 30;

impl SamplingArgs {
    pub fn sampling(&self, width: usize, height: usize) -> Sampling {
        let size_conditioning = SizeConditioning {
            original: self.original_size,
            crop_top_left: self.crops_coords_top_left,
            target: self.target_size,
        };
        let schedule = ScheduleOptions {
            karras: self.scheduler == Schedule::Karras,
            spacing: self.timestep_spacing,
            prediction: self.prediction_type,
            timesteps: (!self.timesteps.is_empty()).then(|| self.timesteps.clone()),
            eta: self.eta,
        };
        Sampling {
            steps: if self.timesteps.is_empty() { self.steps.unwrap_or(DEFAULT_STEPS) } else { self.timesteps.len() },
            guidance_scale: self.cfg,
            sampler: self.sampler,
            schedule,
            width,
            height,
            size_conditioning,
            strength: None,
            prompt_syntax: self.prompt_syntax.into(),
        }
    }
}
