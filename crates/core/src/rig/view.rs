//! Which directions the rig sees: the union of its sensors' fields of view.
//!
//! In: a [`Rig`]. Out: a [`ViewMap`], asked "does some sensor image this direction (rig frame)?".
//!
//! **Why.** A candidate pose must be judged by the model lines its sensors can image, not by
//! every line in sight of its position: one pinhole sensor 50° wide sees a twentieth of the
//! sphere, and a pose scored against the whole sphere explains at most that share however right
//! it is; an omnidirectional rig has a hole beneath it where no sensor looks.
//!
//! **How.** A cube map over the directions of the rig frame, [`FACE_CELLS`]² cells per face, each
//! marked seen when the ray through its centre lands on the image of some sensor (projected
//! through that sensor's lens from its own centre: sensors a few centimetres apart see the same
//! directions of anything a metre away, to well under a cell). A query is a table look-up, cheap
//! enough to ask for every sampled point of every segment of every candidate a search scores.
//! Borders are exact to half a cell (0.7° at a face's centre).
//!
//! Fixed memory: built once in [`ViewMap::new`]; queries allocate nothing.

use super::Rig;
use nalgebra::Vector3;

/// Cells along each edge of a cube face.
pub const FACE_CELLS: usize = 64;

/// The rig's field of view as a cube map of directions.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewMap {
    /// Per face (+x, −x, +y, −y, +z, −z), row-major cells: seen by some sensor.
    seen: Vec<bool>,
    /// Share of the sphere's solid angle seen.
    share: f64,
}

