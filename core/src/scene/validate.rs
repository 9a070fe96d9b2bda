//! Scene validation: every value the types accept but the renderer cannot use (ranges, finiteness, names that
//! must exist), reported as a [`FieldError`] that names the field; `Scene::parse` adds the file and line.

use super::limits::{MAX_CAMERA_COORDINATE, MAX_K, MAX_PASSES, image_side};
use super::{LightSpec, Object, RenderSettings, Scene, Transform};
use crate::error::FieldError;
use crate::geometry::shapes::Rect;
use glam::Vec3;

impl Scene {
    /// Whether the scene has participating media: a global `medium`, an object's `interior`, or an
    /// `interface` material.
    pub fn has_media(&self) -> bool {
        self.medium.is_some()
            || self.materials.values().any(crate::material::Material::is_interface)
            || self
                .objects
                .iter()
                .any(|o| matches!(o, Object::Sphere { interior: Some(_), .. } | Object::Mesh { interior: Some(_), .. }))
    }

    /// Checks every value the types cannot: ranges, finiteness, names that must exist. The first error
    /// found, in the order camera, render, materials, objects, lights.
    pub(super) fn check(&self) -> Result<(), FieldError> {
        self.check_camera()?;
        self.render.check()?;
        for (name, m) in &self.materials {
            m.validate().map_err(|e| e.within(&format!("materials.{name}")))?;
        }
        for (i, o) in self.objects.iter().enumerate() {
            self.check_object(i, o)?;
        }
        check_lights(self)?;
        if let Some(m) = &self.medium {
            m.check().map_err(|e| e.within("medium"))?;
        }
        Ok(())
    }

    fn check_camera(&self) -> Result<(), FieldError> {
        let c = &self.camera;
        // The camera is set up in f32: squares and cross products of coordinates beyond this would overflow
        // (3.4e38), so such a value is refused here with its own field rather than failing a later check.
        coordinate3("camera.eye", c.eye)?;
        coordinate3("camera.look_at", c.look_at)?;
        coordinate3("camera.up", c.up)?;
        nonzero3("camera.up", c.up)?;
        // In f64, where these products cannot overflow.
        let (eye, look_at, up) = (c.eye.as_dvec3(), c.look_at.as_dvec3(), c.up.as_dvec3());
        let view = look_at - eye;
        if view.length() == 0.0 {
            return Err(FieldError::new("camera.look_at", "must differ from camera.eye"));
        }
        // Relative, so that a nearly parallel `up` is caught whatever the scene's scale.
        if up.cross(view).length() <= 1e-6 * up.length() * view.length() {
            return Err(FieldError::new("camera.up", "must not be parallel to the viewing direction"));
        }
        if !(c.fov > 0.0 && c.fov < 180.0) {
            return Err(FieldError::new("camera.fov", format!("expected degrees in (0, 180), found {}", c.fov)));
        }
        for (name, v) in [("camera.width", c.width), ("camera.height", c.height)] {
            image_side(name, v)?;
        }
        positive_or_zero("camera.aperture", c.aperture)?;
        if let Some(f) = c.focus_distance {
            positive("camera.focus_distance", f)?;
        }
        Ok(())
    }

