//! Steering a tracker's decisions: the hook through which guided distance sampling works in
//! heterogeneous media, on top of whichever tracker the medium uses.
//!
//! In the null-collision form (seed notes, section 3.2) a tracker draws tentative collisions
//! and at each one chooses between scattering and going on; any probabilities keep the
//! estimate unbiased once the weight divides by them. A [`Steer`] may replace the tracker's
//! probability at every collision that reads the density: the tracker still computes the
//! weight its own choice would give (its standard weight), and the steer keeps the ratio of its
//! probabilities to the tracker's, by which the caller corrects that weight. Collisions the
//! tracker takes in closed form (decomposition's control) are real ones and are not steered.

use crate::stats::Counters;

/// What a tracker tells its steer at a tentative collision.
#[derive(Clone, Copy, Debug)]
pub struct Tentative {
    /// The ray parameter of the collision.
    pub t: f32,
    /// The tracker's probability of scattering there.
    pub p_std: f32,
    /// What scattering there brings back per unit of in-scattered radiance, and going on per
    /// unit of the radiance arriving along the ray: the path throughput (luminance) times the
    /// scattering and the null coefficient, over the tracker's sampling rate.
    pub scatter: f32,
    /// See `scatter`.
    pub null: f32,
}

/// Chooses the event at a tracker's tentative collisions.
pub trait Steer {
    /// Whether the tentative collision `at` scatters: `standard` is the tracker's own draw
    /// with the uniform variate `u` (true with probability `at.p_std`).
    fn scatters(&mut self, at: Tentative, u: f32, standard: bool, counters: &mut Counters) -> bool;

    /// The flight's weight so far over the tracker's standard weight (one if unsteered):
    /// emission scored along the flight is weighted by it.
    fn gain(&self) -> f32;
}

/// The tracker's own decisions.
#[derive(Clone, Copy, Debug, Default)]
pub struct Unsteered;

impl Steer for Unsteered {
    #[inline(always)]
    fn scatters(&mut self, _: Tentative, _: f32, standard: bool, _: &mut Counters) -> bool {
        standard
    }

    #[inline(always)]
    fn gain(&self) -> f32 {
        1.0
    }
}
