//! Participating media: what a ray meets between surfaces.
//!
//! A medium is either homogeneous (constant RGB extinction and albedo) or heterogeneous: a
//! density field (a `.vol` or `.vdb` grid, one channel or RGB, or the procedural noise cloud)
//! over the unit cube placed by `to_world`, scaled and optionally tinted per channel, with a
//! constant or gridded RGB albedo.
//! Outside its box a heterogeneous medium is empty. Each medium also has a phase function and
//! an optional emission: radiance emitted per unit length is `sigma_a(x) * emission`.
//! `tracking` decides how to walk through a medium; this module only answers lookups.

mod grid;
mod majorant;
mod noise;
mod vdb;
mod vol;

pub use grid::Grid;
pub use majorant::{CellSpan, Dda, MajorantGrid};
pub use noise::NoiseCloud;
pub use vdb::{MAX_DENSE_VOXELS, VdbError, VdbGrid};
pub use vol::{VolError, VolGrid};

use crate::math::{Aabb, Ray, Spectrum, is_grey};
use crate::phase::PhaseFunction;
use crate::transform::Transform;
use glam::Vec3A;

/// The extinction and single-scattering albedo at a point.
#[derive(Clone, Copy, Debug)]
pub struct Coefficients {
    /// Extinction coefficient per channel.
    pub sigma_t: Spectrum,
    /// Single-scattering albedo per channel.
    pub albedo: Spectrum,
}

/// A density supplied by the embedding application, for example from its own simulation:
/// zerovar derives majorants from its bounds and tracks through it like any grid.
///
/// The bounds are promises: the analog trackers (`delta`, `decomposition`, spectral) are
/// unbiased only if `density` never exceeds them; the weighted trackers
/// (`TrackerChoice::WeightedDelta`, `WeightedDecomposition`) stay unbiased when they are
/// violated, at a cost in variance.
pub trait DensityFunction: Send + Sync + std::fmt::Debug {
    /// The density at a point of the unit cube: finite and non-negative.
    fn density(&self, p: Vec3A) -> f32;
    /// An upper bound of the density over the whole unit cube.
    fn max_density(&self) -> f32;
    /// Lower and upper bounds of the density over the box `[lo, hi]` of the unit cube, for
    /// local majorants and decomposition controls; by default `(0, max_density())`.
    fn bounds(&self, lo: Vec3A, hi: Vec3A) -> (f32, f32) {
        let _ = (lo, hi);
        (0.0, self.max_density())
    }
}

/// A scalar density field over the unit cube.
#[derive(Clone, Debug)]
pub enum DensityField {
    /// A dense voxel grid.
    Grid(Grid),
    /// The procedural noise cloud.
    Noise(NoiseCloud),
    /// A density function of the embedding application.
    Custom(std::sync::Arc<dyn DensityFunction>),
}

impl DensityField {
    /// The density at a point of the unit cube.
    #[inline]
    pub fn at(&self, p: Vec3A) -> f32 {
        match self {
            DensityField::Grid(g) => g.scalar(p),
            DensityField::Noise(n) => n.density(p),
            DensityField::Custom(f) => f.density(p),
        }
    }

    /// The density at a point of the unit cube per channel: an RGB grid's three, the same
    /// value in each otherwise.
    #[inline]
    pub fn rgb(&self, p: Vec3A) -> Spectrum {
        match self {
            DensityField::Grid(g) => g.rgb(p),
            d => Spectrum::splat(d.at(p)),
        }
    }

    /// Whether the density differs between channels (a three-channel grid).
    pub fn is_rgb(&self) -> bool {
        matches!(self, DensityField::Grid(g) if g.channels() == 3)
    }

    /// An upper bound of the density over the cube (over every channel).
    pub fn max_value(&self) -> f32 {
        match self {
            DensityField::Grid(g) => g.max_value(),
            DensityField::Noise(_) => 1.0,
            DensityField::Custom(f) => f.max_density(),
        }
    }
}

/// A single-scattering albedo field.
#[derive(Clone, Debug)]
pub enum AlbedoField {
    /// The same albedo everywhere.
    Constant(Spectrum),
    /// An RGB (or grey) grid over the same unit cube as the density.
    Grid(Grid),
}

/// A medium whose coefficients vary over a box.
#[derive(Clone, Debug)]
pub struct Heterogeneous {
    to_world: Transform,
    density: DensityField,
    scale: f32,
    tint: Spectrum,
    albedo: AlbedoField,
    majorant: Spectrum,
    bounds: Aabb,
    bound_grid: MajorantGrid,
}

