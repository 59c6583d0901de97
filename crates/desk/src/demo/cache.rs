//! Where the demo keeps its recording, table and pictures: the directory given, or the first
//! usable of the defaults, each refused with the reason (a directory that cannot be made or
//! written), and the name a scenario's recording is kept under.
//!
//! In: an optional directory, a scenario. Out: a usable cache directory and its description, or
//! every reason none was usable.

use super::*;

/// A directory that cannot serve as the cache.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("{}: cannot create directory: {source}", .dir.display())]
    Create { dir: PathBuf, source: std::io::Error },
    #[error("{}: not writable: {source}", .dir.display())]
    NotWritable { dir: PathBuf, source: std::io::Error },
}

pub(super) fn join(problems: &[CacheError]) -> String {
    problems.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
}

/// Where recordings and pictures are kept, and why there.
pub(super) fn choose_cache_dir(explicit: Option<&Path>) -> Result<(PathBuf, String), DemoError> {
    if let Some(dir) = explicit {
        prepare_cache(dir)?;
        return Ok((dir.to_path_buf(), "as given".into()));
    }
    let env = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(dir) = env("OMNITRACK_CACHE") {
        // An explicit setting that does not work is an error to report, not to paper over.
        prepare_cache(&dir).map_err(DemoError::CacheVariable)?;
        return Ok((dir, "$OMNITRACK_CACHE".into()));
    }
    let mut candidates: Vec<(PathBuf, String)> = Vec::new();
    if let Some(x) = env("XDG_CACHE_HOME").filter(|p| p.is_absolute()) {
        candidates.push((x.join("omnitrack"), "$XDG_CACHE_HOME/omnitrack".into()));
    }
    if cfg!(windows) {
        if let Some(l) = env("LOCALAPPDATA") {
            candidates.push((l.join("omnitrack"), "%LOCALAPPDATA%\\omnitrack".into()));
        }
    } else if let Some(home) = env("HOME") {
        if cfg!(target_os = "macos") {
            candidates.push((
                home.join("Library/Caches/omnitrack"),
                "~/Library/Caches/omnitrack".into(),
            ));
        } else {
            candidates.push((home.join(".cache/omnitrack"), "~/.cache/omnitrack".into()));
        }
    }
    // The workspace root (this crate is crates/desk of it).
    let tree = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).canonicalize();
    if let Ok(tree) = tree {
        candidates.push((
            tree.join("target/omnitrack-cache"),
            "no user cache directory: the source tree's target/".into(),
        ));
    }
    candidates.push((
        std::env::temp_dir().join("omnitrack-cache"),
        "no user cache directory: the temporary directory".into(),
    ));
    let mut problems = Vec::new();
    for (dir, why) in candidates {
        match prepare_cache(&dir) {
            Ok(()) => return Ok((dir, why)),
            Err(e) => problems.push(e),
        }
    }
    Err(DemoError::NoCache { tried: problems })
}

/// Creates `dir` and checks it is writable by writing its cache tag, which also keeps backup
/// tools out of it (https://bford.info/cachedir/).
fn prepare_cache(dir: &Path) -> Result<(), CacheError> {
    create_dir(dir)?;
    std::fs::write(
        dir.join("CACHEDIR.TAG"),
        "Signature: 8a477f597d28d172789f06886806bc55\n# omnitrack cache: the demo's recordings, tables and pictures, the desk tools' IfcOpenShell\n",
    )
    .map_err(|source| CacheError::NotWritable {
        dir: dir.to_path_buf(),
        source,
    })
}

pub(super) fn create_dir(dir: &Path) -> Result<(), CacheError> {
    std::fs::create_dir_all(dir).map_err(|source| CacheError::Create {
        dir: dir.to_path_buf(),
        source,
    })
}

/// The cache label of a scenario: its own plan if it is not the built-in one of its name, so
/// that two different buildings never share a recording.
pub(super) fn cache_label(scenario: &Scenario) -> String {
    if scenario.geojson == Scenario::get(scenario.name).geojson {
        return "default".into();
    }
    // FNV-1a: stable across runs and platforms, unlike the std hasher.
    let hash = scenario.geojson.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    });
    format!("plan{hash:016x}")
}
