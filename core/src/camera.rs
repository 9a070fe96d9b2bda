//! A perspective camera with an optional thin lens.
//!
//! ```toml
//! [camera]
//! eye = [0.0, 1.0, 3.4]
//! look_at = [0.0, 1.0, 0.0]
//! up = [0.0, 1.0, 0.0]
//! fov = 40.0             # vertical, degrees
//! width = 512
//! height = 512
//! aperture = 0.0         # lens radius; 0 is a pinhole
//! ```

use crate::error::FieldError;
use crate::math::Ray;
use crate::math::fmath;
use crate::scene::CameraSpec;
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};

/// The camera, ready to generate rays.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    eye: Vec3A,
    /// Unit vectors: right, up, forward.
    right: Vec3A,
    up: Vec3A,
    forward: Vec3A,
    /// Half extents of the image plane at distance 1.
    half_w: f32,
    half_h: f32,
    lens_radius: f32,
    focus: f32,
    /// Image size in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// A camera from its scene description (already validated).
    pub fn new(spec: &CameraSpec) -> Self {
        let eye = Vec3A::from(spec.eye);
        let forward = fmath::normalize(Vec3A::from(spec.look_at) - eye);
        let right = fmath::normalize(fmath::cross(forward, Vec3A::from(spec.up)));
        let up = fmath::cross(right, forward);
        let half_h = fmath::tan(spec.fov.to_radians() * 0.5);
        let half_w = half_h * spec.width as f32 / spec.height as f32;
        let focus = spec.focus_distance.unwrap_or_else(|| (spec.look_at - spec.eye).length());
        Self {
            eye,
            right,
            up,
            forward,
            half_w,
            half_h,
            lens_radius: spec.aperture,
            focus,
            width: spec.width,
            height: spec.height,
        }
    }

    /// The ray through film position `film` (pixels, from the top-left corner; `(x + 0.5, y + 0.5)` is the centre
    /// of pixel (x, y)) and lens sample `lens`.
    #[inline]
    pub fn ray(&self, film: Vec2, lens: Vec2) -> Ray {
        let sx = (2.0 * film.x / self.width as f32 - 1.0) * self.half_w;
        let sy = (1.0 - 2.0 * film.y / self.height as f32) * self.half_h;
        let d = fmath::normalize(self.forward + sx * self.right + sy * self.up);
        if self.lens_radius <= 0.0 {
            return Ray::new(self.eye, d);
        }
        // Thin lens: every ray through the lens meets the pinhole ray on the plane of focus.
        let focus_point = self.eye + d * (self.focus / d.dot(self.forward));
        let l = crate::math::concentric_disk(lens) * self.lens_radius;
        let o = self.eye + l.x * self.right + l.y * self.up;
        Ray::new(o, fmath::normalize(focus_point - o))
    }

    /// Checks a camera that arrived from elsewhere (a frame blob) as the scene's validation checks the
    /// `[camera]` it is built from: sizes within the limits, every number finite, the frame's axes unit length.
    /// Errors name the field under `camera.`.
    pub fn check(&self) -> Result<(), FieldError> {
        crate::scene::image_side("camera.width", self.width)?;
        crate::scene::image_side("camera.height", self.height)?;
        for (name, v) in [("eye", self.eye), ("right", self.right), ("up", self.up), ("forward", self.forward)] {
            let unit = name == "eye" || (v.length() - 1.0).abs() < 1e-3;
            if !v.is_finite() || !unit {
                return Err(FieldError::new(
                    format!("camera.{name}"),
                    format!("expected a finite unit vector, found {v}"),
                ));
            }
        }
        for (name, v) in [("half_width", self.half_w), ("half_height", self.half_h), ("focus", self.focus)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(FieldError::new(
                    format!("camera.{name}"),
                    format!("expected a positive number, found {v}"),
                ));
            }
        }
        if !(self.lens_radius.is_finite() && self.lens_radius >= 0.0) {
            return Err(FieldError::new(
                "camera.aperture",
                format!("expected a non-negative number, found {}", self.lens_radius),
            ));
        }
        Ok(())
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3A {
        self.eye
    }

    /// The unit viewing direction.
    pub fn forward(&self) -> Vec3A {
        self.forward
    }

    /// A point on the lens for the 2D sample `u` (the eye for a pinhole): uniform over the lens disc, as
    /// [`Camera::ray`] places its origins.
    #[inline]
    pub fn lens_point(&self, u: Vec2) -> Vec3A {
        if self.lens_radius <= 0.0 {
            return self.eye;
        }
        let l = crate::math::concentric_disk(u) * self.lens_radius;
        self.eye + l.x * self.right + l.y * self.up
    }

    /// The film position (pixels, as [`Camera::ray`] takes it) of the ray that leaves lens point `o` in unit
    /// direction `d`, and `cos θ = d · forward`; `None` when `d` does not point forwards or the position is off
    /// the film. The inverse of [`Camera::ray`]: a thin lens sends every ray through the point where the pinhole
    /// ray of its film position meets the plane of focus.
    pub fn film_position(&self, o: Vec3A, d: Vec3A) -> Option<(Vec2, f32)> {
        let cos = d.dot(self.forward);
        if cos.is_nan() || cos <= 0.0 {
            return None;
        }
        // The direction from the eye to where the ray meets the plane of focus (the ray itself for a pinhole),
        // scaled to reach the image plane at distance 1.
        let q = if self.lens_radius <= 0.0 {
            d / cos
        } else {
            let focus_point = o + d * (self.focus / cos);
            (focus_point - self.eye) / self.focus
        };
        let (sx, sy) = (q.dot(self.right), q.dot(self.up));
        let film = Vec2::new(
            (sx / self.half_w + 1.0) * 0.5 * self.width as f32,
            (1.0 - sy / self.half_h) * 0.5 * self.height as f32,
        );
        let inside = film.x >= 0.0 && film.y >= 0.0 && film.x < self.width as f32 && film.y < self.height as f32;
        (inside && film.is_finite()).then_some((film, cos))
    }

    /// The width of one pixel (scene units) on the plane of focus (the plane through `look_at` unless
    /// `focus_distance` is set): the scale of detail the image resolves there.
    pub fn pixel_footprint(&self) -> f32 {
        2.0 * self.half_h * self.focus / self.height as f32
    }

    /// The solid-angle density, at a lens point, of the direction of a camera ray sampled uniformly within one
    /// pixel, for a ray at `cos θ = cos` to the viewing direction: `1 / (A_pixel · cos³θ)`, with `A_pixel` the
    /// pixel's area on the image plane at distance 1 (the image-plane density `1/A_pixel` turned into solid
    /// angle by `d²/cos θ`, `d = 1/cos θ`). For a thin lens the plane of focus scales area and distance alike,
    /// so the density is the same. This is the camera's importance per pixel, the `W_e` of light tracing
    /// (Veach 1997, §10.2; pbrt-v4 §5.2.2, where the lens area cancels against its sampling density).
    #[inline]
    pub fn pixel_direction_pdf(&self, cos: f32) -> f32 {
        let pixel_area = 4.0 * self.half_w * self.half_h / (self.width as f32 * self.height as f32);
        1.0 / (pixel_area * cos * cos * cos)
    }
}
