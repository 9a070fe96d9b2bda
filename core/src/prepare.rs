//! From a parsed [`Scene`] to the [`Prepared`] value that renders: meshes loaded, primitives gathered under a
//! BVH, materials resolved to indices, lights built.

use crate::Rgb;
use crate::camera::Camera;
use crate::codec::{self, CodecError};
use crate::geometry::{Geometry, NONE, PlanePrimitive, Primitive};
use crate::integrator::PhotonMaps;
use crate::light::{Light, LightSet};
use crate::material::Material;
use crate::photon::{PhotonKind, trace_photons};
use crate::photon_map::{Estimator, Gather, PhotonMap};
use crate::scene::{Emission, GatherMode, Integrator, LightSpec, Object, RenderSettings, Scene, SceneError};
use crate::shapes::{Plane, Shape, Sphere, Triangle};
use glam::Vec3A;
use serde::{Deserialize, Serialize};

/// The scene blob, written from borrowed parts and read into owned ones (the same encoding).
#[derive(Serialize)]
struct SceneRef<'a> {
    geometry: &'a Geometry,
    materials: &'a [Material],
    lights: &'a LightSet,
}

#[derive(Deserialize)]
struct SceneOwned {
    geometry: Geometry,
    materials: Vec<Material>,
    lights: LightSet,
}

/// The frame blob, borrowed and owned.
#[derive(Serialize)]
struct FrameRef<'a> {
    camera: &'a Camera,
    settings: &'a RenderSettings,
}

#[derive(Deserialize)]
struct FrameOwned {
    camera: Camera,
    settings: RenderSettings,
}

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
}

impl Prepared {
    /// Loads meshes, builds the BVH, the lights and the photon maps the method needs, for a validated scene.
    /// `scene_path` names the scene in errors.
    pub fn new(scene: &Scene, scene_path: &std::path::Path) -> Result<Self, SceneError> {
        let mut prep = Self::without_photons(scene, scene_path)?;
        prep.photons = prep.photon_maps_if_needed(scene_path)?;
        Ok(prep)
    }

    /// The photon maps the method needs (`None` for methods without maps, and for progressive photon mapping,
    /// which traces its own photons pass by pass).
    pub fn photon_maps_if_needed(&self, scene_path: &std::path::Path) -> Result<Option<PhotonMaps>, SceneError> {
        if !self.settings.integrator.needs_photon_maps() {
            return Ok(None);
        }
        self.build_photon_maps().map(Some).map_err(|message| SceneError::Invalid {
            path: scene_path.into(),
            field: "render.photons".into(),
            message,
        })
    }

