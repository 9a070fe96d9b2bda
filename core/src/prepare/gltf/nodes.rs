//! The node hierarchy of a glTF scene: each node's world transform (its matrix, or translation × rotation ×
//! scale, after its parent's: glTF 2.0 §3.5.3), and what it carries: mesh primitives as world-space triangles,
//! the first perspective camera, `KHR_lights_punctual` lights.
//!
//! Positions are `f32` `VEC3`; normals `f32` `VEC3`, transformed by the inverse transpose and normalised;
//! tangents `f32` `VEC4`, transformed by the linear part, their `w` the bitangent's sign; UVs (`TEXCOORD_0`, float
//! or normalised integers) flipped to photon's `v`-up convention (`v' = 1 − v`); each attribute one value a
//! vertex; indices unsigned integers, each below the vertex count. A node whose world transform mirrors
//! (negative determinant) has its triangles' winding reversed, as glTF asks, so faces keep their front, and its
//! tangents' `w` turned. Without normals a primitive is flat shaded and its tangents ignored, as the
//! specification asks. A primitive whose material is a textured cut-out carries its mask (`materials`).

use super::materials::emission_scale;
use super::types::{Import, ImportError, Imported, ImportedCamera, ImportedMesh, malformed};
use crate::Rgb;
use crate::geometry::MeshShading;
use crate::geometry::mesh::MeshData;
use crate::scene::LightSpec;
use glam::{Affine3A, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Semantic;

/// Walks the default scene (or the first; with none, every node without a parent) from `world_from_object`.
pub(super) fn walk(im: &mut Import<'_>, world_from_object: &Affine3A, out: &mut Imported) -> Result<(), ImportError> {
    let doc = im.doc;
    let roots: Vec<gltf::Node<'_>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let children: std::collections::BTreeSet<usize> =
                doc.nodes().flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>()).collect();
            doc.nodes().filter(|n| !children.contains(&n.index())).collect()
        }
    };
    let mut visited = vec![false; doc.nodes().len()];
    let mut stack: Vec<(gltf::Node<'_>, Affine3A)> = roots.into_iter().rev().map(|n| (n, *world_from_object)).collect();
    while let Some((node, parent)) = stack.pop() {
        let seen = visited.get_mut(node.index()).ok_or_else(|| malformed(im.file, "a node index is out of range"))?;
        if std::mem::replace(seen, true) {
            return Err(malformed(
                im.file,
                format!("nodes[{}] is reached twice: nodes must form trees (one parent each, no cycles)", node.index()),
            )
            .into());
        }
        let local = Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()));
        let world = parent * local;
        if !world.is_finite() {
            return Err(malformed(im.file, format!("nodes[{}]: its transform is not finite", node.index())).into());
        }
        if let Some(mesh) = node.mesh() {
            if node.skin().is_some() {
                im.warn("skins are not supported: skinned meshes are posed as their nodes place them");
            }
            for p in mesh.primitives() {
                if let Some(m) = primitive(im, &mesh, &p, &world)? {
                    out.meshes.push(m);
                }
            }
        }
        if let Some(c) = node.camera() {
            camera(im, &c, &world, &mut out.camera);
        }
        if let Some(l) = node.light() {
            out.lights.extend(light(im, &l, &world));
        }
        stack.extend(node.children().collect::<Vec<_>>().into_iter().rev().map(|c| (c, world)));
    }
    Ok(())
}

/// The first perspective camera; an orthographic one is warned about.
fn camera(im: &mut Import<'_>, c: &gltf::Camera<'_>, world: &Affine3A, slot: &mut Option<ImportedCamera>) {
    match c.projection() {
        gltf::camera::Projection::Perspective(p) => {
            if slot.is_none() {
                *slot = Some(ImportedCamera { world_from_camera: *world, yfov: p.yfov(), aspect: p.aspect_ratio() });
            }
        }
        gltf::camera::Projection::Orthographic(_) => {
            im.warn("orthographic cameras are not supported: they are ignored");
        }
    }
}

