//! The model's segments re-projected into one sensor's image: what the desk's pictures draw over
//! a frame's images and what the live view annotates its images with, one function for both.
//!
//! In: a [`Sensor`], the pose `T_rig_world` (the inverse of the rig's `T_world_rig`), segments'
//! end points in world coordinates, and the spacing of the samples in pixels. Out: polylines in
//! the sensor's pixels (OpenCV convention), one per stretch of a segment that the sensor images.
//!
//! A straight 3D segment is a curve in a fisheye image, so each segment is sampled along its
//! length, more finely the more of the view it spans, and every sample goes through the lens.
//! Where a segment leaves the image (across the border, behind a pinhole, past a fisheye's
//! image circle), its polyline ends on the border, found by bisection between the samples on
//! either side: with the last sample before it instead, a line would stop up to a spacing short
//! of the image's edge. A jump of more than a quarter of the image between neighbouring samples
//! (a panorama's seam) also breaks the polyline. A segment the sensor does not see gives nothing.

use super::Sensor;
use crate::geometry::{Lens, Pose};
use nalgebra::{Point2, Point3};

/// Samples along one segment at most, however fine the spacing asked.
pub const MAX_SAMPLES: usize = 20_000;
/// Halvings of the interval between a seen and an unseen sample: 2⁻³⁰ of it, far below a pixel.
const BISECTIONS: usize = 30;

/// Pixels per radian a lens reaches at most (a fisheye's ≈ f; a pinhole's grows towards its
/// edge), so that samples a spacing apart on the sphere are at most about that far apart on
/// the image.
fn pixels_per_radian(lens: &Lens) -> f64 {
    let f = lens.fx().max(lens.fy());
    match lens {
        Lens::Pinhole(_) | Lens::Radtan(_) => 3.0 * f,
        _ => 1.5 * f,
    }
}

/// The polylines of `segments` (world end points) as `sensor` sees them from `t_rig_world`,
/// samples about `spacing_px` pixels apart or closer (a spacing that is not a positive number is
/// taken as 1 px).
pub fn project_segments<I>(sensor: &Sensor, t_rig_world: &Pose, segments: I, spacing_px: f64) -> Vec<Vec<Point2<f64>>>
where
    I: IntoIterator<Item = (Point3<f64>, Point3<f64>)>,
{
    let mut out = Vec::new();
    for (a, b) in segments {
        project_segment(sensor, t_rig_world, (&a, &b), spacing_px, &mut out);
    }
    out
}

/// One segment's polylines (none, one, or several where it leaves and re-enters the image),
/// appended to `out`.
pub fn project_segment(
    sensor: &Sensor,
    t_rig_world: &Pose,
    (a_world, b_world): (&Point3<f64>, &Point3<f64>),
    spacing_px: f64,
    out: &mut Vec<Vec<Point2<f64>>>,
) {
    let finite = |p: &Point3<f64>| p.coords.iter().all(|x| x.is_finite());
    if !(finite(a_world) && finite(b_world)) {
        return;
    }
    let a = t_rig_world.transform_point(a_world);
    let b = t_rig_world.transform_point(b_world);
    let centre = sensor.centre();
    let (ra, rb) = (a - centre, b - centre);
    // A segment through the sensor's centre spans any angle up to π: sample it as if it did.
    let angle = if ra.norm() < 1e-9 || rb.norm() < 1e-9 {
        std::f64::consts::PI
    } else {
        ra.angle(&rb)
    };
    let spacing = if spacing_px.is_finite() && spacing_px > 0.0 {
        spacing_px
    } else {
        1.0
    };
    let n = ((angle * pixels_per_radian(&sensor.lens) / spacing).ceil() as usize).clamp(2, MAX_SAMPLES);
    let jump = 0.25 * f64::from(sensor.width.min(sensor.height));
    let at = |t: f64| sensor.project_from_rig(&Point3::from(a.coords.lerp(&b.coords, t)));
    let mut run: Vec<Point2<f64>> = Vec::new();
    let mut prev: Option<(f64, Option<Point2<f64>>)> = None;
    for k in 0..=n {
        let t = k as f64 / n as f64;
        let px = at(t);
        match (prev, px) {
            (Some((_, Some(p0))), Some(p1)) => {
                if (p1 - p0).norm() > jump {
                    finish(&mut run, out);
                }
                run.push(p1);
            }
            // Coming into view: the run starts on the border.
            (Some((t0, None)), Some(p1)) => {
                run.push(border(&at, (t, p1), t0));
                run.push(p1);
            }
            (None, Some(p1)) => run.push(p1),
            // Going out of view: the run ends on the border.
            (Some((t0, Some(p0))), None) => {
                run.push(border(&at, (t0, p0), t));
                finish(&mut run, out);
            }
            (_, None) => {}
        }
        prev = Some((t, px));
    }
    finish(&mut run, out);
}

/// The last seen point between a seen parameter (with its pixel) and an unseen one.
fn border(
    at: &impl Fn(f64) -> Option<Point2<f64>>,
    (mut seen, mut px): (f64, Point2<f64>),
    mut unseen: f64,
) -> Point2<f64> {
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (seen + unseen);
        match at(mid) {
            Some(p) => (seen, px) = (mid, p),
            None => unseen = mid,
        }
    }
    px
}

