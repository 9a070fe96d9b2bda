//! Level of detail for OBJ meshes: how far a mesh's surface may move without a pixel noticing, and the
//! simplification that stays within it (meshoptimizer's edge-collapse simplifier, through the `meshopt` crate).
//!
//! ```toml
//! [[objects]]
//! type = "mesh"
//! file = "meshes/bunny.obj"
//! material = "white"
//! lod = 1.0        # the surface may move by up to 1 pixel's footprint; 0 keeps every triangle
//! ```
//! Which meshes are simplified, and with which bound, is decided for the whole scene in
//! [`crate::prepare::lod`]; this module only knows meshes, bounds and a view.

use crate::geometry::MeshShading;
use crate::geometry::mesh::MeshData;
use crate::math::Aabb;
use crate::math::fmath;
use glam::Vec3;
use std::collections::HashMap;

/// The default `lod` of a mesh: the surface may move by a quarter of a pixel's footprint. At one pixel the
/// Stanford bunny's silhouette moved enough that its error was 2–5× the noise of 16 samples per pixel from 64
/// units on; at a quarter it stayed below that noise at every distance measured, with 28× to 2 200× fewer
/// triangles (docs/RESULTS.md, "Level of detail").
pub const DEFAULT_LOD: f32 = 0.25;

/// Below this fraction of the mesh's bounding-box diagonal a bound is not worth simplifying for (positions are
/// f32, good to about 6·10⁻⁸ of their magnitude, and few collapses fit): the mesh is kept whole.
pub const MIN_RELATIVE_BOUND: f32 = 1e-5;

/// What the camera resolves: its eye and the size of the smallest pixel footprint per unit of distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Position of the eye (scene units).
    pub eye: Vec3,
    /// The smallest width of one pixel's footprint at distance 1 from the eye, in scene units per unit of
    /// distance (an angle in radians, to first order).
    pub pixel_per_distance: f32,
}

impl View {
    /// The view of a pinhole camera at `eye` with vertical field of view `fov_degrees` and an image of `width`
    /// × `height` pixels.
    ///
    /// A pixel is `s = 2·tan(fov/2) / height` wide on the image plane at distance 1 (pbrt-v4 §5.1.4 builds the
    /// same plane). Seen from the eye at angle α off the axis, it subtends `s·cos²α` (dθ = cos²α · d(tan α)),
    /// smallest at the image's corner, where `tan²α = half_w² + half_h²`; so `pixel_per_distance =
    /// s / (1 + half_w² + half_h²)`, a footprint no pixel of the image is smaller than. A lens (depth of field)
    /// only blurs, making footprints larger; it is ignored, which keeps the bound safe.
    pub fn pinhole(eye: Vec3, fov_degrees: f32, width: u32, height: u32) -> Self {
        let half_h = fmath::tan(fov_degrees.to_radians() * 0.5);
        let half_w = half_h * width as f32 / height.max(1) as f32;
        let s = 2.0 * half_h / height.max(1) as f32;
        Self { eye, pixel_per_distance: s / (1.0 + half_w * half_w + half_h * half_h) }
    }

    /// The error bound of a mesh whose world-space bounding box is `bounds`, for a `lod` in pixels: `lod` × the
    /// smallest pixel footprint at the box's nearest point to the eye (no point of the mesh is nearer, so no
    /// point of it sees a smaller footprint), rounded down to a quarter octave ([`quantise_down`]) so that a
    /// small move of the camera gives the same bound, hence the same mesh. `None` when the mesh is kept whole:
    /// `lod` is 0, the box is empty, or the bound is below [`MIN_RELATIVE_BOUND`] of the box's diagonal (the
    /// eye is inside the box or very near it).
    pub fn error_bound(&self, bounds: Aabb, lod: f32) -> Option<f32> {
        if lod.is_nan() || lod <= 0.0 || bounds.min.x.partial_cmp(&bounds.max.x).is_none_or(|o| o.is_gt()) {
            return None;
        }
        let (lo, hi) = (bounds.min, bounds.max);
        let distance = (self.eye.clamp(lo, hi) - self.eye).length();
        let bound = quantise_down(lod * distance * self.pixel_per_distance);
        let diagonal = (hi - lo).length();
        (bound.is_finite() && bound > 0.0 && bound >= MIN_RELATIVE_BOUND * diagonal).then_some(bound)
    }
}

