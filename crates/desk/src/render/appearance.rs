//! What the synthetic images look like: the [`Appearance`] switches and the small deterministic
//! hash, noise and colour helpers behind them.

/// Every image effect of the renderer, each a level that is off at 0 so that a benchmark can
/// sweep it. `Default` is a moderate setting, the one the tracker's synthetic figures were
/// measured on; [`Appearance::realistic`] adds what real furnished rooms and cameras show (issue
/// 19), tuned so that the edges at the true pose resemble those of real photos;
/// [`Appearance::plain`] turns every effect off (flat, distinct surface colours only).
#[derive(Debug, Clone, PartialEq)]
pub struct Appearance {
    /// Seeds every random choice (colours, texture, lights, clutter, people, noise).
    pub seed: u64,
    /// Saturation of the surface colours, 0 = grey levels only, 1 = default. Hues are spread
    /// over surfaces by the golden ratio; brightness also differs per surface, so even at 0
    /// neighbouring surfaces differ.
    pub colour: f64,
    /// Amplitude of the procedural surface texture (two octaves of value noise, ~35 cm and
    /// ~9 cm), as a fraction of brightness. 0 = flat.
    pub texture: f64,
    /// Mix between flat colour (0) and the full light model (1): ambient, a headlamp term with
    /// distance and incidence-angle falloff, and `lights` point lights.
    pub shading: f64,
    /// Point lights placed deterministically near the ceiling inside the model's bounds.
    pub lights: u32,
    /// Standard deviation of the additive sensor noise, in 8-bit grey levels. 0 = none.
    pub noise: f64,
    /// Brightness lost at the corner of the image (quadratic in the off-axis angle). 0 = none.
    pub vignetting: f64,
    /// Fraction of the frame interval the shutter is open; sub-frame poses are spread over the
    /// end of the interval from the previous to the current pose. 0 = no motion blur.
    pub motion_blur: f64,
    /// Sub-frame renders averaged when `motion_blur > 0` (cost scales with it).
    pub motion_blur_samples: u32,
    /// Rays per pixel along each axis, on a regular grid over the pixel's area, averaged: a
    /// real pixel integrates the light falling on it, so an edge crossing it gives a value in
    /// between (what sub-pixel edge location relies on). 1 = one ray through the pixel centre
    /// (aliased edges); cost scales with its square.
    pub pixel_samples: u32,
    /// Amplitude of the global lighting drift over time: brightness varies by about ±this,
    /// white balance by about ±0.4× this per channel, as smooth functions of time. 0 = none.
    pub lighting_drift: f64,
    /// Clutter not in the model (furniture boxes on the floor, shelves against walls, posters on
    /// walls); 1 = about one furniture box per 12 m² of floor, one shelf per 25 m², one poster
    /// per 10 m². 0 = none.
    pub clutter: f64,
    /// Transient occluders: people (capsules) walking back and forth on straight paths;
    /// 1 = about one person per 40 m² of floor. 0 = none.
    pub people: f64,

