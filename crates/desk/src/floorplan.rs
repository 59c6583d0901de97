//! Floor-plan extrusion: a 2D blueprint in, a 3D building model out (Koch & Teller built their
//! CORRIDOR model the same way).
//!
//! In: a GeoJSON `FeatureCollection` in metres (local planar x east, y north, no CRS) of walls
//! (`LineString` axes), doors and windows (two-point `LineString`s on a wall axis) and rooms
//! (`Polygon`s); `docs/floorplan.md` is the reference. Out: Wavefront OBJ text (metres, z up) of
//! planar faces, each under a `g` naming its feature (`wall_3`, `room_corridor_floor`) and a
//! `usemtl` naming its kind (`wall`, `floor`, `ceiling`, `door_reveal`, `window_reveal`).
//!
//! The faces are laid out for [`omnitrack_core::model::Model`]'s segment extraction, so that its model
//! segments are exactly the lines a camera sees: wall corners, floor and ceiling lines, door and
//! window frames. Walls are cut into coplanar rectangular panels around their openings instead of
//! polygons with holes (OBJ has none), which costs nothing: seams between coplanar panels are not
//! segments. Every error is one line naming the file and the feature.

use nalgebra::{Point2, Point3, Vector2, Vector3};
use serde_json::{Map, Value};
use std::collections::HashMap;
use std::fmt::Write as _;

/// An opening's ends may stray this far from a thin wall's axis (hand-typed or snapped
/// coordinates); a thick wall allows half its thickness, so the ends may be drawn on a face.
const OPENING_TOLERANCE_M: f64 = 0.05;
/// A wall end this close to another wall's axis abuts it. Tight, because a looser test would
/// capture ends meant to stop short of a wall.
const JOIN_TOLERANCE_M: f64 = 1e-3;
/// Lengths below this are zero: far above rounding of plan-sized numbers.
const EPS_M: f64 = 1e-6;
/// The shortest edge a face may get. The model loader welds vertices within 10 µm, so a sliver
/// (a wall stopping 2 µm past an opening) would come out of it degenerate; 1 mm is below any
/// drawing's precision.
const MIN_M: f64 = 1e-3;
/// Larger magnitudes are mistakes (or a geographic CRS) and would cost precision at the 1 nm grid.
const MAX_ABS_M: f64 = 1e6;
/// Output coordinates are rounded to 1 nm so that vertices computed along different paths (a
/// mitre point seen from both of its pieces) print identically and decimal inputs print as typed.
const GRID_PER_M: f64 = 1e9;

/// A plan that cannot be extruded; displays as one line: `file: features[i] (kind): problem`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {place}{message}")]
pub struct FloorPlanError {
    pub file: String,
    /// `"features[3] (door): "`, or empty for problems of the whole file.
    pub place: String,
    pub message: String,
}

/// Plan-wide defaults, from the collection's top-level `properties` member.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanDefaults {
    pub storey_height_m: f64,
    pub door_head_height_m: f64,
    pub window_sill_height_m: f64,
    pub window_head_height_m: f64,
    pub wall_thickness_m: f64,
}

impl Default for PlanDefaults {
    fn default() -> Self {
        Self {
            storey_height_m: 2.7,
            door_head_height_m: 2.1,
            window_sill_height_m: 0.9,
            window_head_height_m: 2.1,
            wall_thickness_m: 0.0,
        }
    }
}

/// A wall: a vertical extrusion of its axis polyline, `thickness_m` wide (0 = one two-sided
/// surface on the axis).
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Index in the collection's `features`.
    pub feature: usize,
    /// At least two points, no two consecutive ones equal; a closed ring does not repeat its
    /// first point.
    pub axis: Vec<Point2<f64>>,
    pub closed: bool,
    pub thickness_m: f64,
    pub base_m: f64,
    pub height_m: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpeningKind {
    Door,
    Window,
}

impl Opening {
    /// The opening's bottom and head in a wall spanning z0..z1, snapped to the wall's base and
    /// top when within 1 mm so that no sliver of wall is left below or above.
    fn span(&self, z0: f64, z1: f64) -> (f64, f64) {
        let bottom = if self.sill_height_m < MIN_M {
            z0
        } else {
            z0 + self.sill_height_m
        };
        let head = if z0 + self.head_height_m > z1 - MIN_M {
            z1
        } else {
            z0 + self.head_height_m
        };
        (bottom, head)
    }
}

impl OpeningKind {
    fn name(self) -> &'static str {
        match self {
            OpeningKind::Door => "door",
            OpeningKind::Window => "window",
        }
    }
}

/// A door or window: a rectangular hole through the wall whose axis its ends lie on.
#[derive(Debug, Clone, PartialEq)]
pub struct Opening {
    pub feature: usize,
    pub kind: OpeningKind,
    pub ends: [Point2<f64>; 2],
    /// Above the wall's base; 0 for a door.
    pub sill_height_m: f64,
    /// Above the wall's base.
    pub head_height_m: f64,
}

