//! End to end through files: render a short `lab` recording with the desk renderer, read it back
//! through the mock camera, and check frames, timestamps, ground truth, and that the images show
//! the model where the lens and the ground-truth pose say it is.
#![cfg(feature = "desk")]

use nalgebra::{Point2, Vector3};
use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack::desk::recording::{write_recording, RecordingOptions};
use omnitrack::desk::render::{Appearance, Renderer};
use omnitrack::desk::scenario::{Scenario, ScenarioName};
use omnitrack::frame::FrameSet;
use omnitrack::{Model, Rig};

fn rig() -> Rig {
    crate::common::shipped_rig()
}

/// Largest per-channel spread of colours in the 5 × 5 patch around a pixel.
fn spread(frame: &FrameSet, sensor: usize, px: &Point2<f64>) -> i32 {
    let img = frame.sensor(sensor);
    let (u0, v0) = (px.x.round() as i64, px.y.round() as i64);
    let mut lo = [255i32; 3];
    let mut hi = [0i32; 3];
    for v in v0 - 2..=v0 + 2 {
        for u in u0 - 2..=u0 + 2 {
            if u < 0 || v < 0 || u >= img.width() as i64 || v >= img.height() as i64 {
                continue;
            }
            let c = img.rgb(u as u32, v as u32);
            for k in 0..3 {
                lo[k] = lo[k].min(c[k] as i32);
                hi[k] = hi[k].max(c[k] as i32);
            }
        }
    }
    (0..3).map(|k| hi[k] - lo[k]).max().unwrap()
}

#[test]
fn rendered_recording_replays_with_its_ground_truth_and_model_vertices_on_colour_boundaries() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let lab = Scenario::get(ScenarioName::Lab);
    let obj = lab.model_obj().unwrap();
    let model = Model::from_obj_str(&obj, "model.obj").unwrap();
    let rig = rig();
    let truth = lab.trajectory(4, 7);
    // Geometry is what is checked here: no clutter, people, noise, vignetting or texture to blur
    // the answer (shading and lighting drift stay on; tests/desk/render.rs covers the effects). Face
    // middles then spread by at most ~4 grey levels and model vertices by at least ~12.
    let appearance = Appearance {
        clutter: 0.0,
        people: 0.0,
        noise: 0.0,
        vignetting: 0.0,
        texture: 0.0,
        ..Appearance::default()
    };
    let options = RecordingOptions {
        appearance,
        ..RecordingOptions::default()
    };
    let summary = write_recording(&rec, &rig, &obj, &truth, &options, |_, _| {}).unwrap();
    assert_eq!((summary.frames, summary.images), (4, 24));

    let mut replay = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
    let gt = replay.ground_truth().expect("groundtruth.tum written").clone();
    assert_eq!(gt.len(), 4);
    for (a, b) in gt.iter().zip(&truth) {
        assert_eq!(a.timestamp_ns, b.timestamp_ns);
        assert!((a.pose.translation.vector - b.pose.translation.vector).norm() < 1e-8);
        assert!(a.pose.rotation.angle_to(&b.pose.rotation) < 1e-9);
    }
    assert!(replay.model_path().is_some());

    // The same scene (clutter and people included) tells which vertices each sensor really sees.
    let scene = Renderer::new(
        &model,
        &rig,
        options.appearance.clone(),
        &truth
            .iter()
            .map(|s| s.pose.translation.vector.into())
            .collect::<Vec<_>>(),
    );
    let mut frame = FrameSet::for_rig(&rig);
    let mut frames = 0;
    let mut checked = 0;
    let mut inside = 0;
    let (mut min_vertex, mut max_inside) = (i32::MAX, 0);
    const BOUNDARY: i32 = 8;
    while replay.next_frame(&mut frame).unwrap() {
        let k = frames;
        frames += 1;
        let pose = truth[k].pose;
        for s in &rig.sensors {
            let img = frame.sensor(s.id);
            assert!(img.valid, "frame {k} sensor {}", s.id);
            let expected = truth[k].timestamp_ns + s.id as u64 * options.sensor_stagger_ns;
            assert_eq!(img.timestamp_ns, expected);
            let centre = pose * s.centre();
            for v in &model.vertices {
                let Some(px) = s.project_from_rig(&pose.inverse_transform_point(v)) else {
                    continue;
                };
                // Keep clear of the image border so the 5 × 5 patch is whole.
                if px.x < 3.0 || px.y < 3.0 || px.x > s.width as f64 - 4.0 || px.y > s.height as f64 - 4.0 {
                    continue;
                }
                let to = v - centre;
                let dist = to.norm();
                let Some(hit) = scene.cast(&centre, &(to / dist)) else {
                    continue;
                };
                if (hit.t - dist).abs() > 0.02 || dist > 12.0 {
                    continue; // hidden behind a wall, clutter or a person, or too far to resolve
                }
                let sp = spread(&frame, s.id, &px);
                min_vertex = min_vertex.min(sp);
                assert!(
                    sp >= BOUNDARY,
                    "frame {k} sensor {}: vertex {v:?} at {px:?} shows no colour boundary ({sp})",
                    s.id
                );
                checked += 1;
            }
            // The negative control: the middle of every face in view is not on a boundary.
            for f in &model.faces {
                let mid = f
                    .vertices
                    .iter()
                    .fold(Vector3::zeros(), |a, &i| a + model.vertices[i as usize].coords)
                    / f.vertices.len() as f64;
                let Some(px) = s.project_from_rig(&pose.inverse_transform_point(&mid.into())) else {
                    continue;
                };
                if px.x < 3.0 || px.y < 3.0 || px.x > s.width as f64 - 4.0 || px.y > s.height as f64 - 4.0 {
                    continue;
                }
                let to = mid - centre.coords;
                let dist = to.norm();
                let Some(hit) = scene.cast(&centre, &(to / dist)) else {
                    continue;
                };
                // Far enough from every segment in the image that the patch is inside the face.
                let clear = model.segments.iter().all(|seg| {
                    (0..=20).all(|j| {
                        let p = seg.a + (seg.b - seg.a) * (j as f64 / 20.0);
                        s.project_from_rig(&pose.inverse_transform_point(&p))
                            .is_none_or(|q| (q - px).norm() > 12.0)
                    })
                });
                if (hit.t - dist).abs() > 0.02 || !clear {
                    continue;
                }
                let sp = spread(&frame, s.id, &px);
                max_inside = max_inside.max(sp);
                assert!(
                    sp < BOUNDARY,
                    "frame {k} sensor {}: face middle {mid:?} at {px:?} looks like a boundary ({sp})",
                    s.id
                );
                inside += 1;
            }
        }
    }
    assert_eq!(frames, 4);
    eprintln!("{checked} vertices (smallest spread {min_vertex}), {inside} face middles (largest spread {max_inside})");
    assert!(checked >= 20, "only {checked} visible vertices checked");
    assert!(inside >= 10, "only {inside} face middles checked");
    assert_eq!(replay.stats().frames_delivered, 4);
}