/// A `KHR_lights_punctual` light at its node: glTF's photometric numbers read as radiometric ones (candela as
/// W/sr, lux as W/m²: docs/SCENE.md), its colour multiplying them.
fn light(im: &mut Import<'_>, l: &gltf::khr_lights_punctual::Light<'_>, world: &Affine3A) -> Option<LightSpec> {
    let intensity = Vec3::from(l.color()) * l.intensity();
    let position = Vec3::from(world.translation);
    // Spot and directional lights shine down their node's −z axis.
    let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
    if l.range().is_some() {
        im.warn("KHR_lights_punctual range is not supported: lights fall off with the inverse square to any distance");
    }
    match l.kind() {
        gltf::khr_lights_punctual::Kind::Point => {
            Some(LightSpec::Point { position, intensity: Some(intensity.max(Vec3::ZERO)), power: None })
        }
        gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
            spot_light(im, position, direction, intensity, inner_cone_angle, outer_cone_angle)
        }
        gltf::khr_lights_punctual::Kind::Directional => directional_light(direction, intensity),
    }
}

/// A spot light at `position` shining along `direction` with `intensity` (W/sr) on its axis, full within
/// `inner` of the axis and zero beyond `outer` (radians, glTF's `innerConeAngle` and `outerConeAngle`), falling
/// off between as photon's spot lights do (a smoothstep in the cosine; glTF suggests a squared linear ramp in
/// the cosine, which differs by a few per cent inside the ramp). Angles outside `0 ≤ inner < outer ≤ π/2` are
/// clamped into it, with a warning.
fn spot_light(
    im: &mut Import<'_>,
    position: Vec3,
    direction: Vec3,
    intensity: Vec3,
    inner: f32,
    outer: f32,
) -> Option<LightSpec> {
    let outer_deg = if outer.is_finite() { outer.to_degrees().clamp(1e-3, 90.0) } else { 45.0 };
    let inner_deg = if inner.is_finite() { inner.to_degrees().clamp(0.0, outer_deg) } else { 0.0 };
    if outer_deg != outer.to_degrees() || inner_deg != inner.to_degrees() {
        im.warn("KHR_lights_punctual spot cone angles outside 0 ≤ inner < outer ≤ π/2 are clamped into that range");
    }
    Some(LightSpec::Spot {
        position,
        direction,
        intensity: Some(intensity.max(Vec3::ZERO)),
        power: None,
        inner_angle: inner_deg,
        outer_angle: outer_deg,
    })
}

/// A directional light travelling along `direction` with `irradiance` (W/m²) on a surface facing it.
fn directional_light(direction: Vec3, irradiance: Vec3) -> Option<LightSpec> {
    Some(LightSpec::Directional { direction, irradiance: irradiance.max(Vec3::ZERO) })
}

/// Checks that `accessor` holds `dims` of one of `types`; `what` names it in the error.
fn check_accessor(
    im: &Import<'_>,
    accessor: &gltf::Accessor<'_>,
    dims: Dimensions,
    types: &[DataType],
    what: &str,
) -> Result<(), ImportError> {
    if accessor.dimensions() != dims || !types.contains(&accessor.data_type()) {
        return Err(malformed(
            im.file,
            format!(
                "{what} (accessors[{}]) is {:?} of {:?}; expected {dims:?} of {types:?}",
                accessor.index(),
                accessor.dimensions(),
                accessor.data_type()
            ),
        )
        .into());
    }
    if accessor.normalized() && accessor.data_type() == DataType::F32 {
        return Err(
            malformed(im.file, format!("{what} (accessors[{}]) is float and normalized", accessor.index())).into()
        );
    }
    Ok(())
}

