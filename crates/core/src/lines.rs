//! The lines CSV of `omnitrack pose` (docs/interfaces.md): one image edge and its model segment a row,
//! `sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2` — pixel end points in sensor `sensor` of the rig and
//! the segment's world end points.
//!
//! In: CSV text and the rig. Out: [`Correspondence`]s, each edge turned into the plane through its
//! sensor's centre (rig frame) by unprojecting its end points through that sensor's lens. Errors
//! are one line, `file:line: what is wrong`.

use crate::geometry::{Correspondence, EdgePlane};
use crate::rig::Rig;
use nalgebra::{Point2, Point3};

pub const HEADER: [&str; 11] = ["sensor", "u1", "v1", "u2", "v2", "x1", "y1", "z1", "x2", "y2", "z2"];

/// A lines file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{line}: {message}")]
pub struct LinesError {
    pub file: String,
    pub line: usize,
    pub message: String,
}

/// Parses the CSV (header first; columns after the eleventh are ignored, blank lines skipped).
pub fn parse_lines(text: &str, file: &str, rig: &Rig) -> Result<Vec<Correspondence>, LinesError> {
    let err = |line: usize, message: String| LinesError {
        file: file.to_string(),
        line,
        message,
    };
    let mut rows = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let Some((h, header)) = rows.next() else {
        return Err(err(1, format!("empty file: expected the header {}", HEADER.join(","))));
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    if names.len() < HEADER.len() || names[..HEADER.len()] != HEADER {
        return Err(err(
            h + 1,
            format!("header must start with {}, found {}", HEADER.join(","), header.trim()),
        ));
    }
    let mut out = Vec::new();
    for (i, row) in rows {
        let n = i + 1;
        let fields: Vec<&str> = row.split(',').map(str::trim).collect();
        if fields.len() < HEADER.len() {
            return Err(err(
                n,
                format!("expected {} fields, found {}", HEADER.len(), fields.len()),
            ));
        }
        let sensor: usize = fields[0]
            .parse()
            .map_err(|_| err(n, format!("sensor '{}' is not a sensor id", fields[0])))?;
        let Some(s) = rig.sensors.get(sensor) else {
            return Err(err(
                n,
                format!("sensor {sensor} is not in the rig ({} sensors)", rig.sensors.len()),
            ));
        };
        let mut v = [0.0; 10];
        for (k, f) in fields[1..HEADER.len()].iter().enumerate() {
            v[k] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(n, format!("{} '{f}' is not a finite number", HEADER[k + 1])))?;
        }
        let ray = |u: f64, v: f64| {
            s.ray_in_rig(&Point2::new(u, v))
                .ok_or_else(|| err(n, format!("pixel ({u}, {v}) has no ray through sensor {sensor}'s lens")))
        };
        let (r1, r2) = (ray(v[0], v[1])?, ray(v[2], v[3])?);
        let edge = EdgePlane::from_rays(s.centre(), &r1, &r2)
            .ok_or_else(|| err(n, "the edge's two end points see the same direction (no plane)".into()))?;
        let a = Point3::new(v[4], v[5], v[6]);
        let b = Point3::new(v[7], v[8], v[9]);
        if (b - a).norm() < 1e-9 {
            return Err(err(n, "the model segment has zero length".into()));
        }
        out.push(Correspondence { edge, segment: [a, b] });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig() -> Rig {
        Rig::from_toml_str(
            "name = \"cam\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
             intrinsics = [800.0, 800.0, 319.5, 239.5]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "cam.toml",
        )
        .unwrap()
    }

    #[test]
    fn rows_become_planes_through_the_sensor_centre() {
        let text = "sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2,comment\n0,319.5,239.5,719.5,239.5,0,0,5,1,0,5,x\n\n";
        let c = parse_lines(text, "l.csv", &rig()).unwrap();
        assert_eq!(c.len(), 1);
        // The image row through the centre is the plane y = 0 of the camera.
        assert!((c[0].edge.normal.y.abs() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_rows_name_the_line() {
        let h = "sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2\n";
        let cases = [
            (format!("{h}0,1,2,3\n"), "l.csv:2: expected 11 fields, found 4"),
            (
                format!("{h}7,1,2,3,4,0,0,1,1,0,1\n"),
                "l.csv:2: sensor 7 is not in the rig (1 sensors)",
            ),
            (
                format!("{h}x,1,2,3,4,0,0,1,1,0,1\n"),
                "l.csv:2: sensor 'x' is not a sensor id",
            ),
            (
                format!("{h}0,1,nan,3,4,0,0,1,1,0,1\n"),
                "l.csv:2: v1 'nan' is not a finite number",
            ),
            (
                format!("{h}0,1,2,1,2,0,0,1,1,0,1\n"),
                "l.csv:2: the edge's two end points see the same direction",
            ),
            (
                format!("{h}0,1,2,3,4,0,0,1,0,0,1\n"),
                "l.csv:2: the model segment has zero length",
            ),
            ("u1,v1\n".to_string(), "l.csv:1: header must start with sensor,u1"),
            (String::new(), "l.csv:1: empty file"),
        ];
        for (text, expected) in cases {
            let e = parse_lines(&text, "l.csv", &rig()).unwrap_err().to_string();
            assert!(e.starts_with(expected), "{e:?} vs {expected:?}");
        }
    }
}
