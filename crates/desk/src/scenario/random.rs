//! Buildings nobody here drew: random building models for tests and benchmarks, unlike the three
//! scenarios in every way a model from another tool can be (issue 20).
//!
//! In: a seed and optional [`Choices`] that pin some of the draws. Out: a [`RandomBuilding`]: the
//! model as OBJ text written the way exporters write it, the walked ground storey as a GeoJSON
//! floor plan for [`super::walk_through`], the motion to walk it with, and a one-line
//! description. Everything is deterministic in the seed.
//!
//! The model is not extruded by [`crate::floorplan`], whose tidy mitred solids are what the
//! tracker has always seen. Instead every wall is an independent box, or a single two-sided quad
//! for a thin wall: boxes overlap at corners and T-junctions, the pieces around an opening are
//! separate boxes whose faces touch inside the wall, floors and ceilings run under the walls to
//! their axes, a stair is a pile of step boxes, and, when drawn so, every face is split into
//! triangles and about half the faces are wound the other way.
//!
//! What the seed varies: the outline (rectangle, L, U or courtyard) over a grid of 3–5 × 2–4 bays
//! 3–6.5 m wide; the rooms (bays merged along a row); doors along a random spanning tree of the
//! rooms plus a few loops; windows in the exterior walls; walls thin, thick (0.1–0.3 m), or thick
//! outside and thin inside; the storey height (2.5–3 m); one storey or two, a two-storey building
//! having a double-height hall with a stair up to the upper floor; triangulation; the motion
//! (a cart at 1.2 m and 5 Hz, or hand-held at 10 Hz). Furniture and people are not in the model:
//! the renderer adds them to the images as clutter, as the real world does.

use super::Motion;
use crate::floorplan::{self, FloorPlan, FloorPlanError};
use crate::render::appearance::Rng;
use nalgebra::{Point2, Vector2};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::fmt::{self, Write as _};

type P2 = Point2<f64>;

/// The building's outline over its grid of bays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outline {
    Rectangle,
    /// One corner block of bays missing.
    L,
    /// The middle columns of the back rows missing.
    U,
    /// The inner bays missing: a ring of rooms round an open court.
    Courtyard,
}

/// How walls are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallStyle {
    /// Every wall a single two-sided face (what many sketching tools export).
    Thin,
    /// Every wall a box 0.1–0.3 m thick.
    Thick,
    /// Exterior walls thick, interior walls single faces.
    ThickOutside,
}

/// Draws to pin instead of drawing them from the seed; `None` draws.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Choices {
    pub outline: Option<Outline>,
    pub walls: Option<WallStyle>,
    /// 1 or 2 (2 also needs a room long enough for the stair; otherwise the building has 1).
    pub storeys: Option<usize>,
    pub triangulated: Option<bool>,
    /// Fraction of faces wound the other way (default 0.5).
    pub flip_fraction: Option<f64>,
    /// Bays in x and y (each at least 3 and 2, and 3 × 3 for a courtyard); drawn as 3–5 × 2–4.
    pub bays: Option<[usize; 2]>,
    /// How the walk moves: `true` a cart at 1.2 m and 5 Hz, `false` hand-held at 10 Hz.
    pub cart: Option<bool>,
}

impl Choices {
    /// Reads `L,thin,cart`-style pins, comma-separated, any order: an outline (`rectangle`, `L`,
    /// `U`, `courtyard`), a wall style (`thin`, `thick`, `thick-outside`), `1-storey` or
    /// `2-storeys`, `triangles` or `quads`, `cart` or `hand-held`.
    pub fn parse(spec: &str) -> Result<Choices, String> {
        let mut c = Choices::default();
        for word in spec.split(',').map(str::trim).filter(|w| !w.is_empty()) {
            match word.to_ascii_lowercase().as_str() {
                "rectangle" => c.outline = Some(Outline::Rectangle),
                "l" => c.outline = Some(Outline::L),
                "u" => c.outline = Some(Outline::U),
                "courtyard" => c.outline = Some(Outline::Courtyard),
                "thin" => c.walls = Some(WallStyle::Thin),
                "thick" => c.walls = Some(WallStyle::Thick),
                "thick-outside" => c.walls = Some(WallStyle::ThickOutside),
                "1-storey" => c.storeys = Some(1),
                "2-storeys" => c.storeys = Some(2),
                "triangles" => c.triangulated = Some(true),
                "quads" => c.triangulated = Some(false),
                "cart" => c.cart = Some(true),
                "hand-held" => c.cart = Some(false),
                _ => {
                    return Err(format!(
                        "unknown building pin {word:?}: expected rectangle, L, U, courtyard, thin, thick, \
                         thick-outside, 1-storey, 2-storeys, triangles, quads, cart or hand-held"
                    ))
                }
            }
        }
        Ok(c)
    }
}

