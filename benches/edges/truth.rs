//! The edge benchmark's ground truth and its scoring (the bench's doc, "Accuracy"): the visible
//! runs of the model segments per sensor image, found by ray casting the rendered scene, and
//! the recall, normal error and share of edges on the model of a frame's detected edges.
//!
//! In: the model, the rig, the renderer, a pose; a frame's edges. Out: [`Truth`] runs; a
//! [`Score`] accumulated over frames.

use nalgebra::{Point3, Vector3};
use omnitrack::desk::render::{Ray, Renderer};
use omnitrack::edges::Edge;
use omnitrack::geometry::Pose;
use omnitrack::{Model, Rig};

/// A run being collected: first and last ray, pixel length, last pixel.
type Run = Option<(Vector3<f64>, Vector3<f64>, f64, nalgebra::Point2<f64>)>;

/// A visible run of a model segment in one sensor.
pub(crate) struct Truth {
    pub(crate) sensor: usize,
    pub(crate) normal: Vector3<f64>,
    /// First and last visible sample rays (rig frame, from the sensor centre).
    pub(crate) r1: Vector3<f64>,
    pub(crate) r2: Vector3<f64>,
}

pub(crate) fn ground_truth(model: &Model, rig: &Rig, renderer: &Renderer, pose: &Pose, t_s: f64, out: &mut Vec<Truth>) {
    out.clear();
    let (people, _) = renderer.scene().people_at(t_s);
    let inv = pose.inverse();
    for (k, s) in rig.sensors.iter().enumerate() {
        let c_rig = s.centre();
        let c_world = pose * c_rig;
        let (w, h) = (s.width as f64, s.height as f64);
        for seg in &model.segments {
            let (a, b) = (inv * seg.a, inv * seg.b);
            let normal = (a - c_rig).cross(&(b - c_rig));
            if normal.norm() < 1e-9 {
                continue;
            }
            let normal = normal.normalize();
            let n = ((seg.length() / 0.01).ceil() as usize).clamp(20, 4000);
            let mut run: Run = None;
            let mut flush = |run: &mut Run| {
                if let Some((r1, r2, len, _)) = run.take() {
                    if len > 30.0 {
                        out.push(Truth {
                            sensor: k,
                            normal,
                            r1,
                            r2,
                        });
                    }
                }
            };
            for i in 0..=n {
                let t = i as f64 / n as f64;
                let p_rig = a + (b - a) * t;
                let p_world: Point3<f64> = seg.a + (seg.b - seg.a) * t;
                let visible = s.project_from_rig(&p_rig).filter(|px| {
                    px.x >= 3.0 && px.y >= 3.0 && px.x <= w - 4.0 && px.y <= h - 4.0 && {
                        let d = p_world - c_world;
                        let dist = d.norm();
                        let dir = d / dist;
                        let by_scene = match renderer.cast(&c_world, &dir) {
                            Some(hit) => hit.t >= dist - 0.02,
                            None => true,
                        };
                        let ray = Ray::new(
                            [c_world.x as f32, c_world.y as f32, c_world.z as f32],
                            [dir.x as f32, dir.y as f32, dir.z as f32],
                        );
                        by_scene
                            && !people
                                .iter()
                                .any(|p| p.intersect(&ray, 1e-4, (dist - 0.02) as f32).is_some())
                    }
                });
                match (visible, run.as_mut()) {
                    (Some(px), Some(r)) if (px - r.3).norm() < 20.0 => {
                        r.2 += (px - r.3).norm();
                        r.1 = (p_rig - c_rig).normalize();
                        r.3 = px;
                    }
                    (Some(px), _) => {
                        flush(&mut run);
                        let r = (p_rig - c_rig).normalize();
                        run = Some((r, r, 0.0, px));
                    }
                    (None, _) => flush(&mut run),
                }
            }
            flush(&mut run);
        }
    }
}

/// Angular interval of rays r1, r2 along the plane with normal n, from reference e1.
fn interval(n: &Vector3<f64>, e1: &Vector3<f64>, r1: &Vector3<f64>, r2: &Vector3<f64>) -> (f64, f64) {
    let e2 = n.cross(e1);
    let a = |r: &Vector3<f64>| r.dot(&e2).atan2(r.dot(e1));
    let (x, y) = (a(r1), a(r2));
    (x.min(y), x.max(y))
}

