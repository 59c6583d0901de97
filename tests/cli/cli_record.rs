//! `omnitrack record` as a black box: a replay re-recorded is the same recording (every image
//! to the byte, every timestamp), so it tracks to the same trajectory; a non-empty output
//! directory and a bad source are one line and a non-zero exit.

use crate::common::omnitrack;

#[cfg(feature = "desk")]
#[test]
fn a_replay_recorded_again_replays_to_the_same_frames_and_trajectory() {
    use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
    use omnitrack::config::TrackerConfig;
    use omnitrack::frame::FrameSet;
    use omnitrack::runtime::{track, RunOptions};
    use omnitrack::tracker::SearchVolume;

    let lab = crate::common::lab_recording(8);
    let out = lab.dir.path().join("again");
    let (code, stdout, stderr) = omnitrack(&[
        "record",
        "--source",
        &format!("replay:{}", lab.rec.display()),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty());
    assert!(
        stderr.contains("8 frames captured, 8 written (48 images), 0 dropped"),
        "{stderr}"
    );

    // Frame by frame: the same images, validity, timestamps and numbers.
    let mut a = ReplaySource::open(&lab.rec, Pacing::AsFastAsPossible).unwrap();
    let mut b = ReplaySource::open(&out, Pacing::AsFastAsPossible).unwrap();
    assert_eq!(a.rig(), b.rig());
    let (mut fa, mut fb) = (FrameSet::for_rig(a.rig()), FrameSet::for_rig(b.rig()));
    let mut frames = 0;
    while a.next_frame(&mut fa).unwrap() {
        assert!(b.next_frame(&mut fb).unwrap(), "the copy ends early");
        assert_eq!(fa.sequence, fb.sequence);
        for (x, y) in fa.sensors().iter().zip(fb.sensors()) {
            assert_eq!((x.valid, x.timestamp_ns), (y.valid, y.timestamp_ns));
            assert!(
                x.pixels() == y.pixels(),
                "frame {} sensor {} differs",
                fa.sequence,
                x.sensor()
            );
        }
        frames += 1;
    }
    assert!(!b.next_frame(&mut fb).unwrap(), "the copy has more frames");
    assert_eq!(frames, 8);

    // And the tracker, given the same frames, gives the same poses.
    let trajectory = |dir: &std::path::Path| {
        let mut source = ReplaySource::open(dir, Pacing::AsFastAsPossible).unwrap();
        let opts = RunOptions {
            hint: Some(SearchVolume {
                centre: nalgebra::Point3::from(lab.truth[0].pose.translation.vector),
                diameter_m: Some(3.0),
            }),
            ..RunOptions::default()
        };
        let mut poses = Vec::new();
        let mut cfg = TrackerConfig::default();
        // The searches stop on their work, which repeats; the consensus's clock backstop is
        // moved out of reach.
        cfg.maintenance.time_budget_ms *= 5.0;
        track(&mut source, &lab.model, &lab.table, &cfg, &opts, &mut |r, _| {
            poses.push(r.result.pose);
            Ok(())
        })
        .unwrap();
        poses
    };
    assert_eq!(trajectory(&lab.rec), trajectory(&out));
}

#[test]
fn a_non_empty_output_and_a_bad_source_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("keep.txt"), "mine").unwrap();
    let (code, _, stderr) = omnitrack(&[
        "record",
        "--source",
        "replay:/nonexistent",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_ne!(code, 0);
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.contains("/nonexistent"), "{stderr}");
    let (code, _, stderr) = omnitrack(&["record", "--source", "bogus", "--out", "/tmp/never"]);
    assert_ne!(code, 0);
    assert!(stderr.contains("unknown source"), "{stderr}");
    assert!(!std::path::Path::new("/tmp/never").exists());
}
