//! The scene the renderer casts rays into: the model's faces (triangulated, coloured per
//! surface), plus clutter and people that exist only in the images, never in the model.
//!
//! In: a [`Model`], an [`Appearance`] and keep-out points (the trajectory) that clutter and
//! people must leave free. Out: a [`Scene`]: one triangle BVH over model, fixtures (module
//! [`super::fixtures`]) and clutter, the surface table its hits index (each surface with the
//! [`Pattern`] painted on it), the people and the lights. With `Appearance::wall_offset_m` the
//! model's triangles are those of its displaced vertices.
//!
//! Besides the model, the scene holds what submodules place: [`super::fixtures`] first (clutter
//! keeps out of them), then `clutter` (furniture, shelves, posters) and `people`, each drawing
//! from a seeded stream of its own.

mod clutter;
mod people;

pub use people::{Person, PersonColours, PlacedPerson};

/// Clutter items placed in a scene (in the images only, not in the model), by kind.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct ClutterCounts {
    /// Furniture boxes on the floor.
    pub furniture: usize,
    /// Shelving units against walls.
    pub shelves: usize,
    /// Posters on walls.
    pub posters: usize,
}

use super::appearance::{hash64, hsv, Appearance, Rng};
use super::fixtures::{self, FixtureCounts, Probe};
use nalgebra::Point3;
use omnitrack_core::model::bvh::{Triangle, TriangleBvh};
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
    /// Clutter items placed.
    pub clutter_counts: ClutterCounts,
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

/// Where the things the model leaves out may go: the model's floor and wall triangles (each with
/// its face, and their running areas for [`sample_on`]), ray queries on the model, the keep-out
/// points and the boxes fixtures took.
struct Site<'a> {
    model: &'a Model,
    floor_tris: &'a [(Triangle, usize)],
    floor_cum: &'a [f64],
    wall_tris: &'a [(Triangle, usize)],
    wall_cum: &'a [f64],
    floor_area: f64,
    probe: &'a Probe<'a>,
    keep: &'a [[f64; 3]],
    blockers: &'a [([f64; 3], [f64; 3])],
}

impl Site<'_> {
    /// How many items a level asks for: `level` per `per_m2` of floor.
    fn count(&self, level: f64, per_m2: f64) -> usize {
        (level.max(0.0) * self.floor_area / per_m2).round() as usize
    }
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
        let site = Site {
            model,
            floor_tris: &floor_tris,
            floor_cum: &floor_cum,
            wall_tris: &wall_tris,
            wall_cum: &wall_cum,
            floor_area,
            probe: &probe,
            keep: &keep,
            blockers: &fixtures.blockers,
        };
        let clutter_counts = clutter::place(&site, appearance, &mut surfaces, &mut triangles, &mut payload);

        for piece in fixtures.pieces {
            let sid = surfaces.len() as u32;
            surfaces.push(piece.surface);
            payload.resize(payload.len() + piece.triangles.len(), sid);
            triangles.extend(piece.triangles);
        }

        let people = people::place(&site, appearance);

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
}