impl Heterogeneous {
    /// A heterogeneous medium: `sigma_t(x) = scale * tint * density(x)` (per channel for an
    /// RGB grid) over the unit cube mapped by `to_world`.
    pub fn new(
        to_world: Transform,
        density: DensityField,
        scale: f32,
        tint: Spectrum,
        albedo: AlbedoField,
    ) -> Self {
        let majorant = tint * (scale * density.max_value());
        let mut bounds = Aabb::EMPTY;
        for i in 0..8 {
            let c = Vec3A::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32);
            bounds = bounds.grow(to_world.point(c));
        }
        let bound_grid = MajorantGrid::build(&density);
        Self { to_world, density, scale, tint, albedo, majorant, bounds, bound_grid }
    }

    /// The coarse grid of density bounds (built with the medium), for local majorants and
    /// minorants.
    pub fn bound_grid(&self) -> &MajorantGrid {
        &self.bound_grid
    }

    /// `scale * tint`: the extinction per unit density.
    pub fn extinction_per_density(&self) -> Spectrum {
        self.tint * self.scale
    }

    /// `ray` in the unit cube's space (the affine map keeps ray parameters).
    #[inline]
    pub fn local_ray(&self, ray: &Ray) -> Ray {
        Ray::new(self.to_world.inv_point(ray.origin), self.to_world.inv_vector(ray.direction))
    }

    /// Extinction and albedo at a point of the unit cube (the medium's local space).
    #[inline]
    pub fn coefficients_local(&self, local: Vec3A) -> Coefficients {
        if !(local.cmpge(Vec3A::ZERO).all() && local.cmple(Vec3A::ONE).all()) {
            return Coefficients { sigma_t: Spectrum::ZERO, albedo: Spectrum::ZERO };
        }
        let sigma_t = self.tint * (self.density.rgb(local) * self.scale);
        Coefficients { sigma_t, albedo: self.albedo_local(local) }
    }

    /// The albedo at a point of the unit cube, without a density lookup.
    #[inline]
    pub fn albedo_local(&self, local: Vec3A) -> Spectrum {
        match &self.albedo {
            AlbedoField::Constant(a) => *a,
            AlbedoField::Grid(g) => g.rgb(local),
        }
    }

    /// A per-channel upper bound of the extinction anywhere in the medium.
    pub fn majorant(&self) -> Spectrum {
        self.majorant
    }

    /// World-space bounds of the medium's box.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The density field.
    pub fn density(&self) -> &DensityField {
        &self.density
    }

    /// The part `(t0, t1)` of `ray` within `(0, t_max)` that lies inside the box.
    #[inline]
    pub fn clip(&self, ray: &Ray, t_max: f32) -> Option<(f32, f32)> {
        // The affine map keeps ray parameters, so the local hit interval is the world one.
        let local =
            Ray::new(self.to_world.inv_point(ray.origin), self.to_world.inv_vector(ray.direction));
        let unit = Aabb::from_points(Vec3A::ZERO, Vec3A::ONE);
        unit.intersect(&local, local.direction.recip(), 0.0, t_max)
    }

    /// Extinction and albedo at a world-space point.
    #[inline]
    pub fn coefficients(&self, p: Vec3A) -> Coefficients {
        let local = self.to_world.inv_point(p);
        if !(local.cmpge(Vec3A::ZERO).all() && local.cmple(Vec3A::ONE).all()) {
            return Coefficients { sigma_t: Spectrum::ZERO, albedo: Spectrum::ZERO };
        }
        let sigma_t = self.tint * (self.density.rgb(local) * self.scale);
        let albedo = match &self.albedo {
            AlbedoField::Constant(a) => *a,
            AlbedoField::Grid(g) => g.rgb(local),
        };
        Coefficients { sigma_t, albedo }
    }

    /// Whether the albedo varies with position or colour (the extinction may still be grey).
    pub fn albedo_field(&self) -> &AlbedoField {
        &self.albedo
    }
}

/// How a medium's coefficients are given.
#[derive(Clone, Debug)]
pub enum MediumKind {
    /// Constant coefficients everywhere.
    Homogeneous {
        /// Extinction per channel.
        sigma_t: Spectrum,
        /// Single-scattering albedo per channel.
        albedo: Spectrum,
    },
    /// Coefficients varying over a box.
    Heterogeneous(Box<Heterogeneous>),
}

/// A participating medium of the scene.
#[derive(Clone, Debug)]
pub struct Medium {
    /// The name the scene file gave it.
    pub name: String,
    /// Its coefficients.
    pub kind: MediumKind,
    /// Its phase function.
    pub phase: PhaseFunction,
    /// Emitted radiance per unit absorption (zero for none).
    pub emission: Spectrum,
}

impl Medium {
    /// Whether the extinction differs between channels, which needs per-channel tracking.
    pub fn is_chromatic(&self) -> bool {
        match &self.kind {
            MediumKind::Homogeneous { sigma_t, .. } => !is_grey(*sigma_t),
            MediumKind::Heterogeneous(h) => !is_grey(h.tint) || h.density.is_rgb(),
        }
    }

    /// Whether the medium emits light.
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// Extinction and albedo at a point.
    #[inline]
    pub fn coefficients(&self, p: Vec3A) -> Coefficients {
        match &self.kind {
            MediumKind::Homogeneous { sigma_t, albedo } => {
                Coefficients { sigma_t: *sigma_t, albedo: *albedo }
            }
            MediumKind::Heterogeneous(h) => h.coefficients(p),
        }
    }

    /// A per-channel upper bound of the extinction.
    pub fn majorant(&self) -> Spectrum {
        match &self.kind {
            MediumKind::Homogeneous { sigma_t, .. } => *sigma_t,
            MediumKind::Heterogeneous(h) => h.majorant(),
        }
    }
}