    // The levels below imitate what real furnished rooms show and the model lacks (issue 19:
    // on real 360° photos only ~61 % of the segments in sight find an edge and ~22 of the 40
    // strongest edges lie on the model). `Default` keeps them all at 0 so that the recordings
    // and figures made before they existed stay valid; [`Appearance::realistic`] turns them on.
    /// Share (0–1) of each model surface's own colour given up for one paint per kind (walls
    /// and reveals off-white, ceilings white, floors one wood tone). Default colours every
    /// surface apart, so every model line is a strong colour edge; in real houses neighbouring
    /// walls and the ceiling share one paint and a corner shows only as a change of shading.
    /// Furniture and shelves lose 0.7× this of their saturation (real furnishings are mostly
    /// wood, grey and beige). 0 = distinct colours.
    pub paint: f64,
    /// Directional floor patterns, as a contrast level: floorboards (long strips ~14 cm wide
    /// with dark seams, staggered board ends and grain along them) or, on some floors, tiles with
    /// grout lines; plus rugs (flat rectangles of another colour) at about one per 25 m² × level.
    /// Real floors give long, strong, parallel edges that run along the building's own axes,
    /// the worst kind of distractor for a line tracker. 0 = the plain value-noise floor.
    pub floor_pattern: f64,
    /// Structured texture on clutter and fixtures, as a contrast level: wood grain streaks on
    /// furniture, shelves, cabinets and doors, and stripes on posters. Real furniture is not
    /// flat-coloured; its grain and panel lines make short strong edges. 0 = none.
    pub clutter_texture: f64,
    /// Trims the model does not draw, as a size factor (1 = real sizes): casings 7 cm wide
    /// protruding 1.5 cm around every opening of the model's walls, found from the model's
    /// geometry (any OBJ), a sill under windows, and baseboards 8 cm high along the foot of the
    /// walls. Real trims add two or three parallel edges a few cm from each model line and often
    /// hide the line itself. 0 = none.
    pub trims: f64,
    /// Built-in cabinets and counters against walls (base units 88 cm high and 60 cm deep with a
    /// worktop and door seams, often wall units above): about one per 20 m² of floor × level.
    /// In real kitchens and studies they hide the floor–wall line over metres and bring strong
    /// horizontal edges the model lacks. 0 = none.
    pub built_ins: f64,
    /// Fraction (0–1) of the door-sized openings (reaching the floor) closed by a door slab,
    /// flush with the wall or recessed up to 4 cm, with a handle. Models draw doors as openings;
    /// in photos many are shut, so the reveal lines vanish and the room behind is hidden.
    /// Openings the trajectory passes through stay open. 0 = all open.
    pub closed_doors: f64,
    /// Fraction (0–1) of the window openings with a blind (horizontal slats, 2.5 cm pitch)
    /// lowered over part of the window. Real blinds give dozens of strong parallel edges.
    pub blinds: f64,
    /// Largest displacement (metres) of each vertical model plane along its normal in the
    /// rendered world, a seeded random offset per plane in [−this, this]: real walls are built a
    /// few cm off the drawing. Vertices where planes meet move so that every plane keeps its
    /// offset (the mesh stays closed). The model given to the tracker is unchanged. 0 = none.
    pub wall_offset_m: f64,
    /// JPEG quality (1–100) each rendered image is encoded at and decoded from before it leaves
    /// the renderer: real cameras and photo sets deliver JPEG, whose 8×8 blocks and ringing
    /// make weak false edges and blur weak true ones. 0 = no JPEG.
    pub jpeg_quality: u8,
    /// Mix (0–1) of a cos⁴ falloff into the vignetting, cos⁴ of the off-axis angle scaled so
    /// that the lens's largest angle maps to 60° (6 % there): the natural falloff of a real
    /// lens, steeper towards the edge than the quadratic `vignetting`. 0 = none.
    pub lens_falloff: f64,
    /// Standard deviation (pixels) of a Gaussian blur over the finished image: a real lens and
    /// the Bayer demosaicing soften edges over a pixel or two, so weak edges (two walls of one
    /// paint meeting) fade into noise where a ray-traced pixel keeps them sharp. 0 = none.
    pub blur_px: f64,
}

impl Default for Appearance {
    fn default() -> Self {
        Appearance {
            seed: 1,
            colour: 1.0,
            texture: 0.06,
            shading: 1.0,
            lights: 4,
            noise: 2.0,
            vignetting: 0.3,
            motion_blur: 0.0,
            motion_blur_samples: 4,
            pixel_samples: 1,
            lighting_drift: 0.1,
            clutter: 1.0,
            people: 1.0,
            paint: 0.0,
            floor_pattern: 0.0,
            clutter_texture: 0.0,
            trims: 0.0,
            built_ins: 0.0,
            closed_doors: 0.0,
            blinds: 0.0,
            wall_offset_m: 0.0,
            jpeg_quality: 0,
            lens_falloff: 0.0,
            blur_px: 0.0,
        }
    }
}

/// A spec [`Appearance::from_spec`] cannot read; displays as one line starting with the spec.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SpecError {
    #[error("{spec}: {preset:?} is not default, realistic or plain")]
    UnknownPreset { spec: String, preset: String },
    #[error("{spec}: {part:?} is not field=value")]
    NotFieldValue { spec: String, part: String },
    #[error("{spec}: {value:?} is not a number")]
    NotANumber { spec: String, value: String },
    /// Negative or not finite: every level is off at 0 and grows from there.
    #[error("{spec}: {field} = {value} is not a level (finite, 0 or more)")]
    NotALevel { spec: String, field: String, value: String },
    #[error("{spec}: no level {field:?}")]
    UnknownLevel { spec: String, field: String },
}

impl Appearance {
    /// Every effect off: distinct flat surface colours, nothing else.
    pub fn plain() -> Self {
        Appearance {
            seed: 1,
            colour: 1.0,
            texture: 0.0,
            shading: 0.0,
            lights: 0,
            noise: 0.0,
            vignetting: 0.0,
            motion_blur: 0.0,
            motion_blur_samples: 1,
            pixel_samples: 1,
            lighting_drift: 0.0,
            clutter: 0.0,
            people: 0.0,
            // The realism levels are off in `Default` already.
            ..Appearance::default()
        }
    }

