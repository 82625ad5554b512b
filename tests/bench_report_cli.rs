//! `vkdiff bench report` and `bench compare` as a user runs them: two reports of the tiny models
//! (the small suite at 128², on lavapipe at two vector widths, the second beside references that
//! answer: a stub Python printing fixed JSON), their JSON and table, compared as Markdown and as a
//! page headless Chromium shows; reports 100× apart drawn on a log scale; bad input refused in one
//! line.

mod cli;

use cli::{chromium, error_line_with, scratch, screenshot, vkdiff, vkdiff_with};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use vkdiff_testkit::fixture;

/// A stand-in for `$VKDIFF_REFERENCE_PYTHON`, run as `STUB -c SCRIPT ARGS…`: it knows each reference
/// by the usage line its script carries, checks the arguments the quick suite gives it (the
/// image's: 128², 2 steps timed, 1 run, no warm-up image, and the UNet's: no warm-up evaluation,
/// as vkdiff's quick suite makes neither; the kernels' 10 runs; a model's config, first, is not
/// checked), that `tools/reference_timing.py` came with each timed reference, and prints fixed
/// JSON.
fn stub_python() -> PathBuf {
    let path = scratch("bench-report-stub").join("python");
    let diffusers = r#""torch": "9.1", "diffusers": "9.2", "where": "stub CPU float32", "settings": ["channels_last"], "sdpa": "math", "host": "stub host", "clocks": null"#;
    let compiled =
        |s: f64| format!(r#""gpu": null, "compiled": {{"wall": [{s}], "gpu": null, "how": "stub compile"}}"#);
    let (unet_compiled, vae_compiled) = (compiled(0.12), compiled(0.25));
    let script = format!(
        r#"#!/bin/sh
cat > /dev/null
script=$2
shift 2
case "$script" in
  *"Usage: workflow_reference.py"*) want="128 2 1 0"
    answer='{{"images": [{{"seconds": 7.0, "steps": [4.0, 1.5]}}], {diffusers}}}' ;;
  *"Usage: unet_reference.py"*) shift; want="16 16 2 1 0"
    answer='{{"ms": 240.0, "times_ms": [240.0], "peak_mib": 1.0, {unet_compiled}, {diffusers}}}' ;;
  *"Usage: vae_reference.py"*) shift; want="128 1 cpu f32"
    answer='{{"seconds": 0.5, "times": [0.5], "peak_mib": 1.0, {vae_compiled}, {diffusers}}}' ;;
  *"Usage: kernels_reference.py"*) want="10"
    answer='{{"linear": [0.5], "conv": [0.25], "attention": [0.125], "torch": "9.1", "where": "stub CPU", "settings": ["channels_last", "wall-clock"], "sdpa": "math", "host": "stub host", "clocks": null}}' ;;
  *"sdcpp_reference.py MODEL"*) shift; want="64 2"
    answer='{{"load_s": 4.2, "steps": [9.0, 3.0], "total_s": 12.5, "what": "stub sd.cpp"}}' ;;
  *) echo "stub: no such reference" >&2; exit 2 ;;
esac
[ "$*" = "$want" ] || {{ echo "stub: arguments $*, not $want" >&2; exit 2; }}
case "$script" in
  *"import reference_timing"*) [ -n "$VKDIFF_REFERENCE_TIMING" ] || {{ echo "stub: reference_timing.py not given" >&2; exit 2; }} ;;
esac
echo "$answer"
"#
    );
    std::fs::write(&path, script).unwrap();
    let mut permissions = std::fs::metadata(&path).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut permissions, 0o755);
    std::fs::set_permissions(&path, permissions).unwrap();
    path
}

/// The tiny workflow's flags: SDXL with a UNet swapped in (a distilled UNet's file), its depth
/// ControlNet, an IP-Adapter and a LoRA.
fn model_flags() -> Vec<String> {
    let f = |p: &str| fixture(p).display().to_string();
    [
        ("--model", f("pipeline/tiny-sdxl")),
        ("--unet", f("few_step/unet-diffusers.safetensors")),
        ("--controlnet", f("workflow/controlnet")),
        ("--ip-adapter", f("workflow/ip-adapter_tiny.safetensors")),
        ("--image-encoder", f("workflow/image_encoder")),
        ("--lora", f("workflow/lora-peft.safetensors")),
    ]
    .into_iter()
    .flat_map(|(flag, value)| [flag.to_string(), value])
    .collect()
}

