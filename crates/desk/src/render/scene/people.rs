//! People walking back and forth on straight paths, which exist only in the images. In: floor
//! samples, ray queries and the keep-out points their paths stay clear of; out: [`Person`]s, and
//! per instant their [`PlacedPerson`] capsules with a BVH over them.

use super::{add, sample_on, Scene, Site};
use crate::render::appearance::{hsv, Appearance, Rng};
use omnitrack_core::model::bvh::{Aabb, Bvh, Ray};

/// A person: a vertical capsule walking back and forth between `start` and `end` (floor points).
#[derive(Debug, Clone, PartialEq)]
pub struct Person {
    pub start: [f64; 3],
    pub end: [f64; 3],
    pub speed_m_s: f64,
    /// Phase offset of the walk, in metres along the back-and-forth path.
    pub phase_m: f64,
    pub radius: f32,
    pub height: f32,
    pub colours: PersonColours,
}

/// A person's colours (linear RGB), bottom to top.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PersonColours {
    pub trousers: [f32; 3],
    pub shirt: [f32; 3],
    pub head: [f32; 3],
}

impl PersonColours {
    /// The colour at `z`, a fraction of the person's height above the floor: trousers below
    /// 0.47, shirt below 0.86, head above.
    pub fn at_height(&self, z: f32) -> [f32; 3] {
        if z < 0.47 {
            self.trousers
        } else if z < 0.86 {
            self.shirt
        } else {
            self.head
        }
    }
}

impl Person {
    /// Floor point under the person at time `t_s`.
    pub fn position(&self, t_s: f64) -> [f64; 3] {
        let d = [
            self.end[0] - self.start[0],
            self.end[1] - self.start[1],
            self.end[2] - self.start[2],
        ];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9);
        let s = (self.speed_m_s * t_s + self.phase_m).rem_euclid(2.0 * len);
        let f = if s <= len { s / len } else { 2.0 - s / len };
        [
            self.start[0] + f * d[0],
            self.start[1] + f * d[1],
            self.start[2] + f * d[2],
        ]
    }
}

/// A person placed at one instant, ready for intersection.
#[derive(Debug, Clone, Copy)]
pub struct PlacedPerson {
    pub x: f32,
    pub y: f32,
    /// Centres of the two cap spheres.
    pub z_low: f32,
    pub z_high: f32,
    pub radius: f32,
    pub floor: f32,
    pub index: u32,
}

impl PlacedPerson {
    pub fn bounds(&self) -> Aabb {
        let r = self.radius;
        Aabb {
            min: [self.x - r, self.y - r, self.z_low - r],
            max: [self.x + r, self.y + r, self.z_high + r],
        }
    }

    /// First entry of the ray into the capsule in `(t_min, t_max)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
        let r2 = self.radius * self.radius;
        let (ox, oy) = (ray.origin[0] - self.x, ray.origin[1] - self.y);
        let (dx, dy, dz) = (ray.dir[0], ray.dir[1], ray.dir[2]);
        let mut best = t_max;
        let mut found = false;
        let a = dx * dx + dy * dy;
        if a > 0.0 {
            let b = ox * dx + oy * dy;
            let c = ox * ox + oy * oy - r2;
            let disc = b * b - a * c;
            if disc >= 0.0 {
                let t = (-b - disc.sqrt()) / a;
                let z = ray.origin[2] + t * dz;
                if t > t_min && t < best && z >= self.z_low && z <= self.z_high {
                    best = t;
                    found = true;
                }
            }
        }
        for zc in [self.z_low, self.z_high] {
            let oz = ray.origin[2] - zc;
            let a = dx * dx + dy * dy + dz * dz;
            let b = ox * dx + oy * dy + oz * dz;
            let c = ox * ox + oy * oy + oz * oz - r2;
            let disc = b * b - a * c;
            if disc >= 0.0 {
                let t = (-b - disc.sqrt()) / a;
                if t > t_min && t < best {
                    best = t;
                    found = true;
                }
            }
        }
        found.then_some(best)
    }

    /// Outward normal at a surface point.
    pub fn normal(&self, p: [f32; 3]) -> [f32; 3] {
        let zc = p[2].clamp(self.z_low, self.z_high);
        let n = [p[0] - self.x, p[1] - self.y, p[2] - zc];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt().max(1e-12);
        [n[0] / l, n[1] / l, n[2] / l]
    }
}