/// A room: a floor and a ceiling over its outline.
#[derive(Debug, Clone, PartialEq)]
pub struct Room {
    pub feature: usize,
    pub name: Option<String>,
    /// At least three points, not repeating the first, enclosing some area.
    pub outline: Vec<Point2<f64>>,
    pub floor_m: f64,
    pub ceiling_m: f64,
}

/// A parsed, validated floor plan.
#[derive(Debug, Clone, PartialEq)]
pub struct FloorPlan {
    pub defaults: PlanDefaults,
    pub walls: Vec<Wall>,
    pub openings: Vec<Opening>,
    pub rooms: Vec<Room>,
}

/// Reads a GeoJSON floor plan and returns the OBJ text of its extrusion; `file` names the plan
/// in error messages and in the OBJ header.
pub fn extrude(geojson: &str, file: &str) -> Result<String, FloorPlanError> {
    parse(geojson, file)?.to_obj(file)
}

// ---------------------------------------------------------------------------------------------
// GeoJSON reading. Walked by hand rather than through serde derive so that every message can
// name the feature and the property.

const PLAN_KEYS: [&str; 5] = [
    "storey_height_m",
    "door_head_height_m",
    "window_sill_height_m",
    "window_head_height_m",
    "wall_thickness_m",
];
const WALL_KEYS: [&str; 3] = ["thickness_m", "height_m", "base_m"];
const DOOR_KEYS: [&str; 1] = ["head_height_m"];
const WINDOW_KEYS: [&str; 2] = ["sill_height_m", "head_height_m"];
const ROOM_KEYS: [&str; 2] = ["floor_m", "ceiling_m"];

struct Reader<'a> {
    file: &'a str,
    place: String,
}

impl Reader<'_> {
    fn err(&self, message: impl Into<String>) -> FloorPlanError {
        FloorPlanError {
            file: self.file.to_string(),
            place: self.place.clone(),
            message: message.into(),
        }
    }

    /// Properties are open-ended (editors add `name`, `stroke`, `fill`…), but a misspelt length
    /// must not fall back to a default unnoticed: unknown keys ending in `_m` are refused.
    fn check_keys(&self, props: &Map<String, Value>, known: &[&str], what: &str) -> Result<(), FloorPlanError> {
        match props.keys().find(|k| k.ends_with("_m") && !known.contains(&k.as_str())) {
            Some(k) => Err(self.err(format!(
                "unknown property {k:?} for {what} (known: {})",
                known.join(", ")
            ))),
            None => Ok(()),
        }
    }

    fn length(&self, props: &Map<String, Value>, key: &str) -> Result<Option<f64>, FloorPlanError> {
        match props.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::Number(n)) => {
                let x = n.as_f64().unwrap_or(f64::NAN);
                if x.is_finite() && x.abs() <= MAX_ABS_M {
                    Ok(Some(x))
                } else {
                    Err(self.err(format!(
                        "{key} = {n} is out of range (a finite number of metres within ±{MAX_ABS_M:e} expected)"
                    )))
                }
            }
            Some(other) => Err(self.err(format!("{key} must be a number of metres, found {}", brief(other)))),
        }
    }

    fn point(&self, v: &Value) -> Result<Point2<f64>, FloorPlanError> {
        let coords = match v.as_array() {
            Some(a) if a.len() >= 2 => a,
            _ => return Err(self.err(format!("a position must be an array [x, y], found {}", brief(v)))),
        };
        // A third number (altitude) is allowed by GeoJSON and has no meaning here: ignored.
        let mut xy = [0.0; 2];
        for (c, value) in xy.iter_mut().zip(coords) {
            let x = value
                .as_f64()
                .ok_or_else(|| self.err(format!("coordinate {} is not a number", brief(value))))?;
            if !(x.is_finite() && x.abs() <= MAX_ABS_M) {
                return Err(self.err(format!(
                    "coordinate {} is out of range \
                     (finite metres within ±{MAX_ABS_M:e} of the plan's origin expected)",
                    brief(value)
                )));
            }
            *c = x;
        }
        Ok(Point2::new(xy[0], xy[1]))
    }

    fn line_string(&self, coordinates: &Value) -> Result<Vec<Point2<f64>>, FloorPlanError> {
        let list = coordinates.as_array().ok_or_else(|| {
            self.err(format!(
                "LineString coordinates must be an array of positions, found {}",
                brief(coordinates)
            ))
        })?;
        list.iter().map(|p| self.point(p)).collect()
    }
}

/// A JSON value shortened for a one-line message.
fn brief(v: &Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s
    }
}

/// Drops repeated consecutive points (a double click in an editor), which would otherwise make
/// slivers.
fn dedup_points(points: &mut Vec<Point2<f64>>) {
    points.dedup_by(|b, a| (*b - *a).norm() < MIN_M);
}

