//! Edges made from planes for the unit tests: every field but the plane, the sensor and the
//! edgel count at a plain value (no hue, no polarity, no gaps), so that a test states only what
//! it is about.

use nalgebra::Point2;
use omnitrack_core::geometry::EdgePlane;
use omnitrack_edges::{Edge, HueSignature};

/// An edge of `sensor` along `plane` (its length the angle between its end rays), fitted to
/// `edgels` edgels.
pub(crate) fn edge_on(sensor: u8, plane: EdgePlane, edgels: u32) -> Edge {
    Edge {
        sensor,
        length_rad: plane.ends[0].angle(&plane.ends[1]),
        plane,
        px: [Point2::origin(); 2],
        strength: 1.0,
        hue: HueSignature::NONE,
        edgels,
        polarity: 0,
        rms_rad: 0.0,
        gaps: Default::default(),
        n_gaps: 0,
        shown: Default::default(),
        n_shown: 0,
    }
}
