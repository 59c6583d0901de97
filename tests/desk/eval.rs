//! `desk::eval` on TUM text against numbers evo 1.38.1 printed for the same files
//! (`evo_ape tum gt.tum est.tum [-r angle_deg] [-a]`, `evo_rpe ... --delta 2 --delta_unit f`),
//! plus the file-level behaviour: errors that name the files, and the table.
#![cfg(feature = "desk")]

use nalgebra::{Isometry3, Vector3};
use omnitrack::desk::eval::{evaluate, evaluate_files, transformed, EvalOptions, Stats};
use omnitrack::trajectory::{parse_tum, to_tum_string};

/// Ten ground-truth poses at 10 Hz.
const GT: &str = "\
100.000 1.0000 2.0000 1.5000 0.014999437506 0.000000000000 0.000000000000 0.999887502109
100.100 1.5000 2.2524 1.5200 0.012821418591 0.022424893700 0.099486158219 0.994703593886
100.200 2.0000 2.2728 1.5400 0.010181308424 0.025254033755 0.198261508164 0.979770865620
100.300 2.5000 2.0423 1.5600 0.013286944892 0.007802650455 0.295434567923 0.955238709338
100.400 3.0000 1.7730 1.5800 0.021179475100 -0.011583520797 0.389566216261 0.920682037963
100.500 3.5000 1.7123 1.6000 0.024650388417 -0.013844951789 0.479549394696 0.877059321658
100.600 4.0000 1.9162 1.6200 0.016323038602 0.002704519275 0.564651653258 0.825163471355
100.700 4.5000 2.1971 1.6400 0.000891261548 0.022221898292 0.643869912043 0.764811695291
100.800 5.0000 2.2968 1.6600 -0.007292236848 0.027985264557 0.716797549110 0.696681363206
100.900 5.5000 2.1236 1.6800 0.001253768216 0.018152429611 0.783101155511 0.621628102326
";

/// An estimate: 5 cm / ~2° noise, timestamps off by up to 4 ms, the pose at 100.4 s missing.
const EST: &str = "\
100.000 1.0020 2.0232 1.4770 0.019061785160 0.009360841845 0.005111163953 0.999761421035
100.096 1.5265 2.1716 1.5309 0.018556390191 0.022350280919 0.117573527406 0.992639204837
100.203 1.9912 2.3921 1.6106 0.017978716714 0.026388692241 0.201439712300 0.978980308778
100.300 2.4742 2.1076 1.5489 0.009870528031 0.009623602632 0.267333012217 0.963505588737
100.500 3.4720 1.6600 1.6248 0.025938038600 0.009859994299 0.492683439818 0.869766075905
100.602 4.0415 1.9181 1.6079 0.010548902661 -0.000611525832 0.554337675239 0.832224782435
100.696 4.4568 2.1662 1.6626 -0.002174685306 0.021302336006 0.652175036696 0.757765928724
100.803 4.8318 2.3370 1.5883 -0.009729513877 0.023002210323 0.715188463846 0.698485286933
100.900 5.6011 2.1685 1.6443 0.004291459981 0.028454237194 0.775173328320 0.631092901892
";

/// evo's rmse, mean, median, std, min, max.
const APE_T: [f64; 6] = [
    0.10036957263588944,
    0.08857665410444653,
    0.07108403477574983,
    0.047204104257705416,
    0.03272980293249565,
    0.18721156481371518,
];
const APE_R: [f64; 6] = [
    2.0440586439469084,
    1.8411914959631943,
    1.6229191540014907,
    0.8878004365210056,
    0.6933931045152741,
    3.385962471959623,
];
const APE_T_ALIGNED: [f64; 6] = [
    0.09719661926809697,
    0.08988842140611994,
    0.07473678407167719,
    0.03697640456106026,
    0.04935801057145009,
    0.16608209803884946,
];
const APE_R_ALIGNED: [f64; 6] = [
    2.0463395370761317,
    1.9119303756673958,
    1.5999836417467979,
    0.7294023166958612,
    1.0559104066868799,
    3.4809082827425675,
];
const RPE2_T: [f64; 6] = [
    0.144340305346003,
    0.13498014619922274,
    0.1526499319956216,
    0.051132024010534176,
    0.05069792915607023,
    0.18392279164957753,
];
const RPE2_R: [f64; 6] = [
    2.6939768261384796,
    2.5213767932290927,
    2.967748596880303,
    0.9487730004257784,
    0.8919123543023629,
    3.258097624853402,
];

fn assert_stats(name: &str, ours: &Stats, evo: [f64; 6], count: usize) {
    let got = [ours.rmse, ours.mean, ours.median, ours.std, ours.min, ours.max];
    for (k, (a, b)) in got.iter().zip(evo).enumerate() {
        assert!(
            (a - b).abs() <= 1e-9 * b.abs().max(1e-9),
            "{name} stat {k}: ours {a}, evo {b}"
        );
    }
    assert_eq!(ours.count, count, "{name} count");
}

