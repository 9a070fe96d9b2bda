//! vcm's multiple importance sampling: the constants of an iteration ([`Iteration`]), the recursive quantities
//! a subpath carries ([`MisState`]), and the weight of each technique from them ([`weights`]), after Georgiev,
//! Křivánek, Davidovič & Slusallek, "Implementing Vertex Connection and Merging" (technical report, Saarland
//! University 2012), whose equation numbers the comments follow.

use crate::method::Techniques;
use crate::photon::Kernel;
use std::f32::consts::PI;

/// The multiple-importance heuristic's exponent applied to a density (or a ratio of densities): the power
/// heuristic with β = 2 (Veach 1997, §9.2.4), the path tracer's.
#[inline]
fn mis(x: f32) -> f32 {
    x * x
}

/// The constants of one iteration (the report's §3.2 and SmallVCM's `InitIteration`).
#[derive(Clone, Copy, Debug)]
pub struct Iteration {
    /// The techniques.
    pub techniques: Techniques,
    /// Light subpaths per iteration, `N` (the number of pixels).
    pub light_paths: f32,
    /// Squared merging radius `r²`.
    pub r2: f32,
    /// `mis(η_VCM)`, `η_VCM = π r² N`, or 0 without merging: merging's weight relative to a connection.
    pub vm_weight: f32,
    /// `mis(1/η_VCM)`, or 0 without connections.
    pub vc_weight: f32,
    /// The merge estimate's normalisation, `1 / (r² N)` (the kernel supplies its own `1/π`).
    pub vm_normalization: f32,
    /// Kernel of the merges.
    pub kernel: Kernel,
    /// The longest path, in segments (`render.max_depth + 1`).
    pub max_len: u32,
}

impl Iteration {
    /// The constants of an iteration of `techniques` over `light_paths` subpaths at squared radius `r2`.
    pub fn new(techniques: Techniques, light_paths: f32, r2: f32, kernel: Kernel, max_depth: u32) -> Self {
        let eta_vcm = PI * r2 * light_paths;
        let vm_weight = if techniques.merge && eta_vcm > 0.0 { mis(eta_vcm) } else { 0.0 };
        let vc_weight = if techniques.connect && techniques.merge && eta_vcm > 0.0 { mis(1.0 / eta_vcm) } else { 0.0 };
        let vm_normalization = if r2 > 0.0 && light_paths > 0.0 { 1.0 / (r2 * light_paths) } else { 0.0 };
        Self {
            techniques,
            light_paths,
            r2,
            vm_weight,
            vc_weight,
            vm_normalization,
            kernel,
            max_len: max_depth.saturating_add(1),
        }
    }
}

/// The recursive MIS quantities of a subpath at its last vertex (the report's eqs. 31–36), and its length.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MisState {
    /// `dVCM`.
    pub d_vcm: f32,
    /// `dVC`.
    pub d_vc: f32,
    /// `dVM`.
    pub d_vm: f32,
    /// Segments from the subpath's origin (the light or the camera) to its last vertex.
    pub len: u32,
}

impl MisState {
    /// The quantities of a light subpath leaving the light (eqs. 31–33; delta lights, eqs. 48–50), before its
    /// first hit: `direct_pdf_a` is the area density of the light point as next-event estimation picks it,
    /// `emission_pdf_w` the density of emitting this point and direction (the product of the point's area
    /// density and the direction's solid-angle density), `cos_light` the cosine at the light.
    pub fn emitted(it: &Iteration, direct_pdf_a: f32, emission_pdf_w: f32, cos_light: f32, delta: bool) -> Self {
        let d_vc = if delta { 0.0 } else { mis(cos_light / emission_pdf_w) };
        Self { d_vcm: mis(direct_pdf_a / emission_pdf_w), d_vc, d_vm: d_vc * it.vc_weight, len: 1 }
    }

    /// The quantities of a camera subpath whose first direction has solid-angle density `camera_pdf_w` (the
    /// camera's importance per pixel), before its first hit.
    pub fn from_camera(it: &Iteration, camera_pdf_w: f32) -> Self {
        Self { d_vcm: mis(it.light_paths / camera_pdf_w), d_vc: 0.0, d_vm: 0.0, len: 1 }
    }

    /// Completes the quantities at a new vertex reached over distance `dist`, whose geometric normal makes
    /// `|cos| = cos_in` with the arriving direction (the area-measure part of eqs. 31–36).
    #[inline]
    pub fn arrive(&mut self, dist: f32, cos_in: f32) {
        self.d_vcm *= mis(dist * dist);
        let c = mis(cos_in);
        self.d_vcm /= c;
        self.d_vc /= c;
        self.d_vm /= c;
    }

