//! A Zillow Indoor Dataset (ZInD) tour: its `zind_data.json` in, the rooms of a coarse building
//! model (as a GeoJSON floor plan for [`omnitrack::desk::floorplan::extrude`]) and every
//! panorama's pose out, in metres with the world right-handed and z up.
//!
//! What ZInD gives (its `data_organization.md` and `code/transformations.py`): per panorama, room
//! layouts in the panorama's own frame, normalised so that the camera is 1 above the floor
//! (floor at z = −1, ceiling at `ceiling_height` − 1), with doors, windows and openings as
//! triples (left end, right end, (bottom z, top z)); and a `floor_plan_transformation` (rotation
//! in degrees, scale, translation) that places the layout on the floor's plan:
//! `global = Rot(rotation) · local · scale + translation` (its code writes this with row vectors,
//! `local · [[c, s], [−s, c]]`). `scale_meters_per_coordinate` turns plan units into metres.
//!
//! **Handedness.** ZInD's panorama azimuth is `atan2(−x, y)` (its code: "the x-axis flip to align
//! the handedness of the pano and room shape coordinate systems"), so a turn to the right in the
//! photo is a turn from +y towards −x: ZInD's plan frame is left-handed with z up. We negate y
//! throughout, so that the world is the real (right-handed) house and the photos are not
//! mirrored. With y negated the pano lookup becomes azimuth = `atan2(−x', −y')` in the
//! panorama's (mirrored) frame, and the plan transformation turns by −rotation.
//!
//! **Which layout.** A complete room (ZInD's `complete_room_*`) may have been annotated in pieces
//! from several panoramas; its `layout_complete` is the merged room, the same in every one of its
//! panoramas. One room of the model per complete room, from the first panorama listed with one,
//! its ceiling from that panorama. Doors and openings become doors of the plan, windows windows:
//! each a hole through the wall it lies on. What the model lacks is what coarse models lack:
//! trims, built-ins, furniture, doors drawn open.

use nalgebra::{Point2, Point3, Rotation2, UnitQuaternion, Vector2, Vector3};
use omnitrack::geometry::Pose;
use serde_json::{json, Value};
use std::path::PathBuf;

/// A door, window or opening of a room, in world metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Opening {
    pub kind: OpeningKind,
    pub ends: [Point2<f64>; 2],
    /// Above the room's floor.
    pub bottom_m: f64,
    pub top_m: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpeningKind {
    Door,
    Window,
    /// A passage with no door leaf (ZInD "openings").
    Opening,
}

/// One complete room of the tour.
#[derive(Debug, Clone, PartialEq)]
pub struct Room {
    pub name: String,
    /// Floor outline, world metres.
    pub outline: Vec<Point2<f64>>,
    pub ceiling_m: f64,
    pub openings: Vec<Opening>,
}

/// One panorama and where it was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Pano {
    /// `pano_14`.
    pub id: String,
    pub label: String,
    /// Relative to the tour directory.
    pub image: PathBuf,
    /// The camera's centre, world metres (z: height above the floor).
    pub centre: Point3<f64>,
    /// ZInD's `rotation` of this panorama's layout, degrees (the plan turns by its negative).
    pub rotation_deg: f64,
    /// `is_inside`: taken inside its room's annotated outline.
    pub inside: bool,
}