/// Requires each attribute of `counts` that a primitive has (a count above 0) to have one value a vertex, as
/// POSITION's `vertices` (specification §3.7.2.1).
fn check_counts(im: &Import<'_>, name: &str, vertices: usize, counts: &[(&str, usize)]) -> Result<(), ImportError> {
    match counts.iter().find(|(_, c)| *c != 0 && *c != vertices) {
        Some((attribute, c)) => Err(malformed(
            im.file,
            format!("{name}.attributes.{attribute} has {c} values, but POSITION has {vertices} vertices"),
        )
        .into()),
        None => Ok(()),
    }
}

/// Reads an accessor through `read`, requiring exactly its `count` items.
fn read_all<T>(
    im: &Import<'_>,
    accessor: &gltf::Accessor<'_>,
    what: &str,
    items: Option<impl Iterator<Item = T>>,
) -> Result<Vec<T>, ImportError> {
    let v: Vec<T> = items.map(Iterator::collect).unwrap_or_default();
    if v.len() != accessor.count() {
        return Err(malformed(
            im.file,
            format!(
                "{what} (accessors[{}]) promises {} items but its buffer data hold {} (a missing buffer view or a \
                 view that reaches past its buffer?)",
                accessor.index(),
                accessor.count(),
                v.len()
            ),
        )
        .into());
    }
    Ok(v)
}

/// One primitive of `mesh` placed by `world`: `None` for a primitive that is not drawn (another mode than
/// triangles, a cut-out material).
fn primitive(
    im: &mut Import<'_>,
    mesh: &gltf::Mesh<'_>,
    p: &gltf::Primitive<'_>,
    world: &Affine3A,
) -> Result<Option<ImportedMesh>, ImportError> {
    let name = format!("meshes[{}].primitives[{}]", mesh.index(), p.index());
    if p.mode() != gltf::mesh::Mode::Triangles {
        im.warn(format!("primitive mode {:?} is not supported: only TRIANGLES are drawn", p.mode()));
        return Ok(None);
    }
    if p.morph_targets().len() > 0 {
        im.warn("morph targets are not supported: meshes keep their base shape");
    }
    if p.get(&Semantic::Colors(0)).is_some() {
        im.warn("COLOR_0 vertex colours are not read: the base colour and its alpha come from the factor and texture");
    }
    let m = p.material();
    if m.alpha_mode() == gltf::material::AlphaMode::Mask
        && m.pbr_metallic_roughness().base_color_factor()[3] < m.alpha_cutoff().unwrap_or(0.5)
    {
        return Ok(None);
    }
    let buffers = &im.buffers;
    let reader = p.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let pos_acc = p.get(&Semantic::Positions).ok_or_else(|| malformed(im.file, format!("{name} has no POSITION")))?;
    check_accessor(im, &pos_acc, Dimensions::Vec3, &[DataType::F32], &format!("{name}.attributes.POSITION"))?;
    let positions = read_all(im, &pos_acc, &format!("{name}.attributes.POSITION"), reader.read_positions())?;
    let normals = match p.get(&Semantic::Normals) {
        Some(a) => {
            let what = format!("{name}.attributes.NORMAL");
            check_accessor(im, &a, Dimensions::Vec3, &[DataType::F32], &what)?;
            read_all(im, &a, &what, reader.read_normals())?
        }
        None => Vec::new(),
    };
    // Without normals the faces shade flat and the tangents are ignored (specification §3.7.2.1).
    let tangents = match p.get(&Semantic::Tangents) {
        Some(a) if !normals.is_empty() => {
            let what = format!("{name}.attributes.TANGENT");
            check_accessor(im, &a, Dimensions::Vec4, &[DataType::F32], &what)?;
            read_all(im, &a, &what, reader.read_tangents())?
        }
        _ => Vec::new(),
    };
    let uvs = match p.get(&Semantic::TexCoords(0)) {
        Some(a) => {
            let what = format!("{name}.attributes.TEXCOORD_0");
            check_accessor(im, &a, Dimensions::Vec2, &[DataType::F32, DataType::U8, DataType::U16], &what)?;
            read_all(im, &a, &what, reader.read_tex_coords(0).map(|t| t.into_f32()))?
        }
        None => Vec::new(),
    };
    let n = positions.len();
    check_counts(im, &name, n, &[("NORMAL", normals.len()), ("TANGENT", tangents.len()), ("TEXCOORD_0", uvs.len())])?;
    let indices: Vec<u32> = match p.indices() {
        Some(a) => {
            let what = format!("{name}.indices");
            check_accessor(im, &a, Dimensions::Scalar, &[DataType::U8, DataType::U16, DataType::U32], &what)?;
            read_all(im, &a, &what, reader.read_indices().map(|i| i.into_u32()))?
        }
        None => (0..n as u32).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(malformed(
            im.file,
            format!("{name}: {} indices is not a whole number of triangles", indices.len()),
        )
        .into());
    }
    if let Some((k, i)) = indices.iter().enumerate().find(|(_, i)| **i as usize >= n) {
        return Err(
            malformed(im.file, format!("{name}.indices[{k}] is {i}, out of range: POSITION has {n} vertices")).into()
        );
    }
    let flip = world.matrix3.determinant() < 0.0;
    let faces: Vec<[u32; 3]> =
        indices.chunks_exact(3).map(|t| if flip { [t[0], t[2], t[1]] } else { [t[0], t[1], t[2]] }).collect();
    let mut shading = shading(world, &faces, &normals, &tangents, &uvs);
    let at = |i: u32| world.transform_point3(Vec3::from(positions[i as usize]));
    let triangles: Vec<[Vec3; 3]> = faces.iter().map(|f| [at(f[0]), at(f[1]), at(f[2])]).collect();
    let emission = emission(&m, faces.len());
    let material = m.index().map_or(im.doc.materials().len(), |i| i) as u32;
    shading.mask = im.material_masks.get(material as usize).copied().flatten();
    let emission_image =
        if emission.is_empty() { None } else { im.material_emission.get(material as usize).copied().flatten() };
    Ok(Some(ImportedMesh {
        mesh: MeshData { triangles, shading },
        material,
        emission,
        emission_image,
        two_sided_emission: m.double_sided(),
    }))
}

