//! `omnitrack pose`: one pose T_world_rig from line correspondences, printed as the JSON object
//! of docs/interfaces.md.

use super::CommandResult;
use omnitrack::config::TrackerConfig;
use omnitrack::solver::{self, Method};
use omnitrack::Rig;
use std::path::PathBuf;

/// `pose`'s arguments.
#[derive(clap::Args)]
pub struct Args {
    /// The rig whose sensors the lines' image end points belong to.
    #[arg(long, value_name = "RIG.toml")]
    rig: PathBuf,
    /// CSV with header sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2.
    #[arg(long, value_name = "FILE.csv")]
    lines: PathBuf,
    /// Solver: Kumar–Hanson's R_and_T, R_then_T or Med_R_and_T (lms), or the ξ simplex (xi).
    #[arg(long, default_value = "r_and_t", value_parser = method_parser())]
    method: Method,
    /// Starting pose tx,ty,tz,qw,qx,qy,qz (without it the solvers search rotation space).
    #[arg(long, value_name = "tx,ty,tz,qw,qx,qy,qz", allow_hyphen_values = true)]
    guess: Option<String>,
    /// Tracker config whose [solver] and [noise] tunables to use (default: the papers' values).
    #[arg(long, value_name = "tracker.toml")]
    config: Option<PathBuf>,
}

/// `--method`: the solver's own names, listed in the help.
fn method_parser() -> impl clap::builder::TypedValueParser<Value = Method> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Method::ALL.map(Method::name))
        .map(|name| name.parse::<Method>().expect("a listed name"))
}

pub fn run(
    Args {
        rig,
        lines,
        method,
        guess,
        config,
    }: Args,
) -> CommandResult {
    let guess = guess.as_deref().map(parse_guess).transpose()?;
    let rig = Rig::load(&rig)?;
    let options = omnitrack::solver::SolverOptions {
        // The rig's pixel: Med_R_and_T judges no line an outlier on a scale finer than this.
        pixel_rad: rig
            .sensors
            .iter()
            .map(|s| 1.0 / s.lens.fx().min(s.lens.fy()))
            .fold(0.0, f64::max),
        ..match config {
            Some(path) => TrackerConfig::load(&path)?.solver_options(),
            None => TrackerConfig::default().solver_options(),
        }
    };
    let name = lines.display().to_string();
    let text = omnitrack::text_file::read_text(&lines, omnitrack::text_file::LARGE_FILE_LIMIT)
        .map_err(|e| format!("{name}: cannot read: {e}"))?;
    let correspondences = omnitrack::lines::parse_lines(&text, &name, &rig)?;
    let solution = solver::solve(method, &correspondences, guess.as_ref(), &options, 0)
        .map_err(|e| format!("{name}: no pose: {e}"))?;
    super::print_line(&pose_json(&solution))?;
    Ok(())
}

/// `tx,ty,tz,qw,qx,qy,qz` (the order of docs/interfaces.md) to a pose.
fn parse_guess(text: &str) -> Result<omnitrack::Pose, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|f| f.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("--guess '{text}': expected 7 finite numbers tx,ty,tz,qw,qx,qy,qz"))?;
    if v.len() != 7 {
        return Err(format!(
            "--guess '{text}': expected 7 numbers tx,ty,tz,qw,qx,qy,qz, found {}",
            v.len()
        ));
    }
    omnitrack::geometry::pose_from_parts([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]])
        .map_err(|e| format!("--guess '{text}': {e}"))
}

/// A JSON number; JSON has no NaN or infinity, so those become null.
fn json_number(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}")
    } else {
        "null".into()
    }
}

/// The JSON object docs/interfaces.md specifies for `omnitrack pose`.
fn pose_json(s: &solver::Solution) -> String {
    let list = |xs: &mut dyn Iterator<Item = f64>| xs.map(json_number).collect::<Vec<_>>().join(",");
    let t = s.pose.translation.vector;
    let q = omnitrack::geometry::rotation_to_wxyz(&s.pose.rotation);
    let inliers: Vec<String> = s.inliers.iter().map(|i| i.to_string()).collect();
    format!(
        "{{\"position\":[{}],\"rotation_wxyz\":[{}],\"covariance\":[{}],\"inliers\":[{}],\"xi_rad2\":{},\"iterations\":{}}}",
        list(&mut t.iter().copied()),
        list(&mut q.iter().copied()),
        list(&mut s.covariance.transpose().iter().copied()),
        inliers.join(","),
        json_number(s.xi_rad2),
        s.iterations
    )
}