    /// The quantities after sampling the next direction: `cos_out = |wi·ng|`, the forward density `pdf` and the
    /// reverse density `pdf_rev` (both in solid angle, Russian roulette included), or for a delta lobe
    /// (`delta`) only the cosine (eqs. 53–55: the delta's densities cancel and no technique ends here).
    #[inline]
    pub fn scatter(&mut self, it: &Iteration, cos_out: f32, pdf: f32, pdf_rev: f32, delta: bool) {
        if delta {
            self.d_vcm = 0.0;
            self.d_vc *= mis(cos_out);
            self.d_vm *= mis(cos_out);
        } else {
            let g = mis(cos_out / pdf);
            self.d_vc = g * (self.d_vc * mis(pdf_rev) + self.d_vcm + it.vm_weight);
            self.d_vm = g * (self.d_vm * mis(pdf_rev) + self.d_vcm * it.vc_weight + 1.0);
            self.d_vcm = mis(1.0 / pdf);
        }
        self.len += 1;
    }
}

/// The MIS weight of each technique, from the quantities of the subpaths it joins and the densities at the
/// join (every density in solid angle includes Russian roulette's `q` at its vertex; area densities are the
/// solid-angle ones times `|cos| / d²` at the vertex they land on). The weights of all the techniques that can
/// make one path sum to 1 (a test checks it on stored paths).
pub mod weights {
    use super::{Iteration, MisState, mis};

    /// A camera subpath that found an area light (eqs. 42–43): `direct_pdf_a` is the area density with which
    /// next-event estimation would pick the point, `emission_pdf_w` the density of emitting towards the
    /// subpath (light choice included in both). 1 when the camera sees the light directly.
    pub fn emission(camera: &MisState, direct_pdf_a: f32, emission_pdf_w: f32) -> f32 {
        if camera.len == 1 {
            return 1.0;
        }
        1.0 / (1.0 + mis(direct_pdf_a) * camera.d_vcm + mis(emission_pdf_w) * camera.d_vc)
    }

    /// Next-event estimation at a camera vertex (eqs. 44–45): `bsdf_pdf` is the density of the BSDF sampling
    /// the light direction (0 for a delta light), `bsdf_pdf_rev` of the reverse direction, `light_pdf_w` the
    /// solid-angle density of the light sample (light choice included), and `emission_ratio` the emission
    /// density of the opposite direction over the light sample's, as area densities at the two ends
    /// (`emission_pdf_w · |cos_vertex| / (direct_pdf_w · |cos_light|)`; the light choice cancels).
    pub fn direct(
        it: &Iteration,
        camera: &MisState,
        bsdf_pdf: f32,
        bsdf_pdf_rev: f32,
        light_pdf_w: f32,
        emission_ratio: f32,
    ) -> f32 {
        let w_light = mis(bsdf_pdf / light_pdf_w);
        let w_camera = mis(emission_ratio) * (it.vm_weight + camera.d_vcm + camera.d_vc * mis(bsdf_pdf_rev));
        1.0 / (w_light + 1.0 + w_camera)
    }

    /// A connection between a camera vertex and a light vertex (eqs. 40–41): `camera_pdf_a` is the camera
    /// vertex's BSDF sampling the light vertex (area density there), `light_pdf_a` the reverse, and each
    /// `*_pdf_rev` the vertex's BSDF sampling its own predecessor from the connecting direction.
    pub fn connect(
        it: &Iteration,
        camera: &MisState,
        light: &MisState,
        camera_pdf_a: f32,
        camera_pdf_rev: f32,
        light_pdf_a: f32,
        light_pdf_rev: f32,
    ) -> f32 {
        let w_light = mis(camera_pdf_a) * (it.vm_weight + light.d_vcm + light.d_vc * mis(light_pdf_rev));
        let w_camera = mis(light_pdf_a) * (it.vm_weight + camera.d_vcm + camera.d_vc * mis(camera_pdf_rev));
        1.0 / (w_light + 1.0 + w_camera)
    }

    /// A light vertex connected to the camera (eqs. 46–47): `camera_pdf_a` is the camera's density of the
    /// vertex (area density), `light_pdf_rev` the vertex's BSDF sampling its predecessor from the camera's
    /// direction. Light tracing alone (no other technique) weighs 1.
    pub fn light_trace(it: &Iteration, light: &MisState, camera_pdf_a: f32, light_pdf_rev: f32) -> f32 {
        if it.techniques.light_tracing_only {
            return 1.0;
        }
        let w_light =
            mis(camera_pdf_a / it.light_paths) * (it.vm_weight + light.d_vcm + light.d_vc * mis(light_pdf_rev));
        1.0 / (1.0 + w_light)
    }

    /// A merge of a camera vertex with a light vertex (eqs. 38–39): `camera_pdf` is the camera vertex's BSDF
    /// sampling the light vertex's incoming direction (with the camera vertex's roulette), `camera_pdf_rev` the
    /// reverse (with the light vertex's roulette: it stands for the light subpath continuing).
    pub fn merge(it: &Iteration, camera: &MisState, light: &MisState, camera_pdf: f32, camera_pdf_rev: f32) -> f32 {
        let w_light = light.d_vcm * it.vc_weight + light.d_vm * mis(camera_pdf);
        let w_camera = camera.d_vcm * it.vc_weight + camera.d_vm * mis(camera_pdf_rev);
        1.0 / (w_light + 1.0 + w_camera)
    }
}
