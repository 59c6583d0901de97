//! The scene the renderer casts rays into: the model's faces (triangulated, coloured per
//! surface), plus clutter and people that exist only in the images, never in the model.
//!
//! In: a [`Model`], an [`Appearance`] and keep-out points (the trajectory) that clutter and
//! people must leave free. Out: a [`Scene`]: one triangle BVH over model, fixtures (module
//! [`super::fixtures`]) and clutter, the surface table its hits index (each surface with the
//! [`Pattern`] painted on it), the people and the lights. With `Appearance::wall_offset_m` the
//! model's triangles are those of its displaced vertices.

use super::appearance::{hash64, hsv, Appearance, Rng};
use super::fixtures::{self, FixtureCounts, Probe};
use nalgebra::{Point3, Vector3};
use omnitrack_core::model::bvh::{Aabb, Bvh, Ray, Triangle, TriangleBvh};
use omnitrack_core::model::Model;
use std::collections::HashMap;

/// What a surface is, from its `usemtl` (or `g`/`o`) name, or from its orientation if unnamed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SurfaceKind {
    Wall,
    Floor,
    Ceiling,
    DoorReveal,
    WindowReveal,
    /// A model face with none of the names above.
    Other,
    /// Clutter: furniture box.
    Furniture,
    /// Clutter: shelving unit.
    Shelf,
    /// Clutter: poster on a wall.
    Poster,
    /// Fixture: door or window casing, sill or baseboard.
    Trim,
    /// Fixture: built-in cabinet or counter.
    BuiltIn,
    /// Fixture: a door slab closing an opening, or its handle.
    Door,
    /// Fixture: a window blind.
    Blind,
    /// Fixture: a rug on the floor.
    Rug,
}

impl SurfaceKind {
    /// Whether the surface belongs to the model (as opposed to clutter and fixtures).
    pub fn in_model(self) -> bool {
        !matches!(
            self,
            SurfaceKind::Furniture
                | SurfaceKind::Shelf
                | SurfaceKind::Poster
                | SurfaceKind::Trim
                | SurfaceKind::BuiltIn
                | SurfaceKind::Door
                | SurfaceKind::Blind
                | SurfaceKind::Rug
        )
    }
}

/// A structured pattern painted on a surface (multiplies its brightness), beyond the value-noise
/// texture. Lines are box-filtered over the pixel's footprint, so that thin seams read as the
/// faint continuous lines a real pixel records rather than dashes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pattern {
    None,
    /// Floorboards along the horizontal unit `axis`: ~14 cm wide, ~1.3 m long with staggered
    /// ends, dark seams and grain; `contrast` scales it all.
    Boards {
        axis: [f32; 2],
        contrast: f32,
    },
    /// Square tiles of side `size` (m) along `axis`, with grout lines.
    Tiles {
        axis: [f32; 2],
        size: f32,
        contrast: f32,
    },
    /// Wood grain: streaks along the surface's horizontal direction.
    Grain {
        contrast: f32,
    },
    /// Horizontal bands of `period` (m): a striped print.
    Stripes {
        period: f32,
        contrast: f32,
    },
    /// Blind slats: 2.5 cm pitch, each shaded across its curve, dark gaps between.
    Slats,
}

impl Pattern {
    /// Grain at `level`, or none at 0.
    pub fn grain(level: f64) -> Pattern {
        if level > 0.0 {
            Pattern::Grain { contrast: level as f32 }
        } else {
            Pattern::None
        }
    }
}

/// One colour region of the scene: all model faces in one plane with one material share a
/// surface, so that image edges appear exactly where the model has segments.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    pub kind: SurfaceKind,
    /// Linear RGB in [0, 1].
    pub colour: [f32; 3],
    pub pattern: Pattern,
}

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
    /// Trousers, shirt, head.
    pub colours: [[f32; 3]; 3],
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

