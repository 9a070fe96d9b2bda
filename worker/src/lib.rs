//! photon-worker: renders strips of a prepared scene.