/// Parses and validates a GeoJSON floor plan (everything that needs no geometry across features).
pub fn parse(geojson: &str, file: &str) -> Result<FloorPlan, FloorPlanError> {
    let mut r = Reader {
        file,
        place: String::new(),
    };
    let root: Value = serde_json::from_str(geojson).map_err(|e| r.err(format!("not GeoJSON: invalid JSON: {e}")))?;
    let Some(root) = root.as_object() else {
        return Err(r.err(format!(
            "not GeoJSON: expected a FeatureCollection object, found {}",
            brief(&root)
        )));
    };
    match root.get("type").and_then(Value::as_str) {
        Some("FeatureCollection") => {}
        Some(t) => return Err(r.err(format!("not a GeoJSON FeatureCollection: \"type\" is {t:?}"))),
        None => return Err(r.err("not GeoJSON: no \"type\": \"FeatureCollection\" at the top level")),
    }

    let mut defaults = PlanDefaults::default();
    match root.get("properties") {
        None | Some(Value::Null) => {}
        Some(Value::Object(props)) => {
            r.place = "top-level properties: ".into();
            r.check_keys(props, &PLAN_KEYS, "the plan")?;
            let d = &mut defaults;
            for (key, slot) in [
                ("storey_height_m", &mut d.storey_height_m),
                ("door_head_height_m", &mut d.door_head_height_m),
                ("window_sill_height_m", &mut d.window_sill_height_m),
                ("window_head_height_m", &mut d.window_head_height_m),
                ("wall_thickness_m", &mut d.wall_thickness_m),
            ] {
                if let Some(x) = r.length(props, key)? {
                    *slot = x;
                }
            }
            if defaults.storey_height_m <= 0.0 {
                return Err(r.err(format!("storey_height_m {} must be positive", defaults.storey_height_m)));
            }
            if defaults.wall_thickness_m < 0.0 {
                return Err(r.err(format!(
                    "wall_thickness_m {} is a negative thickness",
                    defaults.wall_thickness_m
                )));
            }
            r.place.clear();
        }
        Some(other) => {
            return Err(r.err(format!(
                "top-level \"properties\" must be an object, found {}",
                brief(other)
            )))
        }
    }

    let features = root
        .get("features")
        .and_then(Value::as_array)
        .ok_or_else(|| r.err("not GeoJSON: a FeatureCollection needs a \"features\" array"))?;
    let mut plan = FloorPlan {
        defaults: defaults.clone(),
        walls: Vec::new(),
        openings: Vec::new(),
        rooms: Vec::new(),
    };
    for (index, feature) in features.iter().enumerate() {
        let kind = feature
            .pointer("/properties/kind")
            .and_then(Value::as_str)
            .unwrap_or("?");
        r.place = format!("features[{index}] ({kind}): ");
        let Some(feature) = feature.as_object() else {
            return Err(r.err(format!("a feature must be an object, found {}", brief(feature))));
        };
        if feature.get("type").and_then(Value::as_str) != Some("Feature") {
            return Err(r.err("not a GeoJSON Feature (\"type\": \"Feature\" missing)"));
        }
        let props = match feature.get("properties") {
            Some(Value::Object(p)) => p,
            _ => return Err(r.err("has no \"properties\" object (it needs at least \"kind\")")),
        };
        let kind = match props.get("kind") {
            Some(Value::String(k)) => k.as_str(),
            None => return Err(r.err("has no \"kind\" property (wall, door, window or room)")),
            Some(other) => return Err(r.err(format!("\"kind\" must be a string, found {}", brief(other)))),
        };
        let expected = match kind {
            "wall" | "door" | "window" => "LineString",
            "room" => "Polygon",
            _ => return Err(r.err(format!("unknown kind {kind:?} (expected wall, door, window or room)"))),
        };
        let geometry = match feature.get("geometry") {
            Some(Value::Object(g)) => g,
            _ => return Err(r.err(format!("has no geometry (a {expected} is needed)"))),
        };
        let gtype = geometry.get("type").and_then(Value::as_str).unwrap_or("(none)");
        if gtype != expected {
            return Err(r.err(format!(
                "wrong geometry type: a {kind} needs a {expected}, found {gtype}"
            )));
        }
        let coordinates = geometry.get("coordinates").unwrap_or(&Value::Null);
        match kind {
            "wall" => plan.walls.push(read_wall(&r, index, props, coordinates, &defaults)?),
            "door" | "window" => plan
                .openings
                .push(read_opening(&r, index, kind, props, coordinates, &defaults)?),
            _ => plan.rooms.push(read_room(&r, index, props, coordinates, &defaults)?),
        }
    }
    Ok(plan)
}

