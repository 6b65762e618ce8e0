//! Path traces for the firefly diagnostic (`zerovar render --fireflies N`).
//!
//! A camera sample is replayed with the same random streams, field and pixel estimate, and
//! every decision of its walks is written down: each flight (guided or standard), each
//! direction (drawn from the guided distribution or from the phase function or BSDF, with the
//! mixture's density and the standard one), each roulette or splitting decision, and each
//! light found with the path weight that carried it. The walk records only when a trace is
//! attached, so ordinary renders pay one branch per decision.

use serde::Serialize;

/// Where light was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LightSource {
    /// Next-event estimation at a medium vertex.
    NeeMedium,
    /// Next-event estimation at a surface vertex.
    NeeSurface,
    /// A guided flight's extra collision for delta lights.
    ExtraCollision,
    /// An area light hit by the path.
    EmitterHit,
    /// An infinite light reached by escaping the scene.
    Escape,
    /// Emission of the medium along a flight.
    MediumEmission,
}

/// Which strategy of a vertex's direction mixture drew the direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    /// The phase function or BSDF.
    Standard,
    /// The guiding field's distribution.
    Guided,
    /// The glow around a point light (`guided::halo`).
    Halo,
}

/// How a path went on after a direction was chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Continuation {
    /// A weight window around the pixel estimate.
    Window,
    /// A weight window at a medium collision, before its next-event estimate.
    VertexWindow,
    /// The standard Russian roulette on the path weight.
    Standard,
}

/// One decision of a traced walk, or light it found. `depth` is the path's depth when the
/// event happened; luminances stand for colours.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum TraceEvent {
    /// A walk starts: the camera path (`walk` 0) or a copy made by splitting.
    Walk {
        /// Index of the walk within the camera sample.
        walk: u32,
        /// Its weight at the start (luminance).
        beta: f32,
        /// Its depth at the start.
        depth: u32,
    },
    /// A free flight through a medium.
    Flight {
        /// Path depth.
        depth: u32,
        /// Whether the flight was a guided one (extra collisions, guided distances).
        guided: bool,
        /// Whether it ended in a real scattering collision.
        scattered: bool,
        /// How far it went.
        t: f32,
        /// The factor it multiplied the path weight by (luminance).
        weight: f32,
    },
    /// A scattering direction was chosen.
    Direction {
        /// Path depth (the vertex's).
        depth: u32,
        /// At a surface (or in a medium).
        surface: bool,
        /// Whether the field had a region there.
        loaded: bool,
        /// The strategy that drew it.
        strategy: Strategy,
        /// The density the direction was drawn with (the mixture's when guided).
        pdf: f32,
        /// The phase function's or BSDF's own density of it.
        standard_pdf: f32,
        /// The factor it multiplied the path weight by (luminance).
        weight: f32,
    },
    /// Roulette or splitting.
    Continue {
        /// Path depth.
        depth: u32,
        /// Which rule decided.
        rule: Continuation,
        /// The expected number of copies (below 1: survival probability).
        q: f32,
        /// Copies that go on (0: the path ended).
        copies: u32,
    },
    /// Light reached the camera.
    Light {
        /// Path depth of the vertex that found it.
        depth: u32,
        /// What found it.
        source: LightSource,
        /// Its contribution to the sample (luminance), path weight included.
        contribution: f32,
        /// The path weight that carried it (luminance).
        beta: f32,
        /// Distance from the vertex to the light sample (0 where none applies).
        distance: f32,
    },
}

/// A trace being written: the events of one camera sample, in order.
pub type Trace = Vec<TraceEvent>;
