//! Photon maps: the photons stored at diffuse hits ([`map`]), the kd-tree over them and the radiance estimate
//! with normalised kernels ([`kernel`]), and the set of maps a photon method reads ([`PhotonMaps`]).
//!
//! Tracing photons needs the prepared scene, so it lives in `prepare::photons`; this module knows only photons,
//! never lights or geometry. A new density-estimation kernel is a variant of [`Kernel`].

pub mod kernel;
pub mod map;
mod maps;

pub use kernel::{Estimator, Gather, Kernel};
pub use map::{Photon, PhotonMap, PhotonMapError};
pub use maps::{PhotonMaps, photon_flux, photon_radiance, precompute_irradiance, volume_radiance, with_scratch};