impl Pano {
    /// `T_world_rig` of a rig centred on the panorama, x forward along the photo's centre column,
    /// y left, z up.
    pub fn t_world_rig(&self) -> Pose {
        // The centre column looks along local +y; in the mirrored frame local −y, which the plan
        // turns by −rotation.
        let forward = self.local_to_world(Vector2::new(0.0, -1.0));
        let yaw = forward.y.atan2(forward.x);
        Pose::from_parts(
            self.centre.coords.into(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        )
    }

    /// A horizontal direction of the panorama's (y-negated) layout frame in the world.
    fn local_to_world(&self, v: Vector2<f64>) -> Vector2<f64> {
        Rotation2::new(-self.rotation_deg.to_radians()) * v
    }

    /// Where a world direction appears in a `width`×`height` equirectangular panorama (pixel
    /// centres at integers, ZInD's `sphere_to_pixel`).
    pub fn pixel_of(&self, d_world: &Vector3<f64>, width: u32, height: u32) -> (f64, f64) {
        let h = Rotation2::new(self.rotation_deg.to_radians()) * Vector2::new(d_world.x, d_world.y);
        let azimuth = (-h.x).atan2(-h.y);
        let elevation = (d_world.z / d_world.norm()).clamp(-1.0, 1.0).asin();
        let u = (azimuth + std::f64::consts::PI) / (2.0 * std::f64::consts::PI) * (width as f64 - 1.0);
        let v = (1.0 - (elevation + std::f64::consts::FRAC_PI_2) / std::f64::consts::PI) * (height as f64 - 1.0);
        (u, v)
    }
}

/// A whole tour (one floor).
#[derive(Debug, Clone, PartialEq)]
pub struct Tour {
    pub rooms: Vec<Room>,
    pub panos: Vec<Pano>,
}

/// A layout's placement on the plan, with y negated (module doc).
struct Placement {
    rotation: Rotation2<f64>,
    scale_m: f64,
    translation_m: Vector2<f64>,
}

impl Placement {
    fn point(&self, local: [f64; 2]) -> Point2<f64> {
        let mirrored = Vector2::new(local[0], -local[1]);
        Point2::from(self.rotation * mirrored * self.scale_m + self.translation_m)
    }
}

fn num(v: &Value, what: &str) -> Result<f64, String> {
    v.as_f64()
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("{what}: expected a finite number"))
}

fn pair(v: &Value, what: &str) -> Result<[f64; 2], String> {
    match v.as_array().map(Vec::as_slice) {
        Some([a, b]) => Ok([num(a, what)?, num(b, what)?]),
        _ => Err(format!("{what}: expected a pair of numbers")),
    }
}

fn field<'a>(v: &'a Value, key: &str, what: &str) -> Result<&'a Value, String> {
    v.get(key).ok_or_else(|| format!("{what}: no \"{key}\""))
}

fn objects<'a>(v: &'a Value, what: &str) -> Result<Vec<(&'a String, &'a Value)>, String> {
    let map = v.as_object().ok_or_else(|| format!("{what}: expected an object"))?;
    let mut entries: Vec<_> = map.iter().collect();
    // ZInD numbers its keys (`pano_14`); natural order keeps output stable and readable.
    entries.sort_by_key(|(k, _)| natural_key(k));
    Ok(entries)
}

fn natural_key(s: &str) -> (String, u64) {
    let digits: String = s
        .chars()
        .rev()
        .take_while(char::is_ascii_digit)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    (s[..s.len() - digits.len()].to_string(), digits.parse().unwrap_or(0))
}

