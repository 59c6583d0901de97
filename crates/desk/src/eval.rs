//! Trajectory evaluation: how far an estimated trajectory is from the ground truth, with the
//! numbers `evo` prints, so that our tables can be checked against it (`tools/check_evo.py`).
//!
//! In: two trajectories of `T_world_rig` (ground truth and estimate, [`omnitrack_core::trajectory`]) and
//! [`EvalOptions`]. Out: an [`Evaluation`] — the poses associated by timestamp, the absolute pose
//! error (ATE) and the relative pose error (RPE), each as statistics and per-pose errors, for
//! translation (metres) and rotation (degrees).
//!
//! The definitions are evo's (1.38):
//! - association: the trajectory with fewer poses (the estimate on a tie) keeps each pose whose
//!   nearest timestamp in the other lies within `max_diff_s` (a tie goes to the earlier pose);
//! - ATE translation `‖t_est − t_gt‖` (`evo_ape tum gt est`), ATE rotation the angle of
//!   `R_est⁻¹ R_gt` (`-r angle_deg`);
//! - RPE over consecutive pairs `(0, d), (d, 2d), …` of the associated poses
//!   (`evo_rpe tum gt est --delta d --delta_unit f`): `E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)`, translation
//!   `‖t(E)‖`, rotation the angle of `R(E)`;
//! - statistics: RMSE, mean, median (mean of the middle two for an even count), population
//!   standard deviation, min, max;
//! - alignment (`--align`): Umeyama's least-squares rigid motion (no scale) of the estimated
//!   positions onto the ground-truth positions, applied to the estimate before the errors.
//!
//! No alignment is the default here (evo's default too): the tracker estimates poses in the
//! model's frame, so any rigid offset is an error to report, not a gauge freedom to remove.
//!
//! Files, each importing only those before it: `eval/options.rs` ([`EvalOptions`], [`EvalError`]),
//! `eval/stats.rs` (the error series and their [`Stats`]), `eval/associate.rs` ([`associate`]),
//! `eval/align.rs` ([`align_rigid`]); this one compares ([`evaluate`]) and prints the result
//! ([`Evaluation::table`]).

mod align;
mod associate;
mod options;
mod stats;

pub use align::{align_rigid, transformed};
pub use associate::associate;
pub use options::{EvalError, EvalOptions};
pub use stats::{ErrorSeries, PoseError, Stats};

use nalgebra::{Point3, UnitQuaternion};
use omnitrack_core::geometry::Pose;
use omnitrack_core::trajectory::{load_tum_whole_lines, Stamped, TumError};
use std::fmt::Write as _;
use std::path::Path;

/// The comparison of an estimate with the ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    pub options: EvalOptions,
    pub gt_poses: usize,
    pub est_poses: usize,
    /// Associated (ground-truth index, estimate index) pairs in time order.
    pub pairs: Vec<(usize, usize)>,
    /// The rigid motion applied to the estimate (`T_world_est`), when aligning.
    pub alignment: Option<Pose>,
    pub ate: ErrorSeries,
    /// `None` when fewer than `rpe_delta + 1` poses were associated.
    pub rpe: Option<ErrorSeries>,
    /// Lines left out of the files read: a last line cut off by its writer (a full disk).
    pub cut_lines: Vec<TumError>,
}

fn angle_deg(r: &UnitQuaternion<f64>) -> f64 {
    r.angle().to_degrees()
}

