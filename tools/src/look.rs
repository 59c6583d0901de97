//! `omnitrack-desk overlay` and `omnitrack-desk plot`: the demo's pictures for anyone's run.
//!
//! In: a recording (the layout `omnitrack run --source replay:DIR` reads, e.g. one made by
//! `omnitrack record`), the building model, a TUM trajectory (`omnitrack run --trajectory`) and,
//! for `plot`, optionally the ground truth. Out: PNG files.
//!
//! - overlay: one frame's sensor images tiled, the model re-projected through each sensor's lens
//!   at the trajectory's pose for that frame (Koch–Teller Figure 12): a wrong calibration, frame
//!   convention or model shows at a glance;
//! - plot: the trajectory over the floor plan, coloured by its position error when the ground
//!   truth is given (Figures 1, 10, 11), and the position and rotation error over time.

use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack::desk::eval::{evaluate, EvalOptions};
use omnitrack::desk::pictures::{
    error_over_time, frame_images, omni_view, plan_view, ErrorTrace, OmniOptions, PlanOptions,
};
use omnitrack::frame::FrameSet;
use omnitrack::trajectory::{load_tum, Stamped};
use omnitrack::Model;
use std::path::Path;

/// A file's name, for a picture's title (its whole path may not fit).
fn name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

/// Largest gap (ns) between a frame's timestamp and the trajectory pose drawn over it.
const SAME_INSTANT_NS: u64 = 10_000_000;

/// `overlay`: frame `frame` of `recording` (its number in frames.csv; default the first frame
/// with a pose) with the model drawn at the trajectory's pose, to `out`.
pub fn overlay(
    recording: &Path,
    model_path: &Path,
    trajectory: &Path,
    frame: Option<u64>,
    out: &Path,
) -> Result<String, String> {
    let model = Model::load(model_path).map_err(|e| e.to_string())?;
    let poses = load_tum(trajectory).map_err(|e| e.to_string())?;
    if poses.is_empty() {
        return Err(format!("{}: no poses", trajectory.display()));
    }
    let mut source = ReplaySource::open(recording, Pacing::AsFastAsPossible).map_err(|e| e.to_string())?;
    let rig = source.rig().clone();
    let mut set = FrameSet::for_rig(&rig);
    loop {
        if !source.next_frame(&mut set).map_err(|e| e.to_string())? {
            return Err(match frame {
                Some(n) => format!(
                    "{}: no frame {n}, or it has no pose in {}",
                    recording.display(),
                    trajectory.display()
                ),
                None => format!(
                    "{}: no frame has a pose in {} (timestamps within 10 ms)",
                    recording.display(),
                    trajectory.display()
                ),
            });
        }
        if frame.is_some_and(|n| set.sequence != n) {
            continue;
        }
        let Some(t) = set.timestamp_ns() else { continue };
        if let Some(pose) = nearest(&poses, t) {
            let options = OmniOptions {
                title: format!(
                    "{}, frame {}: the model at the pose of {}",
                    name(recording),
                    set.sequence,
                    name(trajectory)
                ),
                columns: columns(rig.sensors.len()),
                ..OmniOptions::default()
            };
            omni_view(out, &rig, &frame_images(&set), &model, &pose.pose, &options).map_err(|e| e.to_string())?;
            return Ok(format!("{}: frame {}", out.display(), set.sequence));
        }
        if frame.is_some() {
            return Err(format!(
                "{}: frame {} (t = {t} ns) has no pose in {} within 10 ms",
                recording.display(),
                set.sequence,
                trajectory.display()
            ));
        }
    }
}

/// The pose within [`SAME_INSTANT_NS`] of `t`, the nearest.
fn nearest(poses: &[Stamped], t: u64) -> Option<&Stamped> {
    poses
        .iter()
        .filter(|p| p.timestamp_ns.abs_diff(t) <= SAME_INSTANT_NS)
        .min_by_key(|p| p.timestamp_ns.abs_diff(t))
}

/// Tiles per row: the shipped rig's six portrait images in 3 × 2, one panorama alone.
fn columns(sensors: usize) -> usize {
    match sensors {
        0..=2 => sensors.max(1),
        4 => 2,
        _ => 3,
    }
}

/// `plot`: `plan.png` (the trajectory over the plan, coloured by its error when `truth` is
/// given) and, with the truth, `errors.png` (position and rotation error over time) in `out`.
pub fn plot(model_path: &Path, trajectory: &Path, truth: Option<&Path>, out: &Path) -> Result<String, String> {
    let model = Model::load(model_path).map_err(|e| e.to_string())?;
    let estimate = load_tum(trajectory).map_err(|e| e.to_string())?;
    if estimate.is_empty() {
        return Err(format!("{}: no poses", trajectory.display()));
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let plan = out.join("plan.png");
    let Some(truth) = truth else {
        let options = PlanOptions {
            title: format!("{} over the plan of {}", name(trajectory), name(model_path)),
            ..PlanOptions::default()
        };
        plan_view(&plan, &model, &[], &estimate, &[], &options).map_err(|e| e.to_string())?;
        return Ok(format!("{}", plan.display()));
    };
    let gt = load_tum(truth).map_err(|e| e.to_string())?;
    let evaluation = evaluate(&gt, &estimate, &EvalOptions::default()).map_err(|e| e.to_string())?;
    let options = PlanOptions {
        title: format!(
            "{} against {}: ATE RMSE {:.1} cm over {} poses",
            name(trajectory),
            name(truth),
            100.0 * evaluation.ate.translation_m.rmse,
            evaluation.pairs.len()
        ),
        ..PlanOptions::default()
    };
    plan_view(
        &plan,
        &model,
        &gt,
        &estimate,
        &evaluation.position_error_per_estimate(),
        &options,
    )
    .map_err(|e| e.to_string())?;
    let errors = out.join("errors.png");
    let traces = [ErrorTrace {
        label: "ATE",
        errors: &evaluation.ate.per_pose,
    }];
    error_over_time(&errors, "Error over time", &traces, (1600, 800)).map_err(|e| e.to_string())?;
    Ok(format!("{} and {}", plan.display(), errors.display()))
}
