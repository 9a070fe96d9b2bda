//! From a parsed [`Scene`] to the [`Prepared`] value that renders, in steps that callers compose:
//! [`Prepared::new`] loads meshes, gathers primitives under a BVH, resolves materials to indices and builds the
//! lights; [`Prepared::with_photon_maps`] traces the photon maps the method needs ([`photons`]); [`blobs`]
//! encodes the result for the wire and the caches. A path traced in a prepared job carries it in a
//! [`tracer::Tracer`], with its sample stream and ray count.

pub mod blobs;
pub mod budget;
pub mod gltf;
pub mod lod;
pub mod photons;
pub mod textures;
pub mod tracer;

use crate::Rgb;
use crate::camera::Camera;
use crate::geometry::mask::AlphaMask;
use crate::geometry::mesh::Normals;
use crate::geometry::shapes::{Plane, Shape, Sphere, Triangle};
use crate::geometry::{Geometry, MeshShading, NONE, PlanePrimitive, Primitive};
use crate::light::{BoundingSphere, EmissionImage, Light, LightScene, LightSet, SkyDistribution};
use crate::material::{Material, TexelImage};
use crate::math::fmath;
use crate::medium::{Boundary, Media, Medium};
use crate::method::RadiusSetting;
use crate::photon::{Estimator, Gather, PhotonMaps};
use crate::scene::{Emission, GatherMode, LightSpec, MediumSpec, Object, RenderSettings, Scene, SceneError};
use glam::Vec3A;
use serde::{Deserialize, Serialize};

/// Everything a worker needs to render any pixel of a scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Prepared {
    /// The camera.
    pub camera: Camera,
    /// Surfaces and their BVH.
    pub geometry: Geometry,
    /// Materials, indexed by primitives.
    pub materials: Vec<Material>,
    /// Lights.
    pub lights: LightSet,
    /// Render settings.
    pub settings: RenderSettings,
    /// Photon maps, when the method needs them.
    pub photons: Option<PhotonMaps>,
    /// The participating media, when the scene has any (`None` otherwise: no medium code runs).
    pub media: Option<Media>,
    /// The texture images, indexed by the materials' image slots ([`textures`]). They travel as their own
    /// blobs, not with the scene.
    #[serde(skip)]
    pub textures: std::sync::Arc<Vec<TexelImage>>,
}

