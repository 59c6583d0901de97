//! The plan types: what `geojson` reads out of a GeoJSON plan (walls, doors and
//! windows, rooms, and the plan-wide defaults) and what the later stages lay out and extrude.
//! Lengths in metres, heights above the feature's base.

use super::MIN_M;
use nalgebra::Point2;

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
    pub(super) fn span(&self, z0: f64, z1: f64) -> (f64, f64) {
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
    pub(super) fn name(self) -> &'static str {
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