fn read_wall(
    r: &Reader,
    feature: usize,
    props: &Map<String, Value>,
    coordinates: &Value,
    d: &PlanDefaults,
) -> Result<Wall, FloorPlanError> {
    r.check_keys(props, &WALL_KEYS, "a wall")?;
    let thickness_m = r.length(props, "thickness_m")?.unwrap_or(d.wall_thickness_m);
    let height_m = r.length(props, "height_m")?.unwrap_or(d.storey_height_m);
    let base_m = r.length(props, "base_m")?.unwrap_or(0.0);
    if thickness_m < 0.0 {
        return Err(r.err(format!("thickness_m {thickness_m} is a negative thickness")));
    }
    if thickness_m > 0.0 && thickness_m < MIN_M {
        return Err(r.err(format!(
            "thickness_m {thickness_m} is below 1 mm (use 0 for a thin wall)"
        )));
    }
    if height_m < MIN_M {
        return Err(r.err(format!("height_m {height_m} must be positive (at least 1 mm)")));
    }
    let mut axis = r.line_string(coordinates)?;
    dedup_points(&mut axis);
    let closed = axis.len() >= 4 && (axis[0] - axis[axis.len() - 1]).norm() < MIN_M;
    if closed {
        axis.pop();
    }
    if axis.len() < 2 {
        return Err(r.err("a wall's LineString needs at least 2 distinct points"));
    }
    Ok(Wall {
        feature,
        axis,
        closed,
        thickness_m,
        base_m,
        height_m,
    })
}

fn read_opening(
    r: &Reader,
    feature: usize,
    kind: &str,
    props: &Map<String, Value>,
    coordinates: &Value,
    d: &PlanDefaults,
) -> Result<Opening, FloorPlanError> {
    let (kind, sill_height_m, head_height_m) = if kind == "door" {
        r.check_keys(props, &DOOR_KEYS, "a door")?;
        (
            OpeningKind::Door,
            0.0,
            r.length(props, "head_height_m")?.unwrap_or(d.door_head_height_m),
        )
    } else {
        r.check_keys(props, &WINDOW_KEYS, "a window")?;
        let sill = r.length(props, "sill_height_m")?.unwrap_or(d.window_sill_height_m);
        (
            OpeningKind::Window,
            sill,
            r.length(props, "head_height_m")?.unwrap_or(d.window_head_height_m),
        )
    };
    if sill_height_m < 0.0 {
        return Err(r.err(format!("sill_height_m {sill_height_m} is below the wall's base")));
    }
    if head_height_m < sill_height_m + MIN_M {
        return Err(r.err(match kind {
            OpeningKind::Door => format!("head_height_m {head_height_m} must be above the floor (0)"),
            OpeningKind::Window => format!("head_height_m {head_height_m} is not above sill_height_m {sill_height_m}"),
        }));
    }
    let points = r.line_string(coordinates)?;
    let [a, b] = points[..] else {
        return Err(r.err(format!(
            "a {}'s LineString needs exactly 2 points (its ends on a wall axis), found {}",
            kind.name(),
            points.len()
        )));
    };
    if (b - a).norm() < 1e-3 {
        return Err(r.err(format!("its two points ({}) are less than 1 mm apart", xy(&a))));
    }
    Ok(Opening {
        feature,
        kind,
        ends: [a, b],
        sill_height_m,
        head_height_m,
    })
}

fn read_room(
    r: &Reader,
    feature: usize,
    props: &Map<String, Value>,
    coordinates: &Value,
    d: &PlanDefaults,
) -> Result<Room, FloorPlanError> {
    r.check_keys(props, &ROOM_KEYS, "a room")?;
    let floor_m = r.length(props, "floor_m")?.unwrap_or(0.0);
    let ceiling_m = r.length(props, "ceiling_m")?.unwrap_or(d.storey_height_m);
    if ceiling_m <= floor_m {
        return Err(r.err(format!("ceiling_m {ceiling_m} is not above floor_m {floor_m}")));
    }
    let name = match props.get("name") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(other) => return Err(r.err(format!("\"name\" must be a string, found {}", brief(other)))),
    };
    let rings = coordinates.as_array().ok_or_else(|| {
        r.err(format!(
            "Polygon coordinates must be an array of rings, found {}",
            brief(coordinates)
        ))
    })?;
    match rings.len() {
        0 => return Err(r.err("the Polygon has no ring")),
        1 => {}
        n => {
            return Err(r.err(format!(
                "the Polygon has holes ({}); only an outer ring is supported",
                n - 1
            )))
        }
    }
    let mut outline = r.line_string(&rings[0])?;
    dedup_points(&mut outline);
    if outline.len() > 1 && (outline[0] - outline[outline.len() - 1]).norm() < MIN_M {
        outline.pop();
    }
    if outline.len() < 3 {
        return Err(r.err(format!(
            "the Polygon has fewer than 3 distinct points ({})",
            outline.len()
        )));
    }
    if signed_area(&outline).abs() < 1e-6 {
        return Err(r.err("the Polygon has no area (its points are collinear)"));
    }
    Ok(Room {
        feature,
        name,
        outline,
        floor_m,
        ceiling_m,
    })
}

fn signed_area(ring: &[Point2<f64>]) -> f64 {
    let o = ring[0];
    (1..ring.len().saturating_sub(1))
        .map(|k| {
            let (a, b) = (ring[k] - o, ring[k + 1] - o);
            a.x * b.y - a.y * b.x
        })
        .sum::<f64>()
        / 2.0
}

fn xy(p: &Point2<f64>) -> String {
    format!("{}, {}", p.x, p.y)
}

// ---------------------------------------------------------------------------------------------
// Geometry across features: wall joins, openings on walls.

