//! What the edge stage hands on: one observed straight [`Edge`] of one sensor image.
//!
//! In: nothing (plain data, filled by the sensor's selection step). Out: the edge's plane, pixel
//! and ray ends, strength, hue, polarity, and the stretches the image does or does not show
//! ([`Edge::gaps`], [`Edge::pieces`], [`Edge::shown`]), read by the CSV, the tracker and the
//! pictures.

use crate::hue::HueSignature;
use nalgebra::{Point2, Vector3};
use omnitrack_core::geometry::EdgePlane;

/// Gaps an [`Edge`] remembers: the widest, when merging bridged more.
pub const MAX_GAPS: usize = 4;

/// One observed straight edge of one sensor image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Sensor id.
    pub sensor: u8,
    /// Plane through the sensor's centre containing the edge, rig frame; `ends` are the unit
    /// rays of the two end points (in the plane); the normal is oriented as `ends[0] × ends[1]`.
    pub plane: EdgePlane,
    /// Pixel positions of the two ends on the image as it is (on the curved fisheye edge).
    pub px: [Point2<f64>; 2],
    /// Angle between the end rays (rad).
    pub length_rad: f64,
    /// Sum of the edgels' gradient magnitudes / 64 ≈ contrast (grey levels) × length (edgels).
    pub strength: f32,
    pub hue: HueSignature,
    /// Which side is brighter: +1 the left (as for [`HueSignature`]), −1 the right, 0 neither
    /// clearly (fewer than three in four edgels agree). Unlike hue it exists on a grey image,
    /// and like hue it survives a change of exposure.
    pub polarity: i8,
    /// Edgels the plane was fitted to.
    pub edgels: u32,
    /// RMS angle (rad) of the edgels' rays off the fitted plane.
    pub rms_rad: f32,
    /// Where the image does not show the edge: the stretches (rad from `ends[0]` along the
    /// edge, in order) that merging bridged between collinear pieces, such as a line broken by
    /// an occluder or by noise, or plain wall between two window tops. The plane is fitted to
    /// the pieces alone. At most the [`MAX_GAPS`] widest (the first `n_gaps`); see
    /// [`Edge::pieces`].
    pub gaps: [[f32; 2]; MAX_GAPS],
    pub n_gaps: u8,
    /// The pieces ([`Edge::pieces`]) that pass LSD's a-contrario test (rad from `ends[0]`, in
    /// order; the first `n_shown`): along each, the image gradient is across the line at more
    /// pixels than chance explains (number of false alarms below 1, [`EdgeParams::piece_nfa`](crate::EdgeParams::piece_nfa)),
    /// each trimmed to its first and last such pixel with [`EdgeParams::piece_trim`](crate::EdgeParams::piece_trim). A piece
    /// that fails is left out (the image does not show it as a line); none may pass. The edge
    /// itself, its plane and its gaps do not depend on it. See [`Edge::shown`].
    pub shown: [[f32; 2]; MAX_GAPS + 1],
    pub n_shown: u8,
}

impl Edge {
    /// The stretches the image does not show (see [`Edge::gaps`](Edge#structfield.gaps)).
    pub fn gaps(&self) -> &[[f32; 2]] {
        &self.gaps[..usize::from(self.n_gaps).min(MAX_GAPS)]
    }

    /// The stretches the image shows, from `ends[0]` to `ends[1]` (rad along the edge): one for
    /// an edge without gaps.
    pub fn pieces(&self) -> impl Iterator<Item = [f64; 2]> + '_ {
        let gaps = self.gaps();
        (0..=gaps.len()).map(move |k| {
            let from = if k == 0 { 0.0 } else { f64::from(gaps[k - 1][1]) };
            let to = gaps.get(k).map_or(self.length_rad, |g| f64::from(g[0]));
            [from, to]
        })
    }

    /// The pieces the image shows as lines, meaningful by LSD's a-contrario test (see
    /// [`Edge::shown`](Edge#structfield.shown)): a subset of [`Edge::pieces`], maybe trimmed;
    /// empty when none is.
    pub fn shown(&self) -> &[[f32; 2]] {
        &self.shown[..usize::from(self.n_shown).min(MAX_GAPS + 1)]
    }

    /// The unit ray (rig frame, from the sensor's centre) `t` rad from `ends[0]` along the edge.
    pub fn ray_at(&self, t: f64) -> Vector3<f64> {
        let e0 = self.plane.ends[0].into_inner();
        let towards = self.plane.normal.cross(&e0);
        e0 * t.cos() + towards * t.sin()
    }
}