/// Compares an estimate with the ground truth (both `T_world_rig`, in time order).
pub fn evaluate(gt: &[Stamped], est: &[Stamped], options: &EvalOptions) -> Result<Evaluation, EvalError> {
    if !(options.max_diff_s.is_finite() && options.max_diff_s >= 0.0) {
        return Err(EvalError::Option(format!(
            "max time difference must be a finite number ≥ 0 s, found {}",
            options.max_diff_s
        )));
    }
    if options.rpe_delta == 0 {
        return Err(EvalError::Option("RPE delta must be at least 1 frame".into()));
    }
    let pairs = associate(gt, est, options.max_diff_s);
    if pairs.is_empty() {
        return Err(EvalError::NoMatches {
            max_diff_s: options.max_diff_s,
            gt_poses: gt.len(),
            est_poses: est.len(),
        });
    }
    let alignment = if options.align {
        let from: Vec<Point3<f64>> = pairs
            .iter()
            .map(|&(_, e)| est[e].pose.translation.vector.into())
            .collect();
        let to: Vec<Point3<f64>> = pairs
            .iter()
            .map(|&(g, _)| gt[g].pose.translation.vector.into())
            .collect();
        Some(align_rigid(&from, &to)?)
    } else {
        None
    };
    let est_pose = |k: usize| match &alignment {
        Some(t) => t * est[k].pose,
        None => est[k].pose,
    };

    let ate = pairs
        .iter()
        .map(|&(g, e)| {
            let p = est_pose(e);
            let q = &gt[g].pose;
            PoseError {
                timestamp_ns: est[e].timestamp_ns,
                gt_index: g,
                est_index: e,
                translation_m: (p.translation.vector - q.translation.vector).norm(),
                rotation_deg: angle_deg(&(p.rotation.inverse() * q.rotation)),
            }
        })
        .collect();
    let ate = ErrorSeries::from_errors(ate).ok_or(EvalError::NoMatches {
        max_diff_s: options.max_diff_s,
        gt_poses: gt.len(),
        est_poses: est.len(),
    })?;

    let d = options.rpe_delta;
    let rpe = (0..pairs.len())
        .step_by(d)
        .zip((d..pairs.len()).step_by(d))
        .map(|(i, j)| {
            let ((gi, ei), (gj, ej)) = (pairs[i], pairs[j]);
            let q_rel = gt[gi].pose.inv_mul(&gt[gj].pose);
            let p_rel = est_pose(ei).inv_mul(&est_pose(ej));
            let e = q_rel.inv_mul(&p_rel);
            PoseError {
                timestamp_ns: est[ej].timestamp_ns,
                gt_index: gj,
                est_index: ej,
                translation_m: e.translation.vector.norm(),
                rotation_deg: angle_deg(&e.rotation),
            }
        })
        .collect();
    let rpe = ErrorSeries::from_errors(rpe);

    Ok(Evaluation {
        options: *options,
        gt_poses: gt.len(),
        est_poses: est.len(),
        pairs,
        alignment,
        ate,
        rpe,
        cut_lines: Vec::new(),
    })
}

/// Reads two TUM files and compares them; errors name both files.
pub fn evaluate_files(gt: &Path, est: &Path, options: &EvalOptions) -> Result<Evaluation, EvalError> {
    let (gt_traj, gt_cut) = load_tum_whole_lines(gt)?;
    let (est_traj, est_cut) = load_tum_whole_lines(est)?;
    let mut evaluation = evaluate(&gt_traj, &est_traj, options).map_err(|e| EvalError::Files {
        gt: gt.display().to_string(),
        est: est.display().to_string(),
        source: Box::new(e),
    })?;
    evaluation.cut_lines.extend(gt_cut.into_iter().chain(est_cut));
    Ok(evaluation)
}

impl Evaluation {
    /// The estimate's ATE position error (m) per estimated pose, `None` where the pose was not
    /// associated; for colouring the estimated path.
    pub fn position_error_per_estimate(&self) -> Vec<Option<f64>> {
        let mut out = vec![None; self.est_poses];
        for e in &self.ate.per_pose {
            out[e.est_index] = Some(e.translation_m);
        }
        out
    }