/// Reads `zind_data.json`; `floor` names the floor (`floor_01`), `None` takes the first.
pub fn parse(json: &str, floor: Option<&str>) -> Result<Tour, String> {
    let root: Value = serde_json::from_str(json).map_err(|e| format!("invalid JSON: {e}"))?;
    let merger = field(&root, "merger", "zind_data.json")?;
    let floors = objects(merger, "merger")?;
    let (floor_name, floor_value) = match floor {
        Some(name) => floors
            .into_iter()
            .find(|(k, _)| k.as_str() == name)
            .ok_or_else(|| format!("merger: no floor {name:?}"))?,
        None => floors.into_iter().next().ok_or("merger: no floor")?,
    };
    let metres = num(
        field(
            field(&root, "scale_meters_per_coordinate", "zind_data.json")?,
            floor_name,
            "scale_meters_per_coordinate",
        )?,
        &format!("scale_meters_per_coordinate.{floor_name} (a tour without a metric scale cannot be used)"),
    )?;
    let mut tour = Tour {
        rooms: Vec::new(),
        panos: Vec::new(),
    };
    for (room_name, room) in objects(floor_value, floor_name)? {
        let mut built = false;
        for (partial_name, partial) in objects(room, room_name)? {
            for (pano_name, pano) in objects(partial, partial_name)? {
                let what = format!("{floor_name}.{room_name}.{partial_name}.{pano_name}");
                let t = field(pano, "floor_plan_transformation", &what)?;
                let scale = num(field(t, "scale", &what)?, &format!("{what}.scale"))?;
                let rotation_deg = num(field(t, "rotation", &what)?, &format!("{what}.rotation"))?;
                let translation = pair(field(t, "translation", &what)?, &format!("{what}.translation"))?;
                let camera_height = num(field(pano, "camera_height", &what)?, &format!("{what}.camera_height"))?;
                // One layout unit in metres (the camera is `camera_height` units above the floor).
                let unit_m = scale * metres;
                let place = Placement {
                    rotation: Rotation2::new(-rotation_deg.to_radians()),
                    scale_m: unit_m,
                    translation_m: Vector2::new(translation[0], -translation[1]) * metres,
                };
                let origin = place.point([0.0, 0.0]);
                tour.panos.push(Pano {
                    id: pano_name.clone(),
                    label: pano.get("label").and_then(Value::as_str).unwrap_or("").to_string(),
                    image: PathBuf::from(
                        field(pano, "image_path", &what)?
                            .as_str()
                            .ok_or(format!("{what}.image_path: expected a string"))?,
                    ),
                    centre: Point3::new(origin.x, origin.y, camera_height * unit_m),
                    rotation_deg,
                    inside: pano.get("is_inside").and_then(Value::as_bool).unwrap_or(true),
                });
                if built {
                    continue;
                }
                let Some(layout) = pano.get("layout_complete").filter(|l| !l.is_null()) else {
                    continue;
                };
                let ceiling = num(field(pano, "ceiling_height", &what)?, &format!("{what}.ceiling_height"))?;
                let vertices = field(layout, "vertices", &what)?
                    .as_array()
                    .ok_or(format!("{what}.layout_complete.vertices: expected an array"))?;
                let outline = vertices
                    .iter()
                    .map(|v| pair(v, &format!("{what}.layout_complete.vertices")).map(|p| place.point(p)))
                    .collect::<Result<Vec<_>, _>>()?;
                if outline.len() < 3 {
                    return Err(format!("{what}.layout_complete: fewer than 3 vertices"));
                }
                let mut openings = Vec::new();
                for (key, kind) in [
                    ("doors", OpeningKind::Door),
                    ("windows", OpeningKind::Window),
                    ("openings", OpeningKind::Opening),
                ] {
                    let list = layout
                        .get(key)
                        .and_then(Value::as_array)
                        .map(Vec::as_slice)
                        .unwrap_or(&[]);
                    if list.len() % 3 != 0 {
                        return Err(format!(
                            "{what}.layout_complete.{key}: {} entries, not triples",
                            list.len()
                        ));
                    }
                    for triple in list.chunks(3) {
                        let w = format!("{what}.layout_complete.{key}");
                        let [a, b, z] = [pair(&triple[0], &w)?, pair(&triple[1], &w)?, pair(&triple[2], &w)?];
                        openings.push(Opening {
                            kind,
                            ends: [place.point(a), place.point(b)],
                            bottom_m: (z[0] + camera_height) * unit_m,
                            top_m: (z[1] + camera_height) * unit_m,
                        });
                    }
                }
                tour.rooms.push(Room {
                    name: format!(
                        "{room_name} ({})",
                        pano.get("label").and_then(Value::as_str).unwrap_or("?")
                    ),
                    outline,
                    ceiling_m: ceiling * unit_m,
                    openings,
                });
                built = true;
            }
        }
    }
    if tour.rooms.is_empty() {
        return Err(format!("{floor_name}: no room has a layout_complete"));
    }
    Ok(tour)
}

