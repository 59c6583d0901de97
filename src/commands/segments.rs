//! `omnitrack segments`: the model segments of an OBJ as CSV, x1,y1,z1,x2,y2,z2,faces (OBJ face
//! numbers, space-separated; empty for a free `l` segment).

use super::CommandResult;
use omnitrack::Model;
use std::io::Write;
use std::path::PathBuf;

/// `segments`' arguments.
#[derive(clap::Args)]
pub struct Args {
    /// The building model.
    #[arg(long, value_name = "MODEL.obj")]
    model: PathBuf,
}

pub fn run(Args { model }: Args) -> CommandResult {
    let m = Model::load(&model)?;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let write = |out: &mut std::io::BufWriter<_>| -> std::io::Result<()> {
        writeln!(out, "x1,y1,z1,x2,y2,z2,faces")?;
        for s in &m.segments {
            let faces: Vec<String> = s
                .faces
                .iter()
                .map(|&f| m.faces[f as usize].obj_number.to_string())
                .collect();
            writeln!(
                out,
                "{},{},{},{},{},{},{}",
                s.a.x,
                s.a.y,
                s.a.z,
                s.b.x,
                s.b.y,
                s.b.z,
                faces.join(" ")
            )?;
        }
        out.flush()
    };
    write(&mut out).map_err(super::stdout_error)?;
    Ok(())
}