/// A point light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    pub position: [f32; 3],
    pub intensity: f32,
}

/// Everything the rays can hit.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Model and clutter triangles; payload = index into `surfaces`.
    pub geometry: TriangleBvh,
    pub surfaces: Vec<Surface>,
    pub people: Vec<Person>,
    pub lights: Vec<Light>,
    /// Clutter items placed (furniture, shelves, posters).
    pub clutter_counts: [usize; 3],
    /// Model triangles (the first `model_triangles` of the input, before clutter).
    pub model_triangles: usize,
    /// What [`super::fixtures`] found and added.
    pub fixture_counts: FixtureCounts,
}

pub(super) fn kind_of(model: &Model, face: &omnitrack_core::model::Face, mid_z: f64) -> SurfaceKind {
    for label in [face.material, face.group, face.object] {
        let name = model.label(label).to_ascii_lowercase();
        if name.contains("door") {
            return SurfaceKind::DoorReveal;
        }
        if name.contains("window") {
            return SurfaceKind::WindowReveal;
        }
        if name.contains("floor") {
            return SurfaceKind::Floor;
        }
        if name.contains("ceiling") {
            return SurfaceKind::Ceiling;
        }
        if name.contains("wall") {
            return SurfaceKind::Wall;
        }
    }
    if face.normal.z.abs() > 0.9 {
        let z = face.offset * face.normal.z; // height of a horizontal plane
        if z < mid_z {
            SurfaceKind::Floor
        } else {
            SurfaceKind::Ceiling
        }
    } else if face.normal.z.abs() < 0.1 {
        SurfaceKind::Wall
    } else {
        SurfaceKind::Other
    }
}

/// Colour of the `index`-th surface: hues spread by the golden ratio, saturation and value by
/// kind, value varied per surface too.
fn surface_colour(kind: SurfaceKind, index: usize, appearance: &Appearance) -> [f32; 3] {
    const PHI: f64 = 0.618_033_988_749_895;
    let base = (super::appearance::hash64(appearance.seed) >> 11) as f64 / (1u64 << 53) as f64;
    let hue = base + PHI * index as f64;
    let var = (0.381_966 * index as f64 + 0.5 * base).fract();
    let (s, v) = match kind {
        SurfaceKind::Wall => (0.40, 0.62 + 0.30 * var),
        SurfaceKind::Floor => (0.50, 0.38 + 0.22 * var),
        SurfaceKind::Ceiling => (0.22, 0.80 + 0.15 * var),
        SurfaceKind::DoorReveal => (0.75, 0.45 + 0.25 * var),
        SurfaceKind::WindowReveal => (0.65, 0.70 + 0.25 * var),
        _ => (0.45, 0.50 + 0.40 * var),
    };
    let own = hsv(hue, (s * appearance.colour).clamp(0.0, 1.0), v);
    let p = appearance.paint.clamp(0.0, 1.0) as f32;
    if p == 0.0 {
        return own;
    }
    let sat = appearance.colour.clamp(0.0, 1.0);
    let paint = match kind {
        SurfaceKind::Wall | SurfaceKind::DoorReveal | SurfaceKind::WindowReveal => hsv(0.11, 0.10 * sat, 0.86),
        SurfaceKind::Ceiling => hsv(0.11, 0.04 * sat, 0.93),
        SurfaceKind::Floor => hsv(0.07, 0.50 * sat, 0.50),
        _ => own,
    };
    [0, 1, 2].map(|k| (1.0 - p) * own[k] + p * paint[k])
}