impl Prepared {
    /// What the lights read beside themselves: the geometry, the texture images and the environment's
    /// distribution.
    #[inline]
    pub fn light_scene(&self) -> LightScene<'_> {
        self.lights.scene(&self.geometry, &self.textures)
    }

    /// Loads meshes, builds the BVH, resolves materials to indices and builds the lights, for a validated
    /// scene; `scene_path` names the scene in errors. Photon maps are a separate step
    /// ([`Prepared::with_photon_maps`]): `photons` is `None` here.
    pub fn new(scene: &Scene, scene_path: &std::path::Path) -> Result<Self, SceneError> {
        let mut imported = gltf::import_all(scene, scene_path)?;
        let (materials, images, env_slot) = textures::load_with(scene, scene_path, &mut imported)?;
        let (mut geometry, emitters, boundaries) = geometry(scene, scene_path, &imported)?;
        check_photon_radius(scene, &geometry, scene_path)?;
        let specs: Vec<LightSpec> =
            scene.lights.iter().chain(imported.iter().flatten().flat_map(|i| i.lights.iter())).cloned().collect();
        check_imported_lights(scene, scene_path, &specs)?;
        let lights = lights(&specs, &mut geometry, &emitters, &images, env_slot);
        let media = boundaries.map(|boundaries| media(scene, &geometry, &lights, boundaries));
        if media.is_some() && scene.render.integrator.warns_in_media() {
            tracing::warn!(
                "{}: {}'s subpaths do not cross participating media; its passes are the volumetric path tracer's \
                 samples",
                scene_path.display(),
                scene.render.integrator
            );
        }
        Ok(Self {
            camera: Camera::new(&scene.camera),
            geometry,
            materials,
            lights,
            settings: scene.render.clone(),
            photons: None,
            media,
            textures: std::sync::Arc::new(images),
        })
    }

    /// The gather radius in scene units: `render.photons.radius`, or 2% of the diagonal of the bounding box of
    /// the bounded primitives (1 unit for a scene of planes only).
    pub fn photon_radius(&self) -> f32 {
        self.settings.photons.radius.unwrap_or_else(|| 0.02 * scene_size(&self.geometry))
    }

    /// The first merging radius of vertex connection and merging, in scene units: `render.photons.merge_radius`,
    /// or the width of one pixel on the plane of focus ([`crate::camera::Camera::pixel_footprint`]). Merges
    /// estimate the density of light vertices per pixel, and a camera subpath meets `width × height` light
    /// subpaths per iteration: a pixel's footprint holds a few of their vertices (Georgiev et al. 2012, §7,
    /// use a radius of that order). The photon maps' `radius` is not used: it is sized for maps of far fewer
    /// photons (a stress scene's radius of 1 made vcm 14× slower and 5.7 % too dark).
    pub fn merge_radius(&self) -> f32 {
        self.settings.photons.merge_radius.unwrap_or_else(|| self.camera.pixel_footprint())
    }

    /// The radiance estimator of the photon settings.
    pub fn estimator(&self) -> Estimator {
        let ph = &self.settings.photons;
        let radius = self.photon_radius();
        let gather = match ph.gather {
            GatherMode::KNearest => Gather::KNearest { k: ph.k, max_radius: radius },
            GatherMode::Radius => Gather::Radius { radius },
        };
        Estimator { gather, kernel: ph.kernel, disc: ph.disc, same_object: ph.same_object }
    }

    /// The volume gather radius in scene units: `render.photons.volume_radius`, or twice the surface radius
    /// ([`Prepared::photon_radius`]): photons in a volume are spread over three dimensions, not two.
    pub fn volume_radius(&self) -> f32 {
        self.settings.photons.volume_radius.unwrap_or_else(|| 2.0 * self.photon_radius())
    }

    /// How the volume photon map is gathered: like the surface maps (`gather`, `k`), within the volume radius.
    pub fn volume_gather(&self) -> Gather {
        let ph = &self.settings.photons;
        let radius = self.volume_radius();
        match ph.gather {
            GatherMode::KNearest => Gather::KNearest { k: ph.k, max_radius: radius },
            GatherMode::Radius => Gather::Radius { radius },
        }
    }

    /// Loads and prepares a scene file, with the photon maps its method needs.
    pub fn load(path: &std::path::Path) -> Result<Self, SceneError> {
        let scene = Scene::load(path)?;
        Self::new(&scene, path)?.with_photon_maps(path)
    }
}

/// The smallest gather radius allowed, as a fraction of the scene's size (`scene_size`). Positions are
/// f32, good to about 6·10⁻⁸ of their magnitude, so a smaller disc holds no photon that is not a rounding
/// accident, and its squared radius may underflow (1e-25² is 0 in f32), which turns `Φ / (π r²)` into NaN.
pub const MIN_RELATIVE_PHOTON_RADIUS: f32 = 1e-6;

/// The size of the scene: the diagonal of the bounding box of its bounded primitives, or 1 unit for a scene
/// of planes only.
fn scene_size(geometry: &Geometry) -> f32 {
    let b = geometry.bounds();
    let d = (b.max - b.min).length();
    if d.is_finite() && d > 0.0 { d } else { 1.0 }
}

