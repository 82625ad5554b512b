//! The torch-compatible RNG and the schedulers against torch 2.15 / diffusers 0.42.1
//! (tests/fixtures/pipeline/samplers.*, written by tools/make_sampler_fixtures.py).

use serde_json::Value;
use vkdiff_formats::SafeTensors;
use vkdiff_pipeline::{Error, Sampler, SamplerKind, ScheduleOptions, SchedulerConfig, TorchCpuRng};

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/pipeline/samplers");

/// Largest relative L2 error allowed between a loop's latents and diffusers' (after every step where
/// recorded, and at the end). Measured worst: euler 5.2e-8, euler_a 4.4e-8, dpmpp_2m 2.7e-7, ddim
/// 1.1e-7, lcm 3.6e-7, tcd 7.0e-7; most cases are bit-exact, the rest differ through torch's (MKL's)
/// sqrt, ln and exp, which are off by one ulp in a fraction of a percent of cases, and numpy's
/// float32 log.
const LOOP_TOLERANCE: f64 = 1e-6;

fn fixtures() -> (SafeTensors, Value) {
    let tensors = SafeTensors::open(format!("{FIXTURES}.safetensors").as_ref()).unwrap();
    let listing = serde_json::from_str(&std::fs::read_to_string(format!("{FIXTURES}.json")).unwrap()).unwrap();
    (tensors, listing)
}

fn values(tensors: &SafeTensors, name: &str) -> Vec<f32> {
    tensors.values(name).unwrap().1
}

#[test]
fn randn_matches_torch_bit_for_bit() {
    let (tensors, listing) = fixtures();
    for case in listing["rng"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let got = TorchCpuRng::new(case["seed"].as_u64().unwrap()).randn(case["n"].as_u64().unwrap() as usize);
        let want = values(&tensors, name);
        assert_eq!(got.len(), want.len(), "{name}");
        let differing = got.iter().zip(&want).filter(|(g, w)| g.to_bits() != w.to_bits()).count();
        assert_eq!(differing, 0, "{name}: {differing} of {} values differ", want.len());
    }
}

#[test]
fn consecutive_randn_calls_continue_torchs_stream() {
    let (tensors, listing) = fixtures();
    for case in listing["rng_sequences"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let mut rng = TorchCpuRng::new(case["seed"].as_u64().unwrap());
        let got: Vec<u32> = case["sizes"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|n| rng.randn(n.as_u64().unwrap() as usize))
            .map(f32::to_bits)
            .collect();
        let want: Vec<u32> = values(&tensors, name).iter().map(|v| v.to_bits()).collect();
        assert_eq!(got, want, "{name}");
    }
}

fn sampler(case: &Value) -> Result<Sampler, Error> {
    let kind: SamplerKind = case["kind"].as_str().unwrap().parse().unwrap();
    let config = SchedulerConfig::from_json(&case["config"].to_string()).unwrap();
    let options = ScheduleOptions {
        karras: case["karras"].as_bool().unwrap(),
        timesteps: case["timesteps"].as_array().map(|t| t.iter().map(|t| t.as_u64().unwrap() as u32).collect()),
        eta: case["eta"].as_f64(),
        ..Default::default()
    };
    Sampler::new(kind, &config, case["steps"].as_u64().unwrap() as usize, &options)
}

fn cases(listing: &Value, errors: bool) -> impl Iterator<Item = &Value> {
    listing["samplers"].as_array().unwrap().iter().filter(move |c| c["error"].as_bool().unwrap() == errors)
}

fn assert_close(name: &str, what: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{name} {what}: {got:?} vs {want:?}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= 1e-6 * w.abs(), "{name} {what}[{i}]: {g} vs diffusers {w}");
    }
}

#[test]
fn schedules_match_diffusers() {
    let (tensors, listing) = fixtures();
    for case in cases(&listing, false) {
        let name = case["name"].as_str().unwrap();
        let sampler = sampler(case).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_close(name, "timesteps", sampler.timesteps(), &values(&tensors, &format!("{name}/timesteps")));
        let sigmas = tensors.values(&format!("{name}/sigmas")).ok().map(|(_, v)| v);
        assert_eq!(sampler.sigmas().is_some(), sigmas.is_some(), "{name}: sigmas");
        if let (Some(got), Some(want)) = (sampler.sigmas(), sigmas) {
            assert_close(name, "sigmas", got, &want);
        }
        assert_close(
            name,
            "init_noise_sigma",
            &[sampler.init_noise_sigma()],
            &values(&tensors, &format!("{name}/init_noise_sigma")),
        );
    }
}