    /// `Default` plus everything real furnished rooms show that the model lacks, at levels
    /// meant to make a render as hard for the tracker as the real photos (issue 19; docs/real-photos.md
    /// has what it measures against them). Why each level:
    pub fn realistic() -> Self {
        Appearance {
            // Walls and ceilings mostly one paint, as in the real house; what is left of the
            // distinct colours stands for the real differences of light between walls. (0.8:
            // at 0.9 and above the model's lines grow too weak beside the clutter's, below 0.7
            // too strong, against the photos' ~22 of 40 strongest edges on the model.)
            paint: 0.8,
            // Floorboards or tiles at full contrast: real seams are dark and continuous.
            floor_pattern: 1.0,
            // Grain and stripes clearly visible but weaker than the surface edges, as on real
            // veneer and prints.
            clutter_texture: 1.0,
            // Real sizes: casings 7 cm × 1.5 cm, baseboards 8 cm.
            trims: 1.0,
            // About one cabinet run per 20 m²: a kitchen and a study's worth in a flat.
            built_ins: 1.0,
            // Half the doors shut, as in the real tour's photos.
            closed_doors: 0.5,
            // Most windows of a lived-in house have blinds or shades.
            blinds: 0.7,
            // Built walls are within a few cm of the plan; 3 cm is a typical as-built tolerance.
            wall_offset_m: 0.03,
            // A typical camera's default quality.
            jpeg_quality: 85,
            // Real wide lenses lose about a stop towards the edge of the field.
            lens_falloff: 0.5,
            // A real lens and demosaicing soften edges over 1–2 px; this is what most brings the
            // share of segments with an edge down from ~0.8 towards the photos' 0.61.
            blur_px: 1.5,
            // Indoor light is dim: more sensor noise than Default's 2 grey levels.
            noise: 3.0,
            // Twice the texture of Default: real walls and floors carry stains, light gradients
            // and sun patches that the value noise stands in for.
            texture: 0.12,
            ..Appearance::default()
        }
    }

    /// An appearance from a spec: `default`, `realistic` or `plain`, then any `+field=value`
    /// overrides of its levels (`realistic+blur_px=0+trims=0`), so that a bench can take one
    /// effect out of a preset and see what it did.
    pub fn from_spec(spec: &str) -> Result<Appearance, SpecError> {
        let mut parts = spec.split('+');
        let mut a = match parts.next().unwrap_or_default() {
            "default" => Appearance::default(),
            "realistic" => Appearance::realistic(),
            "plain" => Appearance::plain(),
            other => {
                return Err(SpecError::UnknownPreset {
                    spec: spec.to_string(),
                    preset: other.to_string(),
                })
            }
        };
        for part in parts {
            let (field, v) = part.split_once('=').ok_or_else(|| SpecError::NotFieldValue {
                spec: spec.to_string(),
                part: part.to_string(),
            })?;
            let x: f64 = v.parse().map_err(|_| SpecError::NotANumber {
                spec: spec.to_string(),
                value: v.to_string(),
            })?;
            // Every level is off at 0 and grows from there: a negative or non-finite one would
            // render nonsense (or, as a blur radius, never finish).
            if !(x.is_finite() && x >= 0.0) {
                return Err(SpecError::NotALevel {
                    spec: spec.to_string(),
                    field: field.to_string(),
                    value: v.to_string(),
                });
            }
            let level = match field {
                "seed" => {
                    a.seed = x as u64;
                    continue;
                }
                "lights" => {
                    a.lights = x as u32;
                    continue;
                }
                "jpeg_quality" => {
                    a.jpeg_quality = x.clamp(0.0, 100.0) as u8;
                    continue;
                }
                "colour" => &mut a.colour,
                "texture" => &mut a.texture,
                "shading" => &mut a.shading,
                "noise" => &mut a.noise,
                "vignetting" => &mut a.vignetting,
                "lighting_drift" => &mut a.lighting_drift,
                "clutter" => &mut a.clutter,
                "people" => &mut a.people,
                "paint" => &mut a.paint,
                "floor_pattern" => &mut a.floor_pattern,
                "clutter_texture" => &mut a.clutter_texture,
                "trims" => &mut a.trims,
                "built_ins" => &mut a.built_ins,
                "closed_doors" => &mut a.closed_doors,
                "blinds" => &mut a.blinds,
                "wall_offset_m" => &mut a.wall_offset_m,
                "lens_falloff" => &mut a.lens_falloff,
                "blur_px" => &mut a.blur_px,
                _ => {
                    return Err(SpecError::UnknownLevel {
                        spec: spec.to_string(),
                        field: field.to_string(),
                    })
                }
            };
            *level = x;
        }
        Ok(a)
    }