/// One straight piece of a wall axis.
struct Piece {
    start: Point2<f64>,
    /// Unit direction and its left normal (the wall's +n face is on this side).
    u: Vector2<f64>,
    n: Vector2<f64>,
    len: f64,
}

fn left_of(v: Vector2<f64>) -> Vector2<f64> {
    Vector2::new(-v.y, v.x)
}

fn pieces(w: &Wall) -> Vec<Piece> {
    let m = w.axis.len();
    let count = if w.closed { m } else { m - 1 };
    (0..count)
        .map(|i| {
            let (a, b) = (w.axis[i], w.axis[(i + 1) % m]);
            let len = (b - a).norm();
            let u = (b - a) / len;
            Piece {
                start: a,
                u,
                n: left_of(u),
                len,
            }
        })
        .collect()
}

/// Where a wall's two faces end at one axis point: `left` on the +n side, `right` on the −n side
/// (the same point for a thin wall). `cap` marks a free end of a thick wall, closed by an end face.
#[derive(Clone, Copy)]
struct Joint {
    left: Point2<f64>,
    right: Point2<f64>,
    cap: bool,
}

impl Joint {
    fn side(&self, k: f64) -> Point2<f64> {
        if k < 0.0 {
            self.right
        } else {
            self.left
        }
    }
}

/// A wall ready to emit: its pieces, one joint per axis point, and the openings on each piece
/// as `(opening index, s0, s1)` along the piece, sorted.
struct Laid {
    pieces: Vec<Piece>,
    joints: Vec<Joint>,
    openings: Vec<Vec<(usize, f64, f64)>>,
}

struct Layout<'a> {
    plan: &'a FloorPlan,
    file: &'a str,
    pieces: Vec<Vec<Piece>>,
}