/// A generated building.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomBuilding {
    pub seed: u64,
    pub outline: Outline,
    pub walls: WallStyle,
    pub bays: [usize; 2],
    pub storeys: usize,
    pub triangulated: bool,
    pub storey_height_m: f64,
    /// Rooms of the walked ground storey, and their total floor area.
    pub rooms: usize,
    pub floor_area_m2: f64,
    pub doors: usize,
    pub windows: usize,
    /// Faces of the OBJ, and how many of them are wound the other way.
    pub faces: usize,
    pub flipped: usize,
    /// The ground storey as a floor plan (walls, doors, rooms; the stair as an obstacle wall):
    /// what the walks are planned in. Its walls are the model's wall axes and thicknesses.
    pub plan_geojson: String,
    /// The model, Wavefront OBJ text, metres, z up.
    pub obj: String,
    pub motion: Motion,
    pub frame_rate_hz: f64,
}

impl fmt::Display for RandomBuilding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:?} outline over {}×{} bays, {} rooms {:.0} m², {} doors, {} windows, {} walls, {} storey{}, \
             {:.2} m high, {}{} of {} faces wound the other way, {}",
            self.outline,
            self.bays[0],
            self.bays[1],
            self.rooms,
            self.floor_area_m2,
            self.doors,
            self.windows,
            match self.walls {
                WallStyle::Thin => "single-face",
                WallStyle::Thick => "thick",
                WallStyle::ThickOutside => "thick exterior, single-face interior",
            },
            self.storeys,
            if self.storeys > 1 {
                "s (a double-height hall with a stair)"
            } else {
                ""
            },
            self.storey_height_m,
            if self.triangulated { "triangulated, " } else { "" },
            self.flipped,
            self.faces,
            match self.motion {
                Motion::Rolling3Dof { height_m } =>
                    format!("walked on a cart at {height_m} m, {} Hz", self.frame_rate_hz),
                Motion::HandHeld6Dof => format!("walked hand-held at {} Hz", self.frame_rate_hz),
            }
        )
    }
}

/// Thickness of the slab between storeys.
const SLAB_M: f64 = 0.25;
/// Stair step rise and the shortest tread the stair may get.
const STEP_RISE_M: f64 = 0.19;
const MIN_TREAD_M: f64 = 0.24;
const STAIR_WIDTH_M: f64 = 1.0;
/// Free floor the hall keeps beside its stair (the walk must pass it).
const HALL_FREE_M: f64 = 2.2;
/// Openings keep this far from the ends of their bay's wall (the walls across).
const OPENING_MARGIN_M: f64 = 0.45;

fn below(rng: &mut Rng, n: usize) -> usize {
    ((rng.unit() * n as f64) as usize).min(n - 1)
}

/// Rounds to 5 cm, as a drawing would.
fn snap(x: f64) -> f64 {
    (x * 20.0).round() / 20.0
}

/// An opening in a wall run: along the run `s0..s1`, heights `z0..z1`.
#[derive(Debug, Clone, Copy)]
struct Hole {
    s0: f64,
    s1: f64,
    z0: f64,
    z1: f64,
}

/// A straight wall along one grid line, from `a` to `b`.
struct Run {
    a: P2,
    b: P2,
    thickness: f64,
    holes: Vec<Hole>,
    /// Doors of the ground storey as `(s0, s1)`, for the floor plan.
    doors: Vec<(f64, f64)>,
}

/// Vertices shared by position; faces grouped by name.
struct Mesh {
    vertices: Vec<[f64; 3]>,
    index: HashMap<[i64; 3], u32>,
    groups: Vec<(String, Vec<Vec<u32>>)>,
}

impl Mesh {
    fn new() -> Self {
        Mesh {
            vertices: Vec::new(),
            index: HashMap::new(),
            groups: Vec::new(),
        }
    }

    fn group(&mut self, name: String) {
        self.groups.push((name, Vec::new()));
    }