/// The fixture's synthetic ε-model, from IEEE-exact float32 operations only.
fn model(x_in: &[f32], t: f32) -> Vec<f32> {
    x_in.iter().map(|x| x / (1.0 + x.abs()) * 0.5 + t / 5000.0).collect()
}

fn relative_l2(got: &[f32], want: &[f32]) -> f64 {
    let diff: f64 = got.iter().zip(want).map(|(&g, &w)| (f64::from(g) - f64::from(w)).powi(2)).sum();
    let norm: f64 = want.iter().map(|&w| f64::from(w).powi(2)).sum();
    (diff / norm).sqrt()
}

#[test]
fn denoising_loops_match_diffusers() {
    let (tensors, listing) = fixtures();
    let mut worst: Vec<(String, f64)> = Vec::new();
    for case in cases(&listing, false) {
        let name = case["name"].as_str().unwrap();
        let mut sampler = sampler(case).unwrap();
        let mut rng = TorchCpuRng::new(case["seed"].as_u64().unwrap());
        let mut x: Vec<f32> = rng.randn(4 * 8 * 8).iter().map(|v| v * sampler.init_noise_sigma()).collect();
        let per_step = tensors.values(&format!("{name}/latents")).ok().map(|(_, v)| v);
        let mut error = 0.0f64;
        for step in 0..sampler.timesteps().len() {
            let eps = model(&sampler.scale_model_input(step, &x), sampler.timesteps()[step]);
            sampler.step(step, &eps, &mut x, &mut rng);
            if let Some(per_step) = &per_step {
                error = error.max(relative_l2(&x, &per_step[step * x.len()..][..x.len()]));
            }
        }
        error = error.max(relative_l2(&x, &values(&tensors, &format!("{name}/final"))));
        let kind = case["kind"].as_str().unwrap().to_string();
        match worst.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, e)) => *e = e.max(error),
            None => worst.push((kind, error)),
        }
        assert!(error <= LOOP_TOLERANCE, "{name}: relative L2 error {error:e}");
    }
    for (kind, error) in worst {
        println!("{kind:>9}: worst relative L2 error {error:.2e}");
    }
}

/// img2img's start: x0 noised to the timestep of step `steps / 2`, as diffusers' `add_noise`
/// does after the pipelines' `set_begin_index`, for every sampler and schedule.
#[test]
fn img2img_noise_matches_diffusers_add_noise() {
    let (tensors, listing) = fixtures();
    let mut checked = 0;
    for case in cases(&listing, false).filter(|c| c["steps"].as_u64().unwrap() >= 2) {
        let name = case["name"].as_str().unwrap();
        let sampler = sampler(case).unwrap();
        let mut rng = TorchCpuRng::new(case["seed"].as_u64().unwrap() + 1);
        let (x0, noise) = (rng.randn(4 * 8 * 8), rng.randn(4 * 8 * 8));
        let begin = case["steps"].as_u64().unwrap() as usize / 2;
        let got = sampler.add_noise(begin, &x0, &noise);
        let want = values(&tensors, &format!("{name}/add_noise"));
        let error = relative_l2(&got, &want);
        assert!(error <= 1e-6, "{name}: relative L2 error {error:e}");
        checked += 1;
    }
    assert!(checked > 60, "only {checked} cases");
}