impl Tour {
    /// The tour as a GeoJSON floor plan (docs of `omnitrack::desk::floorplan`): per room a thin
    /// wall along its closed outline (as tall as its ceiling), its floor and ceiling, and its
    /// doors and windows. Doors and openings start at the floor; every opening stops 1 cm short
    /// of the ceiling at most, so that the wall above it stays one piece with the wall beside it.
    pub fn plan_geojson(&self) -> String {
        let xy = |p: &Point2<f64>| json!([p.x, p.y]);
        let mut features = Vec::new();
        for room in &self.rooms {
            let mut ring: Vec<Value> = room.outline.iter().map(xy).collect();
            ring.push(xy(&room.outline[0]));
            features.push(json!({
                "type": "Feature",
                "properties": {"kind": "wall", "height_m": room.ceiling_m, "thickness_m": 0.0},
                "geometry": {"type": "LineString", "coordinates": ring.clone()}
            }));
            features.push(json!({
                "type": "Feature",
                "properties": {"kind": "room", "name": room.name, "floor_m": 0.0, "ceiling_m": room.ceiling_m},
                "geometry": {"type": "Polygon", "coordinates": [ring]}
            }));
            for o in &room.openings {
                let top = o.top_m.min(room.ceiling_m - 0.01);
                let Some(ends) = on_wall(&room.outline, &o.ends) else {
                    continue;
                };
                let ends = json!([xy(&ends[0]), xy(&ends[1])]);
                let props = match o.kind {
                    OpeningKind::Window if o.bottom_m > 0.01 && top > o.bottom_m + 0.01 => {
                        json!({"kind": "window", "sill_height_m": o.bottom_m, "head_height_m": top})
                    }
                    _ if top > 0.01 => json!({"kind": "door", "head_height_m": top}),
                    _ => continue,
                };
                features.push(json!({
                    "type": "Feature",
                    "properties": props,
                    "geometry": {"type": "LineString", "coordinates": ends}
                }));
            }
        }
        serde_json::to_string_pretty(&json!({
            "type": "FeatureCollection",
            "properties": {"wall_thickness_m": 0.0},
            "features": features
        }))
        .expect("a JSON value always serialises")
    }
}