    fn vertex(&mut self, p: [f64; 3]) -> u32 {
        // 1 µm keys: positions computed along different paths are one vertex.
        let key = p.map(|c| (c * 1e6).round() as i64);
        let next = self.vertices.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.vertices.push(p);
            next
        })
    }

    fn face(&mut self, pts: &[[f64; 3]]) {
        let f: Vec<u32> = pts.iter().map(|&p| self.vertex(p)).collect();
        if let Some((_, faces)) = self.groups.last_mut() {
            faces.push(f);
        }
    }

    /// A horizontal rectangle, wound about `up` (+z) or down.
    fn rect(&mut self, lo: P2, hi: P2, z: f64, up: bool) {
        let mut q = [[lo.x, lo.y, z], [hi.x, lo.y, z], [hi.x, hi.y, z], [lo.x, hi.y, z]];
        if !up {
            q.reverse();
        }
        self.face(&q);
    }

    /// A box around the axis `a`→`b`, `half` either side of it, from `z0` to `z1`; a single
    /// vertical quad when `half` is 0.
    fn wall_box(&mut self, a: P2, b: P2, half: f64, z0: f64, z1: f64) {
        let u = (b - a).normalize();
        let n = Vector2::new(-u.y, u.x) * half;
        let p = |q: P2, z: f64| [q.x, q.y, z];
        if half == 0.0 {
            self.face(&[p(a, z0), p(b, z0), p(b, z1), p(a, z1)]);
            return;
        }
        let (a0, b0, b1, a1) = (a - n, b - n, b + n, a + n);
        // Outward: the −n side, the +n side, the two ends, bottom and top.
        self.face(&[p(a0, z0), p(b0, z0), p(b0, z1), p(a0, z1)]);
        self.face(&[p(b1, z0), p(a1, z0), p(a1, z1), p(b1, z1)]);
        self.face(&[p(b0, z0), p(b1, z0), p(b1, z1), p(b0, z1)]);
        self.face(&[p(a1, z0), p(a0, z0), p(a0, z1), p(a1, z1)]);
        self.face(&[p(a0, z0), p(a1, z0), p(b1, z0), p(b0, z0)]);
        self.face(&[p(a0, z1), p(b0, z1), p(b1, z1), p(a1, z1)]);
    }

    /// A wall run cut around its holes: between consecutive hole edges, one box per solid height
    /// interval. Thick runs reach half their thickness past both ends, so corners close.
    fn run(&mut self, r: &Run, top: f64) {
        let len = (r.b - r.a).norm();
        let u = (r.b - r.a) / len;
        let half = r.thickness / 2.0;
        let mut cuts = vec![-half, len + half];
        for h in &r.holes {
            cuts.push(h.s0);
            cuts.push(h.s1);
        }
        cuts.sort_by(f64::total_cmp);
        cuts.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
        for w in cuts.windows(2) {
            let (s0, s1) = (w[0], w[1]);
            let mid = (s0 + s1) / 2.0;
            let mut gaps: Vec<(f64, f64)> = r
                .holes
                .iter()
                .filter(|h| h.s0 < mid && mid < h.s1)
                .map(|h| (h.z0, h.z1))
                .collect();
            gaps.sort_by(|x, y| x.0.total_cmp(&y.0));
            let mut z = 0.0;
            for (g0, g1) in gaps.into_iter().chain([(top, top)]) {
                if g0 > z + 1e-6 {
                    self.wall_box(r.a + u * s0, r.a + u * s1, half, z, g0.min(top));
                }
                z = z.max(g1);
            }
        }
    }

    /// OBJ text: triangulated if asked, `flip_fraction` of the faces (drawn by `rng`) reversed.
    /// Returns the text, the face count and how many were reversed.
    fn to_obj(&self, header: &str, triangulate: bool, flip_fraction: f64, rng: &mut Rng) -> (String, usize, usize) {
        let mut out = String::from(header);
        for v in &self.vertices {
            let _ = writeln!(out, "v {} {} {}", v[0], v[1], v[2]);
        }
        let (mut faces, mut flipped) = (0, 0);
        for (name, group) in &self.groups {
            let _ = writeln!(out, "g {name}");
            for f in group {
                let pieces: Vec<Vec<u32>> = if triangulate && f.len() == 4 {
                    // Either diagonal, as exporters choose.
                    if rng.unit() < 0.5 {
                        vec![vec![f[0], f[1], f[2]], vec![f[0], f[2], f[3]]]
                    } else {
                        vec![vec![f[0], f[1], f[3]], vec![f[1], f[2], f[3]]]
                    }
                } else {
                    vec![f.clone()]
                };
                for mut p in pieces {
                    if rng.unit() < flip_fraction {
                        p.reverse();
                        flipped += 1;
                    }
                    faces += 1;
                    out.push('f');
                    for i in p {
                        let _ = write!(out, " {}", i + 1);
                    }
                    out.push('\n');
                }
            }
        }
        (out, faces, flipped)
    }
}