impl Layout<'_> {
    fn err(&self, feature: usize, kind: &str, message: impl Into<String>) -> FloorPlanError {
        FloorPlanError {
            file: self.file.to_string(),
            place: format!("features[{feature}] ({kind}): "),
            message: message.into(),
        }
    }

    fn wall_name(&self, w: usize) -> String {
        format!("features[{}] (wall)", self.plan.walls[w].feature)
    }

    fn joints(&self, w: usize) -> Result<Vec<Joint>, FloorPlanError> {
        let wall = &self.plan.walls[w];
        let ps = &self.pieces[w];
        let h = wall.thickness_m / 2.0;
        let m = wall.axis.len();
        let mut joints = Vec::with_capacity(m);
        for i in 0..m {
            let p = wall.axis[i];
            let end_piece = if wall.closed {
                None
            } else if i == 0 {
                Some(0)
            } else if i == m - 1 {
                Some(ps.len() - 1)
            } else {
                None
            };
            let joint = match end_piece {
                None => {
                    let (a, b) = (&ps[(i + ps.len() - 1) % ps.len()], &ps[i % ps.len()]);
                    let cos = a.n.dot(&b.n);
                    if cos < -1.0 + 1e-9 {
                        return Err(self.err(wall.feature, "wall", format!("turns back on itself at ({})", xy(&p))));
                    }
                    // Its projection on both pieces' normals is exactly 1, so ±h times it lies on
                    // both pieces' offset faces: the mitre line.
                    let mitre = (a.n + b.n) / (1.0 + cos);
                    Joint {
                        left: p + h * mitre,
                        right: p - h * mitre,
                        cap: false,
                    }
                }
                Some(k) => self.end_joint(w, k, p, h)?,
            };
            joints.push(joint);
        }
        Ok(joints)
    }

    /// The joint at a free end of wall `w`, whose end piece is `k`: trimmed to the surface of a
    /// wall whose axis it ends on (a T-junction, no cap), or capped.
    fn end_joint(&self, w: usize, k: usize, end: Point2<f64>, h: f64) -> Result<Joint, FloorPlanError> {
        let wall = &self.plan.walls[w];
        let piece = &self.pieces[w][k];
        let thick = h > 0.0;
        let mut corner_meeting = None;
        for (v, other) in self.plan.walls.iter().enumerate() {
            for (q, target) in self.pieces[v].iter().enumerate() {
                if v == w && q == k {
                    continue;
                }
                let rel = end - target.start;
                let (along, across) = (rel.dot(&target.u), rel.dot(&target.n));
                if across.abs() > JOIN_TOLERANCE_M || along < -JOIN_TOLERANCE_M || along > target.len + JOIN_TOLERANCE_M
                {
                    continue;
                }
                if along < JOIN_TOLERANCE_M || along > target.len - JOIN_TOLERANCE_M {
                    // At a vertex of the other axis: no single surface to stop at.
                    if thick || other.thickness_m > 0.0 {
                        corner_meeting.get_or_insert(v);
                    }
                    continue;
                }
                let sin = piece.u.dot(&target.n);
                if sin.abs() < (1.0f64).to_radians().sin() {
                    return Err(self.err(
                        wall.feature,
                        "wall",
                        format!(
                            "ends at ({}) on {} but runs along it (less than 1° apart)",
                            xy(&end),
                            self.wall_name(v)
                        ),
                    ));
                }
                // Stop at the other wall's face on the side this wall comes from.
                let inner = if end == piece.start {
                    piece.start + piece.len * piece.u
                } else {
                    piece.start
                };
                let side = if (inner - target.start).dot(&target.n) > 0.0 {
                    1.0
                } else {
                    -1.0
                };
                let surface = side * other.thickness_m / 2.0;
                let at = |offset: f64| {
                    let base = piece.start + offset * piece.n;
                    let s = (surface - (base - target.start).dot(&target.n)) / sin;
                    base + s * piece.u
                };
                return Ok(Joint {
                    left: at(h),
                    right: at(-h),
                    cap: false,
                });
            }
        }
        if let Some(v) = corner_meeting {
            return Err(self.err(
                wall.feature,
                "wall",
                format!(
                    "ends at ({}) on an end or corner of {}: continue one LineString through the \
                     corner so it is mitred, or end the wall on the middle of the other's axis",
                    xy(&end),
                    self.wall_name(v)
                ),
            ));
        }
        Ok(Joint {
            left: end + h * piece.n,
            right: end - h * piece.n,
            cap: thick,
        })
    }

    /// The wall piece an opening lies on, and its extent `(s0, s1)` along that piece.
    fn place_opening(&self, o: &Opening) -> Option<(usize, usize, f64, f64)> {
        let mut best: Option<(f64, usize, usize, f64, f64)> = None;
        for (w, wall) in self.plan.walls.iter().enumerate() {
            let tol = OPENING_TOLERANCE_M.max(wall.thickness_m / 2.0);
            for (k, piece) in self.pieces[w].iter().enumerate() {
                let [sa, sb] = o.ends.map(|e| (e - piece.start).dot(&piece.u));
                let [da, db] = o.ends.map(|e| (e - piece.start).dot(&piece.n).abs());
                let on = |s: f64, d: f64| d <= tol && s >= -tol && s <= piece.len + tol;
                if on(sa, da) && on(sb, db) && best.is_none_or(|b| da.max(db) < b.0) {
                    best = Some((da.max(db), w, k, sa.min(sb), sa.max(sb)));
                }
            }
        }
        best.map(|(_, w, k, s0, s1)| (w, k, s0, s1))
    }

    fn lay_out(&self) -> Result<Vec<Laid>, FloorPlanError> {
        let plan = self.plan;
        let mut laid = Vec::with_capacity(plan.walls.len());
        for (w, wall) in plan.walls.iter().enumerate() {
            let joints = self.joints(w)?;
            let ps = &self.pieces[w];
            for (k, piece) in ps.iter().enumerate() {
                let (j0, j1) = (&joints[k], &joints[(k + 1) % joints.len()]);
                for side in [j0.left - j1.left, j0.right - j1.right] {
                    if side.dot(&piece.u) > -MIN_M {
                        return Err(self.err(
                            wall.feature,
                            "wall",
                            format!(
                                "the piece from ({}) to ({}) is too short for the wall's thickness and \
                                 joins: one face has no length left",
                                xy(&piece.start),
                                xy(&(piece.start + piece.len * piece.u))
                            ),
                        ));
                    }
                }
            }
            laid.push(Laid {
                pieces: pieces(wall),
                joints,
                openings: vec![Vec::new(); ps.len()],
            });
        }

        for (i, o) in plan.openings.iter().enumerate() {
            let kind = o.kind.name();
            let Some((w, k, s0, s1)) = self.place_opening(o) else {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "not on any wall: its ends ({}) and ({}) are not both within max(5 cm, half \
                         the thickness) of one straight piece of a wall axis",
                        xy(&o.ends[0]),
                        xy(&o.ends[1])
                    ),
                ));
            };
            let wall = &plan.walls[w];
            if s1 - s0 < MIN_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "runs across {} instead of along it: its extent along the axis is under 1 mm",
                        self.wall_name(w)
                    ),
                ));
            }
            if o.head_height_m > wall.height_m + EPS_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "head_height_m {} is above the height {} of {}",
                        o.head_height_m,
                        wall.height_m,
                        self.wall_name(w)
                    ),
                ));
            }
            let piece = &self.pieces[w][k];
            let l = &laid[w];
            let (j0, j1) = (&l.joints[k], &l.joints[(k + 1) % l.joints.len()]);
            let start = (j0.left - piece.start)
                .dot(&piece.u)
                .max((j0.right - piece.start).dot(&piece.u));
            let end = (j1.left - piece.start)
                .dot(&piece.u)
                .min((j1.right - piece.start).dot(&piece.u));
            if s0 < start + MIN_M || s1 > end - MIN_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "reaches past the end of {}'s faces (a wall must extend beyond its openings)",
                        self.wall_name(w)
                    ),
                ));
            }
            laid[w].openings[k].push((i, s0, s1));
        }

        for (w, l) in laid.iter_mut().enumerate() {
            for list in &mut l.openings {
                list.sort_by(|a, b| a.1.total_cmp(&b.1));
                for pair in list.windows(2) {
                    let ((i, _, s1), (j, s0, _)) = (pair[0], pair[1]);
                    if s0 < s1 + MIN_M {
                        let (a, b) = (&plan.openings[i], &plan.openings[j]);
                        let (first, second) = if a.feature < b.feature { (a, b) } else { (b, a) };
                        return Err(self.err(
                            second.feature,
                            second.kind.name(),
                            format!(
                                "overlaps or touches features[{}] ({}) on {}",
                                first.feature,
                                first.kind.name(),
                                self.wall_name(w)
                            ),
                        ));
                    }
                }
            }
        }
        Ok(laid)
    }
}