fn add(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// Twelve triangles of a box: centre, three orthogonal half-axes.
pub(super) fn box_triangles(c: [f64; 3], ax: [[f64; 3]; 3], out: &mut Vec<Triangle>) {
    let corner = |sx: f64, sy: f64, sz: f64| {
        let mut p = c;
        for (k, s) in [sx, sy, sz].into_iter().enumerate() {
            p = add(p, ax[k], s);
        }
        [p[0] as f32, p[1] as f32, p[2] as f32]
    };
    // Each face: fixed axis k at sign s; the other two axes span it.
    for k in 0..3 {
        for s in [-1.0, 1.0] {
            let q = |a: f64, b: f64| {
                let mut v = [0.0; 3];
                v[k] = s;
                v[(k + 1) % 3] = a;
                v[(k + 2) % 3] = b;
                corner(v[0], v[1], v[2])
            };
            let (p00, p10, p11, p01) = (q(-1.0, -1.0), q(1.0, -1.0), q(1.0, 1.0), q(-1.0, 1.0));
            out.push(Triangle::new(p00, p10, p11));
            out.push(Triangle::new(p00, p11, p01));
        }
    }
}

pub(super) fn quad_triangles(c: [f64; 3], u: [f64; 3], v: [f64; 3], out: &mut Vec<Triangle>) {
    let p = |a: f64, b: f64| {
        let q = add(add(c, u, a), v, b);
        [q[0] as f32, q[1] as f32, q[2] as f32]
    };
    out.push(Triangle::new(p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0)));
    out.push(Triangle::new(p(-1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)));
}

/// A place on a wall for clutter: the wall point at floor height, the horizontal unit normal
/// towards free space, the horizontal axis along the wall, and floor and ceiling heights there.
struct WallSpot {
    base: [f64; 3],
    side: [f64; 3],
    u: [f64; 3],
    floor: f64,
    ceil: f64,
}

use fixtures::near_keep_out;

/// The floor pattern of the `index`-th surface: boards along or across the building's main
/// direction, or (one floor in four) tiles.
fn floor_pattern(axis: [f32; 2], index: usize, appearance: &Appearance) -> Pattern {
    if appearance.floor_pattern <= 0.0 {
        return Pattern::None;
    }
    let h = hash64(appearance.seed ^ 0xF100_u64 << 32 ^ index as u64);
    let contrast = appearance.floor_pattern as f32;
    let across = [-axis[1], axis[0]];
    let along = if h & 1 == 0 { axis } else { across };
    if (h >> 8) % 4 == 0 {
        let size = [0.3, 0.45, 0.6][((h >> 16) % 3) as usize];
        Pattern::Tiles { axis, size, contrast }
    } else {
        Pattern::Boards { axis: along, contrast }
    }
}

/// A furnishing colour muted by `Appearance::paint`: real furniture is mostly wood, grey and
/// beige, not the saturated hues that tell synthetic boxes apart.
fn muted(colour: [f32; 3], appearance: &Appearance) -> [f32; 3] {
    let p = 0.7 * appearance.paint.clamp(0.0, 1.0) as f32;
    if p == 0.0 {
        return colour;
    }
    let grey = 0.3 * colour[0] + 0.59 * colour[1] + 0.11 * colour[2];
    colour.map(|c| (1.0 - p) * c + p * grey)
}

/// The building's main horizontal direction: that of its longest horizontal segment.
fn main_axis(model: &Model) -> [f32; 2] {
    model
        .segments
        .iter()
        .filter(|s| (s.b.z - s.a.z).abs() < 1e-3 * s.length())
        .max_by(|a, b| a.length().total_cmp(&b.length()))
        .and_then(|s| nalgebra::Vector2::new(s.b.x - s.a.x, s.b.y - s.a.y).try_normalize(1e-9))
        .map_or([1.0, 0.0], |d| [d.x as f32, d.y as f32])
}