#[derive(Default)]
pub(crate) struct Score {
    pub(crate) truths: usize,
    pub(crate) recalled: usize,
    pub(crate) errors_deg: Vec<f64>,
    pub(crate) edges: usize,
    pub(crate) edges_on_model: usize,
    pub(crate) sensor_frames: usize,
    /// Misses with no edge plane within 1° at all / with only pieces overlapping < 50 %.
    pub(crate) missed_no_plane: usize,
    pub(crate) missed_fragmented: usize,
}

pub(crate) fn score(truths: &[Truth], edges: &[Edge], s: &mut Score, rig: &Rig, frame: usize) {
    let cos1 = 1f64.to_radians().cos();
    s.edges += edges.len();
    for t in truths {
        let e1 = t.r1;
        let ti = interval(&t.normal, &e1, &t.r1, &t.r2);
        let tlen = (ti.1 - ti.0).max(1e-9);
        let mut best: Option<f64> = None;
        let mut any_plane = false;
        for e in edges.iter().filter(|e| e.sensor as usize == t.sensor) {
            let c = e.plane.normal.dot(&t.normal).abs();
            if c < cos1 {
                continue;
            }
            let ei = interval(&t.normal, &e1, &e.plane.ends[0], &e.plane.ends[1]);
            let overlap = (ti.1.min(ei.1) - ti.0.max(ei.0)).max(0.0);
            any_plane |= overlap > 0.0;
            if overlap >= 0.5 * tlen {
                let err = c.min(1.0).acos().to_degrees();
                best = Some(best.map_or(err, |b: f64| b.min(err)));
            }
        }
        s.truths += 1;
        if best.is_none() && std::env::var("EDGES_MISSES").is_ok() {
            // Diagnostics: nearest plane among overlapping edges, best overlap within 1°.
            let mut near = (f64::INFINITY, 0.0);
            let mut near_px = [nalgebra::Point2::new(f64::NAN, f64::NAN); 2];
            let mut cover = 0.0f64;
            for e in edges.iter().filter(|e| e.sensor as usize == t.sensor) {
                let ei = interval(&t.normal, &e1, &e.plane.ends[0], &e.plane.ends[1]);
                let overlap = (ti.1.min(ei.1) - ti.0.max(ei.0)).max(0.0) / tlen;
                let ang = e.plane.normal.dot(&t.normal).abs().min(1.0).acos().to_degrees();
                if overlap > 0.3 && ang < near.0 {
                    near = (ang, overlap);
                    near_px = e.px;
                }
                if ang < 1.0 {
                    cover = cover.max(overlap);
                }
            }
            let sn = &rig.sensors[t.sensor];
            let px = |r: &Vector3<f64>| {
                sn.project_from_rig(&(sn.centre() + r))
                    .unwrap_or(nalgebra::Point2::new(f64::NAN, f64::NAN))
            };
            let (a, b) = (px(&t.r1), px(&t.r2));
            eprintln!(
                "miss frame {frame} s{} len {:.2}° nearest-plane {:.2}° (overlap {:.2}) best-cover-within-1° {:.2} \
                 truth px ({:.1}, {:.1})–({:.1}, {:.1}) nearest edge px ({:.1}, {:.1})–({:.1}, {:.1})",
                t.sensor,
                tlen.to_degrees(),
                near.0,
                near.1,
                cover,
                a.x,
                a.y,
                b.x,
                b.y,
                near_px[0].x,
                near_px[0].y,
                near_px[1].x,
                near_px[1].y
            );
        }
        if let Some(err) = best {
            s.recalled += 1;
            s.errors_deg.push(err);
        } else if any_plane {
            s.missed_fragmented += 1;
        } else {
            s.missed_no_plane += 1;
        }
    }
    for e in edges {
        let on = truths.iter().any(|t| {
            t.sensor == e.sensor as usize && e.plane.normal.dot(&t.normal).abs() >= cos1 && {
                let ti = interval(&t.normal, &t.r1, &t.r1, &t.r2);
                let ei = interval(&t.normal, &t.r1, &e.plane.ends[0], &e.plane.ends[1]);
                ti.1.min(ei.1) > ti.0.max(ei.0)
            }
        });
        s.edges_on_model += on as usize;
    }
}
