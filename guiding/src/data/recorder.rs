//! Turns a finished path into training samples: every vertex learns the radiance that
//! arrived along the direction sampled from it.
//!
//! **Conventions.** A path is recorded vertex by vertex, in the order the renderer creates
//! them. At vertex `j` the renderer samples the continuation direction `d_j` (pointing away
//! from the vertex: the direction light arrives from) with density `p_j`, multiplies its path
//! throughput weight by the scattering weight `f / p_j`, and calls
//! `add_vertex(x_j, d_j, p_j, beta_j, volume)` with that updated throughput `beta_j`. So
//! `beta_j` is the factor between radiance arriving at `x_j` along `d_j` and its contribution
//! to the pixel: a pixel contribution `C` found later on the path corresponds to radiance
//! `C / beta_j` arriving at vertex `j`.
//!
//! Radiance found after the last vertex (an emitter hit by `d_N`, or medium emission along
//! the next segment) is reported with `add_contribution(L)`, where `L` is the radiance
//! arriving at the last vertex along `d_N` (emission times the transmittance weight of the
//! segment), or equivalently with `add_weighted_contribution(C)`, the pixel contribution
//! `C = beta L` the renderer adds to its film. It propagates backwards: vertex `j` gains
//! `L beta_N / beta_j`. Throughputs are scalars (use the luminance or channel average).
//! Where roulette or splitting acted after the last vertex (a survivor weighted by `1 / q`),
//! report the pixel contribution: only it carries that factor.
//!
//! Next-event estimation at the last vertex is reported with `add_direct_sample`, a separate
//! training sample with its own direction and light-sampling pdf. A vertex that emits `m`
//! samples (its continuation plus direct samples) emits each with its radiance multiplied by
//! `m`: the weights of one vertex sum to an unbiased fluence estimate when the renderer splits
//! direct light between the strategies (MIS weights applied to both the NEE radiance and the
//! emission found by the continuation, or NEE alone counting direct light), so scaling keeps
//! the mean weight per sample, which the field uses as its fluence, unbiased.
//!
//! **Split paths.** A renderer that splits a path (weight windows) records it as a tree:
//! before tracing a copy it calls `resume(branch)` with the [`Branch`] that `branch()`
//! returned where the copy was made. Contributions then propagate to the copy's own
//! ancestors only; a vertex before the split sums what all its copies bring back, each
//! contribution already carrying its copy's `1 / q`, so it still learns an unbiased estimate.
//!
//! Samples with a zero pdf (delta directions, terminated paths) are skipped. The recorder
//! keeps its buffers between paths, so after warm-up it does not allocate.

use crate::data::sample::Sample;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
struct Vertex {
    position: Vec3,
    direction: Vec3,
    pdf: f32,
    throughput: f32,
    volume: bool,
    radiance: f64,
    direct_samples: u32,
    /// The vertex this one's path came from; `None` for the first.
    parent: Option<usize>,
}

#[derive(Clone, Copy, Debug)]
struct Direct {
    vertex: Option<usize>,
    position: Vec3,
    direction: Vec3,
    pdf: f32,
    radiance: f32,
    volume: bool,
}

/// Where a split copy of a path goes on from: the last vertex recorded before the split.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Branch(Option<usize>);

/// Records one path at a time and emits its training samples (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct PathRecorder {
    vertices: Vec<Vertex>,
    direct: Vec<Direct>,
    /// The last vertex of the branch being recorded.
    cursor: Option<usize>,
}

impl PathRecorder {
    /// An empty recorder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the current path (done by `finish` too).
    pub fn clear(&mut self) {
        self.vertices.clear();
        self.direct.clear();
        self.cursor = None;
    }

    /// The branch being recorded, for a split copy to [`resume`](Self::resume) from.
    pub fn branch(&self) -> Branch {
        Branch(self.cursor)
    }

    /// Goes on recording after `branch`'s last vertex: the next vertex is its child, and
    /// contributions reach that vertex and its ancestors only. A branch from before the last
    /// `clear` or `finish` starts a new path.
    pub fn resume(&mut self, branch: Branch) {
        self.cursor = branch.0.filter(|&i| i < self.vertices.len());
    }