/// The shading data of a primitive's `faces` (already wound for `world`) from its object-space attributes, in
/// world space: normals by the inverse transpose, tangents by the linear part, UVs flipped to photon's `v` up.
/// A mirroring `world` turns the bitangent `w · (n × t)` around, so `w` changes sign with it.
fn shading(
    world: &Affine3A,
    faces: &[[u32; 3]],
    normals: &[[f32; 3]],
    tangents: &[[f32; 4]],
    uvs: &[[f32; 2]],
) -> MeshShading {
    let mut shading = MeshShading::default();
    if !normals.is_empty() {
        let normal_from = world.matrix3.inverse().transpose();
        shading.normals =
            normals.iter().map(|v| (normal_from * glam::Vec3A::from(*v)).normalize_or_zero().to_array()).collect();
        shading.normal_indices = faces.to_vec();
        let w_sign = if world.matrix3.determinant() < 0.0 { -1.0 } else { 1.0 };
        shading.tangents = tangents
            .iter()
            .map(|[x, y, z, w]| {
                let t = (world.matrix3 * glam::Vec3A::new(*x, *y, *z)).normalize_or_zero();
                [t.x, t.y, t.z, if *w < 0.0 { -w_sign } else { w_sign }]
            })
            .collect();
    }
    if !uvs.is_empty() {
        shading.uvs = uvs.iter().map(|[u, v]| [*u, 1.0 - *v]).collect();
        shading.uv_indices = faces.to_vec();
    }
    shading
}

/// Each face's emitted radiance scale ([`emission_scale`]; the material's emissive texture multiplies it point
/// by point), or empty when the material emits nothing.
fn emission(m: &gltf::Material<'_>, faces: usize) -> Vec<Rgb> {
    let e = emission_scale(m);
    if e.max_element() > 0.0 { vec![e; faces] } else { Vec::new() }
}
