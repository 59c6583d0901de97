//! GeoJSON reading: the plan's text in, a checked [`FloorPlan`] out, or a [`FloorPlanError`]
//! naming the feature and the property. Checked here is everything that needs no geometry across
//! features; walls meeting walls and openings on walls are `layout`'s.
//!
//! Walked by hand rather than through serde derive so that every message can name the feature and
//! the property.

use super::plan::{FloorPlan, Opening, OpeningKind, PlanDefaults, Room, Wall};
use super::{xy, FloorPlanError, MIN_M};
use nalgebra::Point2;
use serde_json::{Map, Value};

/// Larger magnitudes are mistakes (or a geographic CRS) and would cost precision at the 1 nm grid.
const MAX_ABS_M: f64 = 1e6;

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