#[test]
fn refused_settings_are_one_line_errors() {
    let (_, listing) = fixtures();
    for case in cases(&listing, true) {
        let name = case["name"].as_str().unwrap();
        let message = sampler(case).err().unwrap_or_else(|| panic!("{name} should be refused")).to_string();
        assert!(matches!(sampler(case), Err(Error::Config(_))) && !message.contains('\n'), "{name}: {message}");
    }
    let sdxl = |edit: &str| {
        let mut config: Value =
            serde_json::from_str(r#"{"beta_schedule": "scaled_linear", "beta_start": 0.00085, "beta_end": 0.012}"#)
                .unwrap();
        config.as_object_mut().unwrap().extend(serde_json::from_str::<serde_json::Map<String, Value>>(edit).unwrap());
        SchedulerConfig::from_json(&config.to_string()).unwrap()
    };
    for (kind, edit, key) in [
        (SamplerKind::Euler, r#"{"beta_schedule": "squaredcos_cap_v2"}"#, "beta_schedule"),
        (SamplerKind::Euler, r#"{"rescale_betas_zero_snr": true}"#, "rescale_betas_zero_snr"),
        (SamplerKind::EulerAncestral, r#"{"prediction_type": "sample"}"#, "prediction_type"),
        (SamplerKind::Ddim, r#"{"prediction_type": "flow_prediction"}"#, "prediction_type"),
        (SamplerKind::EulerAncestral, r#"{"timestep_spacing": "uniform"}"#, "timestep_spacing"),
        (SamplerKind::Euler, r#"{"interpolation_type": "log_linear"}"#, "interpolation_type"),
        (SamplerKind::DpmSolver2M, r#"{"algorithm_type": "sde-dpmsolver++"}"#, "algorithm_type"),
        (SamplerKind::DpmSolver2M, r#"{"solver_order": 3}"#, "solver_order"),
        (SamplerKind::Ddim, r#"{"thresholding": true}"#, "thresholding"),
        (SamplerKind::Euler, r#"{"steps_offset": "one"}"#, "steps_offset"),
    ] {
        let message = match Sampler::new(kind, &sdxl(edit), 10, &ScheduleOptions::default()) {
            Err(Error::Config(message)) => message,
            other => panic!("{edit}: {:?}", other.err()),
        };
        assert!(message.contains(key) && !message.contains('\n'), "{edit}: {message}");
    }
    let sdxl_base = SchedulerConfig::sdxl_base();
    let plain = ScheduleOptions::default();
    assert!(Sampler::new(SamplerKind::Euler, &sdxl_base, 0, &plain).is_err());
    // Leading spacing past 1000 steps repeats the first timestep; diffusers would run off its schedule.
    for (kind, steps) in [(SamplerKind::Euler, 1001), (SamplerKind::DpmSolver2M, 1000), (SamplerKind::Ddim, 1001)] {
        assert!(matches!(Sampler::new(kind, &sdxl_base, steps, &plain), Err(Error::Config(_))), "{kind} {steps}");
    }
    let message = "heun".parse::<SamplerKind>().unwrap_err().to_string();
    assert!(message.contains("euler, euler_a, dpmpp_2m, ddim"), "{message}");
}

#[test]
fn sdxl_base_config_gives_the_documented_schedule() {
    let sampler =
        Sampler::new(SamplerKind::Euler, &SchedulerConfig::sdxl_base(), 30, &ScheduleOptions::default()).unwrap();
    assert_eq!(&sampler.timesteps()[..3], [958.0, 925.0, 892.0]);
    assert_eq!(sampler.timesteps()[29], 1.0);
    assert!((sampler.init_noise_sigma() - 11.5203).abs() < 1e-4);
}

/// stabilityai/sdxl-turbo's `scheduler/scheduler_config.json`: its trailing spacing is the
/// schedule with no flag, and `--timestep-spacing` overrides it.
#[test]
fn a_model_folder_whose_config_says_trailing_runs_trailing() {
    let folder = std::env::temp_dir().join(format!("vkdiff-turbo-config-{}", std::process::id()));
    std::fs::create_dir_all(folder.join("scheduler")).unwrap();
    std::fs::write(
        folder.join("scheduler/scheduler_config.json"),
        r#"{"_class_name": "EulerAncestralDiscreteScheduler", "_diffusers_version": "0.24.0.dev0", "beta_end": 0.012,
            "beta_schedule": "scaled_linear", "beta_start": 0.00085, "clip_sample": false, "interpolation_type": "linear",
            "num_train_timesteps": 1000, "prediction_type": "epsilon", "sample_max_value": 1.0, "set_alpha_to_one": false,
            "skip_prk_steps": true, "steps_offset": 1, "timestep_spacing": "trailing", "trained_betas": null,
            "use_karras_sigmas": false}"#,
    )
    .unwrap();
    let config = SchedulerConfig::of_model(&folder).unwrap();
    let timesteps = |options: &ScheduleOptions| {
        [SamplerKind::Euler, SamplerKind::EulerAncestral]
            .map(|kind| Sampler::new(kind, &config, 4, options).unwrap().timesteps().to_vec())
    };
    assert_eq!(timesteps(&ScheduleOptions::default()), [[999.0, 749.0, 499.0, 249.0]; 2]);
    let leading = ScheduleOptions { spacing: Some("leading".parse().unwrap()), ..Default::default() };
    assert_eq!(timesteps(&leading), [[751.0, 501.0, 251.0, 1.0]; 2]);
    // A single file carries no scheduler config: SDXL base's (leading).
    let base = SchedulerConfig::of_model(&folder.join("no-such-file.safetensors")).unwrap();
    let sampler = Sampler::new(SamplerKind::Euler, &base, 4, &ScheduleOptions::default()).unwrap();
    assert_eq!(sampler.timesteps(), [751.0, 501.0, 251.0, 1.0]);
    std::fs::remove_dir_all(&folder).unwrap();
}