/// A report of the image, UNet and VAE at 128² at lavapipe's `bits`-bit vectors, beside the
/// references `python` runs (none without it): its JSON file and its table.
fn report(dir: &Path, bits: &str, python: Option<&Path>) -> (PathBuf, String) {
    let out = dir.join(format!("report-{bits}.json"));
    let reference = if python.is_some() { "cpu" } else { "none" };
    let mut args: Vec<String> =
        format!("bench report --quick --size 128 --only image,unet,vae --reference-device {reference}")
            .split(' ')
            .map(String::from)
            .collect();
    args.extend(model_flags());
    args.extend(["--out".into(), out.display().to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut env = vec![("LP_NATIVE_VECTOR_WIDTH", bits)];
    env.extend(python.map(|p| ("VKDIFF_REFERENCE_PYTHON", p.to_str().unwrap())));
    let result = vkdiff_with(&args, &env);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    (out, String::from_utf8(result.stdout).unwrap())
}

/// The two reports, made once: the first without references, the second beside the stub's.
fn reports() -> &'static [(PathBuf, String); 2] {
    static REPORTS: OnceLock<[(PathBuf, String); 2]> = OnceLock::new();
    REPORTS.get_or_init(|| {
        let dir = scratch("bench-report");
        [report(&dir, "128", None), report(&dir, "256", Some(&stub_python()))]
    })
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn a_report_names_its_machine_and_times_each_figure() {
    let (path, table) = &reports()[0];
    let report = read_json(path);
    assert_eq!(
        (report["suite"].as_str(), report["suite_version"].as_u64()),
        (Some("vkdiff bench report/1 --quick --size 128"), Some(1))
    );
    let system = &report["system"];
    assert!(system["device"].as_str().unwrap().contains("128 bits"), "{system}");
    for key in ["vendor", "driver", "vulkan", "kernels_f16", "kernels_f32", "cpu", "os", "vkdiff", "command", "date"] {
        assert!(system[key].as_str().is_some_and(|v| !v.is_empty()), "system.{key}: {system}");
    }
    assert!(system["command"].as_str().unwrap().contains("--unet"), "{system}");
    let version = String::from_utf8(vkdiff(&["--version"]).stdout).unwrap();
    assert!(version.contains(system["vkdiff"].as_str().unwrap()), "{version} against {system}");
    let figures = report["figures"].as_array().unwrap();
    let ids: Vec<&str> = figures.iter().map(|f| f["id"].as_str().unwrap()).collect();
    // The tiny VAE's config forces f32: it has no f16 row.
    assert_eq!(ids, ["image", "image_4_steps", "unet.f16", "vae.f32"]);
    for f in figures.iter().filter(|f| f["id"] != "image_4_steps") {
        let runs = &f["runs"];
        assert_eq!(runs["count"], 1, "{f}");
        assert!(
            runs["median"].as_f64().unwrap() > 0.0 && runs["min"] == runs["median"] && runs["max"] == runs["median"]
        );
        assert!(f["peak_mib"].as_f64().unwrap() > 0.0 && f["first_run"].as_f64().unwrap() > 0.0, "{f}");
        assert_eq!(f["reference"]["why"], "not asked for (--reference-device none)");
        assert!(table.contains(f["label"].as_str().unwrap()), "{table}");
    }
    // The image's stages, each timed: those on the loop's own thread fit in the image (the scene
    // and the writing have threads of their own); nothing is the image less the others.
    let image = &figures[0];
    let parts: Vec<(String, f64)> = serde_json::from_value(image["parts"].clone()).unwrap();
    let names: Vec<&str> = parts.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "scene (its own thread)",
            "guides",
            "denoise",
            "VAE",
            "writing (its own thread)",
            "once per set (prompt, styles, recording)"
        ]
    );
    assert!(parts.iter().all(|(_, v)| *v > 0.0), "{parts:?}");
    let on_the_loop: f64 = parts[1..4].iter().map(|(_, v)| v).sum();
    let median = image["runs"]["median"].as_f64().unwrap();
    assert!(on_the_loop <= median, "{parts:?} against {median}");
    let rule = "counted at the median of the timed steps after the first";
    assert_eq!(image["note"], format!("2 of the 30 steps timed, the others {rule}"));
    // Lightning's 4 steps without guidance beside it, measured against it in the same run.
    let few = &figures[1];
    assert_eq!(few["note"], format!("2 of the 4 steps timed, the others {rule}"));
    assert_eq!(few["reference"]["value"], image["runs"]["median"], "{few}");
    assert_eq!(few["reference"]["what"], "the paper's 30-step image, this run");
    let ratio = median / few["runs"]["median"].as_f64().unwrap();
    assert!(ratio > 1.0 && table.contains(few["label"].as_str().unwrap()), "{ratio}: {table}");
    assert!(table.contains("| figure | vkdiff (median) |") && table.contains("Reproduce by: `"), "{table}");
}

