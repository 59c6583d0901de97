//! The demo's pipeline on a tiny setup (the `lab` building, a dozen frames, a temporary cache):
//! it tracks, prints its table, and writes four pictures that decode, have the sizes they
//! should and show something (many colours, the re-projected model in green); a second run
//! reuses the recording and the visibility table.
#![cfg(feature = "desk")]

use omnitrack::desk::demo::{run_demo, DemoOptions, ERROR_PLOT_SIZE, STATES_PLOT_SIZE};
use omnitrack::desk::pictures::{omni_layout, OmniOptions, PlanOptions};
use omnitrack::Rig;
use std::collections::HashSet;

const FRAMES: usize = 12;

fn rig() -> Rig {
    crate::common::shipped_rig()
}

#[test]
fn demo_tracks_a_short_lab_recording_and_writes_its_pictures() {
    let cache = tempfile::tempdir().unwrap();
    let opts = DemoOptions {
        frames: FRAMES,
        cache_dir: Some(cache.path().to_path_buf()),
        progress: false,
        ..DemoOptions::default()
    };
    let report = run_demo(&opts).unwrap();
    assert!(report.rendered_now);
    assert_eq!(report.frames, FRAMES as u64);
    assert!(report.tracked > 0, "{report}");
    assert!(
        report.ate_position_m.is_some() && report.init_time.is_some(),
        "{report}"
    );
    assert!(report.frames_per_s > 0.0 && report.latency_p50_ms > 0.0, "{report}");
    let text = report.to_string();
    for needle in [
        "frames tracked",
        "ATE position RMSE / max (cm)",
        "latency p50 / p99 (ms)",
        "excerpt",
    ] {
        assert!(text.contains(needle), "no '{needle}' in:\n{text}");
    }
    assert!(report.skipped.is_empty(), "{:?}", report.skipped);

    let expected = [
        ("plan view", PlanOptions::default().size),
        ("omni view", omni_layout(&rig(), OmniOptions::default().columns).size),
        ("error over time", ERROR_PLOT_SIZE),
        ("correspondence states", STATES_PLOT_SIZE),
    ];
    assert_eq!(report.pictures.len(), expected.len(), "{:?}", report.pictures);
    let green = image::Rgb(OmniOptions::default().colour);
    for (name, size) in expected {
        let p = report
            .pictures
            .iter()
            .find(|p| p.name == name)
            .unwrap_or_else(|| panic!("no {name} in {:?}", report.pictures));
        assert!(p.path.starts_with(cache.path().join("demo")), "{}", p.path.display());
        let img = image::open(&p.path)
            .unwrap_or_else(|e| panic!("{}: {e}", p.path.display()))
            .to_rgb8();
        assert_eq!(img.dimensions(), size, "{name}");
        let colours: HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
        assert!(colours.len() > 20, "{name}: only {} colours", colours.len());
        if name == "omni view" {
            let model_pixels = img.pixels().filter(|&&p| p == green).count();
            assert!(model_pixels > 2000, "omni view: {model_pixels} green model pixels");
        }
    }

    // The second run finds everything in the cache.
    let again = run_demo(&opts).unwrap();
    assert!(!again.rendered_now);
    assert!(again.table_origin.contains("cached"), "{}", again.table_origin);
    assert_eq!(again.frames, FRAMES as u64);
}

#[test]
fn demo_refuses_zero_frames_in_one_line() {
    let cache = tempfile::tempdir().unwrap();
    let opts = DemoOptions {
        frames: 0,
        cache_dir: Some(cache.path().to_path_buf()),
        progress: false,
        ..DemoOptions::default()
    };
    let e = run_demo(&opts).unwrap_err().to_string();
    assert!(!e.contains('\n') && e.contains("frame"), "{e}");
}
