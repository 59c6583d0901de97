//! The desk renderer: synthetic images of a building model seen through the rig's real lenses,
//! with known ground truth.
//!
//! In: a [`Model`], a [`Rig`], an [`Appearance`] and, per frame, `T_world_rig` (plus the
//! previous pose for motion blur). Out: one 8-bit RGB image per sensor. Every pixel's ray goes
//! through the pixel centre from the sensor's optical centre through its lens model
//! ([`crate::rig::Sensor::ray_in_rig`]), so the images carry the true fisheye distortion; pixels
//! with no ray are black. With `Appearance::pixel_samples` > 1 a grid of rays covers each
//! pixel's area and is averaged, as a real pixel integrates light (no aliased edges). Rays are
//! cast into a [`Scene`]: the model's faces ear-clipped into triangles in a binned-SAH
//! [`crate::model::bvh::Bvh`], plus clutter and people that exist only in the images (never in
//! the model). Rows are rendered in parallel (rayon). Output is a pure function of model, rig,
//! appearance (with its seed), keep-out points and frame: byte-identical on rerun.

pub mod appearance;
pub mod scene;

pub use crate::model::bvh::{brute_force_closest, model_triangles, Aabb, Bvh, Ray, Triangle, TriangleBvh};
pub use crate::model::triangulate::{ear_clip, triangulate_polygon};
pub use appearance::Appearance;
pub use scene::{Person, Scene, Surface, SurfaceKind};

use crate::geometry::Pose;
use crate::model::Model;
use crate::rig::{Rig, Sensor};
use crate::trajectory::Stamped;
use appearance::{gaussian_from_hash, hash64, value_noise};
use image::RgbImage;
use nalgebra::{Point2, Point3, Vector3};
use rayon::prelude::*;
use scene::PlacedPerson;

/// What to render: the frame counter (seeds the sensor noise), its time and `T_world_rig`, and
/// the previous frame's pose for motion blur (ignored when blur is off or `None`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSpec {
    pub index: u64,
    pub timestamp_ns: u64,
    /// `T_world_rig` at `timestamp_ns`.
    pub pose: Pose,
    pub previous: Option<Stamped>,
}

/// What a ray hits first in the static scene (model and clutter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneHit {
    /// Distance along the (unit) ray, metres.
    pub t: f64,
    /// Index into [`Scene::surfaces`].
    pub surface: u32,
}

/// Per-pixel rays of one sensor: unit direction in the rig frame and the vignetting factor;
/// `x` is NaN where the lens has no ray. `Appearance::pixel_samples`² rays per pixel, stored
/// together.
struct SensorRays {
    sensor: Sensor,
    rays: Vec<[f32; 4]>,
}

/// One sub-frame sample: where the rig is and where the people are.
struct Sample {
    pose: Pose,
    people: Vec<PlacedPerson>,
    people_bvh: Bvh,
}

/// Renders a model for one rig.
pub struct Renderer {
    scene: Scene,
    appearance: Appearance,
    sensors: Vec<SensorRays>,
}

#[inline]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

const SKY_TOP: [f32; 3] = [0.55, 0.68, 0.88];
const SKY_LOW: [f32; 3] = [0.85, 0.85, 0.8];

