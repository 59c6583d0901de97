//! Edge and hue extraction for the rig's sensors (Koch–Teller §4.2, §4.2.1).
//!
//! In: a [`FrameSet`](omnitrack_core::FrameSet) (one RGB8 image per sensor). Out: per sensor, at
//! most `EdgeConfig::max_edges_per_sensor` [`Edge`]s (the strongest), each the plane through its
//! sensor's optical centre that contains a straight 3D edge (rig frame), its pixel and ray end
//! points, angular length, strength, [`HueSignature`] and gaps (where merging bridged
//! collinear pieces that the image does not join).
//!
//! Per sensor: per colour channel, integer Sobel gradients on the channel smoothed along the
//! derivative's cross axis only (3 px wide across an edge, so a door or window reveal's two edges
//! 2–3 px apart stay apart), the strongest channel kept per pixel → non-maximum suppression →
//! edgels linked into chains (direction within ~50°) → sub-pixel edgels (Gaussian peak: parabola
//! through the log magnitudes across the gradient) unprojected to unit rays through a per-pixel
//! ray table built at start-up → planes fitted to the rays (smallest eigenvector of Σ w r rᵀ, w
//! the gradient magnitude; outliers beyond 2.5 RMS refitted out), chains split where they bend off
//! a great circle or where two planes fit a piece far better than one (two lines a pixel or two
//! apart, end to end or side by side), and neighbouring collinear pieces merged, also across
//! chains (short pieces' normals are loose, so candidates within 5° are tried; the merged fit
//! decides, under the same two-line test) → hue strips on both sides. Fisheye curvature costs
//! nothing: rays, not pixels, are fitted.
//!
//! Memory is fixed: every buffer is sized in [`EdgeDetector::new`] from the rig (resolution) and
//! the [`EdgeConfig`](omnitrack_config::EdgeConfig) (edges per sensor) and written through there
//! (`omnitrack_core::memory::resident`); [`EdgeDetector::detect`] allocates nothing, nor takes
//! memory the detector did not hold from the start. Sensors are
//! spread over a persistent pool of worker threads (the calling thread works too) fed through
//! bounded crossbeam channels.
//!
//! Files, each importing only those before it: `hue.rs` (hue signatures), `params.rs`
//! ([`EdgeParams`]), `edge.rs` (the [`Edge`] handed on), `gradient.rs` and `contrario.rs` (the
//! pixel pass and the a-contrario test), `sensor.rs` with `sensor/` (one sensor's extraction),
//! `detector.rs` (the [`EdgeDetector`] and its workers), `csv.rs` (the `omnitrack edges` CSV) and
//! `cpu.rs` (the thread CPU clock the phases and [`EdgeDetector::last_cpu`] are timed with).
//!
//! A bright square on a dark image from one 50° pinhole gives its four sides:
//!
//! ```
//! use omnitrack_config::EdgeConfig;
//! use omnitrack_core::{FrameSet, Rig};
//! use omnitrack_edges::EdgeDetector;
//!
//! let rig = Rig::from_toml_str(
//!     "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
//!      intrinsics = [686.0, 686.0, 319.5, 239.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
//!      translation_m = [0.0, 0.0, 0.0]\n",
//!     "one.toml",
//! )?;
//! let mut frame = FrameSet::for_rig(&rig);
//! let image = frame.sensor_mut(0);
//! for (k, px) in image.pixels_mut().chunks_mut(3).enumerate() {
//!     let (x, y) = (k % 640, k / 640);
//!     let inside = (220..420).contains(&x) && (140..340).contains(&y);
//!     px.fill(if inside { 230 } else { 20 });
//! }
//! image.timestamp_ns = 1;
//! image.valid = true;
//! let mut detector = EdgeDetector::new(&rig, &EdgeConfig::default());
//! let edges = detector.detect(&frame);
//! // The square's sides, each about 200 px (16°) long.
//! let long: Vec<_> = edges.iter().filter(|e| e.length_rad > 0.2).collect();
//! assert_eq!(long.len(), 4, "{edges:?}");
//! # Ok::<(), omnitrack_core::rig::RigError>(())
//! ```

mod contrario;
mod cpu;
mod csv;
mod detector;
mod edge;
mod gradient;
mod hue;
mod params;
mod sensor;

pub use cpu::thread_cpu_time;
pub use csv::{edges_csv, edges_csv_for_image, EdgesCsvError, EDGES_CSV_HEADER};
pub use detector::{warm_up_blocking, EdgeDetector};
pub use edge::{Edge, MAX_GAPS};
pub use hue::{hue_of, HueSignature};
pub use params::{EdgeParams, Smoothing};
pub use sensor::ExtractionStats;
