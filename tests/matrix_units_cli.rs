//! Where the matrix units run: `VKDIFF_COOPERATIVE` and the trial each run makes as it starts
//! (tests/settings_cli.rs holds the refusal of values no setting takes).
//! On a driver without matrix units (Mesa 22.3 lavapipe) no trial runs; CI's Mesa 26.1 pass
//! runs these tests where one does.

mod cli;

use cli::{command, scratch};

/// stdout of `vkdiff` on the GPU paths with `VKDIFF_COOPERATIVE` unset, so the trial decides.
fn on_gpu_paths(args: &[&str]) -> String {
    let run = command().args(args).env("VKDIFF_GPU_PATHS", "1").env_remove("VKDIFF_COOPERATIVE").output().unwrap();
    assert!(run.status.success(), "{args:?}: {}", String::from_utf8_lossy(&run.stderr));
    String::from_utf8(run.stdout).unwrap()
}

#[test]
fn the_matrix_units_are_tried_as_vkdiff_starts_where_a_variant_fits() {
    let devices: serde_json::Value = serde_json::from_str(&on_gpu_paths(&["devices", "--json"])).unwrap();
    let selected = devices.as_array().unwrap().iter().find(|d| d["selected"] == true).unwrap();
    let fits = !selected["cooperative_variant"].is_null();
    let header = on_gpu_paths(&["bench", "kernels", "--filter", "no such kernel", "--no-cpu-reference"]);
    let trial = header.lines().find_map(|l| l.strip_prefix("matrix-unit trial: "));
    let Some(trial) = trial else {
        assert!(!fits, "a variant fits, but no trial ran:\n{header}");
        assert!(!header.contains("GEMM kernels: Cooperative"), "{header}");
        return;
    };
    assert!(fits, "a trial ran on a device no variant fits:\n{header}");
    // The family the run took is the trial's verdict, whichever way the timing went.
    assert!(trial.contains("results agree"), "{trial}");
    let kept = trial.ends_with("using the matrix units");
    let family = if kept { "GEMM kernels: Cooperative" } else { "GEMM kernels: Tiled" };
    assert!(header.contains(family), "{header}");
}

#[test]
fn a_tuned_generation_says_what_tuning_did() {
    let out = scratch("tuned-gen").join("x.png");
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/pipeline/tiny-sdxl");
    let size = ["--width", "64", "--height", "64"];
    let gen =
        ["gen", "--model", model.to_str().unwrap(), "--prompt", "x", "--steps", "1", "--out", out.to_str().unwrap()];
    let run = command().args(gen).args(size).env("VKDIFF_TUNE", "1").output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let line = stderr.lines().find(|l| l.starts_with("VKDIFF_TUNE: ")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(line.contains("shapes had kernels to choose between") && line.ends_with(" s"), "{line}");
    assert!(out.exists());
}

/// `VKDIFF_MATRIX_TILE` asking for a tile the device's fragment has none of says so in one line
/// and runs on four subgroups: on Mesa 26.1, 128×64 is built for its 8×8×8 fragments but not
/// for Intel's 8×16×16, which its flexible dimensions take where `VKDIFF_FRAGMENT` asks.
#[test]
fn a_tile_not_built_for_the_fragment_is_named() {
    let run = |fragment: Option<&str>| {
        let mut cmd = command();
        cmd.args(["bench", "kernels", "--filter", "no such kernel", "--no-cpu-reference"])
            .env("VKDIFF_GPU_PATHS", "1")
            .env("VKDIFF_COOPERATIVE", "1")
            .env("VKDIFF_MATRIX_TILE", "128x64");
        match fragment {
            Some(shape) => cmd.env("VKDIFF_FRAGMENT", shape),
            None => cmd.env_remove("VKDIFF_FRAGMENT"),
        };
        let out = cmd.output().unwrap();
        assert!(out.status.success(), "{fragment:?}: {}", String::from_utf8_lossy(&out.stderr));
        let note =
            String::from_utf8_lossy(&out.stderr).lines().find(|l| l.contains("VKDIFF_MATRIX_TILE=")).map(String::from);
        (note, String::from_utf8(out.stdout).unwrap())
    };
    let (note, header) = run(None);
    assert_eq!(note, None, "the device's own fragment: {header}");
    if !header.contains("GEMM kernels: Cooperative") {
        return; // no matrix units (Mesa 22.3): no fragment to ask for
    }
    let (note, header) = run(Some("8x16x16"));
    let note = note.unwrap_or_else(|| panic!("no line names the tile:\n{header}"));
    assert!(
        note.starts_with("vkdiff: VKDIFF_MATRIX_TILE=128x64: no such tile is built for")
            && note.contains("8×16×16 fragments at 8 lanes (`")
            && note.ends_with("`); its matrix units keep four subgroups a workgroup"),
        "{note}"
    );
}
