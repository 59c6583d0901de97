//! Koch–Teller §5.4's special case, "vertical camera pose": a rig that rolls upright at a known
//! height has only three unknowns, the position (x, y) on the floor and the yaw ψ about world z.
//! This is Kumar–Hanson's R_and_T (§3.1, the linearised iteration on E1 / E2) restricted to those
//! three, so that the tracker's sampling loop keeps R_and_T's speed while solving half the
//! unknowns (and cannot drift in height, roll or pitch).
//!
//! In: [`Correspondence`]s, a starting `T_world_rig` (its height, roll and pitch are kept),
//! [`SolverOptions`] (error, iteration cap, convergence). Out: the refined `T_world_rig`, or
//! `None` if the 3×3 normal equations are singular or the iteration diverges. Allocates nothing.
//!
//! With `T_world_rig = (t, R)`, `R = Rz(ψ) R0`, an end point P of a segment seen by a sensor
//! centred at c (rig frame) has the E1 residual `r = n · (Rᵀ (P − t) − c)`. Its derivatives:
//! `∂r/∂t = −R n` (x and y components), and, since `R(ψ + δ)ᵀ ≈ Rᵀ (I − δ [e_z]×)`,
//! `∂r/∂ψ = −n · Rᵀ (e_z × (P − t))`. E2 divides each residual by the end point's distance from
//! the sensor centre (held fixed within a step), as in the 6-DOF solver.

use crate::{LineError, SolverOptions};
use nalgebra::{Matrix3, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{Correspondence, Pose};

/// Refines `start` over x, y and yaw by the linearised iteration. E3 (image-side error) is not
/// defined here and is treated as E2.
pub fn refine_upright(c: &[Correspondence], start: &Pose, o: &SolverOptions) -> Option<Pose> {
    if c.len() < 2 {
        return None;
    }
    let mut t = start.translation.vector;
    let mut rot = start.rotation;
    let ez = Vector3::z();
    for _ in 0..o.max_iterations.max(1) {
        let rt = rot.inverse();
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        let mut lever = 0.0;
        for l in c {
            let n = l.edge.normal.into_inner();
            let rn = rot * n;
            for p in &l.segment {
                let d = p.coords - t;
                let local = rt * d - l.edge.centre.coords;
                let w = match o.error {
                    LineError::E1 => 1.0,
                    LineError::E2 | LineError::E3 => 1.0 / local.norm().max(1e-6),
                };
                let r = n.dot(&local) * w;
                let j = Vector3::new(-rn.x, -rn.y, -n.dot(&(rt * ez.cross(&d)))) * w;
                h += j * j.transpose();
                g += j * r;
                lever += local.norm();
            }
        }
        let step = h.cholesky()?.solve(&-g);
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        t.x += step.x;
        t.y += step.y;
        rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), step.z) * rot;
        let scale = (lever / (2 * c.len()) as f64).max(1e-6);
        if step.z.abs().max(step.xy().norm() / scale) < o.convergence_rad {
            break;
        }
    }
    Some(Pose::from_parts(Translation3::from(t), rot))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use omnitrack_core::geometry::EdgePlane;

    fn scene(truth: &Pose) -> Vec<Correspondence> {
        let segments = [
            [Point3::new(3.0, 1.0, 0.0), Point3::new(3.0, 1.0, 2.5)],
            [Point3::new(-2.0, 4.0, 0.0), Point3::new(-2.0, 4.0, 2.5)],
            [Point3::new(-3.0, -2.0, 2.5), Point3::new(2.0, -2.0, 2.5)],
            [Point3::new(4.0, -3.0, 0.0), Point3::new(4.0, 3.0, 0.0)],
            [Point3::new(-1.0, -3.0, 0.0), Point3::new(-1.0, -3.0, 2.5)],
        ];
        let centres = [
            Point3::new(0.04, 0.0, 0.0),
            Point3::new(0.0, 0.04, 0.0),
            Point3::origin(),
        ];
        segments
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let c = centres[i % 3];
                let a = truth.inverse_transform_point(&s[0]) - c;
                let b = truth.inverse_transform_point(&s[1]) - c;
                Correspondence {
                    edge: EdgePlane::from_rays(c, &a, &b).unwrap(),
                    segment: *s,
                }
            })
            .collect()
    }

    #[test]
    fn recovers_x_y_yaw_exactly_from_a_nearby_start_keeping_height_roll_pitch() {
        let truth = Pose::from_parts(
            Translation3::new(0.7, -0.4, 1.2),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.9),
        );
        let c = scene(&truth);
        let start = Pose::from_parts(
            Translation3::new(0.4, -0.1, 1.2),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.75),
        );
        for error in [LineError::E1, LineError::E2] {
            let o = SolverOptions {
                error,
                ..SolverOptions::default()
            };
            let p = refine_upright(&c, &start, &o).unwrap();
            assert!(
                (p.translation.vector - truth.translation.vector).norm() < 1e-9,
                "{error:?}"
            );
            assert!(p.rotation.angle_to(&truth.rotation) < 1e-9, "{error:?}");
        }
    }
}
