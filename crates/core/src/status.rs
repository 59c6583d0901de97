//! The tracker's status vocabulary, defined once: the state it is in ([`TrackerState`]), the
//! search it is waiting for ([`SearchKind`]) and what its last search made of its volume
//! ([`SearchState`]). The tracker speaks these words, the pose and status messages carry their
//! codes (docs/interfaces.md, "Pose service" and "Status service"), and `omnitrack listen`
//! prints their words.
//!
//! In: nothing (plain data). Out: each value's wire code (`u8`), the value of a code (an unknown
//! code is returned as the error), and its word.
//!
//! ```
//! use omnitrack_core::status::{SearchKind, TrackerState};
//!
//! assert_eq!(u8::from(TrackerState::Lost), 2);
//! assert_eq!(TrackerState::try_from(0), Ok(TrackerState::Initialising));
//! assert_eq!(TrackerState::Initialising.to_string(), "initializing");
//! assert_eq!(TrackerState::try_from(7), Err(7));
//! // No search under way is code 0 on the wire.
//! assert_eq!(SearchKind::wire(None), 0);
//! assert_eq!(SearchKind::from_wire(2), Ok(Some(SearchKind::Relocalisation)));
//! ```

use std::fmt;

/// Where the tracker is: the `status` of a pose sample and the `tracker_state` of a status
/// sample. The contract's words are American ("initializing"); the code's are the project's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum TrackerState {
    /// No pose yet: searching the initial volume (the hint, or the whole model).
    Initialising = 0,
    /// Tracking: the pose is the tracker's current estimate.
    Tracking = 1,
    /// Tracking was lost (or this frame got no pose): a search is under way, and the pose
    /// service repeats the last good pose.
    Lost = 2,
}

impl TrackerState {
    /// The word of `omnitrack listen` and the contract: `initializing`, `tracking`, `lost`.
    pub fn as_str(self) -> &'static str {
        match self {
            TrackerState::Initialising => "initializing",
            TrackerState::Tracking => "tracking",
            TrackerState::Lost => "lost",
        }
    }
}

impl From<TrackerState> for u8 {
    fn from(s: TrackerState) -> u8 {
        s as u8
    }
}

impl TryFrom<u8> for TrackerState {
    /// The byte that is not a known state.
    type Error = u8;

    fn try_from(v: u8) -> Result<Self, u8> {
        match v {
            0 => Ok(TrackerState::Initialising),
            1 => Ok(TrackerState::Tracking),
            2 => Ok(TrackerState::Lost),
            other => Err(other),
        }
    }
}

impl fmt::Display for TrackerState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A search the tracker runs off the frame path: while one runs, frames get no pose of their
/// own. On the wire (`searching` of a status sample) `None` is code 0 ([`SearchKind::wire`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum SearchKind {
    /// The first search for a pose: the hint's volume, or the whole model.
    Initialisation = 1,
    /// The motion prior failed on a frame: a local search about the last good pose.
    Relocalisation = 2,
    /// Tracking was lost: a search of a volume that grows with every failed attempt.
    Reinitialisation = 3,
}

impl SearchKind {
    /// The word of `omnitrack listen --status`: `initialising`, `relocalising`,
    /// `reinitialising` (and `none` for no search, [`SearchKind::word`]).
    pub fn as_str(self) -> &'static str {
        match self {
            SearchKind::Initialisation => "initialising",
            SearchKind::Relocalisation => "relocalising",
            SearchKind::Reinitialisation => "reinitialising",
        }
    }

    /// The word of a search under way or of none.
    pub fn word(kind: Option<SearchKind>) -> &'static str {
        kind.map_or("none", SearchKind::as_str)
    }

    /// The wire code of a search under way, 0 for none.
    pub fn wire(kind: Option<SearchKind>) -> u8 {
        kind.map_or(0, |k| k as u8)
    }

    /// The search under way a wire code stands for (`None` for 0); an unknown code is the error.
    pub fn from_wire(v: u8) -> Result<Option<SearchKind>, u8> {
        match v {
            0 => Ok(None),
            1 => Ok(Some(SearchKind::Initialisation)),
            2 => Ok(Some(SearchKind::Relocalisation)),
            3 => Ok(Some(SearchKind::Reinitialisation)),
            other => Err(other),
        }
    }
}

impl fmt::Display for SearchKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What the tracker's last search for a pose made of its volume (`search` of a status sample):
/// why a tracker that publishes no pose has none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum SearchState {
    /// No search since start (or the tracker has tracked since its last one).
    None = 0,
    /// The last search covered the volume it was given (the hint, or the whole model).
    AsGiven = 1,
    /// The volume held no valid visibility node: the last search went out to the nearest ones
    /// (the status sample's `search_widened_to_m` says how far).
    Widened = 2,
    /// The last search had no cell at all to search (a model without valid nodes).
    NoCells = 3,
}

impl SearchState {
    /// The word of `omnitrack listen --status`: `none`, `as_given`, `widened`, `no_cells`.
    pub fn as_str(self) -> &'static str {
        match self {
            SearchState::None => "none",
            SearchState::AsGiven => "as_given",
            SearchState::Widened => "widened",
            SearchState::NoCells => "no_cells",
        }
    }
}

impl From<SearchState> for u8 {
    fn from(s: SearchState) -> u8 {
        s as u8
    }
}

impl TryFrom<u8> for SearchState {
    /// The byte that is not a known search state.
    type Error = u8;

    fn try_from(v: u8) -> Result<Self, u8> {
        match v {
            0 => Ok(SearchState::None),
            1 => Ok(SearchState::AsGiven),
            2 => Ok(SearchState::Widened),
            3 => Ok(SearchState::NoCells),
            other => Err(other),
        }
    }
}

impl fmt::Display for SearchState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every code round-trips, and the codes are the contract's (docs/interfaces.md).
    #[test]
    fn every_code_round_trips_and_unknown_codes_are_refused() {
        for s in [TrackerState::Initialising, TrackerState::Tracking, TrackerState::Lost] {
            assert_eq!(TrackerState::try_from(u8::from(s)), Ok(s));
        }
        assert_eq!(
            [TrackerState::Initialising, TrackerState::Tracking, TrackerState::Lost].map(u8::from),
            [0, 1, 2]
        );
        for k in [
            None,
            Some(SearchKind::Initialisation),
            Some(SearchKind::Relocalisation),
            Some(SearchKind::Reinitialisation),
        ] {
            assert_eq!(SearchKind::from_wire(SearchKind::wire(k)), Ok(k));
        }
        for s in [
            SearchState::None,
            SearchState::AsGiven,
            SearchState::Widened,
            SearchState::NoCells,
        ] {
            assert_eq!(SearchState::try_from(u8::from(s)), Ok(s));
        }
        assert_eq!(TrackerState::try_from(3), Err(3));
        assert_eq!(SearchKind::from_wire(4), Err(4));
        assert_eq!(SearchState::try_from(255), Err(255));
    }
}
