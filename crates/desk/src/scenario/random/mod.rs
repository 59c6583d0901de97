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
//!
//! The parts: `choices` (what may be pinned), `layout` (every draw up to the building's plan),
//! `mesh` (the model's OBJ text), `plan` (the walked storey's GeoJSON) and `campus` (several
//! buildings in one model).

mod campus;
mod choices;
mod layout;
mod mesh;
mod plan;

pub use campus::{campus, Campus};
pub use choices::{Choices, Outline, UnknownPin, WallStyle};

use super::Motion;
use crate::floorplan::{self, FloorPlan, FloorPlanError};
use crate::render::appearance::Rng;
use nalgebra::Point2;
use std::fmt;

type P2 = Point2<f64>;

/// Width of the stair, which the walked plan keeps clear as a wall of this thickness.
const STAIR_WIDTH_M: f64 = 1.0;

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

impl RandomBuilding {
    /// The building of `seed`, every choice drawn.
    pub fn new(seed: u64) -> RandomBuilding {
        Self::generate(seed, &Choices::default())
    }

    /// The building of `seed` with the pinned `choices`.
    pub fn generate(seed: u64, choices: &Choices) -> RandomBuilding {
        let mut rng = Rng::new(seed ^ 0xb111_d1a9);
        let layout = layout::draw(&mut rng, choices);
        let (obj, faces, flipped) = mesh::model_obj(&layout, seed, &mut rng);
        let plan_geojson = plan::plan_geojson(&layout, seed);
        let rects = &layout.rects;
        let openings = &layout.openings;
        let floor_area_m2: f64 = rects.iter().map(|(lo, hi)| (hi.x - lo.x) * (hi.y - lo.y)).sum();
        let doors = openings.iter().filter(|o| o.door && o.z0 == 0.0).count();
        let windows = openings.iter().filter(|o| !o.door).count();
        let cart = rng.unit() < 0.5;
        let (motion, frame_rate_hz) = if choices.cart.unwrap_or(cart) {
            (Motion::Rolling3Dof { height_m: 1.2 }, 5.0)
        } else {
            (Motion::HandHeld6Dof, 10.0)
        };
        RandomBuilding {
            seed,
            outline: layout.outline,
            walls: layout.walls,
            bays: layout.bays,
            storeys: layout.storeys,
            triangulated: layout.triangulated,
            storey_height_m: layout.height,
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
