//! The building's layout, every draw of the seed up to the model: [`Choices`] and the stream in;
//! out, a [`Layout`]: the grid of bays and its outline, the rooms, the openings (doors along a
//! random spanning tree of the rooms plus a few loops, windows in the exterior walls, the upper
//! storey's doors), the stair hall and its stair, and the wall runs with their holes. The draws
//! come in a fixed order, so a seed always gives the same building.

use super::{Choices, Outline, WallStyle, P2, STAIR_WIDTH_M};
use crate::render::appearance::Rng;

/// Thickness of the slab between storeys.
const SLAB_M: f64 = 0.25;
/// Stair step rise and the shortest tread the stair may get.
const STEP_RISE_M: f64 = 0.19;
const MIN_TREAD_M: f64 = 0.24;
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
pub(super) struct Hole {
    pub s0: f64,
    pub s1: f64,
    pub z0: f64,
    pub z1: f64,
}

/// A straight wall along one grid line, from `a` to `b`.
pub(super) struct Run {
    pub a: P2,
    pub b: P2,
    pub thickness: f64,
    pub holes: Vec<Hole>,
    /// Doors of the ground storey as `(s0, s1)`, for the floor plan.
    pub doors: Vec<(f64, f64)>,
}

/// A door or window drawn on one bay's wall.
pub(super) struct Opening {
    /// Index of the bay's wall.
    pub wall: usize,
    /// Along the bay's wall from its start.
    pub s0: f64,
    pub s1: f64,
    pub z0: f64,
    pub z1: f64,
    pub door: bool,
}

/// A bay side between two rooms or between a room and the outside, with the rooms either side.
struct BayWall {
    a: P2,
    b: P2,
    rooms: (Option<usize>, Option<usize>),
}

/// A drawn building, before it is written as a model and a plan.
pub(super) struct Layout {
    pub outline: Outline,
    pub walls: WallStyle,
    pub bays: [usize; 2],
    pub triangulated: bool,
    pub flip_fraction: f64,
    /// Storey height.
    pub height: f64,
    pub storeys: usize,
    /// Top of the ground storey's slab: the upper storey's floor.
    pub top_of_ground: f64,
    /// Steps of the stair.
    pub steps: usize,
    /// Rooms of the ground storey, as (low, high) corners.
    pub rects: Vec<(P2, P2)>,
    /// The stair hall (a room index) and the stair's tread, if two storeys.
    pub hall: Option<(usize, f64)>,
    pub stair_axis: Option<(P2, P2)>,
    pub openings: Vec<Opening>,
    pub runs: Vec<Run>,
}