/// People as many as `Appearance::people` asks for, drawn from a stream of their own.
pub(super) fn place(site: &Site, appearance: &Appearance) -> Vec<Person> {
    let Site {
        floor_tris,
        floor_cum,
        probe,
        keep,
        ..
    } = *site;
    let mut people = Vec::new();
    let want = site.count(appearance.people, 40.0);
    let mut prng = Rng::new(appearance.seed ^ 0x009E_091E_u64 << 20);
    for _ in 0..want * 20 {
        if people.len() >= want {
            break;
        }
        let Some((p, _)) = sample_on(floor_tris, floor_cum, &mut prng) else {
            break;
        };
        let a = prng.range(0.0, std::f64::consts::TAU);
        let d = [a.cos(), a.sin(), 0.0];
        let r = prng.range(0.2, 0.26);
        let height = prng.range(1.6, 1.9);
        if probe.free([p[0], p[1], p[2] + 0.05], [0.0, 0.0, 1.0], 10.0) < height + 0.1 {
            continue;
        }
        let free = [0.3, 1.0, 1.5]
            .into_iter()
            .flat_map(|z| {
                [-r, 0.0, r].map(|o| probe.free(add([p[0] - d[1] * o, p[1] + d[0] * o, p[2] + z], d, -r), d, 8.0))
            })
            .fold(f64::INFINITY, f64::min);
        let len = (free - 2.0 * r - 0.1).min(prng.range(2.0, 6.0));
        if len < 1.5 {
            continue;
        }
        let end = add(p, d, len);
        // Keep the path clear of the trajectory (horizontal distance to the segment).
        let clear = keep.iter().all(|k| {
            if k[2] < p[2] - 0.5 || k[2] > p[2] + height + 0.5 {
                return true;
            }
            let s = ((k[0] - p[0]) * d[0] + (k[1] - p[1]) * d[1]).clamp(0.0, len);
            let q = add(p, d, s);
            ((k[0] - q[0]).powi(2) + (k[1] - q[1]).powi(2)).sqrt() > r + 0.6
        });
        if !clear {
            continue;
        }
        let sat = appearance.colour.clamp(0.0, 1.0);
        people.push(Person {
            start: p,
            end,
            speed_m_s: prng.range(0.8, 1.4),
            phase_m: prng.range(0.0, 2.0 * len),
            radius: r as f32,
            height: height as f32,
            // Drawn in this order (trousers, shirt, head): the seed's people stay the same.
            colours: PersonColours {
                trousers: hsv(prng.unit(), 0.5 * sat, prng.range(0.15, 0.45)),
                shirt: hsv(prng.unit(), 0.7 * sat, prng.range(0.4, 0.9)),
                head: hsv(0.07, 0.45 * sat, prng.range(0.45, 0.8)),
            },
        });
    }
    people
}

impl Scene {
    /// People at time `t_s`, with a BVH over them.
    pub fn people_at(&self, t_s: f64) -> (Vec<PlacedPerson>, Bvh) {
        let placed: Vec<PlacedPerson> = self
            .people
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let q = p.position(t_s);
                PlacedPerson {
                    x: q[0] as f32,
                    y: q[1] as f32,
                    z_low: q[2] as f32 + p.radius,
                    z_high: q[2] as f32 + p.height - p.radius,
                    radius: p.radius,
                    floor: q[2] as f32,
                    index: i as u32,
                }
            })
            .collect();
        let bounds: Vec<Aabb> = placed.iter().map(PlacedPerson::bounds).collect();
        let bvh = Bvh::build(&bounds);
        let ordered = bvh.order.iter().map(|&i| placed[i as usize]).collect();
        (ordered, bvh)
    }
}
