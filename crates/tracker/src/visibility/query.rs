//! `omnitrack visibility query`: the visibility set a table gives a position, as JSON, and the
//! parsing of the position the command line gives.
//!
//! In: a table file (or a loaded table and its model) and a point. Out: the JSON text.

use super::{VisibilityError, VisibilityTable};
use nalgebra::Point3;
use omnitrack_core::model::Model;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn push_num(out: &mut String, x: f64) {
    if x.is_finite() {
        // Shortest representation that reads back to the same f64; integers without ".0".
        if x == x.trunc() && x.abs() < 1e15 {
            let _ = write!(out, "{}", x as i64);
        } else {
            let _ = write!(out, "{x}");
        }
    } else {
        out.push_str("null");
    }
}

fn push_point(out: &mut String, p: &Point3<f64>) {
    out.push('[');
    push_num(out, p.x);
    out.push(',');
    push_num(out, p.y);
    out.push(',');
    push_num(out, p.z);
    out.push(']');
}

/// The JSON of `omnitrack visibility query` (docs/interfaces.md): `{"node_m":[x,y,z],"faces":[OBJ
/// face numbers],"segments":[[x1,y1,z1,x2,y2,z2],...],"vertices":[[x,y,z],...]}` for the node
/// serving `at`. Faces are 1-based OBJ face numbers in file order (a non-planar record split
/// into several faces appears once). A table without valid nodes gives `"node_m":null` and
/// empty lists.
pub fn query_json(table: &VisibilityTable, model: &Model, at: &Point3<f64>) -> String {
    let mut out = String::from("{\"node_m\":");
    let Some(set) = table.query(at) else {
        out.push_str("null,\"faces\":[],\"segments\":[],\"vertices\":[]}");
        return out;
    };
    push_point(&mut out, &set.node_position);
    out.push_str(",\"faces\":[");
    let mut numbers: Vec<u32> = set
        .faces
        .iter()
        .filter_map(|&f| model.faces.get(f as usize).map(|f| f.obj_number))
        .collect();
    numbers.sort_unstable();
    numbers.dedup();
    for (i, n) in numbers.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let _ = write!(out, "{n}");
    }
    out.push_str("],\"segments\":[");
    for (i, &s) in set.segments.iter().enumerate() {
        let Some(seg) = model.segments.get(s as usize) else {
            continue;
        };
        if i > 0 {
            out.push(',');
        }
        out.push('[');
        for (k, c) in [seg.a.x, seg.a.y, seg.a.z, seg.b.x, seg.b.y, seg.b.z]
            .into_iter()
            .enumerate()
        {
            if k > 0 {
                out.push(',');
            }
            push_num(&mut out, c);
        }
        out.push(']');
    }
    out.push_str("],\"vertices\":[");
    for (i, &v) in set.vertices.iter().enumerate() {
        let Some(p) = model.vertices.get(v as usize) else {
            continue;
        };
        if i > 0 {
            out.push(',');
        }
        push_point(&mut out, p);
    }
    out.push_str("]}");
    out
}

/// Parses `x,y,z` (negative numbers allowed, e.g. `-1.5,2,1.6`).
pub fn parse_point(text: &str) -> Result<Point3<f64>, PointError> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(PointError::NotThree(text.to_string()));
    }
    let mut c = [0.0; 3];
    for (k, p) in parts.iter().enumerate() {
        c[k] = p
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| PointError::NotANumber {
                text: text.to_string(),
                part: p.to_string(),
            })?;
    }
    Ok(Point3::new(c[0], c[1], c[2]))
}

/// Why `--at` is not a position.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointError {
    #[error("--at {0:?}: expected x,y,z (three numbers separated by commas)")]
    NotThree(String),
    #[error("--at {text:?}: {part:?} is not a number")]
    NotANumber { text: String, part: String },
}

/// `omnitrack visibility query --visibility V --at x,y,z`: reads the table, reads the model it
/// was built from (the path recorded in its header), checks the model hash and returns the JSON
/// line of [`query_json`].
pub fn run_query(visibility: &Path, at: &Point3<f64>) -> Result<String, VisibilityError> {
    let table = VisibilityTable::load_unchecked(visibility)?;
    let file = visibility.display().to_string();
    let model_path = PathBuf::from(&table.header.model_path);
    let model = Model::load(&model_path).map_err(|e| VisibilityError::Invalid {
        file: file.clone(),
        message: format!("cannot read the model the table was built from: {e}"),
    })?;
    table.check_model(&model, &file, &model_path.display().to_string())?;
    Ok(query_json(&table, &model, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_point_accepts_negative() {
        assert_eq!(parse_point("-1.5,2,1.6").unwrap(), Point3::new(-1.5, 2.0, 1.6));
        assert!(parse_point("1,2").is_err());
        assert!(parse_point("1,x,2").is_err());
    }
}