/// `x` rounded down to the nearest `m · 2^e` with `m` in {1, 1.25, 1.5, 1.75}: the exponent and the top two
/// mantissa bits of its f32 form, exact and the same on every platform (no logarithm). A positive normal `x`
/// loses at most 20 % (1.25 → 1); zero, subnormal, negative or non-finite `x` gives 0 or itself unchanged.
pub fn quantise_down(x: f32) -> f32 {
    if !(x.is_normal() && x > 0.0) {
        return if x.is_finite() && x > 0.0 { 0.0 } else { x };
    }
    // Sign 0, 8 exponent bits, 23 mantissa bits: keep the exponent and the mantissa's top two.
    f32::from_bits(x.to_bits() & 0xFFE0_0000)
}

/// The world-space bounding box of the vertex positions (`v` lines) of OBJ text, each placed by
/// `world_from_object` exactly as the loader places it. A line that does not parse is skipped: the loader
/// reports it. Empty when there are no vertices.
pub fn obj_bounds(text: &str, world_from_object: &glam::Affine3A) -> Aabb {
    let mut b = Aabb::EMPTY;
    for line in text.lines() {
        let code = line.split('#').next().unwrap_or("");
        let mut words = code.split_whitespace();
        if words.next() != Some("v") {
            continue;
        }
        let mut p = [0.0f32; 3];
        let mut ok = true;
        for c in &mut p {
            match words.next().map(str::parse::<f32>) {
                Some(Ok(v)) if v.is_finite() => *c = v,
                _ => ok = false,
            }
        }
        if ok {
            let w = world_from_object.transform_point3(Vec3::from_array(p));
            b = b.union(Aabb { min: w, max: w });
        }
    }
    b
}

/// The fewest triangles simplification leaves of a mesh (of more). meshoptimizer's error is a mean over the
/// planes of the faces a vertex replaced, and as a small far mesh degenerates the mean can stay below the bound
/// while the mesh goes: the torus of `scenes/meshes` (1.5 units wide), 30 units away in a 24-pixel image, fell
/// from 1 600 triangles to none at a bound of 0.63 (reported error 0.40), and with it its shadow and the light
/// it reflects. The floor keeps a coarse shape of every mesh.
pub const MIN_TRIANGLES: usize = 32;

/// A mesh corner's position, normal and UV, by their bits.
type Corner = ([u32; 3], [u32; 3], [u32; 2]);

/// A simplified mesh and the error meshoptimizer reports for it.
#[derive(Clone, Debug)]
pub struct Simplified {
    /// The mesh: triangles of the input's vertices, with their own normals and UVs.
    pub mesh: MeshData,
    /// meshoptimizer's error of the result, in scene units: the square root of the area-weighted mean squared
    /// distance from the collapsed vertices to the planes of the faces they replaced (Garland & Heckbert 1997,
    /// "Surface simplification using quadric error metrics"). An estimate of how far the surface moved, not a
    /// hard bound on the largest distance (see `docs/SCENE.md`, "Level of detail").
    pub error: f32,
}