    /// Like [`Prepared::new`], without photon maps: meshes, BVH, materials and lights only.
    pub fn without_photons(scene: &Scene, scene_path: &std::path::Path) -> Result<Self, SceneError> {
        let names: Vec<&String> = scene.materials.keys().collect();
        let materials: Vec<Material> = scene.materials.values().cloned().collect();
        let material_index = |name: &str, field: String| -> Result<u32, SceneError> {
            names.iter().position(|n| n.as_str() == name).map(|i| i as u32).ok_or_else(|| SceneError::Invalid {
                path: scene_path.into(),
                field,
                message: format!("no material named `{name}`"),
            })
        };
        let mut prims: Vec<Primitive> = Vec::new();
        let mut planes = Vec::new();
        let mut meshes = Vec::new();
        // Emission of each light-carrying primitive, by light index, before the BVH reorders primitives.
        let mut emitters: Vec<Emission> = Vec::new();
        for (i, o) in scene.objects.iter().enumerate() {
            let object = i as u32;
            let material = material_index(o.material(), format!("objects[{i}].material"))?;
            let mut push = |shape: Shape, emission: &Option<Emission>| {
                let light = match emission {
                    Some(e) if e.radiance.max_element() > 0.0 && shape.area() > 0.0 => {
                        emitters.push(*e);
                        (emitters.len() - 1) as u32
                    }
                    _ => NONE,
                };
                prims.push(Primitive { shape, material, light, object });
            };
            match o {
                Object::Sphere { center, radius, emission, .. } => {
                    push(Shape::Sphere(Sphere { center: *center, radius: *radius }), emission)
                }
                Object::Plane { point, normal, .. } => planes.push(PlanePrimitive {
                    plane: Plane { point: *point, normal: normal.normalize() },
                    material,
                    object,
                }),
                Object::Rect { emission, .. } => {
                    let rect = o.rect().map_err(|(field, message)| SceneError::Invalid {
                        path: scene_path.into(),
                        field: format!("objects[{i}].{field}"),
                        message,
                    })?;
                    push(Shape::Rect(rect), emission)
                }
                Object::Triangle { vertices, emission, .. } => {
                    push(Shape::Triangle(Triangle::new(vertices[0], vertices[1], vertices[2])), emission)
                }
                Object::Mesh { file, transform, emission, .. } => {
                    let path = scene.base_dir.join(file);
                    let mesh = crate::mesh::load_obj(&path, &transform.matrix()).map_err(|source| {
                        SceneError::Mesh { path: scene_path.into(), field: format!("objects[{i}].file"), source }
                    })?;
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
            }
        }
        let geometry = Geometry::new(prims, planes, meshes);
        let mut lights: Vec<Light> = Vec::new();
        let mut area_lights: Vec<(u32, Light)> = Vec::new();
        for (pi, p) in geometry.prims.iter().enumerate() {
            if p.light != NONE {
                let e = emitters[p.light as usize];
                area_lights.push((
                    p.light,
                    Light::Area {
                        prim: pi as u32,
                        le: Rgb::from(e.radiance),
                        two_sided: e.two_sided,
                        area: p.shape.area(),
                    },
                ));
            }
        }
        // Keep lights in scene order (by their original index), whatever order the BVH put primitives in.
        area_lights.sort_by_key(|(k, _)| *k);
        lights.extend(area_lights.into_iter().map(|(_, l)| l));
        for l in &scene.lights {
            match l {
                LightSpec::Point { position, intensity, power } => {
                    let intensity = match (intensity, power) {
                        (Some(i), _) => Rgb::from(*i),
                        (None, Some(p)) => Rgb::from(*p) / (4.0 * std::f32::consts::PI),
                        (None, None) => Rgb::ZERO,
                    };
                    lights.push(Light::Point { p: Vec3A::from(*position), intensity });
                }
            }
        }
        let mut geometry = geometry;
        // Primitives point at their light by the final light index.
        let mut light_of_prim = vec![NONE; geometry.prims.len()];
        for (li, l) in lights.iter().enumerate() {
            if let Light::Area { prim, .. } = l {
                light_of_prim[*prim as usize] = li as u32;
            }
        }
        for (p, l) in geometry.prims.iter_mut().zip(light_of_prim) {
            p.light = l;
        }
        Ok(Self {
            camera: Camera::new(&scene.camera),
            geometry,
            materials,
            lights: LightSet::new(lights),
            settings: scene.render.clone(),
            photons: None,
        })
    }

    /// The scene blob: geometry with its BVH, materials and lights (what stays the same from frame to frame).
    pub fn encode_scene(&self) -> Result<Vec<u8>, CodecError> {
        codec::encode(&SceneRef { geometry: &self.geometry, materials: &self.materials, lights: &self.lights })
    }

    /// The photons blob, when there are photon maps.
    pub fn encode_photons(&self) -> Result<Option<Vec<u8>>, CodecError> {
        self.photons.as_ref().map(codec::encode).transpose()
    }

    /// The frame blob: camera and render settings (small; it travels with every strip request).
    pub fn encode_frame(&self) -> Result<Vec<u8>, CodecError> {
        Self::encode_frame_of(&self.camera, &self.settings)
    }

    /// The frame blob of a camera and settings.
    pub fn encode_frame_of(camera: &Camera, settings: &RenderSettings) -> Result<Vec<u8>, CodecError> {
        codec::encode(&FrameRef { camera, settings })
    }

    /// A prepared scene from its scene blob, a camera and settings, without photon maps.
    pub fn from_scene_blob(
        scene: &[u8],
        camera: Camera,
        settings: RenderSettings,
        limit: usize,
    ) -> Result<Self, CodecError> {
        let s: SceneOwned = codec::decode(scene, limit)?;
        let (geometry, materials, lights) = (s.geometry, s.materials, s.lights);
        Ok(Self { camera, geometry, materials, lights, settings, photons: None })
    }

    /// Reassembles a prepared scene from its blobs, refusing any blob longer than `limit` bytes.
    pub fn from_blobs(scene: &[u8], photons: Option<&[u8]>, frame: &[u8], limit: usize) -> Result<Self, CodecError> {
        let s: SceneOwned = codec::decode(scene, limit)?;
        let f: FrameOwned = codec::decode(frame, limit)?;
        let photons = photons.map(|p| codec::decode(p, limit)).transpose()?;
        Ok(Self {
            camera: f.camera,
            geometry: s.geometry,
            materials: s.materials,
            lights: s.lights,
            settings: f.settings,
            photons,
        })
    }

    /// The gather radius in scene units: `render.photons.radius`, or 2% of the diagonal of the bounding box of
    /// the bounded primitives (1 unit for a scene of planes only).
    pub fn photon_radius(&self) -> f32 {
        self.settings.photons.radius.unwrap_or_else(|| {
            let b = self.geometry.bounds();
            let d = (b.max - b.min).length();
            if d.is_finite() && d > 0.0 { 0.02 * d } else { 1.0 }
        })
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

    /// Traces and builds the photon maps of the method: the global map, and the caustic map for
    /// `final-gather` when some material has a delta (mirror or glass) component.
    pub fn build_photon_maps(&self) -> Result<PhotonMaps, String> {
        let ph = &self.settings.photons;
        let global = trace_photons(self, u64::from(ph.global), 0, PhotonKind::Global);
        tracing::info!(paths = global.paths, photons = global.photons.len(), "global photon map traced");
        let global = PhotonMap::build(global.photons).map_err(|e| e.to_string())?;
        let caustic = if self.settings.integrator == Integrator::FinalGather
            && self.materials.iter().any(Material::has_specular)
        {
            // Pass index 1 keeps the caustic streams apart from the global ones.
            let c = trace_photons(self, u64::from(ph.caustic), 1, PhotonKind::Caustic);
            tracing::info!(paths = c.paths, photons = c.photons.len(), "caustic photon map traced");
            Some(PhotonMap::build(c.photons).map_err(|e| e.to_string())?)
        } else {
            None
        };
        let estimator = self.estimator();
        let irradiance = if self.settings.integrator == Integrator::FinalGather {
            let entries = crate::integrator::precompute_irradiance(&global, &estimator, 4);
            Some(PhotonMap::build(entries).map_err(|e| e.to_string())?)
        } else {
            None
        };
        Ok(PhotonMaps { global, caustic, estimator, irradiance })
    }

    /// Loads and prepares a scene file.
    pub fn load(path: &std::path::Path) -> Result<Self, SceneError> {
        let scene = Scene::load(path)?;
        Self::new(&scene, path)
    }
}
