//! The desk renderer: synthetic images of a building model seen through the rig's real lenses,
//! with known ground truth.
//!
//! In: a [`Model`], a [`Rig`], an [`Appearance`] and, per frame, `T_world_rig` (plus the
//! previous pose for motion blur). Out: one 8-bit RGB image per sensor. Every pixel's ray goes
//! through the pixel centre from the sensor's optical centre through its lens model
//! ([`omnitrack_core::rig::Sensor::ray_in_rig`]), so the images carry the true fisheye distortion; pixels
//! with no ray are black. With `Appearance::pixel_samples` > 1 a grid of rays covers each
//! pixel's area and is averaged, as a real pixel integrates light (no aliased edges). Rays are
//! cast into a [`Scene`]: the model's faces ear-clipped into triangles in a binned-SAH
//! [`omnitrack_core::model::bvh::Bvh`], plus clutter and people that exist only in the images (never in
//! the model). Rows are rendered in parallel (rayon). Surfaces carry value-noise texture and a
//! structured [`Pattern`] (floorboards, tiles, grain, stripes, slats); with
//! `Appearance::jpeg_quality` each image goes through a JPEG encoder and decoder last, as a real
//! camera's would. Output is a pure function of model, rig, appearance (with its seed),
//! keep-out points and frame: byte-identical on rerun.

pub mod appearance;
pub mod fixtures;
pub mod scene;

pub use appearance::{Appearance, SpecError};
pub use omnitrack_core::model::bvh::{brute_force_closest, model_triangles, Aabb, Bvh, Ray, Triangle, TriangleBvh};
pub use omnitrack_core::model::triangulate::{ear_clip, triangulate_polygon};
pub use scene::{ClutterCounts, Pattern, Person, Scene, Surface, SurfaceKind};

