//! Keypoint evaluation against pycocotools' COCOeval (iouType "keypoints") on fixtures from
//! `tools/make_coco_keypoint_fixtures.py` (pycocotools 2.0.11): every OKS of COCOeval's `ious`,
//! the ten statistics, per category and per area range, and the arrays' sums, for COCO's
//! person sigmas, 1/k sigmas, sigmas given, results with and without boxes, and other caps.

use serde_json::Value;
use vkdiff_eval::{evaluate, AreaRule, AreaSource, Dataset, EvalParams, IouType, Stats};

fn fixture(name: &str) -> Value {
    let path = vkdiff_testkit::fixture("eval").join("keypoints").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

/// One run of the fixture: the ground truth, the results and the scores.
fn scored(run: &Value) -> (Dataset, Dataset, Stats) {
    let gt = Dataset::ground_truth(&fixture(run["gt"].as_str().unwrap()), IouType::Keypoints).unwrap();
    let json = fixture(run["dt"].as_str().unwrap());
    let areas = AreaSource::of_results(&json, AreaRule::LoadRes).unwrap();
    let dt = Dataset::results(&json, &gt, IouType::Keypoints, areas).unwrap();
    let params = EvalParams {
        iou_type: IouType::Keypoints,
        max_dets: run["max_dets"].as_array().unwrap().iter().map(|c| c.as_u64().unwrap() as usize).collect(),
        kpt_sigmas: run["kpt_sigmas"].as_array().map(|_| numbers(&run["kpt_sigmas"])),
    };
    let stats = evaluate(&gt, &dt, &params).unwrap();
    (gt, dt, stats)
}

fn close(got: f64, want: f64, tolerance: f64, what: &str) {
    assert!((got - want).abs() <= tolerance, "{what}: {got}, pycocotools {want}");
}

#[test]
fn oks_equals_pycocotools_for_every_pair() {
    for run in fixture("expected.json")["runs"].as_array().unwrap() {
        let (gt, dt, stats) = scored(run);
        let label = format!("{} {}", run["dt"], run["max_dets"]);
        assert_eq!(stats.kpt_sigmas, numbers(&run["used_sigmas"]), "{label}: sigmas");
        let pairs = run["oks"].as_array().unwrap();
        assert!(pairs.len() > 50, "{label}: {} pairs", pairs.len());
        for pair in pairs {
            let [d, g, want] = numbers(pair)[..] else { panic!("{pair}") };
            let d = dt.annotations.iter().find(|a| a.id == d as u64).unwrap();
            let g = gt.annotations.iter().find(|a| a.id == g as u64).unwrap();
            let got = vkdiff_eval::oks(d, g, &stats.kpt_sigmas);
            close(got, want, 1e-12, &format!("{label}: OKS of result {} with {}", d.id, g.id));
        }
    }
}

#[test]
fn statistics_equal_pycocotools() {
    for run in fixture("expected.json")["runs"].as_array().unwrap() {
        let (_, _, stats) = scored(run);
        let label = format!("{} {}", run["dt"], run["max_dets"]);
        let tag = |n: &str| if run["max_dets"] == serde_json::json!([20]) { n.to_string() } else { format!("{n}@5") };
        let names: Vec<String> =
            ["AP", "AP50", "AP75", "APm", "APl", "AR", "AR50", "AR75", "ARm", "ARl"].map(tag).into();
        assert_eq!(stats.names, names, "{label}");
        for ((name, got), want) in stats.names.iter().zip(&stats.values).zip(numbers(&run["stats"])) {
            close(*got, want, 1e-9, &format!("{label}: {name}"));
        }
        for (k, w) in run["per_category"].as_array().unwrap().iter().enumerate() {
            assert_eq!(stats.categories[k], w["id"].as_u64().unwrap(), "{label}");
            for (got, name) in stats.per_category(k).into_iter().zip(["AP", "AP50", "AR"]) {
                close(got, w[name].as_f64().unwrap(), 1e-9, &format!("{label}: category {k} {name}"));
            }
        }
        let [_, _, _, a_n, _] = stats.dims;
        assert_eq!(a_n, run["per_area"].as_array().unwrap().len(), "{label}: area ranges all, medium, large");
        let sum = |v: &[f64]| v.iter().sum::<f64>();
        close(sum(&stats.precision), run["precision_sum"].as_f64().unwrap(), 1e-7, &format!("{label}: precision sum"));
        close(sum(&stats.recall), run["recall_sum"].as_f64().unwrap(), 1e-7, &format!("{label}: recall sum"));
    }
}

/// Keypoint lists of the wrong length, sigmas that are not positive, results without keypoints:
/// each refused, naming what is wrong.
#[test]
fn mismatched_keypoints_and_sigmas_are_refused() {
    let gt = Dataset::ground_truth(&fixture("gt_9.json"), IouType::Keypoints).unwrap();
    let json = fixture("dt_9.json");
    let dt = Dataset::results(&json, &gt, IouType::Keypoints, AreaSource::Keypoints).unwrap();
    let refused = |sigmas: Vec<f64>| {
        let params = EvalParams { iou_type: IouType::Keypoints, max_dets: vec![20], kpt_sigmas: Some(sigmas) };
        evaluate(&gt, &dt, &params).unwrap_err().to_string()
    };
    assert!(refused(vec![0.1; 17]).contains("has 9 keypoints where 17 are scored"), "{}", refused(vec![0.1; 17]));
    assert!(refused([vec![0.1; 8], vec![0.0]].concat()).contains("sigma 0 is not a positive number"));
    let mut short = json.clone();
    short[0]["keypoints"].as_array_mut().unwrap().pop();
    let e = Dataset::results(&short, &gt, IouType::Keypoints, AreaSource::Keypoints).unwrap_err().to_string();
    assert!(e.contains("results[0]: `keypoints` holds 26 numbers, not x, y, v triples"), "{e}");
    let mut none = json.clone();
    none[1].as_object_mut().unwrap().remove("keypoints");
    let e = Dataset::results(&none, &gt, IouType::Keypoints, AreaSource::Keypoints).unwrap_err().to_string();
    assert!(e.contains("results[1] has no `keypoints`"), "{e}");
}
