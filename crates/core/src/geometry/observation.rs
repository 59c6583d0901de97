//! The one observation type of the pose solvers: an image edge as the plane through its sensor's
//! optical centre that contains it (Koch–Teller Fig. 2; Kumar–Hanson's plane normal N of eq. 4),
//! paired with the model segment it images.
//!
//! In: rays or pixels of an edge's two ends, a sensor's centre, a model segment. Out: planes in
//! the rig frame, and the residuals both papers define on them: Koch–Teller's α and ξ (eq. 1) and
//! Kumar–Hanson's end-point-to-plane distances (the terms of E1, eq. 10). Each edge plane passes
//! through its own sensor's centre, so any mix of sensors (a generalised camera) is handled; a
//! single pinhole camera is the special case of one centre.

use super::Pose;
use nalgebra::{Point3, Unit, Vector3};

/// An observed image edge: the plane through a sensor's optical centre containing the edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgePlane {
    /// Unit normal of the plane, in the rig frame. Its sign carries no meaning.
    pub normal: Unit<Vector3<f64>>,
    /// Optical centre of the sensor that saw the edge, in the rig frame.
    pub centre: Point3<f64>,
    /// Unit rays (rig frame) from the centre through the edge's two image end points; they lie
    /// in the plane. Kumar–Hanson's E3 (eq. 12) measures these against the predicted plane.
    pub ends: [Unit<Vector3<f64>>; 2],
}

impl EdgePlane {
    /// The plane through `centre` containing the two rig-frame rays `r1`, `r2` from it, or `None`
    /// if the rays are (nearly) parallel and so span no plane.
    pub fn from_rays(centre: Point3<f64>, r1: &Vector3<f64>, r2: &Vector3<f64>) -> Option<EdgePlane> {
        let n = r1.cross(r2);
        let norm = n.norm();
        (norm > 1e-12 * r1.norm() * r2.norm()).then(|| EdgePlane {
            normal: Unit::new_unchecked(n / norm),
            centre,
            ends: [Unit::new_normalize(*r1), Unit::new_normalize(*r2)],
        })
    }

    /// The same edge with its plane turned to `normal` (e.g. by noise): the end rays are moved
    /// into the new plane along the normal, so that they still lie in it.
    pub fn with_normal(&self, normal: Unit<Vector3<f64>>) -> EdgePlane {
        let ends = self
            .ends
            .map(|r| Unit::new_normalize(r.into_inner() - normal.into_inner() * normal.dot(&r)));
        EdgePlane {
            normal,
            centre: self.centre,
            ends,
        }
    }

    /// Signed distance (m) of a rig-frame point from the plane.
    #[inline]
    pub fn distance(&self, p_rig: &Point3<f64>) -> f64 {
        self.normal.dot(&(p_rig - self.centre))
    }
}

/// A model segment (world end points) matched to an observed edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    pub edge: EdgePlane,
    /// The segment's end points in the world frame.
    pub segment: [Point3<f64>; 2],
}

impl Correspondence {
    /// The plane a camera at `t_world_rig` would see the segment in: through the edge's sensor
    /// centre and both end points. `None` if the segment points at the centre.
    pub fn predicted_plane(&self, t_world_rig: &Pose) -> Option<EdgePlane> {
        let a = t_world_rig.inverse_transform_point(&self.segment[0]);
        let b = t_world_rig.inverse_transform_point(&self.segment[1]);
        let c = self.edge.centre;
        EdgePlane::from_rays(c, &(a - c), &(b - c))
    }

    /// Koch–Teller's α: the angle (rad, in [0, π/2]) between the observed plane and the plane of
    /// the segment seen from `t_world_rig`. A degenerate prediction counts as π/2 (worst).
    pub fn alpha(&self, t_world_rig: &Pose) -> f64 {
        match self.predicted_plane(t_world_rig) {
            Some(p) => {
                let (n1, n2) = (self.edge.normal, p.normal);
                n1.cross(&n2).norm().atan2(n1.dot(&n2).abs())
            }
            None => std::f64::consts::FRAC_PI_2,
        }
    }

    /// Kumar–Hanson's residuals: the distances (m) of the segment's two end points, moved into the
    /// rig frame by `t_world_rig`, from the observed plane (the terms of E1, eq. 10).
    pub fn endpoint_distances(&self, t_world_rig: &Pose) -> [f64; 2] {
        self.segment
            .map(|p| self.edge.distance(&t_world_rig.inverse_transform_point(&p)))
    }
}

/// Koch–Teller eq. 1: ξ = (1/n) Σ α², the mean squared angle (rad²). Zero for no correspondences.
pub fn xi(correspondences: &[Correspondence], t_world_rig: &Pose) -> f64 {
    if correspondences.is_empty() {
        return 0.0;
    }
    correspondences
        .iter()
        .map(|c| c.alpha(t_world_rig).powi(2))
        .sum::<f64>()
        / correspondences.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    fn pose() -> Pose {
        Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 1.5),
            UnitQuaternion::from_euler_angles(0.05, -0.1, 1.2),
        )
    }

    /// A correspondence observed exactly from `pose` by a sensor centred at `c` (rig frame).
    fn exact(seg: [Point3<f64>; 2], c: Point3<f64>) -> Correspondence {
        let p = pose();
        let a = p.inverse_transform_point(&seg[0]);
        let b = p.inverse_transform_point(&seg[1]);
        Correspondence {
            edge: EdgePlane::from_rays(c, &(a - c), &(b - c)).unwrap(),
            segment: seg,
        }
    }

    #[test]
    fn exact_observations_have_zero_residuals_and_moves_are_seen() {
        let c = exact(
            [Point3::new(4.0, 0.0, 0.0), Point3::new(4.0, 3.0, 2.5)],
            Point3::new(0.04, 0.0, 0.0),
        );
        assert!(c.alpha(&pose()) < 1e-12);
        assert!(c.endpoint_distances(&pose()).iter().all(|d| d.abs() < 1e-12));
        assert!(xi(&[c], &pose()) < 1e-24);
        let moved = Isometry3::translation(0.0, 0.0, 0.1) * pose();
        assert!(c.alpha(&moved) > 1e-3);
        assert!(c.endpoint_distances(&moved)[0].abs() > 1e-3);
    }

    #[test]
    fn alpha_is_the_angle_between_planes_whatever_their_sign() {
        let mut c = exact(
            [Point3::new(4.0, 0.0, 0.0), Point3::new(4.0, 3.0, 0.0)],
            Point3::origin(),
        );
        c.edge.normal = -c.edge.normal;
        assert!(c.alpha(&pose()) < 1e-12);
        // Tilt the observed plane by 2° about an axis in it.
        let axis = Unit::new_normalize(c.edge.normal.cross(&Vector3::new(0.3, 0.5, 0.8)));
        c.edge = c
            .edge
            .with_normal(UnitQuaternion::from_axis_angle(&axis, 2f64.to_radians()) * c.edge.normal);
        assert!(c.edge.ends.iter().all(|r| r.dot(&c.edge.normal).abs() < 1e-15));
        assert!((c.alpha(&pose()) - 2f64.to_radians()).abs() < 1e-9);
        assert!((xi(&[c, c], &pose()) - 2f64.to_radians().powi(2)).abs() < 1e-12);
    }

    #[test]
    fn parallel_rays_span_no_plane() {
        let r = Vector3::new(1.0, 2.0, 3.0);
        assert!(EdgePlane::from_rays(Point3::origin(), &r, &(2.0 * r)).is_none());
    }
}