    fn check_object(&self, i: usize, o: &Object) -> Result<(), FieldError> {
        let f = |s: &str| format!("objects[{i}].{s}");
        if let Some(material) = o.material()
            && !self.materials.contains_key(material)
        {
            let known: Vec<&str> = self.materials.keys().map(String::as_str).collect();
            return Err(FieldError::new(
                f("material"),
                format!(
                    "no material named `{}` (defined: {})",
                    crate::input::excerpt(material),
                    crate::input::excerpt(&known.join(", "))
                ),
            ));
        }
        let emission = match o {
            Object::Sphere { center, radius, emission, interior, .. } => {
                finite3(&f("center"), *center)?;
                positive(&f("radius"), *radius)?;
                if let Some(m) = interior {
                    m.check().map_err(|e| e.within(&f("interior")))?;
                }
                emission
            }
            Object::Plane { point, normal, .. } => {
                finite3(&f("point"), *point)?;
                nonzero3(&f("normal"), *normal)?;
                &None
            }
            Object::Rect { emission, .. } => {
                o.rect().map_err(|e| e.within(&format!("objects[{i}]")))?;
                emission
            }
            Object::Triangle { vertices, emission, uv, .. } => {
                for (k, v) in vertices.iter().enumerate() {
                    finite3(&f(&format!("vertices[{k}]")), *v)?;
                }
                if let Some(uv) = uv {
                    finite_uvs(&f("uv"), uv)?;
                }
                // A triangle without area can never be hit: as a light it would silently emit nothing.
                let [p0, p1, p2] = *vertices;
                if (p1 - p0).cross(p2 - p0).length() == 0.0 {
                    return Err(FieldError::new(f("vertices"), "the vertices are collinear: the triangle has no area"));
                }
                emission
            }
            Object::Mesh { transform, emission, crease_angle, lod, interior, .. } => {
                positive_or_zero(&f("lod"), *lod)?;
                if let Some(m) = interior {
                    m.check().map_err(|e| e.within(&f("interior")))?;
                }
                if !(0.0..=180.0).contains(crease_angle) {
                    return Err(FieldError::new(
                        f("crease_angle"),
                        format!("expected an angle in degrees from 0 to 180, found {crease_angle}"),
                    ));
                }
                check_transform(&f("transform"), transform)?;
                emission
            }
            Object::Gltf { transform, .. } => {
                check_transform(&f("transform"), transform)?;
                &None
            }
        };
        if let Some(e) = emission {
            if o.material().and_then(|m| self.materials.get(m)).is_some_and(crate::material::Material::is_interface) {
                return Err(FieldError::new(
                    f("emission"),
                    format!(
                        "material `{}` is an interface, which has no surface to emit light from",
                        crate::input::excerpt(o.material().unwrap_or_default())
                    ),
                ));
            }
            let v = e.radiance;
            if !v.is_finite() || v.min_element() < 0.0 {
                return Err(FieldError::new(
                    f("emission.radiance"),
                    format!("expected finite non-negative radiance, found {v}"),
                ));
            }
        }
        Ok(())
    }
}

impl Object {
    /// The rectangle this object describes, from either of its two forms; errors name the field.
    pub fn rect(&self) -> Result<Rect, FieldError> {
        let Object::Rect { center, normal, tangent, width, height, corner, u, v, .. } = self else {
            return Err(FieldError::new("type", "not a rectangle"));
        };
        match (center, corner) {
            (Some(c), None) => {
                if u.is_some() || v.is_some() {
                    let field = if u.is_some() { "u" } else { "v" };
                    return Err(FieldError::new(field, "`u` and `v` go with `corner`, not with `center`"));
                }
                finite3("center", *c)?;
                let n = normal.ok_or_else(|| FieldError::new("normal", "a rectangle with `center` needs `normal`"))?;
                nonzero3("normal", n)?;
                let t = match tangent {
                    Some(t) => {
                        nonzero3("tangent", *t)?;
                        if t.cross(n).length() <= 1e-6 * t.length() * n.length() {
                            return Err(FieldError::new("tangent", "must not be parallel to the normal"));
                        }
                        *t
                    }
                    None => crate::math::Frame::from_normal(glam::Vec3A::from(n.normalize())).s.into(),
                };
                let w = width.ok_or_else(|| FieldError::new("width", "a rectangle with `center` needs `width`"))?;
                let h = height.ok_or_else(|| FieldError::new("height", "a rectangle with `center` needs `height`"))?;
                positive("width", w)?;
                positive("height", h)?;
                Ok(Rect::from_center(*c, n, t, w, h))
            }
            (None, Some(c)) => {
                if normal.is_some() || tangent.is_some() || width.is_some() || height.is_some() {
                    return Err(FieldError::new(
                        "corner",
                        "use either `corner`, `u`, `v` or `center`, `normal`, `tangent`, `width`, `height`",
                    ));
                }
                finite3("corner", *c)?;
                let u = u.ok_or_else(|| FieldError::new("u", "a rectangle with `corner` needs edges `u` and `v`"))?;
                let v = v.ok_or_else(|| FieldError::new("v", "a rectangle with `corner` needs edges `u` and `v`"))?;
                finite3("u", u)?;
                finite3("v", v)?;
                if u.cross(v).length() == 0.0 {
                    return Err(FieldError::new("v", "the edges `u` and `v` must not be parallel or zero"));
                }
                Ok(Rect { corner: *c, u, v })
            }
            (Some(_), Some(_)) => Err(FieldError::new("corner", "give `center` or `corner`, not both")),
            (None, None) => Err(FieldError::new("center", "a rectangle needs `center` (or `corner`)")),
        }
    }
}

