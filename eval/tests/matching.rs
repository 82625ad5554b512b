//! `match_at` (what `vkdiff dataset audit` flags by) against pycocotools' COCOeval.evaluate() at
//! one IoU threshold, area "all" (tools/make_coco_match_fixtures.py, pycocotools 2.0.11): the
//! same matches with the same IoUs, the same ground truth missed and results unmatched, for masks
//! and boxes at several thresholds and minimum scores.

use serde_json::Value;
use vkdiff_eval::{match_at, AreaRule, AreaSource, Dataset, IouType};

fn fixture(name: &str) -> Value {
    let path = vkdiff_testkit::fixture("eval").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn matches_equal_pycocotools() {
    for run in fixture("matching/expected.json")["runs"].as_array().unwrap() {
        let iou_type = if run["iou_type"] == "segm" { IouType::Segm } else { IouType::Bbox };
        let min_score = run["min_score"].as_f64().unwrap();
        let label = format!("{} at {} from {min_score}", run["iou_type"], run["iou"]);
        let gt = Dataset::ground_truth(&fixture("gt.json"), iou_type).unwrap();
        let all = fixture(run["results"].as_str().unwrap());
        let kept: Vec<Value> =
            all.as_array().unwrap().iter().filter(|r| r["score"].as_f64().unwrap() >= min_score).cloned().collect();
        let json = Value::from(kept);
        let dt =
            Dataset::results(&json, &gt, iou_type, AreaSource::of_results(&json, AreaRule::LoadRes).unwrap()).unwrap();
        let m = match_at(&gt, &dt, iou_type, run["iou"].as_f64().unwrap(), 100);
        let gt_id = |i: usize| gt.annotations[i].id;
        let mut matched: Vec<(usize, u64, f64)> = m.matched.iter().map(|p| (p.dt, gt_id(p.gt), p.iou)).collect();
        matched.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let want = run["matched"].as_array().unwrap();
        assert_eq!(matched.len(), want.len(), "{label}: {matched:?}");
        for ((dt, g, iou), w) in matched.iter().zip(want) {
            assert_eq!((*dt as u64, *g), (w[0].as_u64().unwrap(), w[1].as_u64().unwrap()), "{label}");
            assert!((iou - w[2].as_f64().unwrap()).abs() < 1e-12, "{label}: IoU {iou}, pycocotools {}", w[2]);
        }
        let mut missed: Vec<u64> = m.missed.iter().map(|&g| gt_id(g)).collect();
        missed.sort_unstable();
        let ids = |v: &Value| v.as_array().unwrap().iter().map(|x| x.as_u64().unwrap()).collect::<Vec<_>>();
        assert_eq!(missed, ids(&run["missed"]), "{label}: missed");
        let mut unmatched: Vec<u64> = m.unmatched.iter().map(|&d| d as u64).collect();
        unmatched.sort_unstable();
        assert_eq!(unmatched, ids(&run["unmatched"]), "{label}: unmatched");
    }
}
