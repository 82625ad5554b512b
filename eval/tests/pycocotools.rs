//! `eval/` against pycocotools' COCOeval on fixtures from `tools/make_coco_eval_fixtures.py`
//! (pycocotools 2.0.10; the area-range bounds 2.0.11): the twelve statistics, per category and
//! per area range to 1e-6, the precision and recall arrays' sums, and every polygon rasterised
//! pixel for pixel as `frPyObjects` does.

use serde_json::Value;
use vkdiff_eval::{evaluate, polygon_rle, union, AreaRule, AreaSource, Dataset, EvalParams, IouType, Stats};
use vkdiff_render::rle::Rle;

fn fixture(name: &str) -> Value {
    let path = vkdiff_testkit::fixture("eval").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn check(iou_type: IouType, results: &str, max_dets: [usize; 3]) {
    check_as("gt.json", iou_type, results, max_dets, AreaRule::LoadRes, "");
}

/// Scores `results` against `ground_truth` with `rule` and compares to the expected entry
/// `"{iou type} {max_dets}{label}"`.
fn check_as(ground_truth: &str, iou_type: IouType, results: &str, max_dets: [usize; 3], rule: AreaRule, label: &str) {
    let masks = iou_type == IouType::Segm;
    let mut gt_json = fixture(ground_truth);
    // pycocotools 2.0.10's loadRes needs the ground truth's `info`; vkdiff does not.
    gt_json.as_object_mut().unwrap().remove("info");
    let gt = Dataset::ground_truth(&gt_json, iou_type).unwrap();
    let json = fixture(results);
    let dt = Dataset::results(&json, &gt, iou_type, AreaSource::of_results(&json, rule).unwrap()).unwrap();
    let stats = evaluate(&gt, &dt, &EvalParams { iou_type, max_dets: max_dets.to_vec(), kpt_sigmas: None }).unwrap();
    let kind = if masks { "segm" } else { "bbox" };
    let key = format!("{kind} {max_dets:?}{label}");
    let want = &fixture("expected.json")[&key];
    // The twelve statistics, each named (a short list must not pass by zipping less).
    assert_eq!((stats.names.len(), stats.values.len()), (12, 12), "{key}: {:?}", stats.names);
    let tag = if max_dets[2] == 100 { String::new() } else { format!("@{}", max_dets[2]) };
    assert_eq!(stats.names[0], format!("AP{tag}"));
    for (i, (name, got)) in stats.names.iter().zip(&stats.values).enumerate() {
        // pycocotools reports AP at 100 detections whatever the caps; vkdiff at the last cap.
        let expected =
            if i == 0 && max_dets[2] != 100 { want["ap_at_last_max_dets"].as_f64() } else { want["stats"][i].as_f64() }
                .unwrap();
        assert!((got - expected).abs() <= 1e-6, "{key}: {name} = {got}, pycocotools {expected}");
    }
    // Per category, the last cap: pycocotools' slices of precision and recall.
    for (k, w) in want["per_category"].as_array().unwrap().iter().enumerate() {
        assert_eq!(stats.categories[k], w["id"].as_u64().unwrap(), "{key}");
        for (got, name) in stats.per_category(k).into_iter().zip(["AP", "AP50", "AR"]) {
            let expected = w[name].as_f64().unwrap();
            assert!((got - expected).abs() <= 1e-6, "{key}: category {k} {name} = {got}, pycocotools {expected}");
        }
    }
    check_per_area(&stats, want, &key, max_dets);
    // Instance mIoU over COCOeval's matches, against numpy over pycocotools' decoded masks.
    if key == "segm [1, 10, 100]" {
        let scores = &fixture("expected.json")["mask_scores"]["dt_segm.json"];
        for (got, name) in [(stats.mean_instance_iou, "mIoU"), (stats.mean_matched_iou, "mIoU_matched")] {
            let expected = scores[name].as_f64().unwrap();
            assert!((got - expected).abs() <= 1e-12, "{name} = {got}, numpy {expected}");
        }
    }
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    for (what, got) in [("precision_sum", sum(&stats.precision)), ("recall_sum", sum(&stats.recall))] {
        let expected = want[what].as_f64().unwrap();
        assert!(
            (got - expected).abs() <= 1e-9 * expected.abs().max(1.0),
            "{key}: {what} {got}, pycocotools {expected}"
        );
    }
}

/// Per area range, over categories: AP over IoU 0.50:0.95, at 0.50 and at 0.75 (the last cap),
/// and AR at every cap, against pycocotools' slices of precision and recall.
fn check_per_area(stats: &Stats, want: &Value, key: &str, max_dets: [usize; 3]) {
    let [t_n, r_n, k_n, a_n, m_n] = stats.dims;
    // numpy's mean of the defined (> -1) entries, -1 where none is.
    let defined_mean = |v: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = v.filter(|&x| x > -1.0).fold((0.0, 0), |(sum, n), x| (sum + x, n + 1));
        if n == 0 {
            -1.0
        } else {
            sum / n as f64
        }
    };
    let wanted = want["per_area"].as_array().unwrap();
    assert_eq!(wanted.len(), a_n, "{key}: area ranges");
    for (a, w) in wanted.iter().enumerate() {
        let precision =
            |t: usize, r: usize, k: usize| stats.precision[(((t * r_n + r) * k_n + k) * a_n + a) * m_n + m_n - 1];
        let ap = |ts: std::ops::Range<usize>| {
            defined_mean(&mut ts.flat_map(|t| (0..r_n).flat_map(move |r| (0..k_n).map(move |k| precision(t, r, k)))))
        };
        let ar = |m: usize| {
            defined_mean(
                &mut (0..t_n).flat_map(|t| (0..k_n).map(move |k| stats.recall[((t * k_n + k) * a_n + a) * m_n + m])),
            )
        };
        let mut figures = vec![("AP".to_string(), ap(0..t_n), &w["AP"]), ("AP50".into(), ap(0..1), &w["AP50"])];
        figures.push(("AP75".into(), ap(5..6), &w["AP75"]));
        figures.extend((0..m_n).map(|m| (format!("AR@{}", max_dets[m]), ar(m), &w["AR"][m])));
        for (name, got, expected) in figures {
            let expected = expected.as_f64().unwrap();
            let range = w["area"].as_str().unwrap();
            assert!((got - expected).abs() <= 1e-6, "{key}: {range} {name} = {got}, pycocotools {expected}");
        }
    }
}

