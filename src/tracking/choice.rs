//! Choosing a tracker per medium: `auto` or one forced by `--tracker`, with the reason
//! `zerovar check` prints.

use super::Tracker;
use crate::media::{Medium, MediumKind};
use std::str::FromStr;
use thiserror::Error;

/// `--tracker`: `auto` (per medium) or one tracker for every medium.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TrackerChoice {
    /// The cheapest correct tracker for each medium.
    #[default]
    Auto,
    /// This tracker for every medium (an error where it cannot apply).
    Force(Tracker),
}

/// A tracker that cannot apply to a medium, or an unknown tracker name.
#[derive(Debug, Error)]
pub enum TrackerError {
    /// No tracker has this name.
    #[error("unknown tracker `{name}`; choose auto or one of {known}")]
    Unknown {
        /// The name given.
        name: String,
        /// The trackers there are, comma-separated.
        known: String,
    },
    /// The forced tracker cannot handle a medium of the scene.
    #[error("tracker: {0}")]
    Inapplicable(String),
}

impl FromStr for TrackerChoice {
    type Err = TrackerError;

    fn from_str(s: &str) -> Result<Self, TrackerError> {
        if s == "auto" {
            return Ok(TrackerChoice::Auto);
        }
        if s == "ray-marching" {
            return Ok(TrackerChoice::Force(Tracker::RayMarching));
        }
        Tracker::ALL.iter().find(|t| t.name() == s).map(|t| TrackerChoice::Force(*t)).ok_or_else(
            || {
                let names: Vec<_> = Tracker::ALL.iter().map(Tracker::name).collect();
                TrackerError::Unknown { name: s.to_string(), known: names.join(", ") }
            },
        )
    }
}

impl Tracker {
    /// Whether this tracker can handle `medium`, and if not, why.
    pub fn check(&self, medium: &Medium) -> Result<(), String> {
        let homogeneous = matches!(medium.kind, MediumKind::Homogeneous { .. });
        let chromatic = medium.is_chromatic();
        match self {
            Tracker::Analytic if !homogeneous || chromatic => Err(format!(
                "analytic sampling needs a homogeneous medium with grey extinction; `{}` is {}",
                medium.name,
                if homogeneous { "chromatic (use analytic-spectral)" } else { "heterogeneous" }
            )),
            Tracker::AnalyticSpectral if !homogeneous => Err(format!(
                "analytic sampling needs a homogeneous medium; `{}` is heterogeneous",
                medium.name
            )),
            Tracker::Regular if !homogeneous => Err(format!(
                "regular tracking needs piecewise-constant extinction; `{}` is interpolated \
                 (trilinear grid or noise), use delta or decomposition tracking",
                medium.name
            )),
            Tracker::Regular
            | Tracker::RayMarching
            | Tracker::Delta
            | Tracker::WeightedDelta
            | Tracker::Decomposition
            | Tracker::WeightedDecomposition
                if chromatic =>
            {
                Err(format!(
                    "{} needs grey extinction; `{}` is chromatic: use spectral, \
                     spectral-decomposition (or analytic-spectral if homogeneous)",
                    self.name(),
                    medium.name
                ))
            }
            _ => Ok(()),
        }
    }

    /// Why `auto` picks this tracker for `medium` (or that it was forced).
    pub fn reason(&self, medium: &Medium) -> &'static str {
        if *self != Tracker::for_medium(medium) {
            return "forced (a tracker chosen for every medium)";
        }
        match self {
            Tracker::Analytic => "auto: homogeneous and grey, so free paths have a closed form",
            Tracker::AnalyticSpectral => {
                "auto: homogeneous but chromatic, so closed forms per channel mixed by MIS"
            }
            Tracker::Delta => {
                "auto: heterogeneous and grey; delta tracking on the bound grid's cells (at \
                 equal time it beat decomposition on every grid measured: the control's \
                 exponential per cell costs more than the lookups it saves; `check --trackers` \
                 measures it on this scene)"
            }
            _ => {
                "auto: heterogeneous and chromatic, so spectral tracking (history-aware, \
                 bounded weights); without decomposition, which did not pay on any grid \
                 measured (`check --trackers` measures it on this scene)"
            }
        }
    }
}

impl TrackerChoice {
    /// The tracker for `medium`.
    pub fn pick(&self, medium: &Medium) -> Result<Tracker, TrackerError> {
        match self {
            TrackerChoice::Auto => Ok(Tracker::for_medium(medium)),
            TrackerChoice::Force(t) => {
                t.check(medium).map(|()| *t).map_err(TrackerError::Inapplicable)
            }
        }
    }
}

/// The trackers worth measuring against each other on `medium` (`zerovar check --trackers`):
/// none for homogeneous media, whose closed forms are exact; delta, weighted delta and both
/// decompositions for grey grids; spectral tracking and spectral decomposition for chromatic
/// ones.
pub fn candidates(medium: &Medium) -> Vec<Tracker> {
    match (&medium.kind, medium.is_chromatic()) {
        (MediumKind::Homogeneous { .. }, _) => Vec::new(),
        (MediumKind::Heterogeneous(_), false) => vec![
            Tracker::Delta,
            Tracker::WeightedDelta,
            Tracker::Decomposition,
            Tracker::WeightedDecomposition,
        ],
        (MediumKind::Heterogeneous(_), true) => {
            vec![Tracker::Spectral, Tracker::SpectralDecomposition]
        }
    }
}

/// `describe` and `reason` in one line, for `zerovar check`.
pub(crate) fn explain(medium: &Medium, tracker: Tracker) -> String {
    format!("{} [{}]", tracker.describe(), tracker.reason(medium))
}