/// Rejects a `render.photons.radius` below [`MIN_RELATIVE_PHOTON_RADIUS`] of the scene's size for the methods
/// that gather photons, and a `render.photons.merge_radius` below it for `vcm`, which merges light vertices
/// within it. Validation cannot do it: it does not know the scene's size before meshes are loaded.
fn check_photon_radius(scene: &Scene, geometry: &Geometry, scene_path: &std::path::Path) -> Result<(), SceneError> {
    let ph = &scene.render.photons;
    let setting = scene.render.integrator.radius();
    let Some(field) = setting.field() else { return Ok(()) };
    let radius = match setting {
        RadiusSetting::Photon => ph.radius,
        RadiusSetting::Merge => ph.merge_radius,
        RadiusSetting::None => None,
    };
    let Some(radius) = radius else { return Ok(()) };
    let size = scene_size(geometry);
    let floor = MIN_RELATIVE_PHOTON_RADIUS * size;
    // Validation has already rejected NaN and non-positive radii.
    if radius < floor {
        return Err(SceneError::Invalid {
            path: scene_path.into(),
            line: None,
            field: field.into(),
            message: format!(
                "{radius:e} is below the smallest gather radius for this scene, {floor:e} \
                 ({MIN_RELATIVE_PHOTON_RADIUS:e} of its size {size})"
            ),
        });
    }
    Ok(())
}

/// A glTF object's directional light in a scene with participating media is refused, as the scene's own are
/// (`Scene::check`): the volumetric paths do not reach infinity. `specs` are the scene's lights, then its glTF
/// objects'.
fn check_imported_lights(scene: &Scene, scene_path: &std::path::Path, specs: &[LightSpec]) -> Result<(), SceneError> {
    let imported = specs.get(scene.lights.len()..).unwrap_or(&[]);
    if scene.has_media() && imported.iter().any(|l| matches!(l, LightSpec::Directional { .. })) {
        return Err(SceneError::Invalid {
            path: scene_path.into(),
            line: None,
            field: "objects".into(),
            message: "a glTF object's directional light is not supported in a scene with participating media".into(),
        });
    }
    Ok(())
}

/// The scene's media: the global one, what each object separates (with the medium outside each closed object:
/// the interior of the closed object around it, or the global one), and the media of the camera and the lights.
fn media(scene: &Scene, geometry: &Geometry, lights: &LightSet, boundaries: Vec<Boundary>) -> Media {
    let mut media = Media {
        global: scene.medium.as_ref().map(MediumSpec::medium),
        boundaries,
        camera: None,
        lights: Vec::new(),
        interfaces: scene.materials.values().any(Material::is_interface),
    };
    // A point on each closed object's surface, tested against every other closed object.
    let mut on_surface: Vec<Option<Vec3A>> = vec![None; media.boundaries.len()];
    for pr in geometry.prims() {
        if let Some(slot @ None) = on_surface.get_mut(pr.object as usize) {
            *slot = Some(pr.shape.sample_area(glam::Vec2::splat(0.5)).0);
        }
    }
    let exteriors: Vec<Option<Medium>> = (0..media.boundaries.len())
        .map(|o| match on_surface[o] {
            Some(p) if matches!(media.boundaries[o], Boundary::Closed { .. }) => media.at(geometry, p, Some(o as u32)),
            _ => media.global,
        })
        .collect();
    for (b, outside) in media.boundaries.iter_mut().zip(exteriors) {
        if let Boundary::Closed { exterior, .. } = b {
            *exterior = outside;
        }
    }
    media.camera = media.at(geometry, Vec3A::from(scene.camera.eye), None);
    media.lights = lights
        .lights
        .iter()
        .map(|l| match l {
            Light::Point { p, .. } | Light::Spot { p, .. } => media.at(geometry, *p, None),
            // An open emitter's medium is the one around a point on it; a closed one's photons leave through
            // its surface, which `Media::leaving` settles.
            Light::Area { prim, .. } => match geometry.prim(*prim) {
                Some(pr) => media.at(geometry, pr.shape.sample_area(glam::Vec2::splat(0.5)).0, Some(pr.object)),
                None => media.global,
            },
            // Not in a scene with media (the scene's check refuses them there).
            Light::Directional { .. } | Light::Environment { .. } => media.global,
        })
        .collect();
    media
}