// ---------------------------------------------------------------------------------------------
// OBJ writing.

struct ObjWriter {
    vertices: Vec<[i64; 3]>,
    index: HashMap<[i64; 3], usize>,
    body: String,
    group: String,
    material: String,
    faces: usize,
    degenerate: usize,
}

impl ObjWriter {
    fn new() -> Self {
        Self {
            vertices: Vec::new(),
            index: HashMap::new(),
            body: String::new(),
            group: String::new(),
            material: String::new(),
            faces: 0,
            degenerate: 0,
        }
    }

    fn label(&mut self, group: &str, material: &str) {
        if self.group != group {
            let _ = writeln!(self.body, "g {group}");
            self.group = group.to_string();
        }
        if self.material != material {
            let _ = writeln!(self.body, "usemtl {material}");
            self.material = material.to_string();
        }
    }

    /// A planar polygon, wound counter-clockwise about `visible` (the side a camera sees; the
    /// model is two-sided, but renderers and humans reading the file like a consistent winding).
    fn face(&mut self, points: &[Point3<f64>], visible: Vector3<f64>) {
        let mut keys: Vec<[i64; 3]> = points
            .iter()
            .map(|p| [p.x, p.y, p.z].map(|c| (c * GRID_PER_M).round() as i64))
            .collect();
        keys.dedup();
        while keys.len() > 1 && keys.first() == keys.last() {
            keys.pop();
        }
        let mut newell = Vector3::zeros();
        for k in 0..keys.len() {
            let (a, b) = (keys[k].map(|c| c as f64), keys[(k + 1) % keys.len()].map(|c| c as f64));
            newell += Vector3::new(
                (a[1] - b[1]) * (a[2] + b[2]),
                (a[2] - b[2]) * (a[0] + b[0]),
                (a[0] - b[0]) * (a[1] + b[1]),
            );
        }
        // Validation upstream leaves no degenerate face; this only keeps a slip out of the file.
        if keys.len() < 3 || newell.norm() == 0.0 {
            self.degenerate += 1;
            return;
        }
        if newell.dot(&visible) < 0.0 {
            keys.reverse();
        }
        self.body.push('f');
        for key in keys {
            let next = self.vertices.len();
            let i = *self.index.entry(key).or_insert(next);
            if i == next {
                self.vertices.push(key);
            }
            let _ = write!(self.body, " {}", i + 1);
        }
        self.body.push('\n');
        self.faces += 1;
    }

    fn vertical(&mut self, a: Point2<f64>, b: Point2<f64>, z0: f64, z1: f64, visible: Vector2<f64>) {
        let pts = [
            Point3::new(a.x, a.y, z0),
            Point3::new(b.x, b.y, z0),
            Point3::new(b.x, b.y, z1),
            Point3::new(a.x, a.y, z1),
        ];
        self.face(&pts, Vector3::new(visible.x, visible.y, 0.0));
    }

    fn horizontal(&mut self, ring: &[Point2<f64>], z: f64, up: bool) {
        let pts: Vec<Point3<f64>> = ring.iter().map(|p| Point3::new(p.x, p.y, z)).collect();
        self.face(&pts, Vector3::new(0.0, 0.0, if up { 1.0 } else { -1.0 }));
    }

    fn finish(self, header: &str) -> String {
        let mut out = String::with_capacity(header.len() + self.body.len() + 40 * self.vertices.len());
        out.push_str(header);
        for key in &self.vertices {
            let [x, y, z] = key.map(|c| c as f64 / GRID_PER_M + 0.0);
            let _ = writeln!(out, "v {x} {y} {z}");
        }
        out.push_str(&self.body);
        out
    }
}

/// An OBJ group name from a user's room name: no whitespace (OBJ splits on it), nothing exotic.
fn group_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

