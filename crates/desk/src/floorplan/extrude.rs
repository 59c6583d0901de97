//! Extrusion proper: a [`FloorPlan`] in, OBJ text out. The walls laid out by `layout` become
//! vertical panels cut around their openings (plus tops, end caps and reveals for a thick wall),
//! every room a floor and a ceiling; the header counts what went in and came out.

use super::layout::{pieces, Laid, Layout};
use super::obj::ObjWriter;
use super::plan::{FloorPlan, Opening, OpeningKind, Wall};
use super::FloorPlanError;
use nalgebra::Point2;

/// An OBJ group name from a user's room name: no whitespace (OBJ splits on it), nothing exotic.
fn group_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

impl FloorPlan {
    /// Lays the plan out in 3D and writes it as OBJ text; `file` names the plan in the header and
    /// in error messages (the cross-feature checks: openings on walls, joins).
    pub fn to_obj(&self, file: &str) -> Result<String, FloorPlanError> {
        let layout = Layout {
            plan: self,
            file,
            pieces: self.walls.iter().map(pieces).collect(),
        };
        let laid = layout.lay_out()?;
        let mut obj = ObjWriter::new();
        for (wall, l) in self.walls.iter().zip(&laid) {
            self.emit_wall(&mut obj, wall, l);
        }
        for room in &self.rooms {
            let name = match &room.name {
                Some(n) if !n.trim().is_empty() => group_name(n.trim()),
                _ => room.feature.to_string(),
            };
            obj.label(&format!("room_{name}_floor"), "floor");
            obj.horizontal(&room.outline, room.floor_m, true);
            obj.label(&format!("room_{name}_ceiling"), "ceiling");
            obj.horizontal(&room.outline, room.ceiling_m, false);
        }
        if obj.degenerate > 0 {
            return Err(FloorPlanError {
                file: file.to_string(),
                place: String::new(),
                message: format!(
                    "extrusion produced {} degenerate faces (a bug in omnitrack's floor-plan \
                     code; please report it with this plan)",
                    obj.degenerate
                ),
            });
        }
        let count = |k| self.openings.iter().filter(|o| o.kind == k).count();
        let header = format!(
            "# Building model extruded from the floor plan {} by omnitrack::desk::floorplan.\n\
             # Metres, z up; faces counter-clockwise about their visible side. g = feature, usemtl = kind.\n\
             # {} walls, {} doors, {} windows, {} rooms: {} vertices, {} faces.\n",
            file.replace(['\n', '\r'], " "),
            self.walls.len(),
            count(OpeningKind::Door),
            count(OpeningKind::Window),
            self.rooms.len(),
            obj.vertices.len(),
            obj.faces
        );
        Ok(obj.finish(&header))
    }

    fn emit_wall(&self, obj: &mut ObjWriter, wall: &Wall, l: &Laid) {
        let h = wall.thickness_m / 2.0;
        let (z0, z1) = (wall.base_m, wall.base_m + wall.height_m);
        let thick = h > 0.0;
        let group = format!("wall_{}", wall.feature);
        let sides: &[f64] = if thick { &[1.0, -1.0] } else { &[1.0] };
        for (k, piece) in l.pieces.iter().enumerate() {
            let (j0, j1) = (l.joints[k], l.joints[(k + 1) % l.joints.len()]);
            let ops: Vec<(&Opening, f64, f64)> = l.openings[k]
                .iter()
                .map(|&(i, s0, s1)| (&self.openings[i], s0, s1))
                .collect();
            // Per side: the face's end points with every opening's two jamb points between.
            let column = |side: f64| -> Vec<Point2<f64>> {
                let base = piece.start + side * h * piece.n;
                let mut pts = vec![j0.side(side)];
                for &(_, s0, s1) in &ops {
                    pts.extend([base + s0 * piece.u, base + s1 * piece.u]);
                }
                pts.push(j1.side(side));
                pts
            };
            let columns: Vec<Vec<Point2<f64>>> = sides.iter().map(|&s| column(s)).collect();

            obj.label(&group, "wall");
            for (side, pts) in sides.iter().zip(&columns) {
                let visible = *side * piece.n;
                for (j, pair) in pts.windows(2).enumerate() {
                    let (a, b) = (pair[0], pair[1]);
                    if j % 2 == 0 {
                        obj.vertical(a, b, z0, z1, visible);
                    } else {
                        let o = ops[j / 2].0;
                        let (bottom, head) = o.span(z0, z1);
                        if bottom > z0 {
                            obj.vertical(a, b, z0, bottom, visible);
                        }
                        if head < z1 {
                            obj.vertical(a, b, head, z1, visible);
                        }
                    }
                }
            }
            if !thick {
                continue;
            }
            let (left, right) = (&columns[0], &columns[1]);
            // The top, broken only where an opening reaches it.
            let mut from = 0;
            for (j, (o, _, _)) in ops.iter().enumerate() {
                if o.span(z0, z1).1 == z1 {
                    obj.horizontal(&[left[from], left[2 * j + 1], right[2 * j + 1], right[from]], z1, true);
                    from = 2 * j + 2;
                }
            }
            let last = left.len() - 1;
            obj.horizontal(&[left[from], left[last], right[last], right[from]], z1, true);
            if k == 0 && j0.cap {
                obj.vertical(j0.left, j0.right, z0, z1, -piece.u);
            }
            if k == l.pieces.len() - 1 && j1.cap {
                obj.vertical(j1.left, j1.right, z0, z1, piece.u);
            }
            for (j, (o, _, _)) in ops.iter().enumerate() {
                let (bottom, head) = o.span(z0, z1);
                obj.label(
                    &format!("{}_{}", o.kind.name(), o.feature),
                    &format!("{}_reveal", o.kind.name()),
                );
                let (a, b) = (2 * j + 1, 2 * j + 2);
                obj.vertical(left[a], right[a], bottom, head, piece.u);
                obj.vertical(left[b], right[b], bottom, head, -piece.u);
                if head < z1 {
                    obj.horizontal(&[left[a], left[b], right[b], right[a]], head, false);
                }
                if bottom > z0 {
                    obj.horizontal(&[left[a], left[b], right[b], right[a]], bottom, true);
                }
                obj.label(&group, "wall");
            }
        }
    }
}