/// Surfaces, emitters (as [`geometry`]) and, when the scene has media, what each object separates.
type GeometryParts = (Geometry, Vec<Emitter>, Option<Vec<Boundary>>);

/// What one light-carrying primitive emits: its radiance and sides, and the image that multiplies the radiance
/// (a glTF `emissiveTexture`).
type Emitter = (Emission, Option<EmissionImage>);

/// A scene's `[[objects]]` triangle; with texture coordinates, they travel as a one-face mesh's, pushed on
/// `meshes`.
fn triangle_object(vertices: &[glam::Vec3; 3], uv: Option<&[[f32; 2]; 3]>, meshes: &mut Vec<MeshShading>) -> Triangle {
    let mut tri = Triangle::new(vertices[0], vertices[1], vertices[2]);
    if let Some(uv) = uv {
        tri.mesh = meshes.len() as u32;
        tri.face = 0;
        meshes.push(MeshShading { uvs: uv.to_vec(), uv_indices: vec![[0, 1, 2]], ..MeshShading::default() });
    }
    tri
}

/// The scene's surfaces under one BVH, the emission of each light-carrying primitive by its light index
/// (each primitive's `light` holds that index until [`lights`] renumbers it), and when the scene has media,
/// each object's [`Boundary`]: spheres and closed meshes are closed (an `interior` on an open mesh is an
/// error that names the field), everything else open.
fn geometry(
    scene: &Scene,
    scene_path: &std::path::Path,
    imported: &[Option<gltf::Imported>],
) -> Result<GeometryParts, SceneError> {
    let with_media = scene.has_media();
    let mut boundaries: Vec<Boundary> = Vec::new();
    let mut prims: Vec<Primitive> = Vec::new();
    let mut planes = Vec::new();
    let mut meshes = Vec::new();
    let mut masks = Vec::new();
    // Emission of each light-carrying primitive, by light index, before the BVH reorders primitives.
    let mut emitters: Vec<Emitter> = Vec::new();
    let lods = lod::plan(scene);
    // glTF objects' materials follow the scene's, object by object (`textures::load_with`).
    let mut gltf_materials = scene.materials.len() as u32;
    for (i, o) in scene.objects.iter().enumerate() {
        let object = i as u32;
        if let Some(imp) = imported.get(i).and_then(Option::as_ref) {
            gltf_materials +=
                gltf_object(imp, object, gltf_materials, &mut prims, &mut meshes, &mut emitters, &mut masks);
            boundaries.extend(with_media.then_some(Boundary::Open));
            continue;
        }
        let name = o.material().unwrap_or_default();
        let material = scene.materials.keys().position(|n| n == name).ok_or_else(|| SceneError::Invalid {
            path: scene_path.into(),
            line: None,
            field: format!("objects[{i}].material"),
            message: format!("no material named `{name}`"),
        })? as u32;
        let mut push = |shape: Shape, emission: &Option<Emission>| {
            let light = match emission {
                Some(e) if e.radiance.max_element() > 0.0 && shape.area() > 0.0 => {
                    emitters.push((*e, None));
                    (emitters.len() - 1) as u32
                }
                _ => NONE,
            };
            prims.push(Primitive { shape, material, light, object });
        };
        let mut boundary = Boundary::Open;
        match o {
            Object::Sphere { center, radius, emission, interior, .. } => {
                boundary = Boundary::Closed {
                    interior: interior.as_ref().map(MediumSpec::medium),
                    exterior: None,
                    inward: false,
                };
                push(Shape::Sphere(Sphere { center: *center, radius: *radius }), emission)
            }
            Object::Plane { point, normal, .. } => planes.push(PlanePrimitive {
                plane: Plane { point: *point, normal: normal.normalize() },
                material,
                object,
            }),
            Object::Rect { emission, .. } => {
                let rect = o.rect().map_err(|e| {
                    let e = e.within(&format!("objects[{i}]"));
                    SceneError::Invalid { path: scene_path.into(), line: None, field: e.field, message: e.message }
                })?;
                push(Shape::Rect(rect), emission)
            }
            Object::Triangle { vertices, emission, uv, .. } => {
                push(Shape::Triangle(triangle_object(vertices, uv.as_ref(), &mut meshes)), emission)
            }
            Object::Mesh { emission, .. } => {
                let (mesh, b) = mesh_object(scene, scene_path, i, lods.get(i).and_then(Option::as_ref), with_media)?;
                boundary = b;
                let mesh_index = meshes.len() as u32;
                for (face, t) in mesh.triangles.iter().enumerate() {
                    let tri = Triangle { p: *t, mesh: mesh_index, face: face as u32 };
                    // Degenerate faces can never be hit; keep them out of the BVH and the lights.
                    if tri.area() > 0.0 {
                        push(Shape::Triangle(tri), emission);
                    }
                }
                meshes.push(mesh.shading);
            }
            // Expanded above, from its import.
            Object::Gltf { .. } => {}
        }
        if with_media {
            boundaries.push(boundary);
        }
    }
    Ok((Geometry::new(prims, planes, meshes).with_masks(masks), emitters, with_media.then_some(boundaries)))
}

