//! Wavefront OBJ reading: records to raw vertices, polygons and polylines, with line numbers for
//! every error. Geometry (welding, planarity, segments) is done by the caller.

use super::{Face, ModelError, ModelStats};
use nalgebra::Point3;
use std::collections::HashMap;

/// Largest coordinate a model may have (m): a UTM northing with a zone prefix is under 1e8, and
/// past about 1e150 the squares in the face geometry overflow.
pub const MAX_COORDINATE_M: f64 = 1e9;

pub(super) struct RawFace {
    /// 0-based indices into `ParsedObj::vertices`, resolved and range-checked.
    pub vertices: Vec<u32>,
    pub obj_number: u32,
    pub object: u32,
    pub group: u32,
    pub material: u32,
}

impl RawFace {
    pub fn label(&self, mut f: Face) -> Face {
        f.obj_number = self.obj_number;
        f.object = self.object;
        f.group = self.group;
        f.material = self.material;
        f
    }
}

pub(super) struct ParsedObj {
    pub vertices: Vec<Point3<f64>>,
    pub faces: Vec<RawFace>,
    pub lines: Vec<Vec<u32>>,
    pub labels: Vec<String>,
    pub stats: ModelStats,
}

struct Labels {
    names: Vec<String>,
    index: HashMap<String, u32>,
}

impl Labels {
    fn intern(&mut self, name: &str) -> u32 {
        if let Some(&i) = self.index.get(name) {
            return i;
        }
        let i = self.names.len() as u32;
        self.names.push(name.to_string());
        self.index.insert(name.to_string(), i);
        i
    }
}

pub(super) fn parse(text: &str, file: &str) -> Result<ParsedObj, ModelError> {
    let err = |line: usize, message: String| ModelError {
        file: file.to_string(),
        line: Some(line),
        message,
    };
    let mut vertices: Vec<Point3<f64>> = Vec::new();
    let mut faces = Vec::new();
    let mut lines = Vec::new();
    // Positive indices may refer to vertices defined later in the file; they are checked at the
    // end, remembering the line that used them.
    let mut max_forward: Option<(u64, usize)> = None;
    let mut labels = Labels {
        names: vec![String::new()],
        index: HashMap::new(),
    };
    labels.index.insert(String::new(), 0);
    let (mut object, mut group, mut material) = (0u32, 0u32, 0u32);
    let mut stats = ModelStats::default();
    let mut face_count = 0u32;
    let mut continued = String::new();
    let mut continued_from = 0;

    for (number, raw_line) in text.lines().enumerate() {
        let number = number + 1;
        // A trailing backslash joins the next line (rare, but part of the format).
        let line: &str = if let Some(head) = raw_line.strip_suffix('\\') {
            if continued.is_empty() {
                continued_from = number;
            }
            continued.push_str(head);
            continued.push(' ');
            continue;
        } else if !continued.is_empty() {
            continued.push_str(raw_line);
            &continued
        } else {
            continued_from = number;
            raw_line
        };
        let at = continued_from;
        let content = line.split('#').next().unwrap_or("");
        let mut tokens = content.split_ascii_whitespace();
        let Some(keyword) = tokens.next() else {
            continued.clear();
            continue;
        };
        match keyword {
            "v" => {
                let mut xyz = [0.0; 3];
                for (k, c) in xyz.iter_mut().enumerate() {
                    let tok = tokens
                        .next()
                        .ok_or_else(|| err(at, format!("vertex needs 3 coordinates, found {k}")))?;
                    *c = tok
                        .parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| err(at, format!("vertex coordinate '{tok}' is not a finite number")))?;
                    if c.abs() > MAX_COORDINATE_M {
                        return Err(err(
                            at,
                            format!(
                                "vertex coordinate '{tok}' is beyond ±{MAX_COORDINATE_M:e} m (the model is in metres; \
                                 even a georeferenced one stays far inside this)"
                            ),
                        ));
                    }
                }
                vertices.push(Point3::from(xyz));
            }
            "f" | "l" => {
                let mut idx = Vec::new();
                for tok in tokens {
                    let first = tok.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(at, format!("'{tok}' is not a vertex index")))?;
                    let resolved = if i > 0 {
                        let i0 = (i - 1) as u64;
                        if i0 >= vertices.len() as u64 && max_forward.is_none_or(|(m, _)| i0 > m) {
                            max_forward = Some((i0, at));
                        }
                        i0
                    } else if i < 0 {
                        let r = vertices.len() as i64 + i;
                        if r < 0 {
                            return Err(err(
                                at,
                                format!(
                                    "relative index {i} reaches before the first vertex ({} defined so far)",
                                    vertices.len()
                                ),
                            ));
                        }
                        r as u64
                    } else {
                        return Err(err(at, "vertex index 0 is invalid (OBJ indices start at 1)".into()));
                    };
                    if resolved > u32::MAX as u64 {
                        return Err(err(at, format!("vertex index {i} is too large")));
                    }
                    idx.push(resolved as u32);
                }
                if keyword == "f" {
                    face_count += 1;
                    if idx.len() < 3 {
                        // A polygon with fewer than three corners has no area: skipped, counted.
                        stats.degenerate_faces += 1;
                    } else {
                        faces.push(RawFace {
                            vertices: idx,
                            obj_number: face_count,
                            object,
                            group,
                            material,
                        });
                    }
                } else {
                    if idx.len() < 2 {
                        return Err(err(
                            at,
                            format!("line record needs at least 2 vertices, found {}", idx.len()),
                        ));
                    }
                    lines.push(idx);
                }
            }
            "o" | "g" | "usemtl" => {
                let name = tokens.collect::<Vec<_>>().join(" ");
                let id = labels.intern(&name);
                match keyword {
                    "o" => object = id,
                    "g" => group = id,
                    _ => material = id,
                }
            }
            _ => stats.ignored_records += 1,
        }
        continued.clear();
    }
    if let Some((i0, at)) = max_forward {
        if i0 >= vertices.len() as u64 {
            return Err(err(
                at,
                format!(
                    "vertex index {} is beyond the {} vertices in the file",
                    i0 + 1,
                    vertices.len()
                ),
            ));
        }
    }
    Ok(ParsedObj {
        vertices,
        faces,
        lines,
        labels: labels.names,
        stats,
    })
}
