//! `omnitrack-desk overlay` and `plot` on a rendered recording: the pictures are made, the
//! model drawn over the images lands on them, and a frame without a pose is one line.

use std::path::Path;
use std::process::Command;

fn desk(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_omnitrack-desk"))
        .args(args)
        .output()
        .unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn overlay_and_plot_draw_a_run_over_its_recording_and_plan() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let (ok, err) = desk(&["scenario", "lab", "--frames", "3", "--out", arg(&rec)]);
    assert!(ok, "{err}");
    let (model, truth) = (rec.join("model.obj"), rec.join("groundtruth.tum"));

    // Drawn at the true pose, the model's green lines land on the sensor images.
    let png = dir.path().join("overlay.png");
    let (ok, err) = desk(&[
        "overlay",
        "--recording",
        arg(&rec),
        "--model",
        arg(&model),
        "--trajectory",
        arg(&truth),
        "--frame",
        "1",
        "--out",
        arg(&png),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("frame 1"), "{err}");
    let img = image::open(&png).unwrap().to_rgb8();
    let green = img.pixels().filter(|p| p.0 == [40, 255, 60]).count();
    assert!(green > 1000, "{green} model pixels");

    // The truth against itself: a plan and an error plot.
    let out = dir.path().join("plots");
    let (ok, err) = desk(&[
        "plot",
        "--model",
        arg(&model),
        "--trajectory",
        arg(&truth),
        "--truth",
        arg(&truth),
        "--out",
        arg(&out),
    ]);
    assert!(ok, "{err}");
    for f in ["plan.png", "errors.png"] {
        assert!(image::open(out.join(f)).is_ok(), "{f}: {err}");
    }

    // A frame that is not there is one line naming it.
    let (ok, err) = desk(&[
        "overlay",
        "--recording",
        arg(&rec),
        "--model",
        arg(&model),
        "--trajectory",
        arg(&truth),
        "--frame",
        "99",
        "--out",
        arg(&png),
    ]);
    assert!(!ok);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("no frame 99"), "{err}");
}