/// The primitives of a glTF object: each imported mesh's triangles with its material (`material_base` plus its
/// index in the import) and, where it emits, its triangle's emission; its cut-outs join `masks`. Returns the
/// import's material count.
fn gltf_object(
    imp: &gltf::Imported,
    object: u32,
    material_base: u32,
    prims: &mut Vec<Primitive>,
    meshes: &mut Vec<MeshShading>,
    emitters: &mut Vec<Emitter>,
    masks: &mut Vec<AlphaMask>,
) -> u32 {
    let mask_base = masks.len() as u32;
    masks.extend(imp.masks.iter().cloned());
    for m in &imp.meshes {
        let mesh_index = meshes.len() as u32;
        let material = material_base + m.material;
        for (face, t) in m.mesh.triangles.iter().enumerate() {
            let tri = Triangle { p: *t, mesh: mesh_index, face: face as u32 };
            if tri.area() <= 0.0 {
                continue;
            }
            let light = match m.emission.get(face) {
                Some(e) if e.max_element() > 0.0 => {
                    let emission = Emission { radiance: (*e).into(), two_sided: m.two_sided_emission };
                    emitters.push((emission, m.emission_image));
                    (emitters.len() - 1) as u32
                }
                _ => NONE,
            };
            prims.push(Primitive { shape: Shape::Triangle(tri), material, light, object });
        }
        let mut shading = m.mesh.shading.clone();
        shading.mask = shading.mask.map(|k| mask_base + k);
        meshes.push(shading);
    }
    imp.materials.len() as u32
}