impl RenderSettings {
    /// Checks the render settings, whether they come from a scene file or from the wire (a worker checks the
    /// frame it is sent with the same rules); errors name the field under `render.`.
    pub fn check(&self) -> Result<(), FieldError> {
        let r = self;
        if r.spp == 0 {
            return Err(FieldError::new("render.spp", "expected at least 1 sample per pixel"));
        }
        if r.max_depth == 0 {
            return Err(FieldError::new("render.max_depth", "expected at least 1 bounce"));
        }
        let ph = &r.photons;
        let pf = |s: &str| format!("render.photons.{s}");
        if ph.global == 0 {
            return Err(FieldError::new(pf("global"), "expected at least 1 photon path"));
        }
        if !(2..=MAX_K).contains(&ph.k) {
            return Err(FieldError::new(pf("k"), format!("expected 2 to {MAX_K} photons, found {}", ph.k)));
        }
        if let Some(radius) = ph.volume_radius {
            positive(&pf("volume_radius"), radius)?;
        }
        if let Some(radius) = ph.radius {
            positive(&pf("radius"), radius)?;
        }
        if let Some(radius) = ph.merge_radius {
            positive(&pf("merge_radius"), radius)?;
        }
        if let Some(disc) = ph.disc {
            positive(&pf("disc"), disc)?;
        }
        if !(ph.alpha > 0.0 && ph.alpha < 1.0) {
            return Err(FieldError::new(pf("alpha"), format!("expected a number in (0, 1), found {}", ph.alpha)));
        }
        if !(0.0..=1.0).contains(&ph.min_roughness) {
            return Err(FieldError::new(
                pf("min_roughness"),
                format!("expected a roughness in [0, 1], found {}", ph.min_roughness),
            ));
        }
        for (name, v) in
            [("passes", ph.passes), ("pass_photons", ph.pass_photons), ("final_gather_rays", ph.final_gather_rays)]
        {
            if v == 0 {
                return Err(FieldError::new(pf(name), "expected at least 1"));
            }
        }
        if ph.passes > MAX_PASSES {
            return Err(FieldError::new(pf("passes"), format!("expected at most {MAX_PASSES}, found {}", ph.passes)));
        }
        if !r.exposure.is_finite() {
            return Err(FieldError::new("render.exposure", "expected a finite number of stops"));
        }
        Ok(())
    }
}

/// The lights: each one's fields ([`check_light`]), at most one environment, and no infinitely distant light
/// (an environment or a directional light) in a scene with participating media, whose paths do not reach
/// infinity.
fn check_lights(scene: &Scene) -> Result<(), FieldError> {
    let mut environment = None;
    for (i, l) in scene.lights.iter().enumerate() {
        check_light(i, l)?;
        let infinite = matches!(l, LightSpec::Environment { .. } | LightSpec::Directional { .. });
        if infinite && scene.has_media() {
            return Err(FieldError::new(
                format!("lights[{i}].type"),
                "environment and directional lights are not supported in a scene with participating media \
                 (a `medium`, an `interior` or an `interface` material)",
            ));
        }
        if matches!(l, LightSpec::Environment { .. }) {
            if let Some(first) = environment {
                return Err(FieldError::new(
                    format!("lights[{i}].type"),
                    format!("a scene has at most one environment; lights[{first}] is one already"),
                ));
            }
            environment = Some(i);
        }
    }
    Ok(())
}

/// Exactly one of a light's `intensity` and `power`, finite and non-negative.
fn check_intensity(
    f: &dyn Fn(&str) -> String,
    intensity: &Option<Vec3>,
    power: &Option<Vec3>,
) -> Result<(), FieldError> {
    let (name, v) = match (intensity, power) {
        (Some(i), None) => ("intensity", *i),
        (None, Some(p)) => ("power", *p),
        _ => return Err(FieldError::new(f("intensity"), "give exactly one of `intensity` and `power`")),
    };
    non_negative3(&f(name), v)
}

fn non_negative3(field: &str, v: Vec3) -> Result<(), FieldError> {
    if !v.is_finite() || v.min_element() < 0.0 {
        return Err(FieldError::new(field, format!("expected finite non-negative values, found {v}")));
    }
    Ok(())
}

