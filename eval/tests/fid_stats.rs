//! `eval::fid` against torch-fidelity 0.4.0 (numpy 2.4.6) on fixtures from
//! `tools/make_fid_stats_fixtures.py`: FID to 1e-10 relative of its exact (40-digit) value and to
//! 1e-6 of torch-fidelity's, whose `eigvals(σ1·σ2)` is itself off by up to ~1e-7 when the
//! covariances are rank-deficient; KID on float64 features (its formulas without float32
//! round-off) to 1e-10, on float32 features (what it computes in practice) to 1e-3; numpy's
//! `RandomState.choice` indices exactly.

use serde_json::Value;
use std::collections::HashMap;
use std::path::PathBuf;
use vkdiff_eval::fid::numpy_rng::RandomState;
use vkdiff_eval::fid::{fid, kid, KidOptions};

fn dir() -> PathBuf {
    vkdiff_testkit::fixture("fid_stats")
}

fn expected() -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap()).unwrap()
}

/// The fixture's feature sets, by name.
fn features() -> HashMap<String, Vec<f32>> {
    let file = vkdiff_formats::SafeTensors::open(&dir().join("features.safetensors")).unwrap();
    file.entries.keys().map(|name| (name.clone(), file.values(name).unwrap().1)).collect()
}

fn rel(got: f64, want: f64) -> f64 {
    (got - want).abs() / want.abs()
}

/// Checks `got` against a reference and returns the relative error, for the summary line.
fn close(what: &str, got: f64, want: f64, rel_tol: f64, abs_tol: f64) -> f64 {
    let err = rel(got, want);
    assert!(err <= rel_tol || (got - want).abs() <= abs_tol, "{what}: {got}, torch-fidelity {want} (rel {err:.2e})");
    err
}

#[test]
fn fid_and_kid_equal_torch_fidelity() {
    let (want, feats) = (expected(), features());
    for (name, case) in want["cases"].as_object().unwrap() {
        let (x, y) = (&feats[&format!("{name}.x")], &feats[&format!("{name}.y")]);
        let dim = case["dim"].as_u64().unwrap() as usize;
        let opts = KidOptions {
            subsets: case["kid_subsets"].as_u64().unwrap() as usize,
            subset_size: case["kid_subset_size"].as_u64().unwrap() as usize,
            ..KidOptions::default()
        };
        let got_fid = fid(x, y, dim).unwrap();
        let got_kid = kid(x, y, dim, &opts).unwrap();
        assert_eq!(got_kid.subset_size, opts.subset_size);
        let f64_ref = &case["float64"];
        let f32_ref = &case["float32"];
        let v = |r: &Value, k: &str| r[k].as_f64().unwrap();
        let errors = [
            close(&format!("{name} FID (exact)"), got_fid, v(case, "fid_exact"), 1e-10, 0.0),
            close(&format!("{name} FID (f64)"), got_fid, v(f64_ref, "fid"), 1e-6, 0.0),
            close(&format!("{name} KID mean (f64)"), got_kid.mean, v(f64_ref, "kid_mean"), 1e-10, 0.0),
            close(&format!("{name} KID std (f64)"), got_kid.std, v(f64_ref, "kid_std"), 1e-10, 1e-15),
            close(&format!("{name} FID (f32)"), got_fid, v(f32_ref, "fid"), 1e-6, 0.0),
            close(&format!("{name} KID mean (f32)"), got_kid.mean, v(f32_ref, "kid_mean"), 1e-3, 0.0),
            close(&format!("{name} KID std (f32)"), got_kid.std, v(f32_ref, "kid_std"), 1e-3, 1e-9),
        ];
        println!(
            "{name}: relative errors: FID vs exact {:.1e}; vs torch-fidelity float64 (FID, KID mean, std) \
             {:.1e} {:.1e} {:.1e}; vs float32 {:.1e} {:.1e} {:.1e}",
            errors[0], errors[1], errors[2], errors[3], errors[4], errors[5], errors[6]
        );
    }
}

#[test]
fn fid_is_zero_for_a_set_with_itself_and_symmetric() {
    let (want, feats) = (expected(), features());
    for (name, case) in want["cases"].as_object().unwrap() {
        let (x, y) = (&feats[&format!("{name}.x")], &feats[&format!("{name}.y")]);
        let dim = case["dim"].as_u64().unwrap() as usize;
        let (xy, yx) = (fid(x, y, dim).unwrap(), fid(y, x, dim).unwrap());
        assert!(rel(yx, xy) < 1e-12, "{name}: FID(x, y) {xy}, FID(y, x) {yx}");
        for z in [x, y] {
            let own = fid(z, z, dim).unwrap();
            assert!(own.abs() < 1e-12 * xy, "{name}: FID with itself {own}");
        }
    }
}

#[test]
fn bad_features_are_clear_errors() {
    let x: Vec<f32> = (0..12).map(|i| i as f32).collect();
    assert!(fid(&x[..3], &x, 3).unwrap_err().to_string().contains("1 feature row(s); at least 2"));
    assert!(fid(&x[..11], &x, 3).unwrap_err().to_string().contains("11 values are not rows of dimension 3"));
    let mut nan = x.clone();
    nan[7] = f32::NAN;
    assert!(kid(&x, &nan, 3, &KidOptions::default())
        .unwrap_err()
        .to_string()
        .contains("KID set 2: row 2 has a non-finite"));
    let no_subsets = KidOptions { subsets: 0, ..KidOptions::default() };
    assert!(kid(&x, &x, 3, &no_subsets).unwrap_err().to_string().contains("at least 1 subset"));
}

/// torch-fidelity refuses a KID subset larger than a set; we clamp to the smaller set.
#[test]
fn kid_clamps_the_subset_size() {
    let (want, feats) = (expected(), features());
    let clamped = &want["cases"]["small"]["kid_clamped"];
    let opts = KidOptions { subsets: 10, ..KidOptions::default() };
    let got = kid(&feats["small.x"], &feats["small.y"], 64, &opts).unwrap();
    assert_eq!(got.subset_size, 30);
    close("clamped KID mean", got.mean, clamped[0].as_f64().unwrap(), 1e-10, 0.0);
    close("clamped KID std", got.std, clamped[1].as_f64().unwrap(), 1e-10, 1e-15);
}

fn indices(v: &Value) -> Vec<usize> {
    v.as_array().unwrap().iter().map(|i| i.as_u64().unwrap() as usize).collect()
}

#[test]
fn random_state_choice_equals_numpy() {
    let want = expected();
    let u = |v: &Value| v.as_u64().unwrap() as usize;
    for c in want["choices"].as_array().unwrap() {
        let mut rng = RandomState::new(c["seed"].as_u64().unwrap() as u32);
        let got = rng.choice_without_replacement(u(&c["n"]), u(&c["k"]));
        assert_eq!(got, indices(&c["indices"]), "seed {} n {} k {}", c["seed"], c["n"], c["k"]);
    }
    for s in want["sequences"].as_array().unwrap() {
        let mut rng = RandomState::new(s["seed"].as_u64().unwrap() as u32);
        for (i, d) in s["draws"].as_array().unwrap().iter().enumerate() {
            let got = rng.choice_without_replacement(u(&d["n"]), u(&d["k"]));
            assert_eq!(got, indices(&d["indices"]), "seed {} draw {i}", s["seed"]);
        }
    }
}