    /// Number of vertices recorded for the current path.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// True when no vertex has been recorded.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    /// Records a scattering vertex at `pos` and the direction `dir` sampled from it with
    /// density `pdf`; `throughput` is the path throughput weight after this vertex's
    /// scattering weight was applied (see the module docs). `volume` marks medium vertices.
    pub fn add_vertex(&mut self, pos: Vec3, dir: Vec3, pdf: f32, throughput: f32, volume: bool) {
        self.vertices.push(Vertex {
            position: pos,
            direction: dir,
            pdf,
            throughput,
            volume,
            radiance: 0.0,
            direct_samples: 0,
            parent: self.cursor,
        });
        self.cursor = Some(self.vertices.len() - 1);
    }

    /// Adds `radiance(beta)` to the last vertex and each of its ancestors, `beta` being that
    /// vertex's throughput.
    fn propagate(&mut self, radiance: impl Fn(f64) -> f64) {
        let mut at = self.cursor;
        while let Some(i) = at {
            let v = &mut self.vertices[i];
            let beta = f64::from(v.throughput);
            if beta > 0.0 && beta.is_finite() {
                v.radiance += radiance(beta);
            }
            at = v.parent;
        }
    }

    /// Adds radiance arriving at the last vertex along its sampled direction, and propagates
    /// it to every earlier vertex of its branch divided by the throughput between them.
    pub fn add_contribution(&mut self, radiance: f32) {
        let Some(last) = self.cursor else { return };
        let beta_last = f64::from(self.vertices[last].throughput);
        let radiance = f64::from(radiance);
        if !(radiance.is_finite() && radiance > 0.0 && beta_last.is_finite()) {
            return;
        }
        self.propagate(|beta| radiance * beta_last / beta);
    }

    /// Adds a pixel contribution `throughput * radiance` found after the last vertex, as the
    /// renderer adds it to its film: the same as `add_contribution(contribution / beta_N)`.
    pub fn add_weighted_contribution(&mut self, contribution: f32) {
        let Some(last) = self.cursor else { return };
        let beta_last = f64::from(self.vertices[last].throughput);
        if beta_last.is_nan() || beta_last <= 0.0 {
            return;
        }
        let contribution = f64::from(contribution);
        if !(contribution.is_finite() && contribution > 0.0) {
            return;
        }
        self.propagate(|beta| contribution / beta);
    }

    /// Records a next-event-estimation sample at `pos` (normally the last vertex): light
    /// `radiance` arriving from `dir`, sampled with density `pdf`.
    pub fn add_direct_sample(
        &mut self,
        pos: Vec3,
        dir: Vec3,
        pdf: f32,
        radiance: f32,
        volume: bool,
    ) {
        let vertex = self.cursor;
        if let Some(v) = vertex
            && pdf > 0.0
        {
            self.vertices[v].direct_samples += 1;
        }
        self.direct.push(Direct { vertex, position: pos, direction: dir, pdf, radiance, volume });
    }

