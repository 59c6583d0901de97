//! The translation of lines whose rotation is known: Kumar–Hanson eq. 9 in the world frame, by
//! linear least squares, with an upright variant that keeps the height.
//!
//! In: line correspondences, the rotation of `T_world_rig`, optionally the known height (upright,
//! Koch–Teller §5.4), and a point the answer is gently pulled to (the cell centre). Out: the rig
//! position in the world, or `None` when the planes do not fix it.
//!
//! R_then_T's translation stage ([`crate::refine::kumar_hanson`]) solves the same equations for
//! `T_rig_world`; this form serves the initialiser, whose samples are three lines that may be
//! parallel in plan, so a tiny pull (1e-6 of the normal matrix) keeps the system solvable.

use nalgebra::{Matrix2, Matrix3, Point3, UnitQuaternion, Vector2, Vector3};
use omnitrack_core::geometry::Correspondence;

/// Eq. 9 with the rotation known: every end point P of a segment lies on its edge's plane, whose
/// world normal is m = R n through the world point t + R c: m · t = m · (P − R c). Upright: z is
/// the known height and only x, y are solved. `None` if the planes do not fix the position.
pub fn translation_given_rotation(
    c: &[Correspondence],
    rotation: &UnitQuaternion<f64>,
    upright_height: Option<f64>,
    centre: &Point3<f64>,
) -> Option<Vector3<f64>> {
    match upright_height {
        Some(z) => {
            let mut a = Matrix2::zeros();
            let mut b = Vector2::zeros();
            for l in c {
                let m = rotation * l.edge.normal.into_inner();
                let rc = rotation * l.edge.centre.coords;
                for p in &l.segment {
                    let row = Vector2::new(m.x, m.y);
                    let rhs = m.dot(&(p.coords - rc)) - m.z * z;
                    a += row * row.transpose();
                    b += row * rhs;
                }
            }
            // A little pull towards the cell centre keeps a pair of parallel planes solvable.
            a += Matrix2::identity() * 1e-6;
            b += Vector2::new(centre.x, centre.y) * 1e-6;
            let xy = a.lu().solve(&b)?;
            Some(Vector3::new(xy.x, xy.y, z))
        }
        None => {
            let mut a = Matrix3::zeros();
            let mut b = Vector3::zeros();
            for l in c {
                let m = rotation * l.edge.normal.into_inner();
                let rc = rotation * l.edge.centre.coords;
                for p in &l.segment {
                    a += m * m.transpose();
                    b += m * m.dot(&(p.coords - rc));
                }
            }
            a += Matrix3::identity() * 1e-6;
            b += centre.coords * 1e-6;
            a.lu().solve(&b)
        }
    }
}