impl FloorPlan {
    /// Lays the plan out in 3D and writes it as OBJ text; `file` names the plan in the header and
    /// in error messages (the cross-feature checks: openings on walls, joins).
    pub fn to_obj(&self, file: &str) -> Result<String, FloorPlanError> {
        let layout = Layout {
            plan: self,
            file,
            pieces: self.walls.iter().map(pieces).collect(),
        };
        let laid = layout.lay_out()?;
        let mut obj = ObjWriter::new();
        for (wall, l) in self.walls.iter().zip(&laid) {
            self.emit_wall(&mut obj, wall, l);
        }
        for room in &self.rooms {
            let name = match &room.name {
                Some(n) if !n.trim().is_empty() => group_name(n.trim()),
                _ => room.feature.to_string(),
            };
            obj.label(&format!("room_{name}_floor"), "floor");
            obj.horizontal(&room.outline, room.floor_m, true);
            obj.label(&format!("room_{name}_ceiling"), "ceiling");
            obj.horizontal(&room.outline, room.ceiling_m, false);
        }
        if obj.degenerate > 0 {
            return Err(FloorPlanError {
                file: file.to_string(),
                place: String::new(),
                message: format!(
                    "extrusion produced {} degenerate faces (a bug in omnitrack's floor-plan \
                     code; please report it with this plan)",
                    obj.degenerate
                ),
            });
        }
        let count = |k| self.openings.iter().filter(|o| o.kind == k).count();
        let header = format!(
            "# Building model extruded from the floor plan {} by omnitrack::desk::floorplan.\n\
             # Metres, z up; faces counter-clockwise about their visible side. g = feature, usemtl = kind.\n\
             # {} walls, {} doors, {} windows, {} rooms: {} vertices, {} faces.\n",
            file.replace(['\n', '\r'], " "),
            self.walls.len(),
            count(OpeningKind::Door),
            count(OpeningKind::Window),
            self.rooms.len(),
            obj.vertices.len(),
            obj.faces
        );
        Ok(obj.finish(&header))
    }

    fn emit_wall(&self, obj: &mut ObjWriter, wall: &Wall, l: &Laid) {
        let h = wall.thickness_m / 2.0;
        let (z0, z1) = (wall.base_m, wall.base_m + wall.height_m);
        let thick = h > 0.0;
        let group = format!("wall_{}", wall.feature);
        let sides: &[f64] = if thick { &[1.0, -1.0] } else { &[1.0] };
        for (k, piece) in l.pieces.iter().enumerate() {
            let (j0, j1) = (l.joints[k], l.joints[(k + 1) % l.joints.len()]);
            let ops: Vec<(&Opening, f64, f64)> = l.openings[k]
                .iter()
                .map(|&(i, s0, s1)| (&self.openings[i], s0, s1))
                .collect();
            // Per side: the face's end points with every opening's two jamb points between.
            let column = |side: f64| -> Vec<Point2<f64>> {
                let base = piece.start + side * h * piece.n;
                let mut pts = vec![j0.side(side)];
                for &(_, s0, s1) in &ops {
                    pts.extend([base + s0 * piece.u, base + s1 * piece.u]);
                }
                pts.push(j1.side(side));
                pts
            };
            let columns: Vec<Vec<Point2<f64>>> = sides.iter().map(|&s| column(s)).collect();

            obj.label(&group, "wall");
            for (side, pts) in sides.iter().zip(&columns) {
                let visible = *side * piece.n;
                for (j, pair) in pts.windows(2).enumerate() {
                    let (a, b) = (pair[0], pair[1]);
                    if j % 2 == 0 {
                        obj.vertical(a, b, z0, z1, visible);
                    } else {
                        let o = ops[j / 2].0;
                        let (bottom, head) = o.span(z0, z1);
                        if bottom > z0 {
                            obj.vertical(a, b, z0, bottom, visible);
                        }
                        if head < z1 {
                            obj.vertical(a, b, head, z1, visible);
                        }
                    }
                }
            }
            if !thick {
                continue;
            }
            let (left, right) = (&columns[0], &columns[1]);
            // The top, broken only where an opening reaches it.
            let mut from = 0;
            for (j, (o, _, _)) in ops.iter().enumerate() {
                if o.span(z0, z1).1 == z1 {
                    obj.horizontal(&[left[from], left[2 * j + 1], right[2 * j + 1], right[from]], z1, true);
                    from = 2 * j + 2;
                }
            }
            let last = left.len() - 1;
            obj.horizontal(&[left[from], left[last], right[last], right[from]], z1, true);
            if k == 0 && j0.cap {
                obj.vertical(j0.left, j0.right, z0, z1, -piece.u);
            }
            if k == l.pieces.len() - 1 && j1.cap {
                obj.vertical(j1.left, j1.right, z0, z1, piece.u);
            }
            for (j, (o, _, _)) in ops.iter().enumerate() {
                let (bottom, head) = o.span(z0, z1);
                obj.label(
                    &format!("{}_{}", o.kind.name(), o.feature),
                    &format!("{}_reveal", o.kind.name()),
                );
                let (a, b) = (2 * j + 1, 2 * j + 2);
                obj.vertical(left[a], right[a], bottom, head, piece.u);
                obj.vertical(left[b], right[b], bottom, head, -piece.u);
                if head < z1 {
                    obj.horizontal(&[left[a], left[b], right[b], right[a]], head, false);
                }
                if bottom > z0 {
                    obj.horizontal(&[left[a], left[b], right[b], right[a]], bottom, true);
                }
                obj.label(&group, "wall");
            }
        }
    }
}