#[test]
fn matches_evo_without_and_with_alignment() {
    let gt = parse_tum(GT, "gt.tum").unwrap();
    let est = parse_tum(EST, "est.tum").unwrap();
    let options = EvalOptions {
        rpe_delta: 2,
        ..EvalOptions::default()
    };
    let ev = evaluate(&gt, &est, &options).unwrap();
    assert_eq!(ev.pairs.len(), 9);
    assert!(ev.pairs.iter().all(|&(g, _)| g != 4), "the missing pose is not matched");
    assert_stats("APE t", &ev.ate.translation_m, APE_T, 9);
    assert_stats("APE r", &ev.ate.rotation_deg, APE_R, 9);
    let rpe = ev.rpe.as_ref().unwrap();
    assert_stats("RPE t", &rpe.translation_m, RPE2_T, 4);
    assert_stats("RPE r", &rpe.rotation_deg, RPE2_R, 4);

    let aligned = evaluate(&gt, &est, &EvalOptions { align: true, ..options }).unwrap();
    assert_stats("APE t aligned", &aligned.ate.translation_m, APE_T_ALIGNED, 9);
    assert_stats("APE r aligned", &aligned.ate.rotation_deg, APE_R_ALIGNED, 9);
    // RPE does not see a rigid motion of the whole estimate.
    assert_stats("RPE t aligned", &aligned.rpe.unwrap().translation_m, RPE2_T, 4);
}

#[test]
fn a_moved_estimate_is_recovered_by_alignment_only() {
    let gt = parse_tum(GT, "gt.tum").unwrap();
    let t = Isometry3::new(Vector3::new(0.3, -0.2, 0.05), Vector3::new(0.0, 0.0, 0.1));
    let moved = parse_tum(&to_tum_string(&transformed(&gt, &t)), "moved.tum").unwrap();
    let raw = evaluate(&gt, &moved, &EvalOptions::default()).unwrap();
    assert!(raw.ate.translation_m.mean > 0.1, "{:?}", raw.ate.translation_m);
    assert!((raw.ate.rotation_deg.mean - 0.1f64.to_degrees()).abs() < 1e-6);
    let aligned = evaluate(
        &gt,
        &moved,
        &EvalOptions {
            align: true,
            ..EvalOptions::default()
        },
    )
    .unwrap();
    // TUM text keeps 9 decimals of position: alignment is exact to that.
    assert!(aligned.ate.translation_m.max < 1e-8, "{:?}", aligned.ate.translation_m);
    assert!(aligned.ate.rotation_deg.max < 1e-6);
}

#[test]
fn files_and_table() {
    let dir = tempfile::tempdir().unwrap();
    let (gt, est, far) = (
        dir.path().join("gt.tum"),
        dir.path().join("est.tum"),
        dir.path().join("far.tum"),
    );
    std::fs::write(&gt, GT).unwrap();
    std::fs::write(&est, EST).unwrap();
    std::fs::write(&far, "5.0 0 0 0 0 0 0 1\n").unwrap();
    let ev = evaluate_files(&gt, &est, &EvalOptions::default()).unwrap();
    let table = ev.table();
    assert!(
        table.starts_with("9 of 9 estimated poses matched to 10 ground-truth poses"),
        "{table}"
    );
    for row in [
        "ATE translation (cm)",
        "ATE rotation (deg)",
        "RPE/1 translation (cm)",
        "RPE/1 rotation (deg)",
    ] {
        assert!(table.contains(row), "{row} missing from\n{table}");
    }
    // The ATE RMSE in cm, as evo says (0.10037 m).
    assert!(table.lines().nth(2).unwrap().contains("10.037"), "{table}");

    let e = evaluate_files(&gt, &far, &EvalOptions::default())
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        format!(
            "{} vs {}: no timestamps match within 0.01 s (10 ground-truth poses, 1 estimated poses)",
            gt.display(),
            far.display()
        )
    );
    let bad = dir.path().join("bad.tum");
    std::fs::write(&bad, "1.0 0 0 0 0 0 1\n").unwrap();
    let e = evaluate_files(&gt, &bad, &EvalOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.starts_with(&format!("{}:1: expected 8 fields", bad.display())), "{e}");
    let e = evaluate_files(&dir.path().join("none.tum"), &est, &EvalOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("none.tum: cannot read trajectory"), "{e}");
    let e = evaluate_files(
        &gt,
        &est,
        &EvalOptions {
            max_diff_s: f64::NAN,
            ..EvalOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.ends_with("bad option: max time difference must be a finite number ≥ 0 s, found NaN"),
        "{e}"
    );
}