    /// A short human-readable table: ATE and RPE, translation in cm and rotation in degrees.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let align = if self.options.align {
            "SE(3)-aligned"
        } else {
            "no alignment"
        };
        let _ = writeln!(
            out,
            "{} of {} estimated poses matched to {} ground-truth poses (max Δt {} s, {align})",
            self.pairs.len(),
            self.est_poses,
            self.gt_poses,
            self.options.max_diff_s
        );
        let _ = writeln!(
            out,
            "{:<22} {:>9} {:>9} {:>9} {:>9} {:>7}",
            "metric", "rmse", "mean", "median", "max", "count"
        );
        let mut row = |name: String, s: Option<&Stats>, scale: f64| match s {
            Some(s) => {
                let _ = writeln!(
                    out,
                    "{name:<22} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>7}",
                    s.rmse * scale,
                    s.mean * scale,
                    s.median * scale,
                    s.max * scale,
                    s.count
                );
            }
            None => {
                let _ = writeln!(out, "{name:<22} {:>9} {:>9} {:>9} {:>9} {:>7}", "n/a", "", "", "", 0);
            }
        };
        row("ATE translation (cm)".into(), Some(&self.ate.translation_m), 100.0);
        row("ATE rotation (deg)".into(), Some(&self.ate.rotation_deg), 1.0);
        let d = self.options.rpe_delta;
        row(
            format!("RPE/{d} translation (cm)"),
            self.rpe.as_ref().map(|r| &r.translation_m),
            100.0,
        );
        row(
            format!("RPE/{d} rotation (deg)"),
            self.rpe.as_ref().map(|r| &r.rotation_deg),
            1.0,
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, Vector3};

    fn wiggly(n: usize) -> Vec<Stamped> {
        (0..n)
            .map(|k| {
                let s = k as f64 * 0.1;
                Stamped {
                    timestamp_ns: 1_000_000_000 + k as u64 * 100_000_000,
                    pose: Isometry3::new(
                        Vector3::new(s.cos() * 3.0, s.sin() * 2.0, 1.5 + 0.1 * (3.0 * s).sin()),
                        Vector3::new(0.1 * s.sin(), 0.05 * s.cos(), s),
                    ),
                }
            })
            .collect()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn identical_trajectories_have_zero_error() {
        let gt = wiggly(50);
        let ev = evaluate(&gt, &gt, &EvalOptions::default()).unwrap();
        assert_eq!(ev.pairs.len(), 50);
        assert!(ev.ate.translation_m.max < 1e-12);
        assert!(ev.ate.rotation_deg.max < 1e-6);
        let rpe = ev.rpe.unwrap();
        assert_eq!(rpe.translation_m.count, 49);
        assert!(rpe.translation_m.max < 1e-12 && rpe.rotation_deg.max < 1e-6);
    }

    #[test]
    fn constant_offset_is_the_ate_and_vanishes_in_rpe_and_with_alignment() {
        let gt = wiggly(40);
        let offset = Vector3::new(0.06, 0.0, 0.08); // 0.1 m
        let est: Vec<Stamped> = gt
            .iter()
            .map(|s| Stamped {
                timestamp_ns: s.timestamp_ns,
                pose: Isometry3::from_parts(Translation3::from(s.pose.translation.vector + offset), s.pose.rotation),
            })
            .collect();
        let ev = evaluate(&gt, &est, &EvalOptions::default()).unwrap();
        let t = ev.ate.translation_m;
        assert!(close(t.rmse, 0.1) && close(t.mean, 0.1) && close(t.median, 0.1));
        assert!(close(t.min, 0.1) && close(t.max, 0.1) && t.std < 1e-9);
        assert!(ev.ate.rotation_deg.max < 1e-6);
        // A shift of the whole trajectory leaves every relative pose as it was.
        assert!(ev.rpe.as_ref().unwrap().translation_m.max < 1e-9);
        let aligned = evaluate(
            &gt,
            &est,
            &EvalOptions {
                align: true,
                ..EvalOptions::default()
            },
        )
        .unwrap();
        assert!(aligned.ate.translation_m.max < 1e-9);
    }

    #[test]
    fn a_known_rotation_gives_its_angle() {
        let gt = wiggly(20);
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 3f64.to_radians());
        // Rotating the rig in its own frame: position unchanged, every ATE rotation is 3°.
        let est: Vec<Stamped> = gt
            .iter()
            .map(|s| Stamped {
                timestamp_ns: s.timestamp_ns,
                pose: s.pose * tilt,
            })
            .collect();
        let ev = evaluate(&gt, &est, &EvalOptions::default()).unwrap();
        assert!(ev.ate.translation_m.max < 1e-12);
        assert!(close(ev.ate.rotation_deg.min, 3.0) && close(ev.ate.rotation_deg.max, 3.0));
        // One pose rotated by 10° about z: one RPE pair into it and one out of it see 10°.
        let mut est = gt.clone();
        est[7].pose *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 10f64.to_radians());
        let ev = evaluate(&gt, &est, &EvalOptions::default()).unwrap();
        let rpe = ev.rpe.unwrap();
        let big: Vec<usize> = rpe
            .per_pose
            .iter()
            .filter(|e| e.rotation_deg > 1e-6)
            .map(|e| e.est_index)
            .collect();
        assert_eq!(big, vec![7, 8]);
        assert!(close(rpe.rotation_deg.max, 10.0));
    }

    #[test]
    fn alignment_removes_a_rigid_transform_exactly() {
        let gt = wiggly(60);
        let t = Isometry3::new(Vector3::new(4.0, -2.0, 0.3), Vector3::new(0.2, -0.1, 1.3));
        let est = transformed(&gt, &t);
        let raw = evaluate(&gt, &est, &EvalOptions::default()).unwrap();
        assert!(raw.ate.translation_m.min > 0.5);
        let ev = evaluate(
            &gt,
            &est,
            &EvalOptions {
                align: true,
                ..EvalOptions::default()
            },
        )
        .unwrap();
        assert!(ev.ate.translation_m.max < 1e-9, "{:?}", ev.ate.translation_m);
        assert!(ev.ate.rotation_deg.max < 1e-6);
        let a = ev.alignment.unwrap();
        assert!((a * t).translation.vector.norm() < 1e-9);
        assert!((a * t).rotation.angle() < 1e-9);
    }

    #[test]
    fn alignment_of_collinear_positions_is_an_error() {
        let gt: Vec<Stamped> = (0..10)
            .map(|k| Stamped {
                timestamp_ns: k * 100_000_000,
                pose: Isometry3::translation(k as f64, 0.0, 0.0),
            })
            .collect();
        let e = evaluate(
            &gt,
            &gt,
            &EvalOptions {
                align: true,
                ..EvalOptions::default()
            },
        )
        .unwrap_err();
        assert!(
            e.to_string().starts_with("cannot align: the positions lie on a line"),
            "{e}"
        );
    }

    #[test]
    fn association_takes_the_nearest_within_max_diff_like_evo() {
        let stamp = |ns: &[u64]| -> Vec<Stamped> {
            ns.iter()
                .map(|&t| Stamped {
                    timestamp_ns: t,
                    pose: Pose::identity(),
                })
                .collect()
        };
        let ms = 1_000_000;
        let gt = stamp(&[0, 100 * ms, 200 * ms, 300 * ms, 400 * ms]);
        // Estimate is shorter: each estimate pose looks for its nearest ground-truth pose.
        let est = stamp(&[5 * ms, 150 * ms, 295 * ms, 411 * ms]);
        // 150 ms is 50 ms from both neighbours: out of range; 411 ms is 11 ms away.
        assert_eq!(associate(&gt, &est, 0.01), vec![(0, 0), (3, 2)]);
        // A tie goes to the earlier pose.
        assert_eq!(associate(&gt, &est, 0.05), vec![(0, 0), (1, 1), (3, 2), (4, 3)]);
        // The ground truth shorter: it drives the search.
        let est = stamp(&[0, 40 * ms, 98 * ms, 101 * ms, 199 * ms, 260 * ms, 310 * ms]);
        assert_eq!(associate(&gt, &est, 0.01), vec![(0, 0), (1, 3), (2, 4), (3, 6)]);
        let e = evaluate(&gt, &stamp(&[50 * ms]), &EvalOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "no timestamps match within 0.01 s (5 ground-truth poses, 1 estimated poses)"
        );
    }

    #[test]
    fn rpe_uses_consecutive_pairs_of_delta_and_stats_match_numpy() {
        let gt = wiggly(11);
        let ev = evaluate(
            &gt,
            &gt,
            &EvalOptions {
                rpe_delta: 3,
                ..EvalOptions::default()
            },
        )
        .unwrap();
        let idx: Vec<usize> = ev.rpe.unwrap().per_pose.iter().map(|e| e.est_index).collect();
        assert_eq!(idx, vec![3, 6, 9]);
        let s = Stats::of(&[1.0, 2.0, 4.0, 3.0]).unwrap();
        assert!(close(s.median, 2.5) && close(s.mean, 2.5) && close(s.rmse, 7.5f64.sqrt()));
        assert!(close(s.std, 1.25f64.sqrt()) && s.min == 1.0 && s.max == 4.0 && s.count == 4);
        let short = evaluate(
            &gt[..2],
            &gt[..2],
            &EvalOptions {
                rpe_delta: 2,
                ..EvalOptions::default()
            },
        )
        .unwrap();
        assert!(short.rpe.is_none());
        assert!(short.table().contains("n/a"));
    }
}