impl Renderer {
    /// Builds the scene (triangulation, clutter, people, lights, BVH) and the per-pixel ray
    /// tables of every sensor. `keep_out` points (the trajectory's positions) are kept clear of
    /// clutter and people.
    pub fn new(model: &Model, rig: &Rig, appearance: Appearance, keep_out: &[Point3<f64>]) -> Renderer {
        let scene = Scene::build(model, &appearance, keep_out);
        let sensors = rig
            .sensors
            .iter()
            .map(|s| {
                let theta_max = s.max_off_axis().max(1e-6);
                let (w, h) = (s.width as usize, s.height as usize);
                let n = appearance.pixel_samples.max(1) as usize;
                let mut rays = vec![[f32::NAN; 4]; w * h * n * n];
                rays.par_chunks_mut(w * n * n).enumerate().for_each(|(v, row)| {
                    for (k, out) in row.iter_mut().enumerate() {
                        let (u, sub) = (k / (n * n), k % (n * n));
                        let off = |i: usize| (i as f64 + 0.5) / n as f64 - 0.5;
                        let px = Point2::new(u as f64 + off(sub % n), v as f64 + off(sub / n));
                        if let (Some(r), Some(rs)) = (s.ray_in_rig(&px), s.lens.unproject(&px)) {
                            let theta = rs.z.clamp(-1.0, 1.0).acos() / theta_max;
                            let vig = (1.0 - appearance.vignetting * theta * theta).max(0.0);
                            *out = [r.x as f32, r.y as f32, r.z as f32, vig as f32];
                        }
                    }
                });
                SensorRays {
                    sensor: s.clone(),
                    rays,
                }
            })
            .collect();
        Renderer {
            scene,
            appearance,
            sensors,
        }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn appearance(&self) -> &Appearance {
        &self.appearance
    }

    /// First hit of a world ray (unit `dir`) on the static scene (model and clutter, not people).
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<SceneHit> {
        let d = dir.normalize();
        let ray = Ray::new(
            [origin.x as f32, origin.y as f32, origin.z as f32],
            [d.x as f32, d.y as f32, d.z as f32],
        );
        self.scene
            .geometry
            .closest(&ray, 1e-4, f32::INFINITY)
            .map(|(surface, t)| SceneHit { t: t as f64, surface })
    }

    fn samples(&self, frame: &FrameSpec) -> Vec<Sample> {
        let k = self.appearance.blur_samples();
        let t_now = frame.timestamp_ns as f64 * 1e-9;
        let mut out = Vec::with_capacity(k as usize);
        for i in 0..k {
            let (pose, t) = match (&frame.previous, k) {
                (Some(prev), k) if k > 1 => {
                    let back = self.appearance.motion_blur.clamp(0.0, 1.0) * i as f64 / (k - 1) as f64;
                    let dt = (frame.timestamp_ns.saturating_sub(prev.timestamp_ns)) as f64 * 1e-9;
                    (prev.pose.lerp_slerp(&frame.pose, 1.0 - back), t_now - back * dt)
                }
                _ => (frame.pose, t_now),
            };
            if i > 0 && frame.previous.is_none() {
                break;
            }
            let (people, people_bvh) = self.scene.people_at(t);
            out.push(Sample {
                pose,
                people,
                people_bvh,
            });
        }
        out
    }

    /// All sensors of one frame, in sensor order.
    pub fn render_frame(&self, frame: &FrameSpec) -> Vec<RgbImage> {
        let samples = self.samples(frame);
        (0..self.sensors.len())
            .map(|s| self.render_with(s, frame, &samples))
            .collect()
    }

    /// One sensor of one frame.
    pub fn render_sensor(&self, sensor: usize, frame: &FrameSpec) -> RgbImage {
        let samples = self.samples(frame);
        self.render_with(sensor, frame, &samples)
    }

    fn render_with(&self, sensor: usize, frame: &FrameSpec, samples: &[Sample]) -> RgbImage {
        let sr = &self.sensors[sensor];
        let (w, h) = (sr.sensor.width as usize, sr.sensor.height as usize);
        let gain = self.appearance.drift_gain(frame.timestamp_ns as f64 * 1e-9);
        let noise = self.appearance.noise as f32;
        let noise_seed = hash64(
            self.appearance.seed
                ^ 0x005E_1150_u64.wrapping_mul(sensor as u64 + 1)
                ^ frame.index.wrapping_mul(0xA24B_AED4_963E_E407),
        );
        // Per sample: sensor origin in the world and the world-from-rig rotation (f32).
        let frames: Vec<([f32; 3], [[f32; 3]; 3])> = samples
            .iter()
            .map(|s| {
                let o = s.pose * sr.sensor.centre();
                let m = s.pose.rotation.to_rotation_matrix();
                let m = m.matrix();
                let rows = [0, 1, 2].map(|r| [m[(r, 0)] as f32, m[(r, 1)] as f32, m[(r, 2)] as f32]);
                ([o.x as f32, o.y as f32, o.z as f32], rows)
            })
            .collect();
        let per_pixel = (self.appearance.pixel_samples.max(1) as usize).pow(2);
        let inv_k = 1.0 / (samples.len() * per_pixel) as f32;
        let mut buf = vec![0u8; w * h * 3];
        buf.par_chunks_mut(w * 3).enumerate().for_each(|(v, row)| {
            for u in 0..w {
                let pix = v * w + u;
                let rays = &sr.rays[pix * per_pixel..(pix + 1) * per_pixel];
                if rays.iter().all(|r| r[0].is_nan()) {
                    continue; // black: no ray
                }
                // Vignetting per ray; with one ray per pixel it is applied last, as it always
                // was, so that those images stay byte-identical.
                let (vig_each, vig_last) = if per_pixel == 1 {
                    (false, rays[0][3])
                } else {
                    (true, 1.0)
                };
                let mut acc = [0.0f32; 3];
                // Part of the pixel without a ray (past the lens's field) counts as black.
                for r in rays.iter().filter(|r| !r[0].is_nan()) {
                    let vig = if vig_each { r[3] } else { 1.0 };
                    for (sample, (o, m)) in samples.iter().zip(&frames) {
                        let d = [
                            dot(m[0], [r[0], r[1], r[2]]),
                            dot(m[1], [r[0], r[1], r[2]]),
                            dot(m[2], [r[0], r[1], r[2]]),
                        ];
                        let c = self.shade(&Ray::new(*o, d), sample);
                        for k in 0..3 {
                            acc[k] += c[k] * vig;
                        }
                    }
                }
                for k in 0..3 {
                    let mut x = acc[k] * inv_k * gain[k] * vig_last * 255.0;
                    if noise > 0.0 {
                        x += noise * gaussian_from_hash(hash64(noise_seed ^ (pix as u64 * 3 + k as u64)));
                    }
                    row[u * 3 + k] = x.round().clamp(0.0, 255.0) as u8;
                }
            }
        });
        RgbImage::from_raw(w as u32, h as u32, buf).expect("buffer sized to the image")
    }

    /// Linear colour seen along a unit ray.
    #[inline]
    fn shade(&self, ray: &Ray, sample: &Sample) -> [f32; 3] {
        let a = &self.appearance;
        let geo = &self.scene.geometry;
        let hit = geo.bvh.closest(ray, f32::INFINITY, |slot, tb| {
            geo.triangles[slot as usize].intersect(ray, 1e-4, tb)
        });
        let t_static = hit.map_or(f32::INFINITY, |(_, t)| t);
        let person = if sample.people.is_empty() {
            None
        } else {
            sample.people_bvh.closest(ray, t_static, |slot, tb| {
                sample.people[slot as usize].intersect(ray, 1e-4, tb)
            })
        };
        let (t, base, normal, tex_seed) = if let Some((slot, t)) = person {
            let p = &sample.people[slot as usize];
            let pt = ray.at(t);
            let person = &self.scene.people[p.index as usize];
            let z = (pt[2] - p.floor) / person.height;
            let colour = person.colours[if z < 0.47 {
                0
            } else if z < 0.86 {
                1
            } else {
                2
            }];
            (t, colour, p.normal(pt), 0xFFFF_0000 ^ p.index)
        } else if let Some((slot, t)) = hit {
            let tri = &geo.triangles[slot as usize];
            let sid = geo.payload[slot as usize];
            let n = [
                tri.e1[1] * tri.e2[2] - tri.e1[2] * tri.e2[1],
                tri.e1[2] * tri.e2[0] - tri.e1[0] * tri.e2[2],
                tri.e1[0] * tri.e2[1] - tri.e1[1] * tri.e2[0],
            ];
            let l = dot(n, n).sqrt().max(1e-30);
            (
                t,
                self.scene.surfaces[sid as usize].colour,
                [n[0] / l, n[1] / l, n[2] / l],
                sid,
            )
        } else {
            let s = ray.dir[2].clamp(0.0, 1.0);
            return [0, 1, 2].map(|k| SKY_LOW[k] + (SKY_TOP[k] - SKY_LOW[k]) * s);
        };
        let mut brightness = 1.0f32;
        if a.texture > 0.0 {
            let p = ray.at(t);
            let seed = (a.seed as u32) ^ tex_seed.wrapping_mul(0x9E37_79B9);
            let n1 = value_noise([p[0] * 2.9, p[1] * 2.9, p[2] * 2.9], seed);
            let n2 = value_noise([p[0] * 11.0, p[1] * 11.0, p[2] * 11.0], seed ^ 0x55);
            brightness *= 1.0 + a.texture as f32 * (1.4 * (n1 - 0.5) + 0.6 * (n2 - 0.5)) * 2.0;
        }
        if a.shading > 0.0 {
            // Normal towards the viewer (faces are two-sided).
            let mut n = normal;
            let dn = dot(n, ray.dir);
            if dn > 0.0 {
                n = [-n[0], -n[1], -n[2]];
            }
            let cos_view = dn.abs();
            let head = cos_view / (1.0 + (t / 6.0) * (t / 6.0));
            let p = ray.at(t);
            let mut lit = 0.0f32;
            for light in &self.scene.lights {
                let l = [
                    light.position[0] - p[0],
                    light.position[1] - p[1],
                    light.position[2] - p[2],
                ];
                let d2 = dot(l, l).max(1e-6);
                let c = dot(n, l) / d2.sqrt();
                if c > 0.0 {
                    lit += light.intensity * c / (1.0 + d2 / 25.0);
                }
            }
            let s = 0.45 + 0.45 * head + 0.35 * lit;
            brightness *= 1.0 - a.shading as f32 + a.shading as f32 * s;
        }
        base.map(|c| c * brightness)
    }
}