    /// Appends the path's training samples to `out` and clears the recorder.
    pub fn finish(&mut self, out: &mut Vec<Sample>) {
        let emitted = |v: &Vertex| u32::from(v.pdf > 0.0) + v.direct_samples;
        for (j, v) in self.vertices.iter().enumerate() {
            if !(v.pdf > 0.0 && v.pdf.is_finite()) {
                continue;
            }
            // The distance to the next vertex along the sampled direction: its first child's
            // (children follow their parent, so the search starts after it).
            let child = self.vertices[j + 1..].iter().find(|c| c.parent == Some(j));
            let distance = child.map_or(f32::INFINITY, |c| (c.position - v.position).length());
            let radiance = (v.radiance * f64::from(emitted(v))).min(f64::from(f32::MAX)) as f32;
            out.push(Sample {
                position: v.position,
                direction: v.direction,
                radiance,
                pdf: v.pdf,
                distance,
                volume: v.volume,
            });
        }
        for d in &self.direct {
            if !(d.pdf > 0.0 && d.pdf.is_finite()) {
                continue;
            }
            let m = d.vertex.map_or(1, |j| emitted(&self.vertices[j]).max(1));
            let radiance = (f64::from(d.radiance) * f64::from(m)).min(f64::from(f32::MAX)) as f32;
            out.push(Sample {
                position: d.position,
                direction: d.direction,
                radiance,
                pdf: d.pdf,
                distance: f32::INFINITY,
                volume: d.volume,
            });
        }
        self.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contributions_propagate_backwards_through_throughput() {
        // Three vertices; the renderer's throughput after each: 0.5, 0.5 * 0.8, 0.5 * 0.8 * 0.25.
        let mut r = PathRecorder::new();
        let p = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 2.0, 0.0)];
        r.add_vertex(p[0], Vec3::X, 0.3, 0.5, true);
        r.add_contribution(1.0); // emission along the first segment, seen at vertex 0
        r.add_vertex(p[1], Vec3::Y, 0.2, 0.4, true);
        r.add_vertex(p[2], Vec3::Z, 0.1, 0.1, false);
        r.add_weighted_contribution(0.1 * 3.0); // an emitter of radiance 3 seen from vertex 2
        let mut out = Vec::new();
        r.finish(&mut out);
        assert_eq!(out.len(), 3);
        // Vertex 2 sees 3; vertex 1 sees 3 * 0.1 / 0.4; vertex 0 sees 1 + 3 * 0.1 / 0.5.
        let expect = [1.0 + 3.0 * 0.1 / 0.5, 3.0 * 0.1 / 0.4, 3.0];
        for (s, e) in out.iter().zip(expect) {
            assert!((s.radiance - e).abs() < 1e-6, "{} vs {e}", s.radiance);
        }
        assert_eq!(out[0].direction, Vec3::X);
        assert_eq!(out[1].pdf, 0.2);
        assert!(!out[2].volume && out[2].distance == f32::INFINITY);
        assert!((out[0].distance - 1.0).abs() < 1e-6 && (out[1].distance - 2.0).abs() < 1e-6);
        assert!(r.is_empty());
    }

    #[test]
    fn direct_samples_and_zero_pdfs() {
        let mut r = PathRecorder::new();
        r.add_vertex(Vec3::ZERO, Vec3::Z, 0.5, 1.0, true);
        r.add_direct_sample(Vec3::ZERO, Vec3::X, 2.0, 4.0, true);
        r.add_contribution(1.0);
        // A delta bounce (pdf 0) is skipped but still carries throughput for propagation.
        r.add_vertex(Vec3::Z, Vec3::Y, 0.0, 0.5, false);
        r.add_contribution(2.0);
        let mut out = Vec::new();
        r.finish(&mut out);
        assert_eq!(out.len(), 2);
        // Vertex 0 emits two samples, each scaled by 2: continuation (1 + 2 * 0.5 / 1) and NEE 4.
        assert!((out[0].radiance - 2.0 * 2.0).abs() < 1e-6, "{}", out[0].radiance);
        assert!((out[1].radiance - 2.0 * 4.0).abs() < 1e-6);
        assert_eq!((out[1].direction, out[1].pdf), (Vec3::X, 2.0));
        // Every emitted sample is valid for Field::update.
        for s in &out {
            s.validate().unwrap();
        }
    }

    #[test]
    fn split_copies_reach_their_own_ancestors_only() {
        // Vertex 0 (throughput 1), then a split in two copies weighted 1/2 each: copy A
        // records vertex 1 (throughput 0.25) and finds a contribution 0.5; copy B records
        // vertex 2 (throughput 0.5) and finds 0.1.
        let mut r = PathRecorder::new();
        r.add_vertex(Vec3::ZERO, Vec3::X, 1.0, 1.0, true);
        let split = r.branch();
        r.add_vertex(Vec3::X, Vec3::Y, 1.0, 0.25, true);
        r.add_weighted_contribution(0.5);
        r.resume(split);
        r.add_vertex(Vec3::new(3.0, 0.0, 0.0), Vec3::Z, 1.0, 0.5, true);
        r.add_weighted_contribution(0.1);
        let mut out = Vec::new();
        r.finish(&mut out);
        let radiance: Vec<f32> = out.iter().map(|s| s.radiance).collect();
        let expect = [0.5 + 0.1, 0.5 / 0.25, 0.1 / 0.5];
        for (got, e) in radiance.iter().zip(expect) {
            assert!((got - e).abs() < 1e-6, "{radiance:?} vs {expect:?}");
        }
        // Vertex 0's distance is to its first child; each copy's last vertex looks to infinity.
        assert!((out[0].distance - 1.0).abs() < 1e-6);
        assert_eq!((out[1].distance, out[2].distance), (f32::INFINITY, f32::INFINITY));
        // A branch kept from a finished path starts the next path afresh.
        r.resume(split);
        r.add_vertex(Vec3::ZERO, Vec3::X, 1.0, 2.0, true);
        r.add_weighted_contribution(1.0);
        out.clear();
        r.finish(&mut out);
        assert_eq!(out.len(), 1);
        assert!((out[0].radiance - 0.5).abs() < 1e-6);
    }
}
