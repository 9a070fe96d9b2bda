//! The one error shape that every check of a value shares: which field, and what was expected. Scene
//! validation turns it into a `SceneError` with the file and the line of the field.

/// A value that is not allowed, named by its field (a dotted path such as `objects[3].radius`, or a path
/// relative to the caller's, which [`FieldError::within`] completes).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct FieldError {
    /// The field, e.g. `objects[3].radius` or `albedo`.
    pub field: String,
    /// What was expected, and what was found.
    pub message: String,
}

impl FieldError {
    /// An error of `field`.
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self { field: field.into(), message: message.into() }
    }

    /// The same error with its field placed under `parent` (`albedo` within `materials.white` is
    /// `materials.white.albedo`).
    pub fn within(self, parent: &str) -> Self {
        Self { field: format!("{parent}.{}", self.field), message: self.message }
    }
}
