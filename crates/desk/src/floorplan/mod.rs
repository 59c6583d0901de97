//! Floor-plan extrusion: a 2D blueprint in, a 3D building model out (Koch & Teller built their
//! CORRIDOR model the same way).
//!
//! In: a GeoJSON `FeatureCollection` in metres (local planar x east, y north, no CRS) of walls
//! (`LineString` axes), doors and windows (two-point `LineString`s on a wall axis) and rooms
//! (`Polygon`s); `docs/models.md` ("Floor plans") is the reference. Out: Wavefront OBJ text (metres, z up) of
//! planar faces, each under a `g` naming its feature (`wall_3`, `room_corridor_floor`) and a
//! `usemtl` naming its kind (`wall`, `floor`, `ceiling`, `door_reveal`, `window_reveal`).
//!
//! The faces are laid out for [`omnitrack_core::model::Model`]'s segment extraction, so that its model
//! segments are exactly the lines a camera sees: wall corners, floor and ceiling lines, door and
//! window frames. Walls are cut into coplanar rectangular panels around their openings instead of
//! polygons with holes (OBJ has none), which costs nothing: seams between coplanar panels are not
//! segments. Every error is one line naming the file and the feature.
//!
//! The stages, one submodule each: `geojson` reads and checks the plan into the types of `plan`;
//! `layout` joins the walls and puts the openings on them; `extrude` turns the laid-out walls and
//! the rooms into faces, which `obj` writes as OBJ text.

mod extrude;
mod geojson;
mod layout;
mod obj;
mod plan;

pub use geojson::parse;
pub use plan::{FloorPlan, Opening, OpeningKind, PlanDefaults, Room, Wall};

use nalgebra::Point2;

/// The shortest edge a face may get. The model loader welds vertices within 10 µm, so a sliver
/// (a wall stopping 2 µm past an opening) would come out of it degenerate; 1 mm is below any
/// drawing's precision.
const MIN_M: f64 = 1e-3;

/// A plan that cannot be extruded; displays as one line: `file: features[i] (kind): problem`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {place}{message}")]
pub struct FloorPlanError {
    pub file: String,
    /// `"features[3] (door): "`, or empty for problems of the whole file.
    pub place: String,
    pub message: String,
}

/// Reads a GeoJSON floor plan and returns the OBJ text of its extrusion; `file` names the plan
/// in error messages and in the OBJ header.
pub fn extrude(geojson: &str, file: &str) -> Result<String, FloorPlanError> {
    parse(geojson, file)?.to_obj(file)
}

/// A point in a message, as the plan would type it.
fn xy(p: &Point2<f64>) -> String {
    format!("{}, {}", p.x, p.y)
}