use appearance::{gaussian_from_hash, hash64, value_noise};
use image::RgbImage;
use nalgebra::{Point2, Point3, Vector3};
use omnitrack_core::geometry::Pose;
use omnitrack_core::model::Model;
use omnitrack_core::rig::{Rig, Sensor};
use omnitrack_core::trajectory::Stamped;
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
    /// Angle one pixel spans (rad, the finest of the sensors'): the footprint patterns are
    /// filtered over.
    pixel_rad: f32,
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
                            let mut vig = (1.0 - appearance.vignetting * theta * theta).max(0.0);
                            if appearance.lens_falloff > 0.0 {
                                let c = (theta * std::f64::consts::FRAC_PI_3)
                                    .min(std::f64::consts::FRAC_PI_2)
                                    .cos();
                                vig *= 1.0 - appearance.lens_falloff + appearance.lens_falloff * c.powi(4);
                            }
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
        let pixel_rad = rig
            .sensors
            .iter()
            .map(|s| s.max_off_axis() / (0.5 * f64::from(s.width).hypot(f64::from(s.height))).max(1.0))
            .fold(f64::INFINITY, f64::min);
        Renderer {
            scene,
            appearance,
            sensors,
            pixel_rad: if pixel_rad.is_finite() { pixel_rad as f32 } else { 1e-3 },
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
        let mut image = RgbImage::from_raw(w as u32, h as u32, buf).expect("buffer sized to the image");
        if self.appearance.blur_px > 0.0 {
            image = gaussian_blur(&image, self.appearance.blur_px);
        }
        if self.appearance.jpeg_quality > 0 {
            jpeg_round_trip(&image, self.appearance.jpeg_quality)
        } else {
            image
        }
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
        let (t, base, normal, tex_seed, pattern) = if let Some((slot, t)) = person {
            let p = &sample.people[slot as usize];
            let pt = ray.at(t);
            let person = &self.scene.people[p.index as usize];
            let z = (pt[2] - p.floor) / person.height;
            let colour = person.colours.at_height(z);
            (t, colour, p.normal(pt), 0xFFFF_0000 ^ p.index, Pattern::None)
        } else if let Some((slot, t)) = hit {
            let tri = &geo.triangles[slot as usize];
            let sid = geo.payload[slot as usize];
            let n = [
                tri.e1[1] * tri.e2[2] - tri.e1[2] * tri.e2[1],
                tri.e1[2] * tri.e2[0] - tri.e1[0] * tri.e2[2],
                tri.e1[0] * tri.e2[1] - tri.e1[1] * tri.e2[0],
            ];
            let l = dot(n, n).sqrt().max(1e-30);
            let surface = &self.scene.surfaces[sid as usize];
            (t, surface.colour, [n[0] / l, n[1] / l, n[2] / l], sid, surface.pattern)
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
        if pattern != Pattern::None {
            let p = ray.at(t);
            let cos = dot(normal, ray.dir).abs().max(0.15);
            let foot = t * self.pixel_rad / cos;
            let seed = hash64(a.seed ^ u64::from(tex_seed).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            brightness *= pattern_factor(&pattern, p, normal, foot, seed);
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

/// `image` encoded as JPEG at `quality` (1–100) and decoded again: what a camera or photo set
/// delivering JPEG does to it (8×8 blocks, ringing, chroma loss).
pub fn jpeg_round_trip(image: &RgbImage, quality: u8) -> RgbImage {
    let mut bytes = Vec::new();
    let encoded =
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality.clamp(1, 100)).encode_image(image);
    // Encoding into memory fails only on an empty image, which has nothing to degrade.
    if encoded.is_err() {
        return image.clone();
    }
    match image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg) {
        Ok(decoded) => decoded.to_rgb8(),
        Err(_) => image.clone(),
    }
}

/// Share of a window `foot` wide centred at `x` that lines `width` wide centred on the
/// multiples of `period` cover: a line seen through a pixel of that footprint.
#[inline]
fn line_cover(x: f32, period: f32, width: f32, foot: f32) -> f32 {
    if foot >= period {
        return (width / period).min(1.0);
    }
    let k = (x / period).round();
    let mut c = 0.0;
    for j in [k - 1.0, k, k + 1.0] {
        let centre = j * period;
        let lo = (x - 0.5 * foot).max(centre - 0.5 * width);
        let hi = (x + 0.5 * foot).min(centre + 0.5 * width);
        c += (hi - lo).max(0.0);
    }
    (c / foot.max(1e-6)).min(1.0)
}

/// Uniform in [0, 1) from a hash of a seed and two cell indices.
#[inline]
fn cell_unit(seed: u64, i: f32, j: f32) -> f32 {
    let h = hash64(seed ^ hash64((i as i64 as u64) ^ (j as i64 as u64).rotate_left(32)));
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Brightness factor of `pattern` at world point `p` on a surface with unit normal `n`, seen
/// through a pixel whose footprint there is `foot` metres.
fn pattern_factor(pattern: &Pattern, p: [f32; 3], n: [f32; 3], foot: f32, seed: u64) -> f32 {
    // In-plane coordinates: `a` horizontal along the surface, `b` up it (across, if horizontal).
    let in_plane = || {
        let h = if n[2].abs() < 0.9 {
            let l = (n[0] * n[0] + n[1] * n[1]).sqrt();
            [-n[1] / l, n[0] / l, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let a = dot(p, h);
        let b = if n[2].abs() < 0.9 { p[2] } else { p[1] };
        (a, b)
    };
    let noise_seed = seed as u32;
    match *pattern {
        Pattern::None => 1.0,
        Pattern::Boards { axis, contrast } => {
            const WIDTH: f32 = 0.14;
            const LENGTH: f32 = 1.3;
            const SEAM: f32 = 0.004;
            let s = p[0] * axis[0] + p[1] * axis[1];
            let q = -p[0] * axis[1] + p[1] * axis[0];
            let row = (q / WIDTH).floor();
            // Board ends are staggered row by row, as boards are laid.
            let se = s + LENGTH * cell_unit(seed, row, -7.0);
            let board = (se / LENGTH).floor();
            let tone = cell_unit(seed ^ 0xB0A4D, row, board) - 0.5;
            let grain = value_noise([s * 1.5, q * 40.0, row], noise_seed) - 0.5;
            let seam = line_cover(q, WIDTH, SEAM, foot).max(line_cover(se, LENGTH, SEAM, foot));
            (1.0 + contrast * (0.36 * tone + 0.16 * grain)) * (1.0 - contrast * 0.6 * seam).max(0.0)
        }
        Pattern::Tiles { axis, size, contrast } => {
            let u = p[0] * axis[0] + p[1] * axis[1];
            let v = -p[0] * axis[1] + p[1] * axis[0];
            let grout = line_cover(u, size, 0.005, foot).max(line_cover(v, size, 0.005, foot));
            let tone = cell_unit(seed, (u / size).floor(), (v / size).floor()) - 0.5;
            (1.0 + contrast * 0.14 * tone) * (1.0 - contrast * 0.45 * grout).max(0.0)
        }
        Pattern::Grain { contrast } => {
            let (a, b) = in_plane();
            let g = 0.7 * value_noise([a * 2.0, b * 35.0, 0.0], noise_seed)
                + 0.3 * value_noise([a * 6.0, b * 110.0, 3.0], noise_seed);
            (1.0 + contrast * 0.5 * (g - 0.5)).max(0.0)
        }
        Pattern::Stripes { period, contrast } => {
            let (_, b) = in_plane();
            let cover = line_cover(b, period, 0.5 * period, foot);
            (1.0 + contrast * 0.35 * (1.0 - 2.0 * cover)).max(0.0)
        }
        Pattern::Slats => {
            const PITCH: f32 = 0.025;
            let (_, b) = in_plane();
            // Each slat is lit more at its top edge than at its bottom (it curves away).
            let shade = if foot < 0.5 * PITCH {
                0.8 + 0.25 * (b / PITCH - (b / PITCH).floor())
            } else {
                0.925
            };
            shade * (1.0 - 0.7 * line_cover(b, PITCH, 0.003, foot))
        }
    }
}

/// `image` blurred by a Gaussian of standard deviation `sigma_px` (separable, kernel to 3σ,
/// edges clamped).
pub fn gaussian_blur(image: &RgbImage, sigma_px: f64) -> RgbImage {
    let r = (3.0 * sigma_px).ceil().max(1.0) as i64;
    let kernel: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma_px * sigma_px)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / sum).collect();
    let (w, h) = (image.width() as i64, image.height() as i64);
    let src: Vec<f32> = image.as_raw().iter().map(|&b| f32::from(b)).collect();
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; src.len()];
        out.par_chunks_mut((w * 3) as usize).enumerate().for_each(|(y, row)| {
            for x in 0..w {
                let mut acc = [0.0f32; 3];
                for (k, wgt) in kernel.iter().enumerate() {
                    let d = k as i64 - r;
                    let (sx, sy) = if horizontal {
                        ((x + d).clamp(0, w - 1), y as i64)
                    } else {
                        (x, (y as i64 + d).clamp(0, h - 1))
                    };
                    let i = ((sy * w + sx) * 3) as usize;
                    for c in 0..3 {
                        acc[c] += wgt * src[i + c];
                    }
                }
                row[(x * 3) as usize..(x * 3 + 3) as usize].copy_from_slice(&acc);
            }
        });
        out
    };
    let blurred = pass(&pass(&src, true), false);
    let bytes = blurred.iter().map(|v| v.round().clamp(0.0, 255.0) as u8).collect();
    RgbImage::from_raw(w as u32, h as u32, bytes).expect("same size")
}