/// Samples a point on one of `tris` (area-weighted), given their cumulative areas.
fn sample_on(tris: &[(Triangle, usize)], cumulative: &[f64], rng: &mut Rng) -> Option<([f64; 3], usize)> {
    let total = *cumulative.last()?;
    if total <= 0.0 {
        return None;
    }
    let x = rng.unit() * total;
    let i = cumulative.partition_point(|&c| c <= x).min(tris.len() - 1);
    let (tri, face) = &tris[i];
    let (mut a, mut b) = (rng.unit(), rng.unit());
    if a + b > 1.0 {
        (a, b) = (1.0 - a, 1.0 - b);
    }
    let p = [0, 1, 2].map(|k| tri.p0[k] as f64 + a * tri.e1[k] as f64 + b * tri.e2[k] as f64);
    Some((p, *face))
}

impl Scene {
    /// Builds the scene. `keep_out` points (e.g. every rig position of the trajectory) stay at
    /// least ~0.6 m clear of clutter and people's paths.
    pub fn build(model: &Model, appearance: &Appearance, keep_out: &[Point3<f64>]) -> Scene {
        let keep: Vec<[f64; 3]> = keep_out.iter().map(|p| [p.x, p.y, p.z]).collect();
        let (lo, hi) = model.bounds().unwrap_or((Point3::origin(), Point3::origin()));
        let mid_z = 0.5 * (lo.z + hi.z);
        let axis = main_axis(model);

        // Surfaces: (material, oriented plane) → surface index, in first-appearance order.
        let mut surfaces: Vec<Surface> = Vec::new();
        let mut keys: HashMap<(u32, [i64; 4]), u32> = HashMap::new();
        let mut triangles = Vec::new();
        let mut payload = Vec::new();
        let mut face_kind = Vec::with_capacity(model.faces.len());
        // (triangle, face index) for placement sampling.
        let mut tri_face: Vec<(Triangle, usize)> = Vec::new();
        let mut face_surface = Vec::with_capacity(model.faces.len());
        for face in &model.faces {
            let kind = kind_of(model, face, mid_z);
            face_kind.push(kind);
            // The plane without its orientation: faces are two-sided, so coplanar faces of one
            // material are one surface whichever way their normals point.
            let key = (face.material, fixtures::oriented_plane(face).2);
            let next = surfaces.len() as u32;
            let sid = *keys.entry(key).or_insert(next);
            if sid == next {
                surfaces.push(Surface {
                    kind,
                    colour: surface_colour(kind, next as usize, appearance),
                    pattern: if kind == SurfaceKind::Floor {
                        floor_pattern(axis, next as usize, appearance)
                    } else {
                        Pattern::None
                    },
                });
            }
            face_surface.push(sid);
        }
        let rendered = if appearance.wall_offset_m > 0.0 {
            let mut moved = model.clone();
            moved.vertices = fixtures::displaced_vertices(model, appearance.wall_offset_m, appearance.seed);
            super::model_triangles(&moved)
        } else {
            super::model_triangles(model)
        };
        for (tri, fi) in rendered {
            triangles.push(tri);
            payload.push(face_surface[fi as usize]);
            tri_face.push((tri, fi as usize));
        }
        let model_triangles = triangles.len();
        let model_bvh = TriangleBvh::build(&triangles, &payload);
        let probe = Probe { bvh: &model_bvh };

        let pick = |want: &dyn Fn(usize) -> bool| {
            let tris: Vec<(Triangle, usize)> = tri_face.iter().filter(|(_, f)| want(*f)).copied().collect();
            let mut acc = 0.0;
            let cum: Vec<f64> = tris
                .iter()
                .map(|(t, _)| {
                    acc += t.area2() as f64 / 2.0;
                    acc
                })
                .collect();
            (tris, cum)
        };
        let (floor_tris, floor_cum) =
            pick(&|f| face_kind[f] == SurfaceKind::Floor && model.faces[f].normal.z.abs() > 0.9);
        let (wall_tris, wall_cum) = pick(&|f| model.faces[f].normal.z.abs() < 0.1);
        let floor_area = floor_cum.last().copied().unwrap_or(0.0);

        // Fixtures: decided before clutter so that clutter keeps out of them, appended after it
        // so that the clutter's surfaces keep their indices (and texture seeds).
        let fixtures = {
            let floor = |rng: &mut Rng| sample_on(&floor_tris, &floor_cum, rng).map(|(p, _)| p);
            fixtures::build(model, &face_kind, appearance, &keep, &probe, &floor, floor_area)
        };
        let blocked = |lo: [f64; 3], hi: [f64; 3]| {
            fixtures
                .blockers
                .iter()
                .any(|b| (0..3).all(|k| lo[k] < b.1[k] && b.0[k] < hi[k]))
        };
        let grain = Pattern::grain(appearance.clutter_texture);

        let mut rng = Rng::new(appearance.seed ^ 0xC1u64 << 32);
        let mut clutter_counts = [0usize; 3];
        let count = |level: f64, per_m2: f64| (level.max(0.0) * floor_area / per_m2).round() as usize;

        // Furniture boxes on the floor.
        let want = count(appearance.clutter, 12.0);
        for _ in 0..want * 20 {
            if clutter_counts[0] >= want {
                break;
            }
            let Some((p, _)) = sample_on(&floor_tris, &floor_cum, &mut rng) else {
                break;
            };
            let (hx, hy, h) = (rng.range(0.2, 0.6), rng.range(0.2, 0.5), rng.range(0.4, 1.1));
            let probe_z = p[2] + 0.3;
            let clear = (0..8).all(|k| {
                let a = k as f64 * std::f64::consts::FRAC_PI_4;
                let d = [a.cos(), a.sin(), 0.0];
                probe.free([p[0], p[1], probe_z], d, 5.0) > (hx * hx + hy * hy).sqrt() + 0.05
            }) && probe.free([p[0], p[1], p[2] + 0.05], [0.0, 0.0, 1.0], 10.0) > h + 0.3;
            let (blo, bhi) = ([p[0] - hx, p[1] - hy, p[2]], [p[0] + hx, p[1] + hy, p[2] + h]);
            if !clear || near_keep_out(&keep, blo, bhi, 0.6) || blocked(blo, bhi) {
                continue;
            }
            let sid = surfaces.len() as u32;
            let colour = hsv(
                rng.unit(),
                0.55 * appearance.colour.clamp(0.0, 1.0),
                rng.range(0.3, 0.8),
            );
            surfaces.push(Surface {
                kind: SurfaceKind::Furniture,
                colour: muted(colour, appearance),
                pattern: grain,
            });
            let before = triangles.len();
            box_triangles(
                [p[0], p[1], p[2] + h / 2.0 + 1e-3],
                [[hx, 0.0, 0.0], [0.0, hy, 0.0], [0.0, 0.0, h / 2.0]],
                &mut triangles,
            );
            payload.resize(payload.len() + triangles.len() - before, sid);
            clutter_counts[0] += 1;
        }

        // A wall spot: point, horizontal unit normal towards free space, along-wall axis, floor z.
        let wall_spot = |rng: &mut Rng, min_free: f64| -> Option<WallSpot> {
            let (p, f) = sample_on(&wall_tris, &wall_cum, rng)?;
            let n = model.faces[f].normal;
            let hn = Vector3::new(n.x, n.y, 0.0).try_normalize(1e-9)?;
            let sides = [[hn.x, hn.y, 0.0], [-hn.x, -hn.y, 0.0]];
            let first = (rng.unit() < 0.5) as usize;
            for side in [sides[first], sides[1 - first]] {
                let q = add(p, side, 0.1);
                if probe.free(q, side, 3.0) < min_free {
                    continue;
                }
                let floor = probe.free(q, [0.0, 0.0, -1.0], 20.0);
                let ceil = probe.free(q, [0.0, 0.0, 1.0], 20.0);
                if floor >= 20.0 || ceil >= 20.0 {
                    continue;
                }
                let u = [-side[1], side[0], 0.0];
                return Some(WallSpot {
                    base: [p[0], p[1], q[2] - floor],
                    side,
                    u,
                    floor: q[2] - floor,
                    ceil: q[2] + ceil,
                });
            }
            None
        };
        // Whether a segment of the wall through `base` along `u` from −w to w at height z is
        // backed by the wall (a ray towards it from `off` metres out hits at about `off`).
        let backed = |base: [f64; 3], side: [f64; 3], u: [f64; 3], w: f64, z: f64, off: f64| {
            [-w, 0.0, w].into_iter().all(|s| {
                let q = add(add([base[0], base[1], z], u, s), side, off);
                (probe.free(q, [-side[0], -side[1], 0.0], off + 0.05) - off).abs() < 0.01
            })
        };

        // Shelving units against walls: two sides, top, bottom and boards, no back.
        let want = count(appearance.clutter, 25.0);
        for _ in 0..want * 20 {
            if clutter_counts[1] >= want {
                break;
            }
            let Some(WallSpot {
                base,
                side,
                u,
                floor,
                ceil,
            }) = wall_spot(&mut rng, 1.2)
            else {
                continue;
            };
            let (w, depth) = (rng.range(0.4, 0.8), 0.18);
            let h = rng.range(1.2, 2.0).min(ceil - floor - 0.2);
            if h < 0.8
                || !backed(base, side, u, w, floor + 0.3, 0.02)
                || !backed(base, side, u, w, floor + h - 0.1, 0.02)
                || probe.free(add([base[0], base[1], floor + h / 2.0], side, 0.2), u, 3.0) < w
                || probe.free(
                    add([base[0], base[1], floor + h / 2.0], side, 0.2),
                    [-u[0], -u[1], 0.0],
                    3.0,
                ) < w
            {
                continue;
            }
            let centre = add([base[0], base[1], floor], side, depth + 0.01);
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for su in [-1.0, 1.0] {
                for sd in [-1.0, 1.0] {
                    let c = add(add(centre, u, su * w), side, sd * depth);
                    for k in 0..2 {
                        lo[k] = lo[k].min(c[k]);
                        hi[k] = hi[k].max(c[k]);
                    }
                }
            }
            (lo[2], hi[2]) = (floor, floor + h);
            if near_keep_out(&keep, lo, hi, 0.6) || blocked(lo, hi) {
                continue;
            }
            let sid = surfaces.len() as u32;
            let colour = hsv(
                rng.unit(),
                0.5 * appearance.colour.clamp(0.0, 1.0),
                rng.range(0.25, 0.7),
            );
            surfaces.push(Surface {
                kind: SurfaceKind::Shelf,
                colour: muted(colour, appearance),
                pattern: grain,
            });
            let before = triangles.len();
            let t = 0.015;
            let up = [0.0, 0.0, 1.0];
            let scale = |v: [f64; 3], s: f64| [v[0] * s, v[1] * s, v[2] * s];
            for su in [-1.0, 1.0] {
                let c = add(add(centre, u, su * (w - t)), up, h / 2.0);
                box_triangles(c, [scale(u, t), scale(side, depth), scale(up, h / 2.0)], &mut triangles);
            }
            let boards = 2 + (h / 0.45) as usize;
            for b in 0..boards {
                let z = t + (h - 2.0 * t) * b as f64 / (boards - 1) as f64;
                let c = add(centre, up, z);
                box_triangles(
                    c,
                    [scale(u, w - 2.0 * t), scale(side, depth), scale(up, t)],
                    &mut triangles,
                );
            }
            payload.resize(payload.len() + triangles.len() - before, sid);
            clutter_counts[1] += 1;
        }

        // Posters: a coloured rectangle with an inner rectangle of another colour, 8–9 mm off a wall.
        let want = count(appearance.clutter, 10.0);
        for _ in 0..want * 20 {
            if clutter_counts[2] >= want {
                break;
            }
            let Some(WallSpot {
                base,
                side,
                u,
                floor,
                ceil,
            }) = wall_spot(&mut rng, 0.5)
            else {
                continue;
            };
            let (w, h) = (rng.range(0.2, 0.5), rng.range(0.25, 0.55));
            let zc = floor + rng.range(1.1, 1.7);
            if zc + h > ceil - 0.05
                || !backed(base, side, u, w, zc - h, 0.03)
                || !backed(base, side, u, w, zc + h, 0.03)
            {
                continue;
            }
            let sat = appearance.colour.clamp(0.0, 1.0);
            let hue = rng.unit();
            let outer = hsv(hue, 0.8 * sat, rng.range(0.5, 0.95));
            let inner = hsv(hue + 0.5, 0.8 * sat, rng.range(0.2, 0.5));
            for (k, (colour, inset, off)) in [(outer, 1.0, 0.008), (inner, 0.7, 0.009)].into_iter().enumerate() {
                let sid = surfaces.len() as u32;
                let pattern = if appearance.clutter_texture > 0.0 && k == 1 {
                    // From a hash, not `rng`: the clutter's placement stays that of Default.
                    let h = hash64(appearance.seed ^ 0x0579_19E5_u64 << 20 ^ sid as u64);
                    Pattern::Stripes {
                        period: 0.02 + 0.04 * (h >> 40) as f32 / (1u64 << 24) as f32,
                        contrast: appearance.clutter_texture as f32,
                    }
                } else {
                    Pattern::None
                };
                surfaces.push(Surface {
                    kind: SurfaceKind::Poster,
                    colour,
                    pattern,
                });
                let before = triangles.len();
                let c = add([base[0], base[1], zc + if k == 1 { 0.1 * h } else { 0.0 }], side, off);
                quad_triangles(
                    c,
                    [u[0] * w * inset, u[1] * w * inset, 0.0],
                    [0.0, 0.0, h * inset * if k == 1 { 0.6 } else { 1.0 }],
                    &mut triangles,
                );
                payload.resize(payload.len() + triangles.len() - before, sid);
            }
            clutter_counts[2] += 1;
        }

        for piece in fixtures.pieces {
            let sid = surfaces.len() as u32;
            surfaces.push(piece.surface);
            payload.resize(payload.len() + piece.triangles.len(), sid);
            triangles.extend(piece.triangles);
        }

        // People walking on straight paths.
        let mut people = Vec::new();
        let want = count(appearance.people, 40.0);
        let mut prng = Rng::new(appearance.seed ^ 0x009E_091E_u64 << 20);
        for _ in 0..want * 20 {
            if people.len() >= want {
                break;
            }
            let Some((p, _)) = sample_on(&floor_tris, &floor_cum, &mut prng) else {
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
                colours: [
                    hsv(prng.unit(), 0.5 * sat, prng.range(0.15, 0.45)),
                    hsv(prng.unit(), 0.7 * sat, prng.range(0.4, 0.9)),
                    hsv(0.07, 0.45 * sat, prng.range(0.45, 0.8)),
                ],
            });
        }

        // Lights near the ceiling, spread over the bounds.
        let mut lrng = Rng::new(appearance.seed ^ 0x11647);
        let lights = (0..appearance.lights)
            .map(|_| Light {
                position: [
                    lrng.range(lo.x, hi.x) as f32,
                    lrng.range(lo.y, hi.y) as f32,
                    (lo.z + 0.85 * (hi.z - lo.z)) as f32,
                ],
                intensity: lrng.range(0.6, 1.0) as f32,
            })
            .collect();

        let geometry = if triangles.len() == model_triangles {
            model_bvh
        } else {
            TriangleBvh::build(&triangles, &payload)
        };
        Scene {
            geometry,
            surfaces,
            people,
            lights,
            clutter_counts,
            model_triangles,
            fixture_counts: fixtures.counts,
        }
    }

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