#[test]
fn segm_statistics_equal_pycocotools() {
    check(IouType::Segm, "dt_segm.json", [1, 10, 100]);
}

#[test]
fn bbox_statistics_equal_pycocotools() {
    check(IouType::Bbox, "dt_bbox.json", [1, 10, 100]);
}

#[test]
fn other_detection_caps_equal_pycocotools() {
    check(IouType::Segm, "dt_segm.json", [1, 3, 5]);
}

/// Objects and unmatched detections exactly on 32² and 96² (and a pixel either side) belong to
/// both ranges they bound; a ground truth's range is its `area` field, not its mask's pixels.
#[test]
fn area_range_bounds_are_closed_as_pycocotools_sets_them() {
    let bounds = "gt_area_bounds.json";
    check_as(bounds, IouType::Segm, "dt_area_bounds_segm.json", [1, 10, 100], AreaRule::LoadRes, " area bounds");
    check_as(bounds, IouType::Bbox, "dt_area_bounds_bbox.json", [1, 10, 100], AreaRule::LoadRes, " area bounds");
}

#[test]
fn detector_results_with_boxes_and_masks_take_box_areas_as_load_res_does() {
    let json = fixture("dt_both.json");
    assert_eq!(AreaSource::of_results(&json, AreaRule::LoadRes).unwrap(), AreaSource::Box);
    check_as("gt.json", IouType::Segm, "dt_both.json", [1, 10, 100], AreaRule::LoadRes, " both");
}

#[test]
fn area_from_mask_is_detectron2s_rule() {
    check_as("gt.json", IouType::Segm, "dt_both.json", [1, 10, 100], AreaRule::Mask, " both, boxes dropped");
}

#[test]
fn results_without_a_mask_take_their_box_polygon_as_load_res_does() {
    check_as("gt.json", IouType::Segm, "dt_mixed.json", [1, 10, 100], AreaRule::LoadRes, " mixed");
}

#[test]
fn box_scoring_of_mask_only_results_takes_boxes_from_the_masks() {
    check_as("gt.json", IouType::Bbox, "dt_segm.json", [1, 10, 100], AreaRule::LoadRes, " from masks");
}

#[test]
fn a_result_without_the_first_ones_box_is_refused_with_the_rule_named() {
    let gt = Dataset::ground_truth(&fixture("gt.json"), IouType::Segm).unwrap();
    let mut json = fixture("dt_both.json");
    json.as_array_mut().unwrap()[4].as_object_mut().unwrap().remove("bbox");
    let areas = AreaSource::of_results(&json, AreaRule::LoadRes).unwrap();
    let e = Dataset::results(&json, &gt, IouType::Segm, areas).unwrap_err().to_string();
    assert!(e.contains("results[4] has no `bbox`") && e.contains("area_from mask"), "{e}");
    // Detectron2's rule needs no boxes.
    Dataset::results(&json, &gt, IouType::Segm, AreaSource::of_results(&json, AreaRule::Mask).unwrap()).unwrap();
}

#[test]
fn polygons_rasterise_as_pycocotools_does() {
    let gt = fixture("gt.json");
    let (h, w) =
        (gt["images"][0]["height"].as_u64().unwrap() as u32, gt["images"][0]["width"].as_u64().unwrap() as u32);
    let expected = fixture("expected.json");
    let wanted = expected["polygon_rles"].as_array().unwrap();
    assert!(wanted.len() >= 5, "the fixture holds polygons");
    for want in wanted {
        let ann = gt["annotations"].as_array().unwrap().iter().find(|a| a["id"] == want["id"]).unwrap();
        let polys: Vec<Rle> = ann["segmentation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| polygon_rle(&p.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>(), h, w))
            .collect();
        let got = union(&polys, h, w);
        let want = Rle::from_coco_string(want["counts"].as_str().unwrap(), h, w).unwrap();
        assert_eq!(got.to_mask(), want.to_mask(), "annotation {}", ann["id"]);
    }
}

#[test]
fn detection_caps_must_be_positive_and_ascending() {
    let gt = Dataset::ground_truth(&fixture("gt.json"), IouType::Bbox).unwrap();
    let json = fixture("dt_bbox.json");
    let dt =
        Dataset::results(&json, &gt, IouType::Bbox, AreaSource::of_results(&json, AreaRule::LoadRes).unwrap()).unwrap();
    for caps in [vec![10, 1, 100], vec![1, 100, 10], vec![0, 10, 100], vec![1, 10]] {
        let refused =
            evaluate(&gt, &dt, &EvalParams { iou_type: IouType::Bbox, max_dets: caps.clone(), kpt_sigmas: None });
        assert!(refused.is_err_and(|e| e.to_string().contains("positive and ascending")), "{caps:?}");
    }
    assert!(
        evaluate(&gt, &dt, &EvalParams { iou_type: IouType::Bbox, max_dets: vec![1, 1, 1], kpt_sigmas: None }).is_ok()
    );
}