/// Draws the layout of a building from `rng`, except what `choices` pins.
pub(super) fn draw(rng: &mut Rng, choices: &Choices) -> Layout {
    let outline = choices
        .outline
        .unwrap_or([Outline::Rectangle, Outline::L, Outline::U, Outline::Courtyard][below(rng, 4)]);
    let walls = choices
        .walls
        .unwrap_or([WallStyle::Thin, WallStyle::Thick, WallStyle::ThickOutside][below(rng, 3)]);
    let want_storeys = choices.storeys.unwrap_or(if rng.unit() < 0.3 { 2 } else { 1 });
    let triangulated = choices.triangulated.unwrap_or(rng.unit() < 0.5);
    let flip_fraction = choices.flip_fraction.unwrap_or(0.5);
    let (nx, ny) = (3 + below(rng, 3), 2 + below(rng, 3));
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
    let xs = edges(nx, rng);
    let ys = edges(ny, rng);
    let mut inside = vec![vec![true; ny]; nx];
    match outline {
        Outline::Rectangle => {}
        Outline::L => {
            let (cx, cy) = (1 + below(rng, nx - 1), 1 + below(rng, ny - 1));
            for col in inside.iter_mut().skip(cx) {
                for c in col.iter_mut().skip(cy) {
                    *c = false;
                }
            }
        }
        Outline::U => {
            let cy = 1 + below(rng, ny - 1);
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

    let (room, rects) = rooms(rng, &inside, &xs, &ys);
    let bay_walls = bay_walls(&inside, &room, &xs, &ys);

    // A hall for the stair, if two storeys: the room whose long side fits the stair best.
    let top_of_ground = height + SLAB_M;
    let steps = (top_of_ground / STEP_RISE_M).ceil() as usize;
    let mut hall = None;
    if want_storeys > 1 {
        hall = stair_hall(&rects, steps, t_out);
    }
    let mut openings = doors(rng, &bay_walls, rects.len());
    // The stair runs along the hall's long side, against one of its two long walls, on a side
    // where it blocks no door; with no such side the building keeps one storey.
    let mut stair_axis = None;
    if let Some((k, tread)) = hall {
        stair_axis = stair(rng, rects[k], tread, t_out, steps, &openings, &bay_walls);
        if stair_axis.is_none() {
            hall = None;
        }
    }
    let storeys = if hall.is_some() { 2 } else { 1 };
    windows(rng, &bay_walls, storeys, top_of_ground, height, hall, &mut openings);
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
    let runs = runs(&bay_walls, &openings, t_out, t_in);
    Layout {
        outline,
        walls,
        bays: [nx, ny],
        triangulated,
        flip_fraction,
        height,
        storeys,
        top_of_ground,
        steps,
        rects,
        hall,
        stair_axis,
        openings,
        runs,
    }
}

/// Rooms: bays merged along rows, up to 11 m. Returns each bay's room (`usize::MAX` outside the
/// outline) and the rooms' corners.
fn rooms(rng: &mut Rng, inside: &[Vec<bool>], xs: &[f64], ys: &[f64]) -> (Vec<Vec<usize>>, Vec<(P2, P2)>) {
    let (nx, ny) = (inside.len(), inside[0].len());
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
    (room, rects)
}

/// Every bay side between two rooms or between a room and the outside.
fn bay_walls(inside: &[Vec<bool>], room: &[Vec<usize>], xs: &[f64], ys: &[f64]) -> Vec<BayWall> {
    let (nx, ny) = (inside.len(), inside[0].len());
    let cell = |i: isize, j: isize| -> Option<usize> {
        (i >= 0 && j >= 0 && (i as usize) < nx && (j as usize) < ny && inside[i as usize][j as usize])
            .then(|| room[i as usize][j as usize])
    };
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
    bay_walls
}

/// The hall for the stair: the room whose long side fits the stair best, and the tread there.
fn stair_hall(rects: &[(P2, P2)], steps: usize, t_out: f64) -> Option<(usize, f64)> {
    let mut best: Option<(f64, usize)> = None;
    for (k, (lo, hi)) in rects.iter().enumerate() {
        let (long, short) = ((hi.x - lo.x).max(hi.y - lo.y), (hi.x - lo.x).min(hi.y - lo.y));
        let tread = (long - 1.6 - t_out) / steps as f64;
        if tread >= MIN_TREAD_M && short >= STAIR_WIDTH_M + HALL_FREE_M + t_out && best.is_none_or(|b| tread > b.0) {
            best = Some((tread, k));
        }
    }
    best.map(|(tread, k)| (k, tread.min(0.3)))
}

/// Doors: a random spanning tree of the `rooms` rooms, and a quarter of the other adjacencies.
fn doors(rng: &mut Rng, bay_walls: &[BayWall], rooms: usize) -> Vec<Opening> {
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
        pairs.swap(k, below(rng, k + 1));
    }
    let mut parent: Vec<usize> = (0..rooms).collect();
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
            let w = ws[below(rng, ws.len())];
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
    openings
}

/// The stair's axis in the hall `(lo, hi)`: along its long side, against one of its two long
/// walls, on a side where it blocks no door; `None` when both sides block one.
fn stair(
    rng: &mut Rng,
    (lo, hi): (P2, P2),
    tread: f64,
    t_out: f64,
    steps: usize,
    openings: &[Opening],
    bay_walls: &[BayWall],
) -> Option<(P2, P2)> {
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
    [first, !first].into_iter().map(axis).find(|&ax| !blocks(ax))
}

/// Windows in exterior bays, on every storey; none in the hall's ground storey.
fn windows(
    rng: &mut Rng,
    bay_walls: &[BayWall],
    storeys: usize,
    top_of_ground: f64,
    height: f64,
    hall: Option<(usize, f64)>,
    openings: &mut Vec<Opening>,
) {
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
}

/// Runs: bay walls merged along their grid line while of one kind (exterior or interior), each
/// with the holes of its openings.
fn runs(bay_walls: &[BayWall], openings: &[Opening], t_out: f64, t_in: f64) -> Vec<Run> {
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
    for o in openings {
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
    runs
}