#[test]
fn the_peer_times_vkdiff_from_one_file_and_says_why_sd_cpp_did_not_run() {
    // The tiny SDXL's single file, with no Python that has stable-diffusion.cpp: vkdiff's steps
    // from the file, and one line saying why the peer's figure is missing.
    let out = scratch("bench-report-peer").join("peer.json");
    let model = fixture("pipeline/tiny-sdxl.safetensors");
    let args = ["bench", "report", "--quick", "--size", "64", "--only", "peer", "--reference-device", "none"];
    let args: Vec<&str> =
        args.into_iter().chain(["--model", model.to_str().unwrap(), "--out", out.to_str().unwrap()]).collect();
    let result = vkdiff_with(&args, &[("VKDIFF_REFERENCE_PYTHON", "/nonexistent/python3")]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let report = read_json(&out);
    let figures = report["figures"].as_array().unwrap();
    assert_eq!(figures.len(), 1, "{figures:?}");
    let peer = &figures[0];
    assert_eq!(
        (peer["id"].as_str(), peer["group"].as_str(), peer["unit"].as_str()),
        (Some("peer.sdcpp"), Some("peer"), Some("s"))
    );
    assert_eq!(peer["runs"]["count"], 1, "the suite's two timed steps, the first left out");
    assert!(peer["runs"]["median"].as_f64().unwrap() > 0.0, "{peer}");
    let why = peer["reference"]["why"].as_str().unwrap();
    assert!(
        why.starts_with("stable-diffusion.cpp (cyllama-vulkan): tools/sdcpp_reference.py: /nonexistent/python3"),
        "{why}"
    );
    assert!(model.exists(), "the user's file stays");
}

/// `figure` in `unit` beside the reference value `value` and `what` ran it, and the speed-up its
/// table row ends with (above 1: vkdiff faster).
fn assert_reference(table: &str, figure: &Value, unit: &str, value: f64, what: &str) {
    assert_eq!(figure["unit"], unit, "{figure}");
    assert_eq!(
        (figure["reference"]["value"].as_f64(), figure["reference"]["what"].as_str()),
        (Some(value), Some(what))
    );
    let median = figure["runs"]["median"].as_f64().unwrap();
    let speedup = if figure["higher_is_better"] == true { median / value } else { value / median };
    let label = figure["label"].as_str().unwrap();
    let row = table.lines().find(|l| l.starts_with(&format!("| {label} |"))).unwrap_or_else(|| panic!("{table}"));
    assert!(row.ends_with(&format!("| {speedup:.2}× |")), "{row}: {speedup:.2}×");
}

#[test]
fn diffusers_beside_the_image_unet_and_vae_gives_each_its_speed_up() {
    let (path, table) = &reports()[1];
    let report = read_json(path);
    let figures = report["figures"].as_array().unwrap();
    let ids: Vec<&str> = figures.iter().map(|f| f["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["image", "image_4_steps", "unet.f16", "unet.f16.compiled", "vae.f32", "vae.f32.compiled"]);
    let diffusers = "stub CPU float32, torch 9.1 / diffusers 9.2; channels_last; SDPA math; stub host";
    // The stub's image ran 2 steps in 7 s: the 28 others at the second step's 1.5 s (the timed
    // steps' mean, the first included, would make it 84 s).
    assert_reference(table, &figures[0], "s", 7.0 + 28.0 * 1.5, diffusers);
    let thirty = figures[0]["runs"]["median"].as_f64().unwrap();
    assert_reference(table, &figures[1], "s", thirty, "the paper's 30-step image, this run");
    assert_reference(table, &figures[2], "ms", 240.0, diffusers);
    // The same vkdiff figure again, against the compiled model: 0.12 s a UNet, 0.25 s a decode.
    assert_reference(table, &figures[3], "ms", 120.0, &format!("stub compile; {diffusers}"));
    assert_eq!(figures[3]["runs"], figures[2]["runs"]);
    assert_reference(table, &figures[4], "s", 0.5, diffusers);
    assert_reference(table, &figures[5], "s", 0.25, &format!("stub compile; {diffusers}"));
    assert!(table.contains(&format!("| 49.0 s ({diffusers}) |")), "{table}");
}

#[test]
fn torch_kernels_and_sd_cpp_beside_vkdiff_give_rates_by_product_and_a_step() {
    let out = scratch("bench-report-kernels").join("kernels.json");
    let model = fixture("pipeline/tiny-sdxl.safetensors");
    let stub = stub_python();
    let args = ["bench", "report", "--quick", "--size", "64", "--only", "kernels,peer", "--reference-device", "cpu"];
    let args: Vec<&str> =
        args.into_iter().chain(["--model", model.to_str().unwrap(), "--out", out.to_str().unwrap()]).collect();
    let result = vkdiff_with(&args, &[("VKDIFF_REFERENCE_PYTHON", stub.to_str().unwrap())]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let table = String::from_utf8(result.stdout).unwrap();
    let report = read_json(&out);
    let figures = report["figures"].as_array().unwrap();
    let ids: Vec<&str> = figures.iter().map(|f| f["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["kernels.linear", "kernels.conv", "kernels.attention", "peer.sdcpp"]);
    for (figure, rate) in figures.iter().zip([0.5, 0.25, 0.125]) {
        assert_eq!(figure["higher_is_better"], true, "{figure}");
        // Ten runs a kernel row on both sides, in the quick suite too (the stub checks torch's).
        assert_eq!(figure["runs"]["count"], 10, "{figure}");
        assert_reference(
            &table,
            figure,
            "TFLOP/s",
            rate,
            "torch 9.1, stub CPU; channels_last, wall-clock; SDPA math; stub host",
        );
    }
    // sd.cpp's steps of 9 and 3 s: its step is the second (their median with the first is 6 s).
    assert_reference(&table, &figures[3], "s", 3.0, "stub sd.cpp, loaded in 4 s");
}

#[test]
fn reports_compare_as_markdown_and_as_a_page_with_charts() {
    let [(a, _), (b, _)] = reports();
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());
    let page = scratch("bench-compare").join("compare.html");
    let out = vkdiff(&["bench", "compare", a, b, "--markdown", "--html", page.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let markdown = String::from_utf8(out.stdout).unwrap();
    let rows: Vec<&str> = markdown.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| figure")).collect();
    assert_eq!(rows.len(), 4, "{markdown}");
    // The second column holds each value beside its speed relative to the first report; the rows
    // that repeat a figure against compiled PyTorch are not vkdiff's own, and are left out.
    let (ra, rb) = (read_json(Path::new(a)), read_json(Path::new(b)));
    let own = |r: &Value| -> Vec<Value> {
        let figures = r["figures"].as_array().unwrap().iter();
        figures.filter(|f| !f["id"].as_str().unwrap().ends_with(".compiled")).cloned().collect()
    };
    let (own_a, own_b) = (own(&ra), own(&rb));
    assert_eq!(own_b.len() + 2, rb["figures"].as_array().unwrap().len(), "the UNet's and the VAE's compiled rows");
    for (row, (fa, fb)) in rows.iter().zip(own_a.iter().zip(&own_b)) {
        let speed = fa["runs"]["median"].as_f64().unwrap() / fb["runs"]["median"].as_f64().unwrap();
        assert!(row.ends_with(&format!("({speed:.2}×) |")), "{row}: {speed:.2}");
    }
    assert!(markdown.contains("- A: llvmpipe") && markdown.contains("128 bits") && markdown.contains("256 bits"));
    let html = std::fs::read_to_string(&page).unwrap();
    assert_eq!(html.matches("<svg ").count(), 3, "a chart per group");
    assert_bars_show(&page);
}

/// Both reports' bars show on `page` as headless Chromium draws it: A's colour and B's.
fn assert_bars_show(page: &Path) {
    let shot = screenshot(&chromium(), &format!("file://{}", page.display()), &page.with_extension("png"));
    assert_eq!(shot[0], [255, 255, 255], "the screenshot is not the page");
    for colour in [[70, 110, 170], [210, 105, 30]] {
        let bars = shot.iter().filter(|p| **p == colour).count();
        assert!(bars > 2000, "only {bars} pixels of bars in {colour:?}: the charts did not render");
    }
}

/// The widths of the bars of report `letter` in `svg`, in order.
fn bar_widths(svg: &str, letter: char) -> Vec<f64> {
    let marker = format!("<rect class=\"bar\" data-report=\"{letter}\"");
    let width = |l: &str| l.split(" width=\"").nth(1).and_then(|w| w.split('"').next()?.parse().ok()).unwrap();
    svg.lines().filter(|l| l.starts_with(&marker)).map(width).collect()
}

#[test]
fn reports_a_hundred_times_apart_both_show_on_a_log_scale() {
    let [(a, _), _] = reports();
    let dir = scratch("bench-compare-100x");
    let mut slow = read_json(a);
    for figure in slow["figures"].as_array_mut().unwrap() {
        for key in ["median", "min", "max"] {
            figure["runs"][key] = (figure["runs"][key].as_f64().unwrap() * 100.0).into();
        }
    }
    let slow_path = dir.join("slow.json");
    std::fs::write(&slow_path, slow.to_string()).unwrap();
    let page = dir.join("compare.html");
    let out = vkdiff(&[
        "bench",
        "compare",
        a.to_str().unwrap(),
        slow_path.to_str().unwrap(),
        "--html",
        page.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let html = std::fs::read_to_string(&page).unwrap();
    // The image group's chart: the 30- and 4-step images, each with A at 1× and B at 0.01×.
    let svg = &html[html.find("<svg ").unwrap()..html.find("</svg>").unwrap()];
    for text in
        [">0.001×</text>", ">0.01×</text>", ">1×</text>", ">speed relative to A (log scale; right is faster)</text>"]
    {
        assert!(svg.contains(text), "{text} in {svg}");
    }
    assert_eq!((svg.matches(">1.00× · ").count(), svg.matches(">0.0100× · ").count()), (2, 2), "{svg}");
    // On the log scale A spans three decades and B one: B's bars a third of A's, not a hundredth.
    let (widths_a, widths_b) = (bar_widths(svg, 'A'), bar_widths(svg, 'B'));
    assert_eq!((widths_a.len(), widths_b.len()), (2, 2), "{svg}");
    for (wa, wb) in widths_a.iter().zip(&widths_b) {
        assert!((wa / wb - 3.0).abs() < 0.01, "{wa} against {wb}");
    }
    assert_bars_show(&page);
}

#[test]
fn bad_reports_and_arguments_are_refused_in_one_line() {
    let [(a, _), _] = reports();
    let dir = scratch("bench-refusals");
    let mut other = read_json(a);
    other["suite"] = "vkdiff bench report/1".into();
    let other_path = dir.join("full.json");
    std::fs::write(&other_path, other.to_string()).unwrap();
    let not_report = dir.join("not.json");
    std::fs::write(&not_report, "{\"images\": []}").unwrap();
    let (a, other, not_report) = (a.to_str().unwrap(), other_path.to_str().unwrap(), not_report.to_str().unwrap());
    for (args, says) in [
        (vec!["bench", "compare", a, other], "reports of different suites do not compare"),
        (vec!["bench", "compare", a, not_report], "not a `vkdiff bench report` JSON"),
        (vec!["bench", "report", "--size", "100"], "--size 100 must be a multiple of 64"),
        (vec!["bench", "report", "--out", "/no/such/folder/r.json"], "no such folder /no/such/folder"),
    ] {
        let line = error_line_with(&args, &[]);
        assert!(line.contains(says), "{args:?}: {line}");
        assert_eq!(vkdiff(&args).status.code(), Some(2), "{args:?}: a usage error");
    }
}
