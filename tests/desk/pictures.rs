//! The pictures of a run: each is a PNG of the promised size with real content (many colours),
//! and the omnidirectional view draws the model in green exactly where the lens projects it.
//! Set OMNITRACK_KEEP_PICTURES=DIR to keep the pictures for a look.
#![cfg(feature = "desk")]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use omnitrack::desk::eval::{evaluate, EvalOptions};
use omnitrack::desk::pictures::{
    correspondence_states, error_over_time, frame_images, omni_layout, omni_view, plan_view, CorrespondenceState,
    ErrorTrace, OmniOptions, PlanOptions, StateTrace, MODEL_GREEN,
};
use omnitrack::desk::render::{Appearance, FrameSpec, Renderer};
use omnitrack::trajectory::Stamped;
use omnitrack::{Model, Rig};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// An 8 × 5 m room, 2.7 m high, split by a partition with a 1 m door gap.
const ROOM_OBJ: &str = "\
o room
v 0 0 0
v 8 0 0
v 8 5 0
v 0 5 0
v 0 0 2.7
v 8 0 2.7
v 8 5 2.7
v 0 5 2.7
usemtl floor
f 1 4 3 2
usemtl ceiling
f 5 6 7 8
usemtl wall
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
o partition
v 5 0 0
v 5 4 0
v 5 4 2.7
v 5 0 2.7
f 9 10 11 12
";

fn out_dir() -> (Option<tempfile::TempDir>, PathBuf) {
    match std::env::var_os("OMNITRACK_KEEP_PICTURES") {
        Some(dir) => {
            std::fs::create_dir_all(&dir).unwrap();
            (None, PathBuf::from(dir))
        }
        None => {
            let tmp = tempfile::tempdir().unwrap();
            let path = tmp.path().to_path_buf();
            (Some(tmp), path)
        }
    }
}

fn rig() -> Rig {
    crate::common::shipped_rig()
}

fn model() -> Model {
    Model::from_obj_str(ROOM_OBJ, "room.obj").unwrap()
}

/// A walk around the partition, through the door, at 30 Hz.
fn ground_truth() -> Vec<Stamped> {
    (0..300)
        .map(|k| {
            let a = k as f64 / 300.0 * std::f64::consts::TAU;
            Stamped {
                timestamp_ns: 5_000_000_000 + k as u64 * 33_333_333,
                pose: Isometry3::from_parts(
                    Translation3::new(4.5 + 2.8 * a.cos(), 2.5 + 1.6 * a.sin(), 1.6),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, a + std::f64::consts::FRAC_PI_2),
                ),
            }
        })
        .collect()
}

/// The ground truth with a smooth error that grows and shrinks, and a few lost frames.
fn estimate(gt: &[Stamped]) -> Vec<Stamped> {
    gt.iter()
        .enumerate()
        .filter(|(k, _)| !(120..135).contains(k))
        .map(|(k, s)| {
            let e = 0.08 * (k as f64 * 0.05).sin().powi(2);
            let wobble = UnitQuaternion::from_euler_angles(0.0, 0.01 * (k as f64 * 0.3).sin(), 0.02 * e);
            Stamped {
                timestamp_ns: s.timestamp_ns + 2_000_000,
                pose: Isometry3::from_parts(
                    Translation3::from(s.pose.translation.vector + Vector3::new(e, -0.5 * e, 0.01)),
                    s.pose.rotation * wobble,
                ),
            }
        })
        .collect()
}

/// Decodes a written PNG, checks its size and returns its RGB pixels.
fn decode(path: &Path, size: (u32, u32)) -> image::RgbImage {
    assert!(path.exists(), "{} was not written", path.display());
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!((img.width(), img.height()), size, "{}", path.display());
    img.to_rgb8()
}

fn distinct_colours(img: &image::RgbImage) -> usize {
    img.pixels().map(|p| p.0).collect::<HashSet<_>>().len()
}