/// A door or window drawn on one bay's wall.
struct Opening {
    /// Index of the bay's wall.
    wall: usize,
    /// Along the bay's wall from its start.
    s0: f64,
    s1: f64,
    z0: f64,
    z1: f64,
    door: bool,
}

impl RandomBuilding {
    /// The building of `seed`, every choice drawn.
    pub fn new(seed: u64) -> RandomBuilding {
        Self::generate(seed, &Choices::default())
    }

    /// The building of `seed` with the pinned `choices`.
    pub fn generate(seed: u64, choices: &Choices) -> RandomBuilding {
        let mut rng = Rng::new(seed ^ 0xb111_d1a9);
        let outline = choices
            .outline
            .unwrap_or([Outline::Rectangle, Outline::L, Outline::U, Outline::Courtyard][below(&mut rng, 4)]);
        let walls = choices
            .walls
            .unwrap_or([WallStyle::Thin, WallStyle::Thick, WallStyle::ThickOutside][below(&mut rng, 3)]);
        let want_storeys = choices.storeys.unwrap_or(if rng.unit() < 0.3 { 2 } else { 1 });
        let triangulated = choices.triangulated.unwrap_or(rng.unit() < 0.5);
        let flip_fraction = choices.flip_fraction.unwrap_or(0.5);
        let (nx, ny) = (3 + below(&mut rng, 3), 2 + below(&mut rng, 3));
        let (nx, mut ny) = match choices.bays {
            Some([x, y]) => (x.max(3), y.max(2)),
            None => (nx, ny),
        };
        if outline == Outline::Courtyard {
            ny = ny.max(3);
        }
        let edges = |n: usize, rng: &mut Rng| {
            let mut v = vec![0.0];
            for _ in 0..n {
                let last = *v.last().expect("starts with 0");
                v.push(snap(last + rng.range(3.0, 6.5)));
            }
            v
        };
        let xs = edges(nx, &mut rng);
        let ys = edges(ny, &mut rng);
        let mut inside = vec![vec![true; ny]; nx];
        match outline {
            Outline::Rectangle => {}
            Outline::L => {
                let (cx, cy) = (1 + below(&mut rng, nx - 1), 1 + below(&mut rng, ny - 1));
                for col in inside.iter_mut().skip(cx) {
                    for c in col.iter_mut().skip(cy) {
                        *c = false;
                    }
                }
            }
            Outline::U => {
                let cy = 1 + below(&mut rng, ny - 1);
                for col in inside.iter_mut().take(nx - 1).skip(1) {
                    for c in col.iter_mut().skip(cy) {
                        *c = false;
                    }
                }
            }
            Outline::Courtyard => {
                for col in inside.iter_mut().take(nx - 1).skip(1) {
                    for c in col.iter_mut().take(ny - 1).skip(1) {
                        *c = false;
                    }
                }
            }
        }
        let (t_out, t_in) = match walls {
            WallStyle::Thin => (0.0, 0.0),
            WallStyle::Thick => {
                let t = snap(rng.range(0.1, 0.3));
                (t, snap(rng.range(0.1, t)))
            }
            WallStyle::ThickOutside => (snap(rng.range(0.15, 0.35)), 0.0),
        };
        let height = snap(rng.range(2.5, 3.0));

        // Rooms: bays merged along rows, up to 11 m.
        let mut room = vec![vec![usize::MAX; ny]; nx];
        let mut rects: Vec<(P2, P2)> = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                if !inside[i][j] {
                    continue;
                }
                let merge = i > 0 && inside[i - 1][j] && rng.unit() < 0.35 && {
                    let r = rects[room[i - 1][j]];
                    xs[i + 1] - r.0.x <= 11.0
                };
                if merge {
                    let k = room[i - 1][j];
                    room[i][j] = k;
                    rects[k].1.x = xs[i + 1];
                } else {
                    room[i][j] = rects.len();
                    rects.push((P2::new(xs[i], ys[j]), P2::new(xs[i + 1], ys[j + 1])));
                }
            }
        }
        let cell = |i: isize, j: isize| -> Option<usize> {
            (i >= 0 && j >= 0 && (i as usize) < nx && (j as usize) < ny && inside[i as usize][j as usize])
                .then(|| room[i as usize][j as usize])
        };

        // Bay walls: every bay side between two rooms or between a room and the outside.
        // (line, a, b, rooms either side)
        struct BayWall {
            a: P2,
            b: P2,
            rooms: (Option<usize>, Option<usize>),
        }
        let mut bay_walls = Vec::new();
        for i in 0..=nx as isize {
            for j in 0..ny as isize {
                let (l, r) = (cell(i - 1, j), cell(i, j));
                if (l.is_some() || r.is_some()) && l != r {
                    bay_walls.push(BayWall {
                        a: P2::new(xs[i as usize], ys[j as usize]),
                        b: P2::new(xs[i as usize], ys[j as usize + 1]),
                        rooms: (l, r),
                    });
                }
            }
        }
        for j in 0..=ny as isize {
            for i in 0..nx as isize {
                let (d, u) = (cell(i, j - 1), cell(i, j));
                if (d.is_some() || u.is_some()) && d != u {
                    bay_walls.push(BayWall {
                        a: P2::new(xs[i as usize], ys[j as usize]),
                        b: P2::new(xs[i as usize + 1], ys[j as usize]),
                        rooms: (d, u),
                    });
                }
            }
        }

        // A hall for the stair, if two storeys: the room whose long side fits the stair best.
        let top_of_ground = height + SLAB_M;
        let steps = (top_of_ground / STEP_RISE_M).ceil() as usize;
        let mut hall = None;
        if want_storeys > 1 {
            let mut best: Option<(f64, usize)> = None;
            for (k, (lo, hi)) in rects.iter().enumerate() {
                let (long, short) = ((hi.x - lo.x).max(hi.y - lo.y), (hi.x - lo.x).min(hi.y - lo.y));
                let tread = (long - 1.6 - t_out) / steps as f64;
                if tread >= MIN_TREAD_M
                    && short >= STAIR_WIDTH_M + HALL_FREE_M + t_out
                    && best.is_none_or(|b| tread > b.0)
                {
                    best = Some((tread, k));
                }
            }
            hall = best.map(|(tread, k)| (k, tread.min(0.3)));
        }

        // Doors: a random spanning tree of the rooms, and a quarter of the other adjacencies.
        let mut pairs: Vec<(usize, usize, Vec<usize>)> = Vec::new();
        for (w, bw) in bay_walls.iter().enumerate() {
            if let (Some(p), Some(q)) = bw.rooms {
                let key = (p.min(q), p.max(q));
                match pairs.iter_mut().find(|x| (x.0, x.1) == key) {
                    Some(x) => x.2.push(w),
                    None => pairs.push((key.0, key.1, vec![w])),
                }
            }
        }
        for k in (1..pairs.len()).rev() {
            pairs.swap(k, below(&mut rng, k + 1));
        }
        let mut parent: Vec<usize> = (0..rects.len()).collect();
        fn find(p: &mut [usize], x: usize) -> usize {
            let mut r = x;
            while p[r] != r {
                r = p[r];
            }
            p[x] = r;
            r
        }
        let mut openings: Vec<Opening> = Vec::new();
        for (p, q, ws) in &pairs {
            let (rp, rq) = (find(&mut parent, *p), find(&mut parent, *q));
            let tree = rp != rq;
            if tree {
                parent[rp] = rq;
            }
            if tree || rng.unit() < 0.25 {
                let w = ws[below(&mut rng, ws.len())];
                let bw = &bay_walls[w];
                let len = (bw.b - bw.a).norm();
                let width = snap(rng.range(0.95, 1.2));
                let s0 = snap(rng.range(OPENING_MARGIN_M, len - OPENING_MARGIN_M - width));
                openings.push(Opening {
                    wall: w,
                    s0,
                    s1: s0 + width,
                    z0: 0.0,
                    z1: snap(rng.range(2.0, 2.15)),
                    door: true,
                });
            }
        }
        // The stair runs along the hall's long side, against one of its two long walls, on a side
        // where it blocks no door; with no such side the building keeps one storey.
        let mut stair_axis = None;
        if let Some((k, tread)) = hall {
            let (lo, hi) = rects[k];
            let along_x = hi.x - lo.x >= hi.y - lo.y;
            let (u0, v) = (t_out / 2.0 + 0.8, t_out / 2.0 + STAIR_WIDTH_M / 2.0);
            let length = steps as f64 * tread;
            let axis = |far: bool| -> (P2, P2) {
                // From the low corner along +u, or from the high corner along −u.
                let (c, sign) = if far { (hi, -1.0) } else { (lo, 1.0) };
                let at = |u: f64| {
                    if along_x {
                        P2::new(c.x + sign * u, c.y + sign * v)
                    } else {
                        P2::new(c.x + sign * v, c.y + sign * u)
                    }
                };
                (at(u0), at(u0 + length))
            };
            let blocks = |(a, b): (P2, P2)| {
                openings.iter().filter(|o| o.door).any(|o| {
                    let bw = &bay_walls[o.wall];
                    let u = (bw.b - bw.a) / (bw.b - bw.a).norm();
                    let c = bw.a + u * ((o.s0 + o.s1) / 2.0);
                    let ab = b - a;
                    let t = ((c - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
                    (a + ab * t - c).norm() < STAIR_WIDTH_M / 2.0 + 0.9
                })
            };
            let first = rng.unit() < 0.5;
            stair_axis = [first, !first].into_iter().map(axis).find(|&ax| !blocks(ax));
            if stair_axis.is_none() {
                hall = None;
            }
        }
        let storeys = if hall.is_some() { 2 } else { 1 };
        // Windows in exterior bays, on every storey; none in the hall's ground storey.
        for (w, bw) in bay_walls.iter().enumerate() {
            if bw.rooms.0.is_some() && bw.rooms.1.is_some() {
                continue;
            }
            for storey in 0..storeys {
                if rng.unit() >= 0.65 {
                    continue;
                }
                let len = (bw.b - bw.a).norm();
                let width = snap(rng.range(0.8, (len - 2.0 * OPENING_MARGIN_M - 0.3).min(2.2)));
                let s0 = snap(rng.range(OPENING_MARGIN_M, len - OPENING_MARGIN_M - width));
                let base = storey as f64 * top_of_ground;
                let sill = snap(rng.range(0.75, 1.0));
                let head = snap(rng.range(1.9, (height - 0.25).min(2.2)));
                if storey == 0 && hall.is_some_and(|(k, _)| Some(k) == bw.rooms.0.or(bw.rooms.1)) {
                    continue;
                }
                openings.push(Opening {
                    wall: w,
                    s0,
                    s1: s0 + width,
                    z0: base + sill,
                    z1: base + head,
                    door: false,
                });
            }
        }
        // Upper-storey doors: the ground doors again, except into the hall's void.
        if let Some((hk, _)) = hall {
            let upper: Vec<Opening> = openings
                .iter()
                .filter(|o| o.door)
                .filter(|o| {
                    let rooms = bay_walls[o.wall].rooms;
                    rooms.0 != Some(hk) && rooms.1 != Some(hk)
                })
                .map(|o| Opening {
                    z0: o.z0 + top_of_ground,
                    z1: o.z1 + top_of_ground,
                    ..*o
                })
                .collect();
            openings.extend(upper);
        }

        // Runs: bay walls merged along their grid line while of one kind (exterior or interior).
        let mut runs: Vec<Run> = Vec::new();
        let mut order: Vec<usize> = (0..bay_walls.len()).collect();
        let horizontal = |bw: &BayWall| bw.a.y == bw.b.y;
        order.sort_by(|&p, &q| {
            let (a, b) = (&bay_walls[p], &bay_walls[q]);
            let ka = (
                horizontal(a),
                if horizontal(a) { a.a.y } else { a.a.x },
                if horizontal(a) { a.a.x } else { a.a.y },
            );
            let kb = (
                horizontal(b),
                if horizontal(b) { b.a.y } else { b.a.x },
                if horizontal(b) { b.a.x } else { b.a.y },
            );
            ka.partial_cmp(&kb).expect("finite coordinates")
        });
        let exterior = |bw: &BayWall| bw.rooms.0.is_none() || bw.rooms.1.is_none();
        // Per bay wall, its run; per run, whether it is exterior.
        let mut run_of = vec![0usize; bay_walls.len()];
        let mut run_exterior: Vec<bool> = Vec::new();
        for &w in &order {
            let bw = &bay_walls[w];
            let t = if exterior(bw) { t_out } else { t_in };
            let extends = runs.last().is_some_and(|r: &Run| {
                (r.b - bw.a).norm() < 1e-9 && r.thickness == t && (horizontal(bw) == (r.a.y == r.b.y))
            }) && run_exterior.last() == Some(&exterior(bw));
            if extends {
                runs.last_mut().expect("checked").b = bw.b;
            } else {
                runs.push(Run {
                    a: bw.a,
                    b: bw.b,
                    thickness: t,
                    holes: Vec::new(),
                    doors: Vec::new(),
                });
                run_exterior.push(exterior(bw));
            }
            run_of[w] = runs.len() - 1;
        }
        for o in &openings {
            let r = &mut runs[run_of[o.wall]];
            let offset = (bay_walls[o.wall].a - r.a).norm();
            r.holes.push(Hole {
                s0: offset + o.s0,
                s1: offset + o.s1,
                z0: o.z0,
                z1: o.z1,
            });
            if o.door && o.z0 == 0.0 {
                r.doors.push((offset + o.s0, offset + o.s1));
            }
        }

        // The model.
        let top = if storeys > 1 { top_of_ground + height } else { height };
        let mut mesh = Mesh::new();
        for (k, r) in runs.iter().enumerate() {
            mesh.group(format!("wall_{k}"));
            mesh.run(r, top);
        }
        for (k, (lo, hi)) in rects.iter().enumerate() {
            let is_hall = hall.is_some_and(|(h, _)| h == k);
            mesh.group(format!("room_{k}_floor"));
            mesh.rect(*lo, *hi, 0.0, true);
            mesh.group(format!("room_{k}_ceiling"));
            mesh.rect(*lo, *hi, if is_hall { top } else { height }, false);
            if storeys > 1 && !is_hall {
                mesh.group(format!("room_{k}_upper_floor"));
                mesh.rect(*lo, *hi, top_of_ground, true);
                mesh.group(format!("room_{k}_upper_ceiling"));
                mesh.rect(*lo, *hi, top, false);
            }
        }
        // The stair: one box per step along the axis chosen above.
        if let (Some((_, tread)), Some((a, b))) = (hall, stair_axis) {
            let u = (b - a) / (b - a).norm();
            let rise = top_of_ground / steps as f64;
            mesh.group("stair".to_string());
            for s in 0..steps {
                let (p, q) = (a + u * (s as f64 * tread), a + u * ((s + 1) as f64 * tread));
                mesh.wall_box(p, q, STAIR_WIDTH_M / 2.0, 0.0, (s + 1) as f64 * rise);
            }
        }
        let floor_area_m2: f64 = rects.iter().map(|(lo, hi)| (hi.x - lo.x) * (hi.y - lo.y)).sum();
        let doors = openings.iter().filter(|o| o.door && o.z0 == 0.0).count();
        let windows = openings.iter().filter(|o| !o.door).count();
        let header = format!(
            "# A random building (omnitrack::desk::scenario::random, seed {seed}): {outline:?} outline, \
             {} rooms, {walls:?} walls, {storeys} storeys.\n# Metres, z up. Walls are independent boxes or \
             single faces; winding carries no meaning.\n",
            rects.len()
        );
        let (obj, faces, flipped) = mesh.to_obj(&header, triangulated, flip_fraction, &mut rng);

        // The walked ground storey as a floor plan.
        let mut features: Vec<Value> = Vec::new();
        for (k, r) in runs.iter().enumerate() {
            features.push(json!({
                "type": "Feature",
                "properties": { "kind": "wall", "name": format!("wall {k}"), "thickness_m": r.thickness },
                "geometry": { "type": "LineString", "coordinates": [[r.a.x, r.a.y], [r.b.x, r.b.y]] },
            }));
            let u = (r.b - r.a) / (r.b - r.a).norm();
            for (d, &(s0, s1)) in r.doors.iter().enumerate() {
                let (p, q) = (r.a + u * s0, r.a + u * s1);
                features.push(json!({
                    "type": "Feature",
                    "properties": { "kind": "door", "name": format!("wall {k} door {d}") },
                    "geometry": { "type": "LineString", "coordinates": [[p.x, p.y], [q.x, q.y]] },
                }));
            }
        }
        if let Some((a, b)) = stair_axis {
            // The stair as a wall as wide as the stair: the walk keeps clear of it.
            features.push(json!({
                "type": "Feature",
                "properties": { "kind": "wall", "name": "stair", "thickness_m": STAIR_WIDTH_M },
                "geometry": { "type": "LineString", "coordinates": [[a.x, a.y], [b.x, b.y]] },
            }));
        }
        for (k, (lo, hi)) in rects.iter().enumerate() {
            features.push(json!({
                "type": "Feature",
                "properties": { "kind": "room", "name": format!("room {k}") },
                "geometry": { "type": "Polygon", "coordinates": [[
                    [lo.x, lo.y], [hi.x, lo.y], [hi.x, hi.y], [lo.x, hi.y], [lo.x, lo.y]
                ]] },
            }));
        }
        let plan = json!({
            "type": "FeatureCollection",
            "name": format!("random building {seed}"),
            "properties": { "storey_height_m": height },
            "features": features,
        });
        let plan_geojson = serde_json::to_string_pretty(&plan).expect("a JSON value always serialises");
        let cart = rng.unit() < 0.5;
        let (motion, frame_rate_hz) = if choices.cart.unwrap_or(cart) {
            (Motion::Rolling3Dof { height_m: 1.2 }, 5.0)
        } else {
            (Motion::HandHeld6Dof, 10.0)
        };
        RandomBuilding {
            seed,
            outline,
            walls,
            bays: [nx, ny],
            storeys,
            triangulated,
            storey_height_m: height,
            rooms: rects.len(),
            floor_area_m2,
            doors,
            windows,
            faces,
            flipped,
            plan_geojson,
            obj,
            motion,
            frame_rate_hz,
        }
    }

    /// `building-SEED`.
    pub fn name(&self) -> String {
        format!("building-{}", self.seed)
    }

    /// The walked ground storey's floor plan.
    pub fn plan(&self) -> Result<FloorPlan, FloorPlanError> {
        floorplan::parse(&self.plan_geojson, &format!("{}.geojson", self.name()))
    }

    /// A walk of `frames` poses through the ground storey (see [`super::walk_through`]).
    pub fn trajectory(&self, frames: usize, seed: u64) -> omnitrack_core::trajectory::Trajectory {
        let plan = self.plan().expect("a generated plan parses");
        super::walk_through(&plan, self.frame_rate_hz, self.motion, frames, seed)
    }
}