/// Simplifies `mesh` with meshoptimizer's `meshopt_simplify` until the next collapse would exceed `bound`
/// (scene units, its absolute-error mode), with the mesh's topological border locked in place.
///
/// Vertices are made unique per (position, normal, UV) corner, compared by their bits, so a UV seam or a crease
/// (two normals at one position) is an attribute discontinuity: meshoptimizer collapses along such a seam only,
/// never across it, and never moves or blends a vertex, so every output corner carries a normal and UV of the
/// input. The same input gives the same output (the simplifier is sequential and deterministic).
///
/// Positions alone decide: weighing the normals in as attributes (`meshopt_simplifyWithAttributes`) keeps the
/// shading of a near smooth mesh closer, but its term does not fade as triangles shrink below a pixel, so a far
/// bumpy mesh would keep most of its triangles (docs/RESULTS.md, "Level of detail").
pub fn simplify(mesh: &MeshData, bound: f32) -> Simplified {
    let sh = &mesh.shading;
    let has_normals = sh.normal_indices.len() == mesh.triangles.len() && !mesh.triangles.is_empty();
    let has_uvs = sh.uv_indices.len() == mesh.triangles.len() && !mesh.triangles.is_empty();
    let bits3 = |v: [f32; 3]| v.map(f32::to_bits);
    // One vertex per distinct (position, normal, uv) by bits; the first corner seen numbers it.
    let mut index_of: HashMap<Corner, u32> = HashMap::new();
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    let mut indices: Vec<u32> = Vec::with_capacity(mesh.triangles.len() * 3);
    for (f, t) in mesh.triangles.iter().enumerate() {
        for (k, p) in t.iter().enumerate() {
            let n = if has_normals { sh.normals[sh.normal_indices[f][k] as usize] } else { [0.0; 3] };
            let uv = if has_uvs { sh.uvs[sh.uv_indices[f][k] as usize] } else { [0.0; 2] };
            let key = (bits3(p.to_array()), bits3(n), uv.map(f32::to_bits));
            let next = positions.len() as u32;
            let i = *index_of.entry(key).or_insert_with(|| {
                positions.push(p.to_array());
                normals.push(n);
                uvs.push(uv);
                next
            });
            indices.push(i);
        }
    }
    let mut error = 0.0f32;
    let options = meshopt::SimplifyOptions::LockBorder | meshopt::SimplifyOptions::ErrorAbsolute;
    // The error bound stops the collapses, or the floor of MIN_TRIANGLES.
    let target = 3 * MIN_TRIANGLES.min(mesh.triangles.len());
    let out = meshopt::simplify_decoder(&indices, &positions, target, bound, options, Some(&mut error));
    // The vertices still used, renumbered in order of first use.
    let mut renumber = vec![u32::MAX; positions.len()];
    let mut used = 0u32;
    let mut shading = MeshShading::default();
    let mut triangles = Vec::with_capacity(out.len() / 3);
    for tri in out.chunks_exact(3) {
        let mut corner = [0u32; 3];
        for (k, &v) in tri.iter().enumerate() {
            let v = v as usize;
            if renumber[v] == u32::MAX {
                renumber[v] = used;
                used += 1;
                if has_normals {
                    shading.normals.push(normals[v]);
                }
                if has_uvs {
                    shading.uvs.push(uvs[v]);
                }
            }
            corner[k] = renumber[v];
        }
        triangles.push([0, 1, 2].map(|k| Vec3::from_array(positions[tri[k] as usize])));
        if has_normals {
            shading.normal_indices.push(corner);
        }
        if has_uvs {
            shading.uv_indices.push(corner);
        }
    }
    Simplified { mesh: MeshData { triangles, shading }, error }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantising_rounds_down_to_quarter_octaves() {
        assert_eq!(quantise_down(1.0), 1.0);
        assert_eq!(quantise_down(1.2), 1.0);
        assert_eq!(quantise_down(1.3), 1.25);
        assert_eq!(quantise_down(1.99), 1.75);
        assert_eq!(quantise_down(0.004), 0.00390625);
        assert_eq!(quantise_down(0.0), 0.0);
        for x in [1e-3f32, 0.37, 5.0, 1234.5] {
            let q = quantise_down(x);
            assert!(q <= x && q > 0.8 * x, "{x} → {q}");
            // A nearby value lands on the same step.
            assert_eq!(quantise_down(q * 1.0001), q);
        }
    }

    #[test]
    fn bound_is_a_pixel_at_the_nearest_point() {
        // A 90° square view of 100 pixels: a pixel is 0.02 wide at distance 1 on the axis, 0.02/3 at the corner.
        let view = View::pinhole(Vec3::ZERO, 90.0, 100, 100);
        assert!((view.pixel_per_distance - 0.02 / 3.0).abs() < 1e-7);
        let b = Aabb { min: Vec3::new(-1.0, -1.0, -11.0), max: Vec3::new(1.0, 1.0, -10.0) };
        let bound = view.error_bound(b, 1.0).unwrap();
        let exact = 10.0 * 0.02 / 3.0;
        assert!(bound <= exact && bound > 0.8 * exact, "{bound}");
        assert_eq!(view.error_bound(b, 2.0).unwrap(), quantise_down(2.0 * 10.0 * view.pixel_per_distance));
        // Off, and the eye inside the box: no bound.
        assert_eq!(view.error_bound(b, 0.0), None);
        let around = Aabb { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) };
        assert_eq!(view.error_bound(around, 1.0), None);
        assert_eq!(view.error_bound(Aabb::EMPTY, 1.0), None);
    }

    #[test]
    fn a_small_far_mesh_keeps_a_coarse_shape() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/meshes/torus.obj");
        let text = std::fs::read_to_string(&path).unwrap();
        let normals = crate::geometry::mesh::Normals::default();
        let torus = crate::geometry::mesh::parse_obj(&text, &path, &glam::Affine3A::IDENTITY, normals).unwrap();
        let s = simplify(&torus, 0.625);
        assert!(s.mesh.triangles.len() >= MIN_TRIANGLES, "{} triangles", s.mesh.triangles.len());
        assert!(s.mesh.triangles.len() < torus.triangles.len() / 10);
    }

    #[test]
    fn obj_bounds_transform_every_vertex() {
        let xf = glam::Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0));
        let b = obj_bounds("v 0 0 0\nv 1 2 3 # c\nvt 9 9\nvn 9 9 9\nv 1 x 0\nf 1 2 1\n", &xf);
        assert_eq!(b.min, Vec3::new(0.0, 0.0, 5.0));
        assert_eq!(b.max, Vec3::new(1.0, 2.0, 8.0));
    }
}