#[test]
fn plan_error_and_state_pictures_are_pngs_with_content() {
    let (_keep, dir) = out_dir();
    let model = model();
    let gt = ground_truth();
    let est = estimate(&gt);
    let ev = evaluate(&gt, &est, &EvalOptions::default()).unwrap();

    let plan = dir.join("plan.png");
    let options = PlanOptions {
        title: format!("Synthetic room: ATE RMSE {:.1} cm", ev.ate.translation_m.rmse * 100.0),
        ..PlanOptions::default()
    };
    plan_view(&plan, &model, &gt, &est, &ev.position_error_per_estimate(), &options).unwrap();
    let img = decode(&plan, options.size);
    assert!(
        distinct_colours(&img) > 100,
        "plan has {} colours",
        distinct_colours(&img)
    );

    let errors = dir.join("errors.png");
    let traces = [
        ErrorTrace {
            label: "ATE",
            errors: &ev.ate.per_pose,
        },
        ErrorTrace {
            label: "RPE (1 frame)",
            errors: &ev.rpe.as_ref().unwrap().per_pose,
        },
    ];
    error_over_time(&errors, "Error over time", &traces, (1200, 900)).unwrap();
    assert!(distinct_colours(&decode(&errors, (1200, 900))) > 50);

    let states = dir.join("states.png");
    let traces: Vec<StateTrace> = (0..6)
        .map(|c| StateTrace {
            label: format!("segment {} / sensor {}", 10 + 7 * c, c % 5),
            samples: (0..90)
                .map(|k| {
                    let code = match (k + 11 * c) % 40 {
                        0..=4 => 0,
                        5..=9 => 1,
                        _ => 2,
                    };
                    (k as f64 / 30.0, CorrespondenceState::from_code(code).unwrap())
                })
                .collect(),
        })
        .collect();
    correspondence_states(&states, "Correspondence states", &traces, (1200, 600)).unwrap();
    let img = decode(&states, (1200, 600));
    assert!(distinct_colours(&img) > 20);
    // All three states show up as bands.
    for colour in [[215, 215, 215], [245, 170, 40], [40, 160, 70]] {
        let n = img.pixels().filter(|p| p.0 == colour).count();
        assert!(n > 2000, "{colour:?}: {n} pixels");
    }
}

#[test]
fn omni_view_draws_the_model_in_green_where_it_projects() {
    let (_keep, dir) = out_dir();
    let model = model();
    let rig = rig();
    let pose = Isometry3::from_parts(
        Translation3::new(3.0, 2.2, 1.5),
        UnitQuaternion::from_euler_angles(0.03, -0.02, 0.4),
    );
    let appearance = Appearance {
        clutter: 0.0,
        people: 0.0,
        ..Appearance::default()
    };
    let images = Renderer::new(&model, &rig, appearance, &[]).render_frame(&FrameSpec {
        index: 0,
        timestamp_ns: 1_000_000_000,
        pose,
        previous: None,
    });
    let path = dir.join("omni.png");
    let options = OmniOptions::default();
    omni_view(&path, &rig, &images, &model, &pose, &options).unwrap();
    let layout = omni_layout(&rig, options.columns);
    let img = decode(&path, layout.size);
    assert!(distinct_colours(&img) > 200);
    let green = |x: u32, y: u32| img.get_pixel(x, y).0 == MODEL_GREEN;
    let (mut checked, mut hit) = (0, 0);
    for (k, &(x0, y0)) in layout.origins.iter().enumerate() {
        let segments = model.segments.iter().map(|s| (s.a, s.b));
        for run in omnitrack::rig::project_segments(&rig.sensors[k], &pose.inverse(), segments, 1.0) {
            for p in run.iter().step_by(7) {
                checked += 1;
                hit += green(x0 + p.x.round() as u32, y0 + p.y.round() as u32) as usize;
            }
        }
    }
    assert!(checked > 300, "only {checked} projected points");
    assert!(
        hit as f64 > 0.97 * checked as f64,
        "{hit} of {checked} projected points are green"
    );

    // A frame's images go through frame_images; a wrong count is an error naming the file.
    let frame = omnitrack::frame::FrameSet::for_rig(&rig);
    let grey = frame_images(&frame);
    assert_eq!(grey.len(), rig.sensors.len());
    let e = omni_view(&path, &rig, &grey[..2], &model, &pose, &options).unwrap_err();
    assert!(
        e.to_string().starts_with(&format!("{}: 2 images", path.display())),
        "{e}"
    );
}

#[test]
fn bad_input_is_an_error_naming_the_file() {
    let (_keep, dir) = out_dir();
    let path = dir.join("nothing.png");
    let e = error_over_time(&path, "t", &[], (800, 600)).unwrap_err();
    assert_eq!(e.to_string(), format!("{}: no errors to draw", path.display()));
    let e = correspondence_states(
        &path,
        "t",
        &[StateTrace {
            label: "a".into(),
            samples: vec![
                (1.0, CorrespondenceState::Unknown),
                (0.5, CorrespondenceState::Accepted),
            ],
        }],
        (800, 600),
    )
    .unwrap_err();
    assert!(
        e.to_string().ends_with("trace 'a': times must be finite and in order"),
        "{e}"
    );
    let gt = ground_truth();
    let e = plan_view(
        &dir.join("missing_dir/plan.png"),
        &model(),
        &gt,
        &gt,
        &[],
        &PlanOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("cannot write PNG"), "{e}");
    assert!(CorrespondenceState::from_code(3).is_none());
}
