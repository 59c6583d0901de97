//! What may be pinned instead of drawn: a `L,thin,cart`-style spec in, [`Choices`] out (or an
//! [`UnknownPin`] naming the word and what is allowed).

/// The building's outline over its grid of bays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outline {
    Rectangle,
    /// One corner block of bays missing.
    L,
    /// The middle columns of the back rows missing.
    U,
    /// The inner bays missing: a ring of rooms round an open court.
    Courtyard,
}

/// How walls are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallStyle {
    /// Every wall a single two-sided face (what many sketching tools export).
    Thin,
    /// Every wall a box 0.1–0.3 m thick.
    Thick,
    /// Exterior walls thick, interior walls single faces.
    ThickOutside,
}

/// Draws to pin instead of drawing them from the seed; `None` draws.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Choices {
    pub outline: Option<Outline>,
    pub walls: Option<WallStyle>,
    /// 1 or 2 (2 also needs a room long enough for the stair; otherwise the building has 1).
    pub storeys: Option<usize>,
    pub triangulated: Option<bool>,
    /// Fraction of faces wound the other way (default 0.5).
    pub flip_fraction: Option<f64>,
    /// Bays in x and y (each at least 3 and 2, and 3 × 3 for a courtyard); drawn as 3–5 × 2–4.
    pub bays: Option<[usize; 2]>,
    /// How the walk moves: `true` a cart at 1.2 m and 5 Hz, `false` hand-held at 10 Hz.
    pub cart: Option<bool>,
}

impl Choices {
    /// Reads `L,thin,cart`-style pins, comma-separated, any order: an outline (`rectangle`, `L`,
    /// `U`, `courtyard`), a wall style (`thin`, `thick`, `thick-outside`), `1-storey` or
    /// `2-storeys`, `triangles` or `quads`, `cart` or `hand-held`.
    pub fn parse(spec: &str) -> Result<Choices, UnknownPin> {
        let mut c = Choices::default();
        for word in spec.split(',').map(str::trim).filter(|w| !w.is_empty()) {
            match word.to_ascii_lowercase().as_str() {
                "rectangle" => c.outline = Some(Outline::Rectangle),
                "l" => c.outline = Some(Outline::L),
                "u" => c.outline = Some(Outline::U),
                "courtyard" => c.outline = Some(Outline::Courtyard),
                "thin" => c.walls = Some(WallStyle::Thin),
                "thick" => c.walls = Some(WallStyle::Thick),
                "thick-outside" => c.walls = Some(WallStyle::ThickOutside),
                "1-storey" => c.storeys = Some(1),
                "2-storeys" => c.storeys = Some(2),
                "triangles" => c.triangulated = Some(true),
                "quads" => c.triangulated = Some(false),
                "cart" => c.cart = Some(true),
                "hand-held" => c.cart = Some(false),
                _ => return Err(UnknownPin(word.to_string())),
            }
        }
        Ok(c)
    }
}

/// A word of a pin spec that pins nothing; displays what is allowed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown building pin {0:?}: expected rectangle, L, U, courtyard, thin, thick, thick-outside, 1-storey, \
     2-storeys, triangles, quads, cart or hand-held"
)]
pub struct UnknownPin(pub String);