/// An opening's ends put on the outline edge they lie along (within 10 cm of its line), and kept
/// 1 cm inside the edge's ends: annotators draw openings up to a corner, and a wall must reach
/// beyond its openings. `None` when no edge carries at least 5 cm of the opening.
fn on_wall(outline: &[Point2<f64>], ends: &[Point2<f64>; 2]) -> Option<[Point2<f64>; 2]> {
    let mut best: Option<(f64, [Point2<f64>; 2])> = None;
    for (i, a) in outline.iter().enumerate() {
        let b = outline[(i + 1) % outline.len()];
        let len = (b - a).norm();
        if len < 0.07 {
            continue;
        }
        let u = (b - a) / len;
        let n = Vector2::new(-u.y, u.x);
        let off = ends.map(|e| (e - a).dot(&n).abs()).into_iter().fold(0.0, f64::max);
        let [s0, s1] = ends.map(|e| (e - a).dot(&u).clamp(0.01, len - 0.01));
        if off > 0.10 || (s1 - s0).abs() < 0.05 || best.is_some_and(|(d, _)| d <= off) {
            continue;
        }
        best = Some((off, [a + u * s0, a + u * s1]));
    }
    best.map(|(_, e)| e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack::desk::floorplan;
    use omnitrack::Model;

    /// A plan unit is 0.5 m; a layout unit is 3 plan units (1.5 m, the camera's height).
    const LAYOUT_UNIT: f64 = 3.0;

    /// A ZInD layout point of a panorama placed with `rotation_deg` and `t` (plan units), from a
    /// plan point: the inverse of ZInD's `to_global`.
    fn to_local(rotation_deg: f64, t: [f64; 2], p: [f64; 2]) -> Value {
        let l = Rotation2::new(-rotation_deg.to_radians()) * Vector2::new(p[0] - t[0], p[1] - t[1]) / LAYOUT_UNIT;
        json!([l.x, l.y])
    }

    /// One 4 m × 3 m room (plan (0,0)–(8,6)), ceiling 2.5 m, seen from two panoramas: A at plan
    /// (2,2) unturned, B at (6,4) turned by 90°. A door on the plan's wall y = 0 (x 2..4, head
    /// 2.1 m), a window on its wall x = 8 (y 2..4, sill 0.9 m, head 2.1 m).
    fn layout_json() -> String {
        let pano = |rotation: f64, t: [f64; 2]| {
            let l = |p: [f64; 2]| to_local(rotation, t, p);
            json!({
                "label": "living room", "is_primary": true, "is_inside": true,
                "ceiling_height": 2.5 / 1.5, "camera_height": 1.0, "image_path": "panos/a.jpg",
                "layout_complete": {
                    "vertices": [l([0.0, 0.0]), l([8.0, 0.0]), l([8.0, 6.0]), l([0.0, 6.0])],
                    "doors": [l([2.0, 0.0]), l([4.0, 0.0]), [-1.0, 0.4]],
                    "windows": [l([8.0, 2.0]), l([8.0, 4.0]), [-0.4, 0.4]],
                    "openings": []
                },
                "floor_plan_transformation": {"rotation": rotation, "scale": LAYOUT_UNIT, "translation": t}
            })
        };
        json!({
            "scale_meters_per_coordinate": {"floor_01": 0.5},
            "merger": {"floor_01": {"complete_room_01": {"partial_room_01": {
                "pano_1": pano(0.0, [2.0, 2.0]),
                "pano_2": pano(90.0, [6.0, 4.0])
            }}}}
        })
        .to_string()
    }

    #[test]
    fn hand_made_layout_gives_the_room_in_metres_with_y_negated() {
        let tour = parse(&layout_json(), None).unwrap();
        assert_eq!((tour.rooms.len(), tour.panos.len()), (1, 2));
        let room = &tour.rooms[0];
        let expect = [(0.0, 0.0), (4.0, 0.0), (4.0, -3.0), (0.0, -3.0)];
        assert_eq!(room.outline.len(), 4);
        for (p, e) in room.outline.iter().zip(expect) {
            assert!((p - Point2::new(e.0, e.1)).norm() < 1e-9, "{p:?} vs {e:?}");
        }
        assert!((room.ceiling_m - 2.5).abs() < 1e-9, "{}", room.ceiling_m);
        let door = &room.openings[0];
        assert_eq!(door.kind, OpeningKind::Door);
        assert!((door.ends[0] - Point2::new(1.0, 0.0)).norm() < 1e-9, "{:?}", door.ends);
        assert!((door.ends[1] - Point2::new(2.0, 0.0)).norm() < 1e-9, "{:?}", door.ends);
        assert!(door.bottom_m.abs() < 1e-9 && (door.top_m - 2.1).abs() < 1e-9);
        let window = &room.openings[1];
        assert_eq!(window.kind, OpeningKind::Window);
        assert!(
            (window.ends[0] - Point2::new(4.0, -1.0)).norm() < 1e-9,
            "{:?}",
            window.ends
        );
        assert!((window.bottom_m - 0.9).abs() < 1e-9 && (window.top_m - 2.1).abs() < 1e-9);
        assert!((tour.panos[0].centre - Point3::new(1.0, -1.0, 1.5)).norm() < 1e-9);
        assert!((tour.panos[1].centre - Point3::new(3.0, -2.0, 1.5)).norm() < 1e-9);
    }

    /// ZInD's own `cartesian_to_pixel` (transformations.py) of a layout-frame point.
    fn zind_pixel(p: [f64; 3], w: u32, h: u32) -> (f64, f64) {
        let theta = (-p[0]).atan2(p[1]);
        let phi = (p[2] / (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).asin();
        let u = (theta + std::f64::consts::PI) / (2.0 * std::f64::consts::PI) * (w as f64 - 1.0);
        let v = (1.0 - (phi + std::f64::consts::FRAC_PI_2) / std::f64::consts::PI) * (h as f64 - 1.0);
        (u, v)
    }

    #[test]
    fn both_panoramas_see_a_corner_where_zind_draws_it() {
        let tour = parse(&layout_json(), None).unwrap();
        let (w, h) = (2048, 1024);
        // Plan corner (8, 6) at the ceiling: world (4, -3, 2.5).
        let corner = Point3::new(4.0, -3.0, 2.5);
        let z = 2.5 / 1.5 - 1.0;
        for (pano, rotation, t) in [(&tour.panos[0], 0.0, [2.0, 2.0]), (&tour.panos[1], 90.0, [6.0, 4.0])] {
            let l = to_local(rotation, t, [8.0, 6.0]);
            let want = zind_pixel([l[0].as_f64().unwrap(), l[1].as_f64().unwrap(), z], w, h);
            let got = pano.pixel_of(&(corner - pano.centre), w, h);
            assert!(
                (got.0 - want.0).abs() < 1e-6 && (got.1 - want.1).abs() < 1e-6,
                "{got:?} vs {want:?}"
            );
        }
    }

    #[test]
    fn rig_forward_is_the_photo_centre_column_and_left_is_left() {
        let tour = parse(&layout_json(), None).unwrap();
        let (w, h) = (2048, 1024);
        for pano in &tour.panos {
            let r = pano.t_world_rig().rotation;
            let (u, v) = pano.pixel_of(&(r * Vector3::x()), w, h);
            assert!((u - (w as f64 - 1.0) / 2.0).abs() < 1e-6 && (v - (h as f64 - 1.0) / 2.0).abs() < 1e-6);
            // The rig's left (+y) is a quarter turn left of the centre column: the photo is
            // not mirrored.
            let (u, _) = pano.pixel_of(&(r * Vector3::y()), w, h);
            assert!((u - (w as f64 - 1.0) / 4.0).abs() < 1e-6, "{u}");
        }
    }

    #[test]
    fn the_plan_extrudes_into_a_room_with_a_door_and_a_window() {
        let tour = parse(&layout_json(), None).unwrap();
        let obj = floorplan::extrude(&tour.plan_geojson(), "test.geojson").unwrap();
        let model = Model::from_obj_str(&obj, "test.obj").unwrap();
        let (lo, hi) = model.bounds().unwrap();
        assert!((lo - Point3::new(0.0, -3.0, 0.0)).norm() < 1e-6, "{lo:?}");
        assert!((hi - Point3::new(4.0, 0.0, 2.5)).norm() < 1e-6, "{hi:?}");
        let has = |a: [f64; 3], b: [f64; 3]| {
            let (a, b) = (Point3::from(a), Point3::from(b));
            model.segments.iter().any(|s| {
                ((s.a - a).norm() < 1e-6 && (s.b - b).norm() < 1e-6)
                    || ((s.a - b).norm() < 1e-6 && (s.b - a).norm() < 1e-6)
            })
        };
        // Door jambs and head; window sides, sill and head.
        assert!(has([1.0, 0.0, 0.0], [1.0, 0.0, 2.1]) && has([2.0, 0.0, 0.0], [2.0, 0.0, 2.1]));
        assert!(has([1.0, 0.0, 2.1], [2.0, 0.0, 2.1]));
        assert!(has([4.0, -1.0, 0.9], [4.0, -2.0, 0.9]) && has([4.0, -1.0, 2.1], [4.0, -2.0, 2.1]));
        assert!(has([4.0, -1.0, 0.9], [4.0, -1.0, 2.1]));
        // Room corners, floor to ceiling.
        assert!(has([4.0, -3.0, 0.0], [4.0, -3.0, 2.5]));
    }
}