/// Moves a run of two or more points to `out`; a lone point is no line.
fn finish(run: &mut Vec<Point2<f64>>, out: &mut Vec<Vec<Point2<f64>>>) {
    if run.len() > 1 {
        out.push(std::mem::take(run));
    } else {
        run.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rig;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// One 640×480 pinhole, f = 500 px, looking along the rig's x axis (sensor x = −rig y,
    /// sensor y = −rig z), its centre at the rig's origin.
    fn pinhole() -> Sensor {
        let rig = Rig::from_toml_str(
            "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
             intrinsics = [500.0, 500.0, 319.5, 239.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "one.toml",
        )
        .unwrap();
        rig.sensors[0].clone()
    }

    /// The rig at (1, 2, 0.5) in the world, turned 90° about z; `rig` takes rig coordinates to
    /// the world's, so that each case is written where the sensor sees it.
    fn placed() -> (Pose, impl Fn(f64, f64, f64) -> Point3<f64>) {
        let t_world_rig = Pose::from_parts(
            Translation3::new(1.0, 2.0, 0.5),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        (t_world_rig.inverse(), move |x, y, z| {
            t_world_rig.transform_point(&Point3::new(x, y, z))
        })
    }

    fn close(p: Point2<f64>, u: f64, v: f64) -> bool {
        (p.x - u).abs() < 1e-6 && (p.y - v).abs() < 1e-6
    }

    #[test]
    fn a_segment_across_the_view_lands_on_its_pixels() {
        let (sensor, (t_rig_world, rig)) = (pinhole(), placed());
        // 4 m ahead, from 1 m right to 1 m left: u = 319.5 ± 500 · 1/4, on the middle row.
        let runs = project_segments(&sensor, &t_rig_world, [(rig(4.0, -1.0, 0.0), rig(4.0, 1.0, 0.0))], 2.0);
        assert_eq!(runs.len(), 1, "{runs:?}");
        let run = &runs[0];
        assert!(close(run[0], 444.5, 239.5), "{:?}", run[0]);
        assert!(close(*run.last().unwrap(), 194.5, 239.5), "{:?}", run.last());
        for w in run.windows(2) {
            // A pinhole keeps it straight; the samples are at most the spacing apart.
            assert!((w[1].y - 239.5).abs() < 1e-9 && w[1].x < w[0].x && w[0].x - w[1].x <= 2.0 + 1e-9);
        }
        // A finer spacing: more samples, the same ends.
        let fine = project_segments(&sensor, &t_rig_world, [(rig(4.0, -1.0, 0.0), rig(4.0, 1.0, 0.0))], 0.5);
        assert!(fine[0].len() > 3 * run.len() && close(*fine[0].last().unwrap(), 194.5, 239.5));
    }

    #[test]
    fn a_segment_behind_or_beside_the_view_gives_nothing() {
        let (sensor, (t_rig_world, rig)) = (pinhole(), placed());
        let behind = (rig(-4.0, -1.0, 0.0), rig(-4.0, 1.0, 0.0));
        let beside = (rig(4.0, 10.0, 0.0), rig(4.0, 12.0, 0.0));
        let above = (rig(1.0, -0.2, 5.0), rig(1.0, 0.2, 5.0));
        assert!(project_segments(&sensor, &t_rig_world, [behind, beside, above], 1.0).is_empty());
    }

    #[test]
    fn a_segment_leaving_the_view_ends_on_the_border() {
        let (sensor, (t_rig_world, rig)) = (pinhole(), placed());
        // From 4 m ahead to 4 m behind, 0.5 m to the left: u = 319.5 − 250 / depth, which reaches
        // the left border (u = −0.5) at a depth of 0.78125 m, long before it goes behind.
        let runs = project_segments(&sensor, &t_rig_world, [(rig(4.0, 0.5, 0.0), rig(-4.0, 0.5, 0.0))], 4.0);
        assert_eq!(runs.len(), 1, "{runs:?}");
        assert!(close(runs[0][0], 257.0, 239.5), "{:?}", runs[0][0]);
        assert!(close(*runs[0].last().unwrap(), -0.5, 239.5), "{:?}", runs[0].last());
        // Reversed, it comes into view there.
        let back = project_segments(&sensor, &t_rig_world, [(rig(-4.0, 0.5, 0.0), rig(4.0, 0.5, 0.0))], 4.0);
        assert!(close(back[0][0], -0.5, 239.5) && close(*back[0].last().unwrap(), 257.0, 239.5));
        // Across the whole view, both ends outside it: clipped to both borders.
        let across = project_segments(&sensor, &t_rig_world, [(rig(4.0, -3.0, 0.0), rig(4.0, 3.0, 0.0))], 4.0);
        assert_eq!(across.len(), 1, "{across:?}");
        assert!(close(across[0][0], 639.5, 239.5), "{:?}", across[0][0]);
        assert!(close(*across[0].last().unwrap(), -0.5, 239.5), "{:?}", across[0].last());
    }

    #[test]
    fn nonsense_gives_nothing_and_no_panic() {
        let (sensor, (t_rig_world, rig)) = (pinhole(), placed());
        let nan = Point3::new(f64::NAN, 0.0, 0.0);
        let runs = project_segments(
            &sensor,
            &t_rig_world,
            [(nan, rig(4.0, 0.0, 0.0)), (rig(0.0, 0.0, 0.0), rig(0.0, 0.0, 0.0))],
            f64::NAN,
        );
        assert!(runs.is_empty(), "{runs:?}");
    }
}
