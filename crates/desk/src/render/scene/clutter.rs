//! Clutter: furniture boxes on the floor, shelving units against walls and posters on them,
//! which exist only in the images. In: where they may go (floor and wall samples, ray queries,
//! keep-out points, the fixtures' boxes) and the [`Appearance`]; out: their surfaces and
//! triangles appended to the scene's, and how many of each were placed. All draws come from one
//! stream in a fixed order, so a scene rebuilt from the same inputs is the same.

use super::{add, box_triangles, quad_triangles, sample_on, ClutterCounts, Pattern, Site, Surface, SurfaceKind};
use crate::render::appearance::{hash64, hsv, Appearance, Rng};
use crate::render::fixtures::{near_keep_out, overlaps};
use nalgebra::Vector3;
use omnitrack_core::model::bvh::Triangle;

/// A place on a wall for clutter: the wall point at floor height, the horizontal unit normal
/// towards free space, the horizontal axis along the wall, and floor and ceiling heights there.
struct WallSpot {
    base: [f64; 3],
    side: [f64; 3],
    u: [f64; 3],
    floor: f64,
    ceil: f64,
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

/// Places the clutter `Appearance::clutter` asks for; returns the furniture, shelves and posters
/// placed.
pub(super) fn place(
    site: &Site,
    appearance: &Appearance,
    surfaces: &mut Vec<Surface>,
    triangles: &mut Vec<Triangle>,
    payload: &mut Vec<u32>,
) -> ClutterCounts {
    let Site {
        model,
        floor_tris,
        floor_cum,
        wall_tris,
        wall_cum,
        probe,
        keep,
        blockers,
        ..
    } = *site;
    let blocked = |lo: [f64; 3], hi: [f64; 3]| blockers.iter().any(|b| overlaps(b, &(lo, hi)));
    let grain = Pattern::grain(appearance.clutter_texture);

    let mut rng = Rng::new(appearance.seed ^ 0xC1u64 << 32);
    let mut clutter_counts = ClutterCounts::default();

    // Furniture boxes on the floor.
    let want = site.count(appearance.clutter, 12.0);
    for _ in 0..want * 20 {
        if clutter_counts.furniture >= want {
            break;
        }
        let Some((p, _)) = sample_on(floor_tris, floor_cum, &mut rng) else {
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
        if !clear || near_keep_out(keep, blo, bhi, 0.6) || blocked(blo, bhi) {
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
            triangles,
        );
        payload.resize(payload.len() + triangles.len() - before, sid);
        clutter_counts.furniture += 1;
    }

    // A wall spot: point, horizontal unit normal towards free space, along-wall axis, floor z.
    let wall_spot = |rng: &mut Rng, min_free: f64| -> Option<WallSpot> {
        let (p, f) = sample_on(wall_tris, wall_cum, rng)?;
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
    let want = site.count(appearance.clutter, 25.0);
    for _ in 0..want * 20 {
        if clutter_counts.shelves >= want {
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
        if near_keep_out(keep, lo, hi, 0.6) || blocked(lo, hi) {
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
            box_triangles(c, [scale(u, t), scale(side, depth), scale(up, h / 2.0)], triangles);
        }
        let boards = 2 + (h / 0.45) as usize;
        for b in 0..boards {
            let z = t + (h - 2.0 * t) * b as f64 / (boards - 1) as f64;
            let c = add(centre, up, z);
            box_triangles(c, [scale(u, w - 2.0 * t), scale(side, depth), scale(up, t)], triangles);
        }
        payload.resize(payload.len() + triangles.len() - before, sid);
        clutter_counts.shelves += 1;
    }

    // Posters: a coloured rectangle with an inner rectangle of another colour, 8–9 mm off a wall.
    let want = site.count(appearance.clutter, 10.0);
    for _ in 0..want * 20 {
        if clutter_counts.posters >= want {
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
        if zc + h > ceil - 0.05 || !backed(base, side, u, w, zc - h, 0.03) || !backed(base, side, u, w, zc + h, 0.03) {
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
                triangles,
            );
            payload.resize(payload.len() + triangles.len() - before, sid);
        }
        clutter_counts.posters += 1;
    }
    clutter_counts
}
