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
        plane_normal(r1, r2).map(|normal| EdgePlane {
            normal: Unit::new_unchecked(normal),
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

/// The unit normal `r1 × r2 / |r1 × r2|` of the plane two rays span, or `None` if they are
/// (nearly) parallel: [`EdgePlane::from_rays`]'s normal, and [`Correspondence::alpha`]'s.
#[inline]
fn plane_normal(r1: &Vector3<f64>, r2: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = r1.cross(r2);
    let norm = n.norm();
    (norm > 1e-12 * r1.norm() * r2.norm()).then(|| n / norm)
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
        let (r1, r2) = self.predicted_rays(t_world_rig);
        EdgePlane::from_rays(self.edge.centre, &r1, &r2)
    }

    /// The rays from the edge's sensor centre to the segment's ends seen from `t_world_rig`.
    #[inline]
    fn predicted_rays(&self, t_world_rig: &Pose) -> (Vector3<f64>, Vector3<f64>) {
        let a = t_world_rig.inverse_transform_point(&self.segment[0]);
        let b = t_world_rig.inverse_transform_point(&self.segment[1]);
        let c = self.edge.centre;
        (a - c, b - c)
    }

    /// Koch–Teller's α: the angle (rad, in [0, π/2]) between the observed plane and the plane of
    /// the segment seen from `t_world_rig`. A degenerate prediction counts as π/2 (worst).
    ///
    /// The predicted plane's normal alone, as [`Self::predicted_plane`] computes it (its end rays,
    /// two square roots and six divisions, are not needed): the consensus scores every sample by
    /// α over the rest of the set, the largest part of the tracker's CPU after the fits.
    #[inline]
    pub fn alpha(&self, t_world_rig: &Pose) -> f64 {
        match self.alpha_terms(t_world_rig) {
            Some((sin, cos)) => sin.atan2(cos),
            None => std::f64::consts::FRAC_PI_2,
        }
    }

    /// The two numbers [`Self::alpha`] is the arc tangent of, `(|n × m|, |n · m|)` for the
    /// observed normal n and the predicted m (`None` where α is π/2 for want of a predicted
    /// plane). Their ratio orders correspondences as α does, without the arc tangent, which is
    /// most of α's cost (a median needs the arc tangent of one element only).
    #[inline]
    pub fn alpha_terms(&self, t_world_rig: &Pose) -> Option<(f64, f64)> {
        let (r1, r2) = self.predicted_rays(t_world_rig);
        let n2 = plane_normal(&r1, &r2)?;
        let n1 = self.edge.normal;
        Some((n1.cross(&n2).norm(), n1.dot(&n2).abs()))
    }

    /// tan² α, the square of [`Self::alpha_terms`]' ratio to within a few 10⁻¹⁶ rad of the angle
    /// (not bit for bit: the predicted normal is not normalised, and no square root is taken);
    /// infinite where α is π/2 for want of a predicted plane. For ranking many correspondences by α where only a few need α itself (a median):
    /// one division instead of four square roots and four divisions.
    #[inline]
    pub fn alpha_tan2(&self, t_world_rig: &Pose) -> f64 {
        let (r1, r2) = self.predicted_rays(t_world_rig);
        let (r1sq, r2sq) = (r1.norm_squared(), r2.norm_squared());
        let n = r1.cross(&r2);
        // `plane_normal`'s test |n| > 1e-12 |r1| |r2|, squared, with a factor of 2 to spare for
        // the rounding of both forms, and only for lengths whose squares and products stay normal
        // numbers; near the test's edge, for NaN or extreme lengths, `alpha_terms` decides.
        let lengths = 1e-140..=1e140;
        if lengths.contains(&r1sq) && lengths.contains(&r2sq) && n.norm_squared() > 2e-24 * r1sq * r2sq {
            let n1 = self.edge.normal;
            let cos = n1.dot(&n);
            n1.cross(&n).norm_squared() / (cos * cos)
        } else {
            self.alpha_terms(t_world_rig)
                .map_or(f64::INFINITY, |(sin, cos)| (sin / cos).powi(2))
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

    /// Uniform draws in [-1, 1) from `seed` (xorshift64).
    fn uniform(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    /// A segment a few metres off observed exactly from a sensor centre near the rig's, and a
    /// pose a few decimetres from the one it was observed at.
    fn random_case(next: &mut impl FnMut() -> f64) -> (Correspondence, Pose) {
        let c = exact(
            [
                Point3::new(4.0 * next(), 4.0 * next(), 2.0 * next()),
                Point3::new(4.0 * next(), 4.0 * next(), 2.0 * next()),
            ],
            Point3::new(0.05 * next(), 0.05 * next(), 0.05 * next()),
        );
        (
            c,
            Isometry3::translation(0.3 * next(), 0.3 * next(), 0.1 * next()) * pose(),
        )
    }

    /// tan² α without the normalisation is `alpha_terms`' ratio squared, to 10⁻¹⁵ rad of angle,
    /// for planes at any angle (exact ones too), and infinite for segments pointing at the centre.
    #[test]
    fn alpha_tan2_is_the_tangent_of_alpha_squared() {
        let mut next = uniform(0x9e37_79b9_7f4a_7c15);
        for i in 0..5000 {
            let (mut c, p) = random_case(&mut next);
            if i % 3 > 0 {
                c.edge.normal = Unit::new_normalize(Vector3::new(next(), next(), next()));
            }
            let (sin, cos) = c.alpha_terms(&p).unwrap();
            let tan = sin / cos;
            let got = c.alpha_tan2(&p).sqrt();
            assert!(
                (got.atan() - tan.atan()).abs() <= 1e-15,
                "{i}: {got} against tan α {tan}"
            );
        }
        let through = Correspondence {
            edge: EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &Vector3::y()).unwrap(),
            segment: [Point3::new(1.0, 1.0, 1.0), Point3::new(2.0, 2.0, 2.0)],
        };
        assert_eq!(through.alpha_tan2(&Pose::identity()), f64::INFINITY);
    }

    /// α from the predicted normal alone is α from the whole predicted plane, bit for bit, for
    /// planes at any angle and for segments pointing at the centre (π/2).
    #[test]
    fn alpha_is_the_predicted_planes_angle_bit_for_bit() {
        let reference = |c: &Correspondence, p: &Pose| match c.predicted_plane(p) {
            Some(pl) => c
                .edge
                .normal
                .cross(&pl.normal)
                .norm()
                .atan2(c.edge.normal.dot(&pl.normal).abs()),
            None => std::f64::consts::FRAC_PI_2,
        };
        let mut next = uniform(0x2545_f491_4f6c_dd1d);
        for _ in 0..5000 {
            let (mut c, p) = random_case(&mut next);
            c.edge.normal = Unit::new_normalize(Vector3::new(next(), next(), next()));
            assert_eq!(c.alpha(&p).to_bits(), reference(&c, &p).to_bits());
        }
        let through = Correspondence {
            edge: EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &Vector3::y()).unwrap(),
            segment: [Point3::new(1.0, 1.0, 1.0), Point3::new(2.0, 2.0, 2.0)],
        };
        let at_origin = Pose::identity();
        assert_eq!(through.alpha(&at_origin), std::f64::consts::FRAC_PI_2);
        assert_eq!(reference(&through, &at_origin), std::f64::consts::FRAC_PI_2);
    }
}