/// Object `i`, a mesh: its triangles loaded from its file at the level of detail `plan` gives, and when the scene
/// has media (`with_media`), the boundary it makes (closed when every edge is shared by two faces wound
/// opposite ways). Another kind of object gives no triangles and an open boundary. Errors name the object's
/// field: the file cannot be loaded, it lacks the texture coordinates its material needs, or it has an
/// `interior` but no inside.
fn mesh_object(
    scene: &Scene,
    scene_path: &std::path::Path,
    i: usize,
    plan: Option<&lod::MeshLod>,
    with_media: bool,
) -> Result<(crate::geometry::mesh::MeshData, Boundary), SceneError> {
    let o = &scene.objects[i];
    let Object::Mesh { file, transform, smooth, crease_angle, lod, interior, .. } = o else {
        return Ok((crate::geometry::mesh::MeshData::default(), Boundary::Open));
    };
    let invalid = |field: &str, message: String| SceneError::Invalid {
        path: scene_path.into(),
        line: None,
        field: format!("objects[{i}].{field}"),
        message,
    };
    let path = scene.base_dir.join(file);
    let normals = if *smooth { Normals::Smooth { crease_angle: *crease_angle } } else { Normals::Flat };
    let limit = scene.limits.mesh_mib.saturating_mul(1 << 20);
    let mesh = crate::geometry::mesh_file::load_mesh(&path, &transform.matrix(), normals, limit)
        .map_err(|source| SceneError::Mesh { path: scene_path.into(), field: format!("objects[{i}].file"), source })?;
    if mesh.shading.uv_indices.is_empty()
        && let Some(m) = o.material().and_then(|name| scene.materials.get(name))
        && m.needs_uv()
    {
        let message = format!(
            "{} has no texture coordinates (an OBJ's `vt` lines, a PLY's `u`/`v` properties), which material `{}` \
             needs for its textures",
            path.display(),
            o.material().unwrap_or_default()
        );
        return Err(invalid("file", message));
    }
    let mesh = level_of_detail(mesh, plan, file, *lod);
    if !with_media {
        return Ok((mesh, Boundary::Open));
    }
    let boundary = match (crate::medium::closed_mesh_orientation(&mesh.triangles), interior) {
        (Some(inward), interior) => {
            Boundary::Closed { interior: interior.as_ref().map(MediumSpec::medium), exterior: None, inward }
        }
        (None, None) => Boundary::Open,
        (None, Some(_)) => {
            let message = format!(
                "{} is not a closed mesh (some edge is not shared by exactly two faces wound opposite ways), so \
                 it has no inside to fill with a medium",
                path.display()
            );
            return Err(invalid("interior", message));
        }
    };
    Ok((mesh, boundary))
}

/// The mesh as the level-of-detail plan of its object says (simplified, or whole), with a line in the log.
fn level_of_detail(
    mesh: crate::geometry::mesh::MeshData,
    plan: Option<&lod::MeshLod>,
    file: &std::path::Path,
    lod: f32,
) -> crate::geometry::mesh::MeshData {
    let before = mesh.triangles.len();
    match plan {
        Some(lod::MeshLod::Simplify { bound }) => {
            let s = crate::geometry::lod::simplify(&mesh, *bound);
            tracing::info!(
                "mesh {}: {before} triangles → {} (lod {lod}, error {:.3e} scene units; bound {bound:.3e})",
                file.display(),
                s.mesh.triangles.len(),
                s.error
            );
            s.mesh
        }
        Some(lod::MeshLod::Full(why)) if *why != lod::Full::Off => {
            tracing::info!("mesh {}: {before} triangles, all kept: no level of detail, as {why}", file.display());
            mesh
        }
        _ => mesh,
    }
}

