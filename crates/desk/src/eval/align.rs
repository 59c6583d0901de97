//! Rigid alignment of an estimate onto the ground truth (evo's `--align`), and moving a
//! trajectory by it.
//!
//! In: associated positions (for [`align_rigid`]); a trajectory and a rigid motion (for
//! [`transformed`]). Out: Umeyama's least-squares rigid motion without scale, or
//! [`EvalError::Alignment`] where it is not determined; the trajectory moved.

use super::options::EvalError;
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::Pose;
use omnitrack_core::trajectory::Stamped;

/// The rigid motion `T` (no scale) minimising `Σ ‖T·from_i − to_i‖²` (Umeyama 1991, as evo's
/// `umeyama_alignment` with `with_scale=False`). Fails for fewer than three points or points
/// on one line, where the rotation is not determined.
pub fn align_rigid(from: &[Point3<f64>], to: &[Point3<f64>]) -> Result<Pose, EvalError> {
    if from.len() != to.len() {
        return Err(EvalError::Alignment(format!(
            "{} points to align onto {}",
            from.len(),
            to.len()
        )));
    }
    if from.len() < 3 {
        return Err(EvalError::Alignment(format!(
            "{} associated poses, at least 3 needed",
            from.len()
        )));
    }
    let n = from.len() as f64;
    let mean_from = from.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
    let mean_to = to.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
    let mut cov = Matrix3::zeros();
    for (a, b) in from.iter().zip(to) {
        cov += (b.coords - mean_to) * (a.coords - mean_from).transpose();
    }
    cov /= n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(EvalError::Alignment("SVD did not converge".into()));
    };
    if svd.singular_values.iter().filter(|&&d| d > f64::EPSILON).count() < 2 {
        return Err(EvalError::Alignment(
            "the positions lie on a line or a point (degenerate covariance)".into(),
        ));
    }
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        // The reflection goes on the smallest singular value (numpy sorts them, nalgebra may not).
        let smallest = svd.singular_values.imin();
        s[(smallest, smallest)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(u * s * v_t);
    let t = mean_to - r * mean_from;
    Ok(Pose::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    ))
}

/// The trajectory with every pose moved by `T` (`T · pose`), e.g. an estimate aligned by
/// [`Evaluation::alignment`](super::Evaluation::alignment) for drawing.
pub fn transformed(trajectory: &[Stamped], t: &Pose) -> Vec<Stamped> {
    trajectory
        .iter()
        .map(|s| Stamped {
            timestamp_ns: s.timestamp_ns,
            pose: t * s.pose,
        })
        .collect()
}