    /// Whether motion blur takes several sub-frame samples.
    pub fn blur_samples(&self) -> u32 {
        if self.motion_blur > 0.0 {
            self.motion_blur_samples.max(1)
        } else {
            1
        }
    }

    /// Global brightness and per-channel white-balance gain at time `t_s` (seconds).
    pub fn drift_gain(&self, t_s: f64) -> [f32; 3] {
        let a = self.lighting_drift;
        if a == 0.0 {
            return [1.0; 3];
        }
        let ph = |k: u64| (hash64(self.seed ^ 0xD1F7 ^ k) as f64 / u64::MAX as f64) * std::f64::consts::TAU;
        let w = |period_s: f64| std::f64::consts::TAU / period_s;
        let brightness = 1.0 + a * (0.7 * (w(17.0) * t_s + ph(0)).sin() + 0.3 * (w(6.1) * t_s + ph(1)).sin());
        let mut g = [0.0f32; 3];
        for (c, gc) in g.iter_mut().enumerate() {
            let wb = 1.0 + 0.4 * a * (w(23.0 + 7.0 * c as f64) * t_s + ph(2 + c as u64)).sin();
            *gc = (brightness * wb).max(0.0) as f32;
        }
        g
    }
}

/// SplitMix64 finaliser: a good 64-bit mix.
#[inline]
pub fn hash64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// A tiny deterministic generator (SplitMix64 stream) for desk decisions (placement, tours):
/// streams must stay reproducible from a seed across versions of any crate, which a
/// general-purpose generator does not promise.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(hash64(seed))
    }
    /// A stream starting from a raw state (no seed mixing).
    pub fn from_state(state: u64) -> Rng {
        Rng(state)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        hash64(self.0)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

#[inline]
fn hash32(x: u32) -> u32 {
    let mut x = x;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^ (x >> 16)
}

#[inline]
fn lattice(ix: i32, iy: i32, iz: i32, seed: u32) -> f32 {
    let h = hash32(
        (ix as u32).wrapping_mul(0x8DA6_B343)
            ^ (iy as u32).wrapping_mul(0xD816_3841)
            ^ (iz as u32).wrapping_mul(0xCB1A_B31F)
            ^ seed,
    );
    (h >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Smooth 3D value noise in [0, 1].
#[inline]
pub fn value_noise(p: [f32; 3], seed: u32) -> f32 {
    let f = [p[0].floor(), p[1].floor(), p[2].floor()];
    let (ix, iy, iz) = (f[0] as i32, f[1] as i32, f[2] as i32);
    let s = |x: f32| x * x * (3.0 - 2.0 * x);
    let (u, v, w) = (s(p[0] - f[0]), s(p[1] - f[1]), s(p[2] - f[2]));
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let c = |dx: i32, dy: i32, dz: i32| lattice(ix + dx, iy + dy, iz + dz, seed);
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), u);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), u);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), u);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Approximately standard-normal noise from a 64-bit hash (sum of four 16-bit uniforms).
#[inline]
pub fn gaussian_from_hash(h: u64) -> f32 {
    let s = (h & 0xFFFF) + ((h >> 16) & 0xFFFF) + ((h >> 32) & 0xFFFF) + (h >> 48);
    // Mean 2·65535, variance 4·65536²/12.
    (s as f32 - 131_070.0) * (1.0 / 37_837.2)
}

/// HSV (all in [0, 1]) to linear RGB in [0, 1].
pub fn hsv(h: f64, s: f64, v: f64) -> [f32; 3] {
    let h = h.rem_euclid(1.0) * 6.0;
    let i = h.floor();
    let f = h - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match i as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r as f32, g as f32, b as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_name_a_preset_and_override_its_levels() {
        assert_eq!(Appearance::from_spec("default"), Ok(Appearance::default()));
        let a = Appearance::from_spec("realistic+blur_px=0+trims=0.5+jpeg_quality=70").unwrap();
        assert_eq!(
            a,
            Appearance {
                blur_px: 0.0,
                trims: 0.5,
                jpeg_quality: 70,
                ..Appearance::realistic()
            }
        );
        assert!(Appearance::from_spec("shiny").is_err());
        assert!(Appearance::from_spec("plain+trims").is_err());
        assert!(Appearance::from_spec("plain+glow=1").is_err());
        assert!(Appearance::from_spec("plain+trims=x").is_err());
        assert!(Appearance::from_spec("plain+trims=-1").is_err());
        assert!(Appearance::from_spec("plain+blur_px=inf").is_err());
        assert!(Appearance::from_spec("plain+noise=NaN").is_err());
    }
}