/// Several random buildings side by side: a campus for building large visibility tables.
#[derive(Debug, Clone, PartialEq)]
pub struct Campus {
    pub buildings: Vec<RandomBuilding>,
    /// Floor area of all ground storeys, m².
    pub floor_area_m2: f64,
    /// The whole campus, OBJ text (each building's groups prefixed `bK_`).
    pub obj: String,
}

/// `count` random buildings of `bays` each (seeds `seed`, `seed + 1`, …), on a grid of rows
/// `gap_m` apart.
pub fn campus(seed: u64, count: usize, bays: [usize; 2], gap_m: f64) -> Campus {
    let buildings: Vec<RandomBuilding> = (0..count as u64)
        .map(|k| {
            RandomBuilding::generate(
                seed + k,
                &Choices {
                    bays: Some(bays),
                    ..Choices::default()
                },
            )
        })
        .collect();
    // Every building starts at its plan's origin; its extent is its largest vertex coordinate.
    let extent = |b: &RandomBuilding| {
        b.obj
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .fold([0.0f64; 2], |m, l| {
                let mut it = l.split_whitespace().filter_map(|x| x.parse::<f64>().ok());
                let (x, y) = (it.next().unwrap_or(0.0), it.next().unwrap_or(0.0));
                [m[0].max(x), m[1].max(y)]
            })
    };
    let per_row = (count as f64).sqrt().ceil().max(1.0) as usize;
    let pitch = buildings
        .iter()
        .map(extent)
        .fold([0.0f64; 2], |m, e| [m[0].max(e[0]), m[1].max(e[1])]);
    let mut obj = format!(
        "# A campus of {count} random buildings (omnitrack::desk::scenario::random, seeds {seed}..{}).\n",
        seed + count as u64
    );
    let mut base = 0usize;
    for (k, b) in buildings.iter().enumerate() {
        let (ox, oy) = (
            (k % per_row) as f64 * (pitch[0] + gap_m),
            (k / per_row) as f64 * (pitch[1] + gap_m),
        );
        let mut vertices = 0;
        for line in b.obj.lines() {
            if let Some(v) = line.strip_prefix("v ") {
                let c: Vec<f64> = v.split_whitespace().filter_map(|x| x.parse().ok()).collect();
                let _ = writeln!(obj, "v {} {} {}", c[0] + ox, c[1] + oy, c[2]);
                vertices += 1;
            } else if let Some(f) = line.strip_prefix("f ") {
                obj.push('f');
                for i in f.split_whitespace().filter_map(|x| x.parse::<usize>().ok()) {
                    let _ = write!(obj, " {}", i + base);
                }
                obj.push('\n');
            } else if let Some(g) = line.strip_prefix("g ") {
                let _ = writeln!(obj, "g b{k}_{g}");
            }
        }
        base += vertices;
    }
    Campus {
        floor_area_m2: buildings.iter().map(|b| b.floor_area_m2).sum(),
        buildings,
        obj,
    }
}