/// The lights: area lights in scene order (whatever order the BVH put their primitives in), then point, spot
/// and directional lights in the order of `specs` (the scene's, then its glTF objects'), then the environment
/// (with the distribution of its image, texture slot `env_slot` of `images`); each emitting primitive is
/// pointed at its final light index.
fn lights(
    specs: &[LightSpec],
    geometry: &mut Geometry,
    emitters: &[Emitter],
    images: &[TexelImage],
    env_slot: u32,
) -> LightSet {
    let mut lights: Vec<Light> = Vec::new();
    let mut area_lights: Vec<(u32, Light)> = Vec::new();
    for (pi, p) in geometry.prims().enumerate() {
        if p.light != NONE {
            let (e, image) = emitters[p.light as usize];
            area_lights.push((
                p.light,
                Light::Area {
                    prim: pi as u32,
                    le: Rgb::from(e.radiance),
                    two_sided: e.two_sided,
                    area: p.shape.area(),
                    image,
                },
            ));
        }
    }
    // Keep lights in scene order (by their original index), whatever order the BVH put primitives in.
    area_lights.sort_by_key(|(k, _)| *k);
    lights.extend(area_lights.into_iter().map(|(_, l)| l));
    let bounds = bounding_sphere(geometry);
    // `intensity`, or `power` over the light's power at unit intensity ([`Light::power`]).
    let intensity = |unit: Light, intensity: &Option<glam::Vec3>, power: &Option<glam::Vec3>| match (intensity, power) {
        (Some(i), _) => Rgb::from(*i),
        (None, Some(p)) => Rgb::from(*p) / unit.power().x,
        (None, None) => Rgb::ZERO,
    };
    let mut environment = None;
    for l in specs {
        let light = match l {
            LightSpec::Point { position, intensity: i, power } => {
                let point = |intensity| Light::Point { p: Vec3A::from(*position), intensity };
                point(intensity(point(Rgb::ONE), i, power))
            }
            LightSpec::Spot { position, direction, intensity: i, power, inner_angle, outer_angle } => {
                let (p, axis) = (Vec3A::from(*position), fmath::normalize(Vec3A::from(*direction)));
                let (cos_outer, cos_inner) =
                    (fmath::cos(outer_angle.to_radians()), fmath::cos(inner_angle.to_radians()));
                let spot = |intensity| Light::Spot { p, intensity, axis, cos_outer, cos_inner };
                spot(intensity(spot(Rgb::ONE), i, power))
            }
            LightSpec::Directional { direction, irradiance } => Light::Directional {
                d: fmath::normalize(Vec3A::from(*direction)),
                irradiance: Rgb::from(*irradiance),
                bounds,
            },
            // The environment comes last ([`LightSet::environment`]).
            LightSpec::Environment { radiance, scale, rotate, .. } => {
                environment = Some(environment_light(*radiance, *scale, *rotate, images, env_slot, bounds));
                continue;
            }
        };
        lights.push(light);
    }
    let sky = environment.and_then(|(light, sky)| {
        lights.push(light);
        sky
    });
    // Primitives point at their light by the final light index.
    let mut light_of_prim = vec![NONE; geometry.prim_count()];
    for (li, l) in lights.iter().enumerate() {
        if let Light::Area { prim, .. } = l {
            light_of_prim[*prim as usize] = li as u32;
        }
    }
    for (p, l) in geometry.prims_mut().iter_mut().zip(light_of_prim) {
        p.light = l;
    }
    LightSet::new(lights, sky)
}

/// The environment light of a `radiance`, or of texture slot `env_slot` of `images` times `scale`, turned by
/// `rotate` degrees about +y, with the distribution of its image.
fn environment_light(
    radiance: Option<glam::Vec3>,
    scale: f32,
    rotate: f32,
    images: &[TexelImage],
    env_slot: u32,
    bounds: BoundingSphere,
) -> (Light, Option<SkyDistribution>) {
    let image = images.get(env_slot as usize);
    let (radiance, mean) = match (radiance, image) {
        (Some(r), _) => (Rgb::from(r), Rgb::from(r)),
        (None, Some(img)) => (Rgb::splat(scale), scale * SkyDistribution::mean_radiance(img)),
        (None, None) => (Rgb::ZERO, Rgb::ZERO),
    };
    let turn = rotate.to_radians();
    let turn = glam::Vec2::new(fmath::cos(turn), fmath::sin(turn));
    let slot = if image.is_some() { env_slot } else { NONE };
    (Light::Environment { radiance, image: slot, turn, mean, bounds }, image.map(SkyDistribution::new))
}

/// The sphere around the bounded primitives (planes are not counted), from which the infinitely distant
/// lights' photons leave: the bounding box's centre and half its diagonal; a unit sphere about the origin when
/// there is no bounded primitive.
fn bounding_sphere(geometry: &Geometry) -> BoundingSphere {
    let b = geometry.bounds();
    let (min, max) = (Vec3A::from(b.min), Vec3A::from(b.max));
    let radius = 0.5 * (max - min).length();
    if radius.is_finite() && radius > 0.0 {
        BoundingSphere { center: 0.5 * (min + max), radius }
    } else {
        BoundingSphere { center: Vec3A::ZERO, radius: 1.0 }
    }
}