fn check_light(i: usize, l: &LightSpec) -> Result<(), FieldError> {
    let f = |s: &str| format!("lights[{i}].{s}");
    match l {
        LightSpec::Point { position, intensity, power } => {
            finite3(&f("position"), *position)?;
            check_intensity(&f, intensity, power)?;
        }
        LightSpec::Spot { position, direction, intensity, power, inner_angle, outer_angle } => {
            finite3(&f("position"), *position)?;
            nonzero3(&f("direction"), *direction)?;
            check_intensity(&f, intensity, power)?;
            if !(*outer_angle > 0.0 && *outer_angle <= 90.0) {
                return Err(FieldError::new(
                    f("outer_angle"),
                    format!("expected degrees in (0, 90], found {outer_angle}"),
                ));
            }
            if !(*inner_angle >= 0.0 && inner_angle <= outer_angle) {
                return Err(FieldError::new(
                    f("inner_angle"),
                    format!("expected degrees in [0, outer_angle = {outer_angle}], found {inner_angle}"),
                ));
            }
        }
        LightSpec::Directional { direction, irradiance } => {
            nonzero3(&f("direction"), *direction)?;
            non_negative3(&f("irradiance"), *irradiance)?;
        }
        LightSpec::Environment { radiance, image, scale, rotate } => {
            match (radiance, image) {
                (Some(r), None) => non_negative3(&f("radiance"), *r)?,
                (None, Some(_)) => {}
                _ => return Err(FieldError::new(f("radiance"), "give exactly one of `radiance` and `image`")),
            }
            if !(scale.is_finite() && *scale >= 0.0) {
                return Err(FieldError::new(f("scale"), format!("expected a finite number ≥ 0, found {scale}")));
            }
            if radiance.is_some() && *scale != 1.0 {
                return Err(FieldError::new(f("scale"), "`scale` goes with `image`; with `radiance` leave it out"));
            }
            if !rotate.is_finite() {
                return Err(FieldError::new(f("rotate"), format!("expected degrees, found {rotate}")));
            }
        }
    }
    Ok(())
}

/// A finite camera vector whose coordinates are at most [`MAX_CAMERA_COORDINATE`] in absolute value.
fn coordinate3(field: &str, v: Vec3) -> Result<(), FieldError> {
    finite3(field, v)?;
    if v.abs().max_element() > MAX_CAMERA_COORDINATE {
        return Err(FieldError::new(
            field,
            format!("expected coordinates within ±{MAX_CAMERA_COORDINATE:e} (the camera works in f32), found {v}"),
        ));
    }
    Ok(())
}

/// Every texture coordinate of `uv` finite; the error names `field[k]`.
fn finite_uvs(field: &str, uv: &[[f32; 2]]) -> Result<(), FieldError> {
    match uv.iter().enumerate().find(|(_, c)| !(c[0].is_finite() && c[1].is_finite())) {
        Some((k, c)) => {
            Err(FieldError::new(format!("{field}[{k}]"), format!("expected finite numbers, got [{}, {}]", c[0], c[1])))
        }
        None => Ok(()),
    }
}

/// A transform's translation and rotation finite and its scale finite and non-zero on every axis; the error names
/// `field.translate`, `field.rotate` or `field.scale`.
fn check_transform(field: &str, t: &Transform) -> Result<(), FieldError> {
    finite3(&format!("{field}.translate"), t.translate)?;
    finite3(&format!("{field}.rotate"), t.rotate)?;
    let s = t.scale.to_vec3();
    if !s.is_finite() || s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
        return Err(FieldError::new(format!("{field}.scale"), format!("expected finite non-zero factors, found {s}")));
    }
    Ok(())
}

fn finite3(field: &str, v: Vec3) -> Result<(), FieldError> {
    if v.is_finite() { Ok(()) } else { Err(FieldError::new(field, format!("expected finite numbers, found {v}"))) }
}

fn nonzero3(field: &str, v: Vec3) -> Result<(), FieldError> {
    finite3(field, v)?;
    if v.length() > 0.0 { Ok(()) } else { Err(FieldError::new(field, "expected a non-zero vector")) }
}

fn positive(field: &str, x: f32) -> Result<(), FieldError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(FieldError::new(field, format!("expected a positive number, found {x}")))
    }
}

fn positive_or_zero(field: &str, x: f32) -> Result<(), FieldError> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(FieldError::new(field, format!("expected a non-negative number, found {x}")))
    }
}