impl ViewMap {
    /// The map of `rig`'s sensors.
    pub fn new(rig: &Rig) -> ViewMap {
        let n = FACE_CELLS;
        let mut seen = vec![false; 6 * n * n];
        let (mut seen_weight, mut total_weight) = (0.0, 0.0);
        for face in 0..6 {
            for row in 0..n {
                for col in 0..n {
                    let u = (col as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                    let v = (row as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                    let d = face_direction(face, u, v);
                    // The direction from each sensor's own centre.
                    let sees = rig
                        .sensors
                        .iter()
                        .any(|s| s.project_from_rig(&(s.centre() + d)).is_some());
                    // A cell's solid angle on the cube face at (u, v): dA / r³.
                    let w = (1.0 + u * u + v * v).powf(-1.5);
                    total_weight += w;
                    if sees {
                        seen_weight += w;
                        seen[(face * n + row) * n + col] = true;
                    }
                }
            }
        }
        ViewMap {
            seen,
            share: seen_weight / total_weight,
        }
    }

    /// Whether some sensor images the direction `d` (rig frame, any length but zero).
    #[inline]
    pub fn sees(&self, d: &Vector3<f64>) -> bool {
        cube_cell(d, FACE_CELLS).is_some_and(|c| self.seen[c])
    }

    /// Share of the sphere of directions that some sensor images, in [0, 1].
    pub fn share(&self) -> f64 {
        self.share
    }
}

/// The cell of direction `d` (any length; `None` for zero) in a cube map of `n`² cells per face:
/// faces +x, −x, +y, −y, +z, −z in that order, each row-major, so the index is below 6`n`².
/// Shared by every cube map of directions (this one, the search's map of directions near an
/// edge), so that they agree on which direction lands in which cell.
#[inline]
pub fn cube_cell(d: &Vector3<f64>, n: usize) -> Option<usize> {
    let (ax, ay, az) = (d.x.abs(), d.y.abs(), d.z.abs());
    // The face of the largest component, and the other two divided by it.
    let (face, u, v) = if ax >= ay && ax >= az && ax > 0.0 {
        if d.x > 0.0 {
            (0, -d.y / ax, -d.z / ax)
        } else {
            (1, d.y / ax, -d.z / ax)
        }
    } else if ay >= az && ay > 0.0 {
        if d.y > 0.0 {
            (2, d.x / ay, -d.z / ay)
        } else {
            (3, -d.x / ay, -d.z / ay)
        }
    } else if d.z > 0.0 {
        (4, d.y / az, d.x / az)
    } else if d.z < 0.0 {
        (5, d.y / az, -d.x / az)
    } else {
        return None;
    };
    let cell = |t: f64| (((t + 1.0) * 0.5 * n as f64) as usize).min(n - 1);
    Some((face * n + cell(v)) * n + cell(u))
}

/// The direction through (u, v) ∈ [−1, 1]² of a cube face; the inverse of the face choice in
/// [`cube_cell`].
fn face_direction(face: usize, u: f64, v: f64) -> Vector3<f64> {
    match face {
        0 => Vector3::new(1.0, -u, -v),
        1 => Vector3::new(-1.0, u, -v),
        2 => Vector3::new(u, 1.0, -v),
        3 => Vector3::new(-u, -1.0, -v),
        4 => Vector3::new(v, u, 1.0),
        _ => Vector3::new(-v, u, -1.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig(text: &str) -> Rig {
        Rig::from_toml_str(text, "test.toml").unwrap()
    }

    const PINHOLE: &str = r#"
name = "one"
[[sensors]]
id = 0
resolution = [640, 480]
model = "pinhole"
intrinsics = [686.0, 686.0, 319.5, 239.5]
rotation_wxyz = [0.5, -0.5, 0.5, -0.5]
translation_m = [0.0, 0.0, 0.0]
"#;

    #[test]
    fn every_face_cell_maps_back_to_itself() {
        let n = FACE_CELLS;
        for face in 0..6 {
            for row in 0..n {
                for col in 0..n {
                    let u = (col as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                    let v = (row as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                    let mut map = ViewMap {
                        seen: vec![false; 6 * n * n],
                        share: 0.0,
                    };
                    map.seen[(face * n + row) * n + col] = true;
                    assert!(
                        map.sees(&(3.0 * face_direction(face, u, v))),
                        "face {face} ({row}, {col})"
                    );
                }
            }
        }
    }

    #[test]
    fn a_forward_pinhole_sees_its_frustum_and_nothing_else() {
        let map = ViewMap::new(&rig(PINHOLE));
        // Rig x forward, y left, z up; the sensor looks along x, 2 × atan(320 / 686) ≈ 50° wide
        // and 2 × atan(240 / 686) ≈ 38° high.
        let at = |yaw_deg: f64, pitch_deg: f64| {
            let (y, p) = (yaw_deg.to_radians(), pitch_deg.to_radians());
            Vector3::new(y.cos() * p.cos(), y.sin() * p.cos(), p.sin())
        };
        assert!(map.sees(&at(0.0, 0.0)));
        assert!(map.sees(&at(23.0, 0.0)) && map.sees(&at(-23.0, 0.0)));
        assert!(map.sees(&at(0.0, 18.0)) && map.sees(&at(0.0, -18.0)));
        assert!(!map.sees(&at(27.0, 0.0)) && !map.sees(&at(-27.0, 0.0)));
        assert!(!map.sees(&at(0.0, 21.0)) && !map.sees(&at(0.0, -21.0)));
        assert!(!map.sees(&at(180.0, 0.0)) && !map.sees(&at(90.0, 0.0)));
        // The frustum's solid angle: 4 asin(sin(a) sin(b)) for half-angles a, b.
        let (a, b) = ((320.0f64 / 686.0).atan(), (240.0f64 / 686.0).atan());
        let expected = 4.0 * (a.sin() * b.sin()).asin() / (4.0 * std::f64::consts::PI);
        assert!((map.share() - expected).abs() < 0.004, "{} vs {expected}", map.share());
    }

    #[test]
    fn the_shipped_omnidirectional_rig_sees_around_but_not_straight_down() {
        let rig = Rig::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../firmware_config/ladybug2.toml"
        )))
        .unwrap();
        let map = ViewMap::new(&rig);
        for k in 0..36 {
            let yaw = (k as f64 * 10.0).to_radians();
            assert!(
                map.sees(&Vector3::new(yaw.cos(), yaw.sin(), 0.0)),
                "heading {}°",
                k * 10
            );
        }
        assert!(map.sees(&Vector3::z()));
        assert!(!map.sees(&-Vector3::z()));
        assert!(map.share() > 0.7 && map.share() < 1.0, "{}", map.share());
    }
}
