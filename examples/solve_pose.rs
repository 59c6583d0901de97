//! Solves one pose from line correspondences with Kumar & Hanson's Med_R_and_T, as
//! `omnitrack pose --method lms` does: twelve segments of a room seen from a known pose, three of
//! them matched to the wrong edge, and the pose recovered without a starting guess.
//!
//! Run: `cargo run --release --example solve_pose`.

use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use omnitrack::geometry::Pose;
use omnitrack::solver::{med_r_and_t, Correspondence, EdgePlane, SolverOptions};

fn main() {
    // The room's edges: the twelve edges of a 6 × 4 × 2.7 m box.
    let (x, y, z) = (6.0, 4.0, 2.7);
    let c = |a: [f64; 3]| Point3::new(a[0] * x, a[1] * y, a[2] * z);
    let corners = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    let mut segments = Vec::new();
    for i in 0..4 {
        let (a, b) = (corners[i], corners[(i + 1) % 4]);
        segments.push([c(a), c(b)]); // floor
        segments.push([c([a[0], a[1], 1.]), c([b[0], b[1], 1.])]); // ceiling
        segments.push([c(a), c([a[0], a[1], 1.])]); // vertical corner
    }
    // The rig stands at (2, 1.5, 1.5), turned 30° about z; one sensor at its centre.
    let truth: Pose = Pose::from_parts(
        Translation3::new(2.0, 1.5, 1.5),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians()),
    );
    // Each edge as the sensor sees it: the rays to the segment's end points, in the rig frame.
    let edge = |s: &[Point3<f64>; 2]| {
        let (a, b) = (
            truth.inverse_transform_point(&s[0]),
            truth.inverse_transform_point(&s[1]),
        );
        EdgePlane::from_rays(Point3::origin(), &a.coords, &b.coords).expect("the segment spans a plane")
    };
    let mut lines: Vec<Correspondence> = segments
        .iter()
        .map(|s| Correspondence {
            edge: edge(s),
            segment: *s,
        })
        .collect();
    // Three wrong matches: each edge paired with another wall's segment.
    for (i, j) in [(0, 4), (5, 10), (7, 2)] {
        lines[i].segment = segments[j];
    }

    let solution = med_r_and_t(&lines, None, &SolverOptions::default(), 1).unwrap_or_else(|e| {
        eprintln!("solve_pose: {e}");
        std::process::exit(1)
    });
    let position_error = (solution.pose.translation.vector - truth.translation.vector).norm();
    let rotation_error = solution.pose.rotation.angle_to(&truth.rotation).to_degrees();
    let mut outliers: Vec<usize> = (0..lines.len()).filter(|i| !solution.inliers.contains(i)).collect();
    outliers.sort_unstable();
    println!(
        "T_world_rig: t = {:.4?}, {} of {} lines inliers (outliers {outliers:?}); error {position_error:.2e} m, {rotation_error:.2e}°",
        solution.pose.translation.vector.as_slice(),
        solution.inliers.len(),
        lines.len()
    );
    // Noise-free lines: anything but the exact pose is a bug, and CI runs this example.
    if position_error > 1e-6 || rotation_error > 1e-6 {
        eprintln!("solve_pose: the pose should be exact with noise-free lines");
        std::process::exit(1)
    }
}
